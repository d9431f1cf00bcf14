// core/device_memory.hpp — device memory that grows (and is trimmed where
// its owner's need fell), pinned host memory, streams and events, each freed
// with its owner (a constructor or a test that stops early leaks nothing).
// Plain C++ over the CUDA runtime: .cpp
// files that talk to the runtime include it too (core/device_buffer.cuh adds
// what needs the CUDA compiler).
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <stdexcept>
#include <utility>
#include <vector>

#include "core/cuda_check.hpp"

namespace marbles::cuda {

// Page-locked host memory for a stage's read-backs (count values of T),
// freed with its owner: a constructor that throws after it leaks nothing.
template <class T>
class PinnedBuffer {
 public:
  explicit PinnedBuffer(std::size_t count) {
    MARBLES_CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&m_ptr), count * sizeof(T)));
    m_count = count;
  }
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;
  ~PinnedBuffer() {
    if (m_ptr) cudaFreeHost(m_ptr);
  }
  operator T*() const { return m_ptr; }
  T* operator->() const { return m_ptr; }
  std::size_t size() const { return m_count; }

 private:
  T* m_ptr = nullptr;
  std::size_t m_count = 0;
};

// A runtime handle destroyed with its owner (Stream, Event).
template <class Handle, cudaError_t (*Destroy)(Handle)>
class Owned {
 public:
  Owned() = default;
  Owned(const Owned&) = delete;
  Owned& operator=(const Owned&) = delete;
  ~Owned() {
    if (m_handle) Destroy(m_handle);
  }
  operator Handle() const { return m_handle; }

 protected:
  Handle m_handle = nullptr;
};

// A stream, empty until create().
class Stream : public Owned<cudaStream_t, cudaStreamDestroy> {
 public:
  void create(unsigned flags = cudaStreamDefault) {
    if (!m_handle) MARBLES_CUDA_CHECK(cudaStreamCreateWithFlags(&m_handle, flags));
  }
};

// An event, created at once (only where a device is).
class Event : public Owned<cudaEvent_t, cudaEventDestroy> {
 public:
  Event() { MARBLES_CUDA_CHECK(cudaEventCreate(&m_handle)); }
};

