// core/device_buffer.cuh — device memory that only grows, launch sizes, and
// the CUB calls every stage shares (scan, stable radix sort), with their
// temporary storage held by the caller and reused. Only .cu files include it.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include "core/cuda_check.hpp"

namespace marbles::cuda {

constexpr int kBlock = 256;

// Blocks for a grid-stride loop over n items.
inline int grid_for(std::size_t n, int sm_count, int per_sm = 8) {
  const std::size_t want = (n + kBlock - 1) / kBlock;
  const std::size_t cap = static_cast<std::size_t>(sm_count) * static_cast<std::size_t>(per_sm);
  return static_cast<int>(want < 1 ? 1 : (want < cap ? want : cap));
}

// A device allocation that only grows (by a quarter more than asked).
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  ~DeviceBuffer() {
    if (m_ptr) cudaFree(m_ptr);
  }
  void* reserve(std::size_t bytes) {
    if (bytes > m_bytes) {
      if (m_ptr) MARBLES_CUDA_CHECK(cudaFree(m_ptr));
      m_ptr = nullptr;
      const std::size_t grown = bytes + bytes / 4 + 256;
      MARBLES_CUDA_CHECK(cudaMalloc(&m_ptr, grown));
      m_bytes = grown;
    }
    return m_ptr;
  }
  template <class T>
  T* as(std::size_t count) {
    return static_cast<T*>(reserve(count * sizeof(T) + 16));
  }
  template <class T>
  T* get_as() const {
    return static_cast<T*>(m_ptr);
  }
  void* get() const { return m_ptr; }
  std::size_t bytes() const { return m_bytes; }
  void swap(DeviceBuffer& other) noexcept {
    std::swap(m_ptr, other.m_ptr);
    std::swap(m_bytes, other.m_bytes);
  }

 private:
  void* m_ptr = nullptr;
  std::size_t m_bytes = 0;
};

// Copies host[] into `buffer` (grown to fit), asynchronously on `stream`: the
// host vector must outlive the copy (synchronise before changing it).
template <class T>
T* upload(DeviceBuffer& buffer, const std::vector<T>& host, cudaStream_t stream) {
  T* d = buffer.as<T>(host.size());
  if (!host.empty())
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(d, host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice, stream));
  return d;
}

// *target = max(*target, v) for the warp's values, one atomic per warp. Every
// thread of the warp must call it (after a grid-stride loop, not inside); a
// maximum of 0 writes nothing, so the target must start at 0.
__device__ inline void warp_atomic_max(unsigned long long* target, unsigned long long v) {
  for (int offset = 16; offset > 0; offset >>= 1) {
    const unsigned long long other = __shfl_down_sync(0xffffffffu, v, offset);
    v = other > v ? other : v;
  }
  if ((threadIdx.x & 31) == 0 && v != 0) atomicMax(target, v);
}

// Exclusive sum of in[0, n) into out[0, n).
template <class T>
void device_exclusive_sum(const T* in, T* out, std::size_t n, DeviceBuffer& temp, cudaStream_t stream) {
  std::size_t bytes = 0;
  MARBLES_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, bytes, in, out, static_cast<int>(n), stream));
  MARBLES_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp.reserve(bytes), bytes, in, out, static_cast<int>(n), stream));
}

// Stable sort of (keys, values)[0, n) by key bits [0, bits); the result is in
// (keys_out, values_out).
template <class Key, class Value>
void device_sort_pairs(const Key* keys_in, Key* keys_out, const Value* values_in, Value* values_out, std::size_t n,
                       int bits, DeviceBuffer& temp, cudaStream_t stream) {
  std::size_t bytes = 0;
  MARBLES_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, bytes, keys_in, keys_out, values_in, values_out,
                                                     static_cast<int>(n), 0, bits, stream));
  MARBLES_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.reserve(bytes), bytes, keys_in, keys_out, values_in,
                                                     values_out, static_cast<int>(n), 0, bits, stream));
}

}  // namespace marbles::cuda
