#include "core/block_stage.cuh"
#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "core/whole_record.hpp"
#include "narrowphase/contacts_cuda.cuh"

namespace marbles::narrowphase::cuda {
namespace {

using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

// A speed (>= 0) as an unsigned word that orders as the speed does, so an
// atomic max gives the exact largest speed whatever the order.
__device__ unsigned long long speed_word(real v) {
  if constexpr (sizeof(real) == 4) return __float_as_uint(v);
  else return static_cast<unsigned long long>(__double_as_longlong(v));
}
__device__ real speed_of(unsigned long long w) {
  if constexpr (sizeof(real) == 4) return __uint_as_float(static_cast<unsigned>(w));
  else return __longlong_as_double(static_cast<long long>(w));
}

__global__ void max_speed_kernel(BodiesView bodies, unsigned long long* max_speed) {
  real v = 0;
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x) {
    const real s = length(bodies.velocity[i]);
    v = s > v ? s : v;
  }
  ::marbles::cuda::warp_atomic_max(max_speed, speed_word(v));
}

__global__ void reach_kernel(BodiesView bodies, real h, const unsigned long long* max_speed, real* reach,
                             real* bound) {
  const real v_max = speed_of(*max_speed);
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x) {
    reach[i] = contact_reach(length(bodies.velocity[i]), v_max, bodies.radius[i], h);
    if (bound) bound[i] = bodies.radius[i] + reach[i];
  }
}

__global__ void sphere_flags_kernel(BodiesView bodies, const IndexPair* pairs, std::size_t count, PairTable table,
                                    real h, const real* reach, std::uint32_t* flags) {
  for (std::size_t k = blockIdx.x * blockDim.x + threadIdx.x; k <= count; k += gridDim.x * blockDim.x) {
    if (k == count) {
      flags[k] = 0;
      continue;
    }
    Contact c;
    flags[k] = make_sphere_contact(bodies, pairs[k].i, pairs[k].j, table, h, reach, c) ? 1u : 0u;
  }
}

// The contacts of items [0, count) whose flag was set (offsets: the flags'
// exclusive scan), make(t, c) writing item t's. A block's items are
// consecutive, so their contacts are one run of the output: staged in shared
// memory, written out whole (core/block_stage.cuh).
template <class Make>
__device__ void write_contacts(std::size_t count, const std::uint32_t* offsets, Contact* out, Make&& make) {
  __shared__ ::marbles::cuda::RunStage<Contact, kBlock> stage;
  for (std::size_t base = std::size_t(blockIdx.x) * blockDim.x; base < count;
       base += std::size_t(gridDim.x) * blockDim.x) {
    const std::size_t t = base + threadIdx.x, end = base + blockDim.x < count ? base + blockDim.x : count;
    Contact* run = out + offsets[base];
    if (t < count && offsets[t + 1] != offsets[t]) {
      Contact c;
      make(t, c);
      stage.put(run, offsets[t] - offsets[base], c);
    }
    __syncthreads();
    stage.flush(run, offsets[end] - offsets[base]);
    __syncthreads();
  }
}

__global__ void __launch_bounds__(kBlock) sphere_write_kernel(BodiesView bodies, const IndexPair* pairs,
                                                              std::size_t count, PairTable table, real h,
                                                              const real* reach, const std::uint32_t* offsets,
                                                              Contact* out) {
  write_contacts(count, offsets, out, [&](std::size_t k, Contact& c) {
    make_sphere_contact(bodies, pairs[k].i, pairs[k].j, table, h, reach, c);
  });
}

__global__ void wall_flags_kernel(BodiesView bodies, const WallShape* walls, std::uint32_t wall_count,
                                  PairTable table, real h, const real* reach, std::uint32_t* flags) {
  const std::size_t items = bodies.count * wall_count;
  for (std::size_t t = blockIdx.x * blockDim.x + threadIdx.x; t <= items; t += gridDim.x * blockDim.x) {
    if (t == items) {
      flags[t] = 0;
      continue;
    }
    const auto i = static_cast<std::uint32_t>(t / wall_count), k = static_cast<std::uint32_t>(t % wall_count);
    Contact c;
    flags[t] = make_wall_contact(bodies, i, walls[k], k, table, h, reach, c) ? 1u : 0u;
  }
}

__global__ void __launch_bounds__(kBlock) wall_write_kernel(BodiesView bodies, const WallShape* walls,
                                                            std::uint32_t wall_count, PairTable table, real h,
                                                            const real* reach, const std::uint32_t* offsets,
                                                            Contact* out) {
  write_contacts(bodies.count * wall_count, offsets, out, [&](std::size_t t, Contact& c) {
    const auto i = static_cast<std::uint32_t>(t / wall_count), k = static_cast<std::uint32_t>(t % wall_count);
    make_wall_contact(bodies, i, walls[k], k, table, h, reach, c);
  });
}

__global__ void advance_walls_kernel(WallShape* walls, std::uint32_t count, real h) {
  const std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k < count) walls[k].point += walls[k].velocity * h;
}

}  // namespace

void launch_contact_reaches(const BodiesView& bodies, real h, unsigned long long* max_speed, real* reach,
                            real* bound, int sm_count, cudaStream_t stream) {
  if (bodies.count == 0) return;
  max_speed_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, max_speed);
  MARBLES_CUDA_CHECK_LAUNCH();
  reach_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, h, max_speed, reach, bound);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_sphere_contact_flags(const BodiesView& bodies, const IndexPair* pairs, std::size_t count,
                                 const PairTable& table, real h, const real* reach, std::uint32_t* flags,
                                 int sm_count, cudaStream_t stream) {
  sphere_flags_kernel<<<grid_for(count + 1, sm_count), kBlock, 0, stream>>>(bodies, pairs, count, table, h, reach,
                                                                            flags);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_sphere_contact_write(const BodiesView& bodies, const IndexPair* pairs, std::size_t count,
                                 const PairTable& table, real h, const real* reach, const std::uint32_t* offsets,
                                 Contact* out, int sm_count, cudaStream_t stream) {
  if (count == 0) return;
  sphere_write_kernel<<<grid_for(count, sm_count), kBlock, 0, stream>>>(bodies, pairs, count, table, h, reach,
                                                                        offsets, out);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_wall_contact_flags(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, const real* reach, std::uint32_t* flags,
                               int sm_count, cudaStream_t stream) {
  wall_flags_kernel<<<grid_for(bodies.count * wall_count + 1, sm_count), kBlock, 0, stream>>>(
      bodies, walls, wall_count, table, h, reach, flags);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_wall_contact_write(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, const real* reach, const std::uint32_t* offsets,
                               Contact* out, int sm_count, cudaStream_t stream) {
  if (bodies.count * wall_count == 0) return;
  wall_write_kernel<<<grid_for(bodies.count * wall_count, sm_count), kBlock, 0, stream>>>(
      bodies, walls, wall_count, table, h, reach, offsets, out);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_advance_walls(WallShape* walls, std::uint32_t count, real h, cudaStream_t stream) {
  if (count == 0) return;
  advance_walls_kernel<<<(count + kBlock - 1) / kBlock, kBlock, 0, stream>>>(walls, count, h);
  MARBLES_CUDA_CHECK_LAUNCH();
}

}  // namespace marbles::narrowphase::cuda
