// broadphase/cell_ids_cuda.cu — bounds of the centres and the cell-ID
// arrays, one thread per sphere (grid-stride).
//
// Bounds: per-thread extremes, a block reduction in shared memory, then one
// atomicMin/atomicMax per block on order-preserving integer encodings (exact:
// the grid must see the same extremes as the CPU backend). Cell IDs: count
// the occupied cells of each sphere, exclusive-scan (CUB), write: only used
// entries are stored, in sphere order, so the stable sort keeps each cell's
// occupants in id order.
#include <cfloat>

#include "broadphase/broadphase_cuda.cuh"

namespace marbles::broadphase::cuda {
namespace {

__global__ void bounds_kernel(const Vec3* __restrict__ centre, const real* __restrict__ radius, std::size_t n,
                              BoundsAccum* acc) {
  real lo[3] = {real(FLT_MAX), real(FLT_MAX), real(FLT_MAX)};
  real hi[3] = {-real(FLT_MAX), -real(FLT_MAX), -real(FLT_MAX)};
  real r_max = 0;
  bool bad = false;
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n;
       i += std::size_t(gridDim.x) * blockDim.x) {
    const Vec3 c = centre[i];
    const real r = radius[i];
    bad = bad || !isfinite(c.x) || !isfinite(c.y) || !isfinite(c.z) || !isfinite(r) || r < 0;
    lo[0] = min(lo[0], c.x), lo[1] = min(lo[1], c.y), lo[2] = min(lo[2], c.z);
    hi[0] = max(hi[0], c.x), hi[1] = max(hi[1], c.y), hi[2] = max(hi[2], c.z);
    r_max = max(r_max, r);
  }
  __shared__ real s[7][kBlock];
  __shared__ int s_bad;
  if (threadIdx.x == 0) s_bad = 0;
  for (int k = 0; k < 3; ++k) s[k][threadIdx.x] = lo[k], s[3 + k][threadIdx.x] = hi[k];
  s[6][threadIdx.x] = r_max;
  __syncthreads();
  if (bad) s_bad = 1;
  for (int stride = kBlock / 2; stride > 0; stride >>= 1) {
    if (threadIdx.x < stride) {
      for (int k = 0; k < 3; ++k) s[k][threadIdx.x] = min(s[k][threadIdx.x], s[k][threadIdx.x + stride]);
      for (int k = 3; k < 7; ++k) s[k][threadIdx.x] = max(s[k][threadIdx.x], s[k][threadIdx.x + stride]);
    }
    __syncthreads();
  }
  if (threadIdx.x == 0) {
    for (int k = 0; k < 3; ++k) {
      atomicMin(&acc->lo[k], encode_ordered(s[k][0]));
      atomicMax(&acc->hi[k], encode_ordered(s[3 + k][0]));
    }
    atomicMax(&acc->r_max, encode_ordered(s[6][0]));
    if (s_bad) atomicOr(&acc->bad, 1u);
  }
}

// The accumulator's start: every lo above and every hi below any encoding.
__global__ void bounds_start_kernel(BoundsAccum* acc) {
  for (int k = 0; k < 3; ++k) acc->lo[k] = ~0ull, acc->hi[k] = 0;
  acc->r_max = 0;
  acc->bad = 0;
  acc->padding = 0;
}

// The home grid of the accumulated bounds where it fits the plan, else
// kNoGrid (the host's check_inputs, on the device: finite bounds, a radius
// >= 0; the margin the host checked); and whether the plan is outsized.
__global__ void home_grid_kernel(const BoundsAccum* acc, real margin, HomePlan plan, std::size_t n, HomeGrid* out,
                                 std::uint32_t* outsized) {
  const Bounds b = decode_bounds(*acc);
  bool ok = acc->bad == 0 && centres_finite(b) && radius_valid(b);
  HomeGrid g;
  if (ok) {
    const KeyWidth width = home_grid_of(b, margin, g);
    ok = plan_fits(plan, g, width);
  }
  *outsized = ok && plan_outsized(plan, g, n) ? 1u : 0u;
  if (!ok) g.cells = kNoGrid;
  *out = g;
}

__global__ void cell_counts_kernel(const Vec3* __restrict__ centre, const real* __restrict__ radius, std::size_t n,
                                   Grid grid, std::uint32_t* __restrict__ counts, std::uint16_t* __restrict__ info) {
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n;
       i += std::size_t(gridDim.x) * blockDim.x) {
    const Neighbourhood nb = sphere_neighbourhood(centre[i], radius[i], grid);
    counts[i] = occupied_count(nb.occupied);
    info[i] = make_info(cell_type(nb.home), type_mask(nb));
  }
  if (blockIdx.x == 0 && threadIdx.x == 0) counts[n] = 0;
}

