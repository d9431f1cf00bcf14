#include "broadphase/broadphase.hpp"
#include "broadphase/broadphase_cuda.cuh"
#include "broadphase/grid.hpp"
#include "broadphase/home_cell_math.hpp"
#include "core/cuda_check.hpp"
#include "sim/device_world.cuh"

namespace marbles {
namespace {

template <class T>
void get(const ::marbles::cuda::DeviceBuffer& buffer, std::vector<T>& host, std::size_t n, cudaStream_t s) {
  host.resize(n);
  if (n > 0)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(host.data(), buffer.get(), n * sizeof(T), cudaMemcpyDeviceToHost, s));
}

using ::marbles::cuda::DeviceBuffer;
using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

// The velocities copied, unless skipped (DeviceWorld::copy_velocities_to).
__global__ void copy_velocities_kernel(const Vec3* from, std::size_t n, Vec3* to, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n; i += std::size_t(gridDim.x) * blockDim.x)
    to[i] = from[i];
}

template <class T>
__global__ void gather_kernel(const T* from, const std::uint32_t* order, std::size_t n, T* to) {
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n; i += std::size_t(gridDim.x) * blockDim.x)
    to[i] = from[order[i]];
}

// The array in `buffer` gathered by order into `spare`, then copied back:
// each array keeps its own allocation (swapping would pass the largest
// one's along the arrays, one numbering after another).
template <class T>
void gather(DeviceBuffer& buffer, const std::uint32_t* order, std::size_t n, int sm_count, cudaStream_t s,
            DeviceBuffer& spare) {
  T* to = spare.as_room<T>(n);
  gather_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(buffer.get_as<T>(), order, n, to);
  MARBLES_CUDA_CHECK_LAUNCH();
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(buffer.get(), to, n * sizeof(T), cudaMemcpyDeviceToDevice, s));
}

// *moved = 1 where order[i] != i for some i (it starts at 0).
__global__ void moved_kernel(const std::uint32_t* order, std::size_t n, unsigned* moved) {
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n; i += std::size_t(gridDim.x) * blockDim.x)
    if (order[i] != i) *moved = 1u;  // any writer's 1
}

__global__ void invert_kernel(const std::uint32_t* order, std::size_t n, std::uint32_t* inverse) {
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n; i += std::size_t(gridDim.x) * blockDim.x)
    inverse[order[i]] = static_cast<std::uint32_t>(i);
}

}  // namespace

void invert_order(const std::uint32_t* order, std::size_t n, std::uint32_t* inverse, int sm_count, cudaStream_t s) {
  if (n == 0) return;
  invert_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(order, n, inverse);
  MARBLES_CUDA_CHECK_LAUNCH();
}

bool DeviceWorld::cell_order(std::uint32_t* order, std::uint64_t& bytes_copied, int sm_count, cudaStream_t s) const {
  namespace bc = broadphase::cuda;
  if (m_count == 0) return false;
  DeviceBuffer bounds(s), grid_word(s), keys(s), index(s), temp(s);  // the stream's: no wait where they go
  bc::BoundsAccum read{};
  bytes_copied += sizeof read;
  const broadphase::HomeGridChoice choice = broadphase::choose_home_grid(
      bc::read_bounds(m_position.get_as<Vec3>(), m_radius.get_as<real>(), m_count, bounds.as<bc::BoundsAccum>(1), &read,
                      sm_count, s),
      0);
  if (choice.width == broadphase::KeyWidth::too_wide) return false;
  // The broad phase's key kernel, which reads its grid on the device (where
  // the broad phase chooses it): the host's choice copied there (from
  // pageable memory, but the stream is idle after the bounds' read).
  auto* grid = grid_word.as<broadphase::HomeGrid>(1);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(grid, &choice.grid, sizeof choice.grid, cudaMemcpyHostToDevice, s));
  bytes_copied += sizeof choice.grid;
  auto* key = keys.as<std::uint64_t>(2 * m_count);
  auto* from = index.as<std::uint32_t>(m_count);
  bc::launch_home_keys<std::uint64_t>(m_position.get_as<Vec3>(), m_count, grid, key, from, sm_count, s);
  // Stable, as the host's radix sort: a cell's spheres keep their order.
  const bool alt = bc::cub_radix_sort(key, from, key + m_count, order, m_count, choice.grid.key_bits, temp, s);
  if (!alt)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(order, from, m_count * sizeof(std::uint32_t), cudaMemcpyDeviceToDevice, s));
  // Whether any sphere moves, read instead of the order (a pile numbered
  // often is mostly in its order already).
  auto* moved = bounds.as<unsigned>(1);
  MARBLES_CUDA_CHECK(cudaMemsetAsync(moved, 0, sizeof(unsigned), s));
  moved_kernel<<<grid_for(m_count, sm_count), kBlock, 0, s>>>(order, m_count, moved);
  MARBLES_CUDA_CHECK_LAUNCH();
  unsigned any = 0;
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(&any, moved, sizeof any, cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  bytes_copied += sizeof any;
  return any != 0;
}

