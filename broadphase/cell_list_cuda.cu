// broadphase/cell_list_cuda.cu — the collision-cell list from the sorted
// cell IDs: one thread per sorted entry (grid-stride); a thread whose entry
// starts a run of equal keys walks the run, counting H and P occupants; a
// run with >= 2 occupants and >= 1 H is a collision cell. Flags -> exclusive
// scan (CUB, in broadphase_cuda.cu) -> write {start, n_home, n_phantom}. The
// keys are type-major, so the list comes out ordered by type: the 8 lists of
// the seed are 8 ranges, found by a binary search per type.
#include "broadphase/broadphase_cuda.cuh"

namespace marbles::broadphase::cuda {
namespace {

struct Run {
  std::uint32_t homes = 0, count = 0;
  bool starts = false;
};

template <class Key>
__device__ __forceinline__ Run run_at(const Key* __restrict__ keys, const std::uint32_t* __restrict__ values,
                                      std::size_t m, std::size_t i) {
  Run r;
  const Key k = keys[i];
  if (i > 0 && keys[i - 1] == k) return r;
  r.starts = true;
  std::size_t j = i;
  while (j < m && keys[j] == k) {
    r.homes += value_phantom(values[j]) ? 0u : 1u;
    ++j;
  }
  r.count = static_cast<std::uint32_t>(j - i);
  return r;
}

template <class Key>
__global__ void cell_flags_kernel(const Key* __restrict__ keys, const std::uint32_t* __restrict__ values,
                                  std::size_t m, std::uint32_t* __restrict__ flags) {
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < m;
       i += std::size_t(gridDim.x) * blockDim.x) {
    const Run r = run_at(keys, values, m, i);
    flags[i] = (r.starts && r.count >= 2 && r.homes >= 1) ? 1u : 0u;
  }
  if (blockIdx.x == 0 && threadIdx.x == 0) flags[m] = 0;
}

template <class Key>
__global__ void cell_write_kernel(const Key* __restrict__ keys, const std::uint32_t* __restrict__ values,
                                  std::size_t m, const std::uint32_t* __restrict__ index,
                                  CollisionCell* __restrict__ cells) {
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < m;
       i += std::size_t(gridDim.x) * blockDim.x) {
    if (index[i + 1] == index[i]) continue;  // not flagged
    const Run r = run_at(keys, values, m, i);
    cells[index[i]] = {static_cast<std::uint32_t>(i), r.homes, r.count - r.homes};
  }
}

// pass_begin[t] = first cell whose type is > t (t = 0..7 counts types 1..t);
// written as begin of type t + 1, with pass_begin[8] = cell count.
__global__ void pass_ranges_kernel(const std::uint32_t* __restrict__ values, const CollisionCell* __restrict__ cells,
                                   const std::uint32_t* __restrict__ cell_count, std::uint32_t* __restrict__ pass_begin) {
  const unsigned t = threadIdx.x;  // 0..8: first cell with type >= t + 1
  if (t > 8) return;
  const std::uint32_t count = *cell_count;
  std::uint32_t lo = 0, hi = count;
  while (lo < hi) {
    const std::uint32_t mid = lo + (hi - lo) / 2;
    if (value_type(values[cells[mid].start]) < t + 1)
      lo = mid + 1;
    else
      hi = mid;
  }
  pass_begin[t] = t == 8 ? count : lo;
}

}  // namespace

template <class Key>
void launch_cell_flags(const Key* keys, const std::uint32_t* values, std::size_t m, std::uint32_t* flags,
                       int sm_count, cudaStream_t stream) {
  cell_flags_kernel<Key><<<grid_for(m, sm_count), kBlock, 0, stream>>>(keys, values, m, flags);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template <class Key>
void launch_cell_write(const Key* keys, const std::uint32_t* values, std::size_t m, const std::uint32_t* index,
                       CollisionCell* cells, std::uint32_t* pass_begin, int sm_count, cudaStream_t stream) {
  cell_write_kernel<Key><<<grid_for(m, sm_count), kBlock, 0, stream>>>(keys, values, m, index, cells);
  MARBLES_CUDA_CHECK_LAUNCH();
  pass_ranges_kernel<<<1, 32, 0, stream>>>(values, cells, index + m, pass_begin);
  MARBLES_CUDA_CHECK_LAUNCH();
}

template void launch_cell_flags<std::uint32_t>(const std::uint32_t*, const std::uint32_t*, std::size_t,
                                               std::uint32_t*, int, cudaStream_t);
template void launch_cell_flags<std::uint64_t>(const std::uint64_t*, const std::uint32_t*, std::size_t,
                                               std::uint32_t*, int, cudaStream_t);
template void launch_cell_write<std::uint32_t>(const std::uint32_t*, const std::uint32_t*, std::size_t,
                                               const std::uint32_t*, CollisionCell*, std::uint32_t*, int,
                                               cudaStream_t);
template void launch_cell_write<std::uint64_t>(const std::uint64_t*, const std::uint32_t*, std::size_t,
                                               const std::uint32_t*, CollisionCell*, std::uint32_t*, int,
                                               cudaStream_t);

}  // namespace marbles::broadphase::cuda
