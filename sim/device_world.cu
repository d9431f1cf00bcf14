#include "core/cuda_check.hpp"
#include "sim/device_world.cuh"

namespace marbles {
namespace {

template <class T>
void put(::marbles::cuda::DeviceBuffer& buffer, const std::vector<T>& host, cudaStream_t s) {
  T* d = buffer.as<T>(host.size());
  if (!host.empty())
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(d, host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice, s));
}

template <class T>
void get(const ::marbles::cuda::DeviceBuffer& buffer, std::vector<T>& host, std::size_t n, cudaStream_t s) {
  host.resize(n);
  if (n > 0)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(host.data(), buffer.get(), n * sizeof(T), cudaMemcpyDeviceToHost, s));
}

}  // namespace

void DeviceWorld::upload(const World& w, cudaStream_t s) {
  m_count = w.size();
  put(m_position, w.position, s);
  put(m_velocity, w.velocity, s);
  put(m_angular_velocity, w.angular_velocity, s);
  put(m_radius, w.radius, s);
  put(m_inv_mass, w.inv_mass, s);
  put(m_inv_inertia, w.inv_inertia, s);
  put(m_material, w.material, s);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));  // the host vectors may change after this returns
}

void DeviceWorld::download_state(World& w, cudaStream_t s) const {
  get(m_position, w.position, m_count, s);
  get(m_velocity, w.velocity, m_count, s);
  get(m_angular_velocity, w.angular_velocity, m_count, s);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
}

BodiesView DeviceWorld::view() const {
  return {m_position.get_as<Vec3>(),       m_velocity.get_as<Vec3>(),   m_angular_velocity.get_as<Vec3>(),
          m_radius.get_as<real>(),         m_inv_mass.get_as<real>(),   m_inv_inertia.get_as<real>(),
          m_material.get_as<std::uint32_t>(), m_count};
}

}  // namespace marbles
