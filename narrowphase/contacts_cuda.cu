#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "narrowphase/contacts_cuda.cuh"

namespace marbles::narrowphase::cuda {
namespace {

using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

__global__ void swept_radius_kernel(BodiesView bodies, real h, real* bound) {
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x)
    bound[i] = bodies.radius[i] + length(bodies.velocity[i]) * h;
}

__global__ void sphere_flags_kernel(BodiesView bodies, const IndexPair* pairs, std::size_t count, PairTable table,
                                    real h, std::uint32_t* flags) {
  for (std::size_t k = blockIdx.x * blockDim.x + threadIdx.x; k <= count; k += gridDim.x * blockDim.x) {
    if (k == count) {
      flags[k] = 0;
      continue;
    }
    Contact c;
    flags[k] = make_sphere_contact(bodies, pairs[k].i, pairs[k].j, table, h, c) ? 1u : 0u;
  }
}

__global__ void sphere_write_kernel(BodiesView bodies, const IndexPair* pairs, std::size_t count, PairTable table,
                                    real h, const std::uint32_t* offsets, Contact* out) {
  for (std::size_t k = blockIdx.x * blockDim.x + threadIdx.x; k < count; k += gridDim.x * blockDim.x) {
    if (offsets[k + 1] == offsets[k]) continue;
    Contact c;
    make_sphere_contact(bodies, pairs[k].i, pairs[k].j, table, h, c);
    out[offsets[k]] = c;
  }
}

__global__ void wall_flags_kernel(BodiesView bodies, const WallShape* walls, std::uint32_t wall_count,
                                  PairTable table, real h, std::uint32_t* flags) {
  const std::size_t items = bodies.count * wall_count;
  for (std::size_t t = blockIdx.x * blockDim.x + threadIdx.x; t <= items; t += gridDim.x * blockDim.x) {
    if (t == items) {
      flags[t] = 0;
      continue;
    }
    const auto i = static_cast<std::uint32_t>(t / wall_count), k = static_cast<std::uint32_t>(t % wall_count);
    Contact c;
    flags[t] = make_wall_contact(bodies, i, walls[k], k, table, h, c) ? 1u : 0u;
  }
}

__global__ void wall_write_kernel(BodiesView bodies, const WallShape* walls, std::uint32_t wall_count,
                                  PairTable table, real h, const std::uint32_t* offsets, Contact* out) {
  const std::size_t items = bodies.count * wall_count;
  for (std::size_t t = blockIdx.x * blockDim.x + threadIdx.x; t < items; t += gridDim.x * blockDim.x) {
    if (offsets[t + 1] == offsets[t]) continue;
    const auto i = static_cast<std::uint32_t>(t / wall_count), k = static_cast<std::uint32_t>(t % wall_count);
    Contact c;
    make_wall_contact(bodies, i, walls[k], k, table, h, c);
    out[offsets[t]] = c;
  }
}

__global__ void advance_walls_kernel(WallShape* walls, std::uint32_t count, real h) {
  const std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k < count) walls[k].point += walls[k].velocity * h;
}

}  // namespace

void launch_swept_radius(const BodiesView& bodies, real h, real* bound, int sm_count, cudaStream_t stream) {
  if (bodies.count == 0) return;
  swept_radius_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, h, bound);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_sphere_contact_flags(const BodiesView& bodies, const IndexPair* pairs, std::size_t count,
                                 const PairTable& table, real h, std::uint32_t* flags, int sm_count,
                                 cudaStream_t stream) {
  sphere_flags_kernel<<<grid_for(count + 1, sm_count), kBlock, 0, stream>>>(bodies, pairs, count, table, h, flags);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_sphere_contact_write(const BodiesView& bodies, const IndexPair* pairs, std::size_t count,
                                 const PairTable& table, real h, const std::uint32_t* offsets, Contact* out,
                                 int sm_count, cudaStream_t stream) {
  if (count == 0) return;
  sphere_write_kernel<<<grid_for(count, sm_count), kBlock, 0, stream>>>(bodies, pairs, count, table, h, offsets, out);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_wall_contact_flags(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, std::uint32_t* flags, int sm_count,
                               cudaStream_t stream) {
  wall_flags_kernel<<<grid_for(bodies.count * wall_count + 1, sm_count), kBlock, 0, stream>>>(bodies, walls,
                                                                                              wall_count, table, h,
                                                                                              flags);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_wall_contact_write(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, const std::uint32_t* offsets, Contact* out,
                               int sm_count, cudaStream_t stream) {
  if (bodies.count * wall_count == 0) return;
  wall_write_kernel<<<grid_for(bodies.count * wall_count, sm_count), kBlock, 0, stream>>>(bodies, walls, wall_count,
                                                                                          table, h, offsets, out);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_advance_walls(WallShape* walls, std::uint32_t count, real h, cudaStream_t stream) {
  if (count == 0) return;
  advance_walls_kernel<<<(count + kBlock - 1) / kBlock, kBlock, 0, stream>>>(walls, count, h);
  MARBLES_CUDA_CHECK_LAUNCH();
}

}  // namespace marbles::narrowphase::cuda
