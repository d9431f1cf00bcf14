#include <vector>

#include "core/cuda_check.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contact_cache_cuda.cuh"
#include "narrowphase/contact_cache_math.hpp"

namespace marbles::narrowphase::cuda {
namespace {

using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

__global__ void flags_kernel(const Contact* contacts, std::uint32_t n, std::uint32_t* flags) {
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k <= n; k += gridDim.x * blockDim.x)
    flags[k] = k < n && contacts[k].normal_impulse > 0 ? 1u : 0u;
}

__global__ void keys_kernel(const Contact* contacts, std::uint32_t n, const std::uint32_t* offsets,
                            std::uint64_t* keys, std::uint32_t* index) {
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x) {
    if (offsets[k + 1] == offsets[k]) continue;
    keys[offsets[k]] = cache_key(contacts[k].a, contacts[k].b);
    index[offsets[k]] = k;
  }
}

__global__ void gather_kernel(const Contact* contacts, const std::uint32_t* index, std::uint32_t m, real* normal,
                              Vec3* tangent, Vec3* rolling) {
  for (std::uint32_t e = blockIdx.x * blockDim.x + threadIdx.x; e < m; e += gridDim.x * blockDim.x) {
    const Contact& c = contacts[index[e]];
    normal[e] = c.normal_impulse;
    tangent[e] = c.tangent_impulse;
    rolling[e] = c.rolling_impulse;
  }
}

__global__ void restore_kernel(Contact* contacts, std::uint32_t n, const std::uint64_t* keys, std::uint32_t m,
                               const real* normal, const Vec3* tangent, const Vec3* rolling, std::uint8_t* matched) {
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x) {
    Contact& c = contacts[k];
    const std::uint64_t key = cache_key(c.a, c.b);
    const std::uint32_t e = cache_lower_bound(keys, m, key);
    if (e == m || keys[e] != key) continue;
    restore_impulses(c, normal[e], tangent[e], rolling[e]);
    matched[e] = 1;  // keys are unique: one contact per entry
  }
}

__global__ void lost_loads_kernel(const std::uint64_t* keys, const real* normal, const std::uint8_t* matched,
                                  std::uint32_t m, BodiesView bodies, real weight_impulse, std::uint32_t* count) {
  std::uint32_t mine = 0;
  for (std::uint32_t e = blockIdx.x * blockDim.x + threadIdx.x; e < m; e += gridDim.x * blockDim.x) {
    if (matched[e]) continue;
    const auto a = static_cast<std::uint32_t>(keys[e] >> 32);
    if (a < bodies.count && is_lost_load(normal[e], bodies.inv_mass[a], weight_impulse)) ++mine;
  }
  if (mine) atomicAdd(count, mine);
}

}  // namespace

ContactCacheCuda::ContactCacheCuda() {
  MARBLES_CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&m_host), 4 * sizeof(std::uint32_t)));
}
ContactCacheCuda::~ContactCacheCuda() {
  if (m_host) cudaFreeHost(m_host);
}

void ContactCacheCuda::store(const Contact* contacts, std::uint32_t n, int sm_count, cudaStream_t s) {
  auto* flags = m_flags.as<std::uint32_t>(n + 1);
  auto* offsets = m_offsets.as<std::uint32_t>(n + 1);
  flags_kernel<<<grid_for(n + 1, sm_count), kBlock, 0, s>>>(contacts, n, flags);
  MARBLES_CUDA_CHECK_LAUNCH();
  ::marbles::cuda::device_exclusive_sum(flags, offsets, n + 1, m_temp, s);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_host, offsets + n, sizeof(std::uint32_t), cudaMemcpyDeviceToHost, s));
  m_bytes += sizeof(std::uint32_t);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  m_count = m_host[0];
  if (m_count == 0) return;
  auto* keys_in = m_keys_in.as<std::uint64_t>(m_count);
  auto* index_in = m_index_in.as<std::uint32_t>(m_count);
  auto* keys = m_keys.as<std::uint64_t>(m_count);
  auto* index = m_index.as<std::uint32_t>(m_count);
  keys_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(contacts, n, offsets, keys_in, index_in);
  MARBLES_CUDA_CHECK_LAUNCH();
  ::marbles::cuda::device_sort_pairs(keys_in, keys, index_in, index, m_count, 64, m_temp, s);
  gather_kernel<<<grid_for(m_count, sm_count), kBlock, 0, s>>>(contacts, index, m_count, m_normal.as<real>(m_count),
                                                               m_tangent.as<Vec3>(m_count),
                                                               m_rolling.as<Vec3>(m_count));
  MARBLES_CUDA_CHECK_LAUNCH();
}

void ContactCacheCuda::restore(Contact* contacts, std::uint32_t n, const BodiesView& bodies,
                               const real* host_inv_mass, real weight_impulse, int sm_count, cudaStream_t s) {
  const std::uint32_t m = m_count;
  if (m == 0 || n == 0) return;
  auto* matched = m_matched.as<std::uint8_t>(m);
  auto* counter = m_counter.as<std::uint32_t>(1);
  MARBLES_CUDA_CHECK(cudaMemsetAsync(matched, 0, m, s));
  MARBLES_CUDA_CHECK(cudaMemsetAsync(counter, 0, sizeof(std::uint32_t), s));
  const auto* keys = m_keys.get_as<std::uint64_t>();
  const auto* normal = m_normal.get_as<real>();
  restore_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(contacts, n, keys, m, normal, m_tangent.get_as<Vec3>(),
                                                          m_rolling.get_as<Vec3>(), matched);
  MARBLES_CUDA_CHECK_LAUNCH();
  lost_loads_kernel<<<grid_for(m, sm_count), kBlock, 0, s>>>(keys, normal, matched, m, bodies, weight_impulse,
                                                             counter);
  MARBLES_CUDA_CHECK_LAUNCH();
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_host, counter, sizeof(std::uint32_t), cudaMemcpyDeviceToHost, s));
  m_bytes += sizeof(std::uint32_t);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  if (m_host[0] == 0) return;

  // A load was lost: the island rule on the host, over the CPU's own code.
  m_host_contacts.resize(n);
  std::vector<std::uint64_t> h_keys(m);
  std::vector<real> h_normal(m);
  std::vector<std::uint8_t> h_matched(m);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_host_contacts.data(), contacts, n * sizeof(Contact), cudaMemcpyDeviceToHost, s));
  m_bytes += n * sizeof(Contact);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_keys.data(), keys, m * sizeof(std::uint64_t), cudaMemcpyDeviceToHost, s));
  m_bytes += m * sizeof(std::uint64_t);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_normal.data(), normal, m * sizeof(real), cudaMemcpyDeviceToHost, s));
  m_bytes += m * sizeof(real);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_matched.data(), matched, m, cudaMemcpyDeviceToHost, s));
  m_bytes += m;
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  BodiesView host_bodies;
  host_bodies.inv_mass = host_inv_mass;
  host_bodies.count = bodies.count;
  if (cold_start_unloaded_islands(m_host_contacts, h_keys.data(), h_normal.data(), h_matched.data(), m, host_bodies,
                                  weight_impulse) > 0) {
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(contacts, m_host_contacts.data(), n * sizeof(Contact), cudaMemcpyHostToDevice, s));
    m_bytes += n * sizeof(Contact);
  }
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
}

}  // namespace marbles::narrowphase::cuda