// A device allocation that grows, to a sixteenth more than asked: room
// for a settled scene's contacts to come and go without a new allocation,
// little enough that the headroom is not a fifth of the device memory
// (docs/architecture.md "Headroom, the extra word and one read for the
// colouring"). Freed with its owner, or by trim() where its owner's need
// fell.
//
// Made with a stream, it takes and gives back its memory in that stream's
// order (cudaMallocAsync, cudaFreeAsync, from the device's default pool):
// neither waits for the device, and the pool (release threshold 0) gives
// the memory back at the next synchronisation, so a rare stage's
// temporaries (a renumbering's) cost no wait and are not held for the run.
// Where the device has no memory pools it allocates as a plain buffer does.
// Such a buffer stays local to its call (the stream must outlive it; swap()
// keeps each allocation with its own way of freeing).
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(cudaStream_t stream) : m_stream(stream), m_ordered(pools()) {}
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  ~DeviceBuffer() {
    if (!m_handle) return;
    if (m_ordered)
      cudaFreeAsync(m_handle, m_stream);
    else
      cudaFree(m_handle);
  }
  // headroom false: exactly `bytes` when it grows (for a count that carries
  // its own headroom: a room sized from the last count).
  void* reserve(std::size_t bytes, bool headroom = true) {
    m_asked = bytes > m_asked ? bytes : m_asked;
    if (bytes > m_bytes) {
      if (m_handle) MARBLES_CUDA_CHECK(m_ordered ? cudaFreeAsync(m_handle, m_stream) : cudaFree(m_handle));
      m_handle = nullptr;
      const std::size_t grown = headroom ? bytes + bytes / 16 + 256 : bytes;
      MARBLES_CUDA_CHECK(m_ordered ? cudaMallocAsync(&m_handle, grown, m_stream) : cudaMalloc(&m_handle, grown));
      m_bytes = grown;
    }
    return m_handle;
  }
  // As reserve(bytes), keeping the first `keep` bytes where it grows: they
  // are copied on `stream` (a stream-ordered buffer's own) into the new
  // memory, then the old is freed after the copy (in the stream's order, or
  // by cudaFree, which waits for the device).
  void* reserve_keeping(std::size_t bytes, std::size_t keep, cudaStream_t stream) {
    return reserve_copying(bytes, stream, [&](void* to, const void* from, std::size_t held) {
      if (keep > 0) MARBLES_CUDA_CHECK(cudaMemcpyAsync(to, from, keep < held ? keep : held, cudaMemcpyDeviceToDevice,
                                                       stream));
    });
  }
  // As reserve_keeping, the old contents handed to copy(to, from, held
  // bytes) on `stream` (where it grows and held memory): for a part known
  // only on the device (a kernel reading a count), so no byte is copied that
  // was never written.
  template <class Copy>
  void* reserve_copying(std::size_t bytes, cudaStream_t stream, Copy&& copy) {
    m_asked = bytes > m_asked ? bytes : m_asked;
    if (bytes <= m_bytes) return m_handle;
    if (m_ordered && stream != m_stream)
      throw std::logic_error("DeviceBuffer::reserve_copying: a stream-ordered buffer grows on its own stream");
    DeviceBuffer grown(m_stream);
    grown.m_ordered = m_ordered;
    grown.reserve(bytes);
    if (m_handle) copy(grown.m_handle, static_cast<const void*>(m_handle), m_bytes);
    swap(grown);              // the old memory goes with `grown`
    m_asked = grown.m_asked;  // the old count, which took `bytes` in above
    return m_handle;
  }
  template <class T>
  T* as(std::size_t count) {
    return static_cast<T*>(reserve(count * sizeof(T) + 16));
  }
  // As as(), without the headroom: `count` is a room that has its own.
  template <class T>
  T* as_room(std::size_t count) {
    return static_cast<T*>(reserve(count * sizeof(T) + 16, false));
  }
  template <class T>
  T* get_as() const {
    return static_cast<T*>(m_handle);
  }
  void* get() const { return m_handle; }
  std::size_t bytes() const { return m_bytes; }
  // The most bytes asked of it (reserve's `bytes`) since the last trim().
  std::size_t asked() const { return m_asked; }
  // Frees the memory where it holds more than an eighth and 4 KiB beyond
  // the most bytes asked of it since the last trim (a need that fell: a
  // transient's records or temporaries), to be reserved again, fitting, at
  // its next use; then counts the asked bytes afresh. Only while its
  // contents are dead: they are lost. A plain buffer's free waits for the
  // device; a stream-ordered one's memory goes back at the stream's next
  // synchronisation. True where it freed.
  bool trim() {
    const std::size_t asked = m_asked;
    if (!m_handle || m_bytes <= asked + asked / 8 + kTrimSlack) {
      m_asked = 0;
      return false;
    }
    release();
    return true;
  }
  // Frees the memory whatever was asked (its contents are lost), freed as
  // it was taken (a stream-ordered buffer stays one), and counts the asked
  // bytes afresh; reserved again, fitting, at its next use.
  void release() {
    if (m_handle) MARBLES_CUDA_CHECK(m_ordered ? cudaFreeAsync(m_handle, m_stream) : cudaFree(m_handle));
    m_handle = nullptr;
    m_bytes = 0;
    m_asked = 0;
  }
  // Whether it takes and gives back its memory in its stream's order.
  bool stream_ordered() const { return m_ordered; }
  static constexpr std::size_t kTrimSlack = 4096;
  void swap(DeviceBuffer& other) noexcept {
    std::swap(m_handle, other.m_handle);
    std::swap(m_bytes, other.m_bytes);
    std::swap(m_stream, other.m_stream);
    std::swap(m_ordered, other.m_ordered);
    std::swap(m_asked, other.m_asked);
  }

 private:
  // Whether the current device has memory pools (asked once).
  static bool pools() {
    static const bool supported = [] {
      int device = 0, value = 0;
      return cudaGetDevice(&device) == cudaSuccess &&
             cudaDeviceGetAttribute(&value, cudaDevAttrMemoryPoolsSupported, device) == cudaSuccess && value != 0;
    }();
    return supported;
  }

  void* m_handle = nullptr;
  std::size_t m_bytes = 0;
  std::size_t m_asked = 0;  // trim()'s: the most bytes asked since the last
  cudaStream_t m_stream = nullptr;
  bool m_ordered = false;
};

// The bytes the buffers hold together.
template <class... Buffers>
std::size_t bytes_of(const Buffers&... buffers) {
  return (std::size_t{0} + ... + buffers.bytes());
}

// Copies host[] into `buffer` (grown to fit), asynchronously on `stream`: the
// host vector must outlive the copy (synchronise before changing it).
template <class T>
T* upload(DeviceBuffer& buffer, const std::vector<T>& host, cudaStream_t stream) {
  T* d = buffer.as<T>(host.size());
  if (!host.empty())
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(d, host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice, stream));
  return d;
}

}  // namespace marbles::cuda
