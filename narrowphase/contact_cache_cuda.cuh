// narrowphase/contact_cache_cuda.cuh — the CUDA twin of contact_cache.cpp:
// entries sorted by key on the device (flag, scan, write, CUB sort), looked
// up by binary search (contact_cache_math.hpp), one thread per contact. When
// a load was lost (rare: a counter says so), the island rule runs on the
// device: islands by min-label propagation with pointer jumping (the same
// islands as the CPU's union-find), their largest impulse by an atomic max,
// then the cold islands' contacts cleared. Only .cu files include it.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "core/device_buffer.cuh"
#include "core/spheres.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {

using ::marbles::cuda::DeviceBuffer;

class ContactCacheCuda {
 public:
  ContactCacheCuda();
  ~ContactCacheCuda();
  ContactCacheCuda(const ContactCacheCuda&) = delete;
  ContactCacheCuda& operator=(const ContactCacheCuda&) = delete;

  // Warm start of contacts[0, n) (device), and each contact's kept colour
  // (kept_colour, device, n entries; ContactCache::restore). False, writing
  // nothing, when the cache or the contacts are empty.
  bool restore(Contact* contacts, std::uint32_t n, const BodiesView& bodies, real weight_impulse,
               std::uint8_t* kept_colour, int sm_count, cudaStream_t stream);
  // The contacts as the sweep's records hold them after the last sweep, with
  // their colours (contact_colour, device, per contact; null: none).
  // `spheres` and `walls`: how many there are (the sort's key bits).
  void store(const SweepRecords& contacts, const std::uint8_t* contact_colour, std::uint32_t n, std::uint32_t spheres,
             std::uint32_t walls, int sm_count, cudaStream_t stream);
  std::uint32_t size() const { return m_count; }
  // The entries as the CPU cache holds them (a checkpoint's copy), and back.
  CacheEntries download(cudaStream_t stream);
  void upload(const CacheEntries& entries, cudaStream_t stream);
  // The entries copied on the device into `to` (the watchdog's undo).
  void copy_to(ContactCacheCuda& to, cudaStream_t stream) const;
  // Which impulses the scene's terms make (before the first store): without
  // friction the tangential impulses, without rolling resistance the rolling
  // ones stay zero, and the cache neither stores nor reads them.
  void set_terms(bool friction, bool rolling) { m_keep_tangent = friction, m_keep_rolling = rolling; }
  // The temporaries (the store's flags, keys and sort, the restore's
  // matches and island labels) live in `scratch` from here on, memory that
  // stages which never run at the same time share (core/device_buffer.cuh:
  // Carve); by default in the cache's own.
  void share_scratch(DeviceBuffer& scratch) { m_scratch = &scratch; }

 // Host<->device bytes copied so far (all calls).
  std::uint64_t bytes_copied() const { return m_bytes; }

 private:
  std::uint64_t m_bytes = 0;
  DeviceBuffer m_keys, m_normal, m_tangent, m_rolling, m_colour, m_counter, m_own_scratch;
  DeviceBuffer* m_scratch = &m_own_scratch;
  std::uint32_t m_count = 0;
  std::uint32_t* m_host = nullptr;  // pinned readback
  bool m_keep_tangent = true, m_keep_rolling = true;
  Vec3* tangent_entries(std::uint32_t m) { return m_keep_tangent ? m_tangent.as<Vec3>(m) : nullptr; }
  Vec3* rolling_entries(std::uint32_t m) { return m_keep_rolling ? m_rolling.as<Vec3>(m) : nullptr; }
};

}  // namespace marbles::narrowphase::cuda
