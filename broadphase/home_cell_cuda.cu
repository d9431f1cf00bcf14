// broadphase/home_cell_cuda.cu — the kernels of the home-cell broad phase
// (math in home_cell_math.hpp; broadphase_cuda.cu strings them together):
//
//   keys       one thread per sphere: home cell -> linear key, id
//   (sort)     CUB or the seed's radix sort of (key, id) over the used bits
//   reorder    one thread per sorted index: the sphere's centre and radius
//              gathered into sorted order (one random read per sphere, so
//              that every later read is of neighbouring memory), and the
//              dense lower-bound array lb over all cells: index i writes
//              lb[k] = i for k in (key[i - 1], key[i]] (each k once, no
//              memset); a gap longer than 8 cells is filled by the whole
//              warp, so one long empty stretch does not serialise a thread
//   count      one thread per sorted sphere: own row, four forward rows
//              (traverse_home_sphere), pairs counted; exclusive scan
//   write      the same walk, pairs written at the scanned offsets
// Output order: by sorted index, then range, then candidate: it depends
// only on the input, and equals the CPU twin's (home_cell_cpu.cpp).
#include "broadphase/broadphase_cuda.cuh"

namespace marbles::broadphase::cuda {
namespace {

__device__ __forceinline__ SortedSphere load_sphere(const SortedSphere* __restrict__ p, std::uint32_t j) {
  if constexpr (sizeof(real) == 4) {
    const float4 v = __ldg(reinterpret_cast<const float4*>(p) + j);
    return SortedSphere{Vec3(v.x, v.y, v.z), v.w};
  } else {
    return p[j];
  }
}

// The launch's grid (launch_home_grid's) in shared memory, one copy a block,
// read there as it was from the kernel's parameters before the device chose
// it: held in registers a thread, its words (sizeof(HomeGrid), 112 bytes)
// cost the traversal kernels 8 registers and a block a SM.
__device__ __forceinline__ const HomeGrid& block_grid(const HomeGrid* at) {
  __shared__ alignas(HomeGrid) unsigned char copy[sizeof(HomeGrid)];
  if (threadIdx.x == 0) *reinterpret_cast<HomeGrid*>(copy) = *at;
  __syncthreads();
  return *reinterpret_cast<const HomeGrid*>(copy);
}

template <class Key>
__global__ void home_keys_kernel(const Vec3* __restrict__ centre, std::size_t n, const HomeGrid* __restrict__ at,
                                 Key* __restrict__ keys, std::uint32_t* __restrict__ ids) {
  const HomeGrid& grid = block_grid(at);
  const bool none = grid.cells == kNoGrid;
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n;
       i += std::size_t(gridDim.x) * blockDim.x) {
    keys[i] = none ? Key{0} : static_cast<Key>(home_key(home_cell(centre[i], grid), grid));
    ids[i] = static_cast<std::uint32_t>(i);
  }
}

constexpr std::uint64_t kOwnFill = 8;  // lb entries a thread writes itself; the rest the warp writes

// lb up to the grid's cells (the device's grid: the plan's array may be
// larger, and its entries past them are never read; one warp fills the
// last key's tail, so filling up to the plan's would cost a quarter of the
// cells in one warp).
template <class Key, bool Dense>
__global__ void home_reorder_kernel(const Key* __restrict__ keys, const std::uint32_t* __restrict__ ids, std::size_t n,
                                    const Vec3* __restrict__ centre, const real* __restrict__ radius,
                                    const HomeGrid* __restrict__ grid, SortedSphere* __restrict__ sorted,
                                    std::uint32_t* __restrict__ lb) {
  const std::uint64_t cells = block_grid(grid).cells;
  const unsigned lane = threadIdx.x & 31u;
  const std::size_t warp = (blockIdx.x * std::size_t(blockDim.x) + threadIdx.x) >> 5;
  const std::size_t warps = (std::size_t(gridDim.x) * blockDim.x) >> 5;
  // whole warps iterate together (the fill below is warp-cooperative); index n closes lb
  for (std::size_t base = warp * 32; base <= n; base += warps * 32) {
    const std::size_t i = base + lane;
    if (i < n) {
      const std::uint32_t id = ids[i];
      sorted[i] = SortedSphere{centre[id], radius[id]};
    }
    if constexpr (Dense) {
      std::uint64_t lo = 1, hi = 0;  // lb[lo..hi] = i; empty when lo > hi
      if (i <= n) {
        lo = i == 0 ? 0 : static_cast<std::uint64_t>(keys[i - 1]) + 1;
        hi = i == n ? cells : static_cast<std::uint64_t>(keys[i]);
      }
      const auto value = static_cast<std::uint32_t>(i);
      const std::uint64_t own_end = lo + kOwnFill < hi + 1 ? lo + kOwnFill : hi + 1;
      for (std::uint64_t k = lo; k < own_end; ++k) lb[k] = value;
      unsigned rest = __ballot_sync(0xffffffffu, lo <= hi && own_end <= hi);
      while (rest) {
        const int src = __ffs(rest) - 1;
        rest &= rest - 1;
        const std::uint64_t b = __shfl_sync(0xffffffffu, own_end, src);
        const std::uint64_t e = __shfl_sync(0xffffffffu, hi, src) + 1;
        const std::uint32_t v = __shfl_sync(0xffffffffu, value, src);
        for (std::uint64_t k = b + lane; k < e; k += 32) lb[k] = v;
      }
    }
  }
}

template <class Key, bool Dense, class Emit>
__device__ __forceinline__ unsigned walk(const HomeTraversal<Key>& in, const HomeGrid& grid, std::uint32_t i,
                                         const SortedSphere& own, Emit&& emit) {
  auto lb = [&](Key k) -> std::uint32_t {
    if constexpr (Dense)
      return __ldg(in.lb + k);
    else
      return lower_bound_key(in.keys, in.n, k);
  };
  auto sphere = [&](std::uint32_t j) { return load_sphere(in.sphere, j); };
  return traverse_home_sphere(i, in.keys[i], own, grid, lb, sphere, in.margin, emit);
}

template <class Key, bool Dense>
__global__ void home_count_kernel(HomeTraversal<Key> in, std::uint32_t* __restrict__ counts,
                                  unsigned long long* __restrict__ tests) {
  const HomeGrid& grid = block_grid(in.grid);
  const bool none = grid.cells == kNoGrid;
  unsigned long long my_tests = 0;
  for (std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < in.n; i += gridDim.x * blockDim.x) {
    std::uint32_t pairs = 0;
    if (!none) my_tests += walk<Key, Dense>(in, grid, i, load_sphere(in.sphere, i), [&](std::uint32_t) { ++pairs; });
    counts[i] = pairs;
  }
  if (blockIdx.x == 0 && threadIdx.x == 0) counts[in.n] = 0;
  for (int o = 16; o > 0; o >>= 1) my_tests += __shfl_down_sync(0xffffffffu, my_tests, o);
  if ((threadIdx.x & 31) == 0 && my_tests) atomicAdd(tests, my_tests);
}

template <class Key, bool Dense>
__global__ void home_write_kernel(HomeTraversal<Key> in, const std::uint32_t* __restrict__ offsets,
                                  std::size_t capacity, IndexPair* __restrict__ pairs) {
  const HomeGrid& grid = block_grid(in.grid);  // every thread, before any returns
  if (offsets[in.n] > capacity) return;        // they do not fit: the caller asks again
  if (grid.cells == kNoGrid) return;           // no grid: the caller plans again and asks again
  for (std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < in.n; i += gridDim.x * blockDim.x) {
    std::uint32_t at = offsets[i];
    if (offsets[i + 1] == at) continue;  // no pairs from this sphere
    const std::uint32_t id = in.ids[i];
    walk<Key, Dense>(in, grid, i, load_sphere(in.sphere, i),
                     [&](std::uint32_t j) { pairs[at++] = ordered_pair(id, __ldg(in.ids + j)); });
  }
}

template <class Key>
__global__ void home_pair_count_kernel(HomeTraversal<Key> in, const std::uint32_t* offsets, std::uint32_t* count) {
  *count = in.grid->cells == kNoGrid ? kNoPairCount : offsets[in.n];
}

}  // namespace