template <class Key>
__global__ void cell_ids_kernel(const Vec3* __restrict__ centre, const real* __restrict__ radius, std::size_t n,
                                Grid grid, const std::uint32_t* __restrict__ offsets, Key* __restrict__ keys,
                                std::uint32_t* __restrict__ values) {
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n;
       i += std::size_t(gridDim.x) * blockDim.x) {
    const SphereCellIds ids = sphere_cell_ids(centre[i], radius[i], grid);
    std::uint32_t at = offsets[i];
    const auto id = static_cast<std::uint32_t>(i);
#pragma unroll
    for (unsigned e = 0; e < 8; ++e) {
      if (e < ids.count) {
        keys[at] = static_cast<Key>(ids.key[e]);
        values[at] = make_value(id, e != 0, key_type(ids.key[e], grid));
        ++at;
      }
    }
  }
}

}  // namespace

void launch_bounds(const Vec3* centre, const real* radius, std::size_t n, BoundsAccum* acc, int sm_count,
                   cudaStream_t stream) {
  bounds_start_kernel<<<1, 1, 0, stream>>>(acc);
  MARBLES_CUDA_CHECK_LAUNCH();
  bounds_kernel<<<grid_for(n, sm_count, 4), kBlock, 0, stream>>>(centre, radius, n, acc);
  MARBLES_CUDA_CHECK_LAUNCH();
}

Bounds read_bounds(const Vec3* centre, const real* radius, std::size_t n, BoundsAccum* acc, BoundsAccum* host,
                   int sm_count, cudaStream_t stream) {
  launch_bounds(centre, radius, n, acc, sm_count, stream);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(host, acc, sizeof(BoundsAccum), cudaMemcpyDeviceToHost, stream));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(stream));
  if (host->bad) throw NonFiniteInput();
  return decode_bounds(*host);
}

void launch_home_grid(const BoundsAccum* acc, real margin, const HomePlan& plan, std::size_t n, HomeGrid* grid,
                      std::uint32_t* outsized, cudaStream_t stream) {
  home_grid_kernel<<<1, 1, 0, stream>>>(acc, margin, plan, n, grid, outsized);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_cell_counts(const Vec3* centre, const real* radius, std::size_t n, const Grid& grid, std::uint32_t* counts,
                        std::uint16_t* info, int sm_count, cudaStream_t stream) {
  cell_counts_kernel<<<grid_for(n, sm_count), kBlock, 0, stream>>>(centre, radius, n, grid, counts, info);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template <class Key>
void launch_cell_ids(const Vec3* centre, const real* radius, std::size_t n, const Grid& grid,
                     const std::uint32_t* offsets, Key* keys, std::uint32_t* values, int sm_count,
                     cudaStream_t stream) {
  cell_ids_kernel<Key><<<grid_for(n, sm_count), kBlock, 0, stream>>>(centre, radius, n, grid, offsets, keys, values);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template void launch_cell_ids<std::uint32_t>(const Vec3*, const real*, std::size_t, const Grid&, const std::uint32_t*,
                                             std::uint32_t*, std::uint32_t*, int, cudaStream_t);
template void launch_cell_ids<std::uint64_t>(const Vec3*, const real*, std::size_t, const Grid&, const std::uint32_t*,
                                             std::uint64_t*, std::uint32_t*, int, cudaStream_t);

}  // namespace marbles::broadphase::cuda
