// sim/device_world.cuh — the world's struct of arrays in device memory.
//
// Hands out the same BodiesView as World::view(), with device pointers, so
// every stage's kernels take what the CPU loops take. Uploaded once (and
// after an edit), downloaded only when output or a test asks. Only .cu
// files include it.
#pragma once

#include <cuda_runtime.h>

#include "core/device_buffer.cuh"
#include "sim/world.hpp"

namespace marbles {

// inverse[order[i]] = i for i < n (device arrays).
void invert_order(const std::uint32_t* order, std::size_t n, std::uint32_t* inverse, int sm_count, cudaStream_t stream);

class DeviceWorld {
 public:
  // Allocates for `world`'s spheres and uploads all of it.
  void upload(const World& world, cudaStream_t stream);
  // The moving state (positions, velocities, angular velocities) into `world`.
  void download_state(World& world, cudaStream_t stream) const;
  // Every array into `world` (after a renumbering).
  void download(World& world, cudaStream_t stream) const;

  // The moving state (positions, velocities, angular velocities) copied on
  // the device into `to`, which is sized to match.
  void copy_state_to(DeviceWorld& to, cudaStream_t stream) const;
  // The velocities alone copied into `to` (grown to fit) by a kernel that
  // copies nothing where `skip` is set when it runs (cuda::skipped: a
  // substep's start kept in a step without waits, where nothing else of
  // the state is written before the substep's check), and put back.
  void copy_velocities_to(::marbles::cuda::DeviceBuffer& to, cudaStream_t stream, const unsigned long long* skip,
                          int sm_count) const;
  void take_velocities(const ::marbles::cuda::DeviceBuffer& from, cudaStream_t stream);

  // The spheres' order by their home cells (cell_order, sim/world.hpp: the
  // same order, from the same grid) into order[0, size()) (device; its
  // temporaries the stream's); false where the spheres keep their order
  // (no spheres or a grid too wide: nothing written; or already in cell
  // order: the identity written). Waits for the bounds and for whether any
  // sphere moves, and adds those reads' bytes to `bytes_copied` (the order
  // itself stays on the device). Throws broadphase::NonFiniteInput as
  // cell_order does.
  bool cell_order(std::uint32_t* order, std::uint64_t& bytes_copied, int sm_count, cudaStream_t stream) const;
  // Every array in `order` (device; new index -> old), as permuted does on
  // the host; each array keeps its allocation. No wait.
  void permute(const std::uint32_t* order, int sm_count, cudaStream_t stream);
  BodiesView view() const;
  std::size_t size() const { return m_count; }
  // Device bytes it holds.
  std::size_t device_bytes() const {
    return ::marbles::cuda::bytes_of(m_position, m_velocity, m_angular_velocity, m_radius, m_inv_mass, m_inv_inertia,
                                     m_material);
  }
  // Device bytes per sphere of the state itself.
  static constexpr std::size_t kBytesPerSphere = 3 * sizeof(Vec3) + 3 * sizeof(real) + sizeof(std::uint32_t);

 private:
  ::marbles::cuda::DeviceBuffer m_position, m_velocity, m_angular_velocity, m_radius, m_inv_mass, m_inv_inertia,
      m_material;
  std::size_t m_count = 0;
};

}  // namespace marbles
