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

}  // namespace

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

void DeviceWorld::copy_state_to(DeviceWorld& to, cudaStream_t s) const {
  to.m_count = m_count;
  const std::size_t bytes = m_count * sizeof(Vec3);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(to.m_position.as<Vec3>(m_count), m_position.get(), bytes, cudaMemcpyDeviceToDevice, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(to.m_velocity.as<Vec3>(m_count), m_velocity.get(), bytes, cudaMemcpyDeviceToDevice, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(to.m_angular_velocity.as<Vec3>(m_count), m_angular_velocity.get(), bytes,
                                     cudaMemcpyDeviceToDevice, s));
}

BodiesView DeviceWorld::view() const {
  return {m_position.get_as<Vec3>(),       m_velocity.get_as<Vec3>(),   m_angular_velocity.get_as<Vec3>(),
          m_radius.get_as<real>(),         m_inv_mass.get_as<real>(),   m_inv_inertia.get_as<real>(),
          m_material.get_as<std::uint32_t>(), m_count};
}

}  // namespace marbles