template <class Key>
void launch_home_keys(const Vec3* centre, std::size_t n, const HomeGrid* grid, Key* keys, std::uint32_t* ids,
                      int sm_count, cudaStream_t stream) {
  home_keys_kernel<Key><<<grid_for(n, sm_count), kBlock, 0, stream>>>(centre, n, grid, keys, ids);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template <class Key>
void launch_home_reorder(const Key* keys, const std::uint32_t* ids, std::size_t n, const Vec3* centre,
                         const real* radius, const HomeGrid* grid, SortedSphere* sorted, std::uint32_t* lb,
                         int sm_count, cudaStream_t stream) {
  const int blocks = grid_for(n + 1, sm_count);
  if (lb)
    home_reorder_kernel<Key, true><<<blocks, kBlock, 0, stream>>>(keys, ids, n, centre, radius, grid, sorted, lb);
  else
    home_reorder_kernel<Key, false><<<blocks, kBlock, 0, stream>>>(keys, ids, n, centre, radius, grid, sorted, lb);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template <class Key>
void launch_home_count(const HomeTraversal<Key>& in, std::uint32_t* counts, unsigned long long* tests, int sm_count,
                       cudaStream_t stream) {
  const int blocks = grid_for(in.n, sm_count);
  if (in.lb)
    home_count_kernel<Key, true><<<blocks, kBlock, 0, stream>>>(in, counts, tests);
  else
    home_count_kernel<Key, false><<<blocks, kBlock, 0, stream>>>(in, counts, tests);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template <class Key>
void launch_home_pair_count(const HomeTraversal<Key>& in, const std::uint32_t* offsets, std::uint32_t* count,
                            cudaStream_t stream) {
  home_pair_count_kernel<Key><<<1, 1, 0, stream>>>(in, offsets, count);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template <class Key>
void launch_home_write(const HomeTraversal<Key>& in, const std::uint32_t* offsets, std::size_t capacity,
                       IndexPair* pairs, int sm_count, cudaStream_t stream) {
  const int blocks = grid_for(in.n, sm_count);
  if (in.lb)
    home_write_kernel<Key, true><<<blocks, kBlock, 0, stream>>>(in, offsets, capacity, pairs);
  else
    home_write_kernel<Key, false><<<blocks, kBlock, 0, stream>>>(in, offsets, capacity, pairs);
  MARBLES_CUDA_CHECK_LAUNCH();
}

#define MARBLES_HOME_INSTANTIATE(Key)                                                                              \
  template void launch_home_keys<Key>(const Vec3*, std::size_t, const HomeGrid*, Key*, std::uint32_t*, int,       \
                                      cudaStream_t);                                                              \
  template void launch_home_reorder<Key>(const Key*, const std::uint32_t*, std::size_t, const Vec3*, const real*, \
                                         const HomeGrid*, SortedSphere*, std::uint32_t*, int, cudaStream_t);         \
  template void launch_home_count<Key>(const HomeTraversal<Key>&, std::uint32_t*, unsigned long long*, int,       \
                                       cudaStream_t);                                                             \
  template void launch_home_pair_count<Key>(const HomeTraversal<Key>&, const std::uint32_t*, std::uint32_t*,      \
                                          cudaStream_t);                                                          \
  template void launch_home_write<Key>(const HomeTraversal<Key>&, const std::uint32_t*, std::size_t, IndexPair*,  \
                                       int, cudaStream_t);
MARBLES_HOME_INSTANTIATE(std::uint32_t)
MARBLES_HOME_INSTANTIATE(std::uint64_t)
#undef MARBLES_HOME_INSTANTIATE

}  // namespace marbles::broadphase::cuda