void DeviceWorld::permute(const std::uint32_t* order, int sm_count, cudaStream_t s) {
  DeviceBuffer spare(s);  // the stream's: no wait where it goes
  gather<Vec3>(m_position, order, m_count, sm_count, s, spare);
  gather<Vec3>(m_velocity, order, m_count, sm_count, s, spare);
  gather<Vec3>(m_angular_velocity, order, m_count, sm_count, s, spare);
  gather<real>(m_radius, order, m_count, sm_count, s, spare);
  gather<real>(m_inv_mass, order, m_count, sm_count, s, spare);
  gather<real>(m_inv_inertia, order, m_count, sm_count, s, spare);
  gather<std::uint32_t>(m_material, order, m_count, sm_count, s, spare);
}

void DeviceWorld::upload(const World& w, cudaStream_t s) {
  m_count = w.size();
  ::marbles::cuda::upload(m_position, w.position, s);
  ::marbles::cuda::upload(m_velocity, w.velocity, s);
  ::marbles::cuda::upload(m_angular_velocity, w.angular_velocity, s);
  ::marbles::cuda::upload(m_radius, w.radius, s);
  ::marbles::cuda::upload(m_inv_mass, w.inv_mass, s);
  ::marbles::cuda::upload(m_inv_inertia, w.inv_inertia, s);
  ::marbles::cuda::upload(m_material, w.material, s);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));  // the host vectors may change after this returns
}

void DeviceWorld::download_state(World& w, cudaStream_t s) const {
  get(m_position, w.position, m_count, s);
  get(m_velocity, w.velocity, m_count, s);
  get(m_angular_velocity, w.angular_velocity, m_count, s);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
}

void DeviceWorld::download(World& w, cudaStream_t s) const {
  get(m_radius, w.radius, m_count, s);
  get(m_inv_mass, w.inv_mass, m_count, s);
  get(m_inv_inertia, w.inv_inertia, m_count, s);
  get(m_material, w.material, m_count, s);
  download_state(w, s);
}

void DeviceWorld::copy_state_to(DeviceWorld& to, cudaStream_t s) const {
  to.m_count = m_count;
  Vec3 *position = to.m_position.as<Vec3>(m_count), *velocity = to.m_velocity.as<Vec3>(m_count),
       *angular = to.m_angular_velocity.as<Vec3>(m_count);
  const std::size_t bytes = m_count * sizeof(Vec3);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(position, m_position.get(), bytes, cudaMemcpyDeviceToDevice, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(velocity, m_velocity.get(), bytes, cudaMemcpyDeviceToDevice, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(angular, m_angular_velocity.get(), bytes, cudaMemcpyDeviceToDevice, s));
}

void DeviceWorld::copy_velocities_to(DeviceBuffer& to, cudaStream_t s, const unsigned long long* skip,
                                     int sm_count) const {
  auto* velocity = static_cast<Vec3*>(to.reserve(m_count * sizeof(Vec3), false));  // the spheres do not grow
  if (m_count == 0) return;
  copy_velocities_kernel<<<grid_for(m_count, sm_count), kBlock, 0, s>>>(m_velocity.get_as<Vec3>(), m_count, velocity,
                                                                        skip);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void DeviceWorld::take_velocities(const DeviceBuffer& from, cudaStream_t s) {
  if (m_count == 0) return;
  MARBLES_CUDA_CHECK(
      cudaMemcpyAsync(m_velocity.get(), from.get(), m_count * sizeof(Vec3), cudaMemcpyDeviceToDevice, s));
}

BodiesView DeviceWorld::view() const {
  return {m_position.get_as<Vec3>(),       m_velocity.get_as<Vec3>(),   m_angular_velocity.get_as<Vec3>(),
          m_radius.get_as<real>(),         m_inv_mass.get_as<real>(),   m_inv_inertia.get_as<real>(),
          m_material.get_as<std::uint32_t>(), m_count};
}

}  // namespace marbles
