#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "integrator/integrator_cuda.cuh"
#include "integrator/integrator_math.hpp"

namespace marbles::integrator::cuda {
namespace {

using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

__global__ void gravity_kernel(BodiesView bodies, Vec3 g, real h) {
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x)
    bodies.velocity[i] = gravity_kick(bodies.velocity[i], g, bodies.inv_mass[i], h);
}

__global__ void drag_kernel(BodiesView bodies, real k1, real k2, real h, DragKick kick, bool gravity, Vec3 gh) {
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x)
    if (bodies.inv_mass[i] > 0) bodies.velocity[i] = drag_update(kick, bodies.velocity[i], gravity, gh, k1, k2, h);
}

__global__ void drift_kernel(BodiesView bodies, real h, unsigned* non_finite, const unsigned long long* skip,
                             const real* reach, std::uint32_t* past, std::uint32_t past_room, const Vec3* shift) {
  if (::marbles::cuda::skipped(skip)) return;
  bool bad = false;
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x) {
    bodies.position[i] = drift(bodies.position[i], bodies.velocity[i], h, shift, i);
    bad = bad || !body_is_finite(bodies.position[i], bodies.velocity[i], bodies.angular_velocity[i]);
    if (reach != nullptr && moved_past_reach(bodies.velocity[i], bodies.radius[i], reach[i], h)) {
      const std::uint32_t slot = atomicAdd(past, 1u);  // its order reaches no state: a set, checked whole
      if (slot < past_room) past[1 + slot] = static_cast<std::uint32_t>(i);
    }
  }
  if (bad) *non_finite = 1u;  // a plain store: every writer writes the same value
}

__global__ void finite_kernel(BodiesView bodies, unsigned* non_finite) {
  bool bad = false;
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x)
    bad = bad || !body_in_range(bodies.position[i], bodies.velocity[i], bodies.angular_velocity[i]);
  if (bad) *non_finite = 1u;
}

}  // namespace

void launch_check_finite(const BodiesView& bodies, unsigned* non_finite, int sm_count, cudaStream_t stream) {
  if (bodies.count == 0) return;
  finite_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, non_finite);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_apply_gravity(const BodiesView& bodies, const Vec3& g, real h, int sm_count, cudaStream_t stream) {
  if (bodies.count == 0) return;
  gravity_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, g, h);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_apply_drag(const BodiesView& bodies, real k1, real k2, real h, DragKick kick, const Vec3* g,
                       int sm_count, cudaStream_t stream) {
  if (bodies.count == 0) return;
  const Vec3 gh = g ? *g * h : Vec3{};
  drag_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, k1, k2, h, kick, g != nullptr, gh);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_integrate_positions(const BodiesView& bodies, real h, unsigned* non_finite, int sm_count,
                                cudaStream_t stream, const unsigned long long* skip, const real* reach,
                                std::uint32_t* past, std::uint32_t past_room, const Vec3* shift) {
  if (bodies.count == 0) return;
  drift_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, h, non_finite, skip,
                                                                        past != nullptr ? reach : nullptr, past,
                                                                        past_room, shift);
  MARBLES_CUDA_CHECK_LAUNCH();
}

}  // namespace marbles::integrator::cuda
