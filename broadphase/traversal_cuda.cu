// broadphase/traversal_cuda.cu — the 8-pass traversal.
//
// Work item: one H occupant of a collision cell (one thread per sorted
// entry, grid-stride; P entries and entries outside collision cells do
// nothing), so a crowded cell (small spheres beside a large one) is spread
// over many threads instead of serialising on one. The per-occupant work is
// traverse_home_occupant() of broadphase_math.hpp, the code the CPU runs;
// the pass T is the cell's type. Run twice: count the pairs of each entry,
// then (after an exclusive scan) write them; entries are in cell order and,
// within a cell, in occupant order, so the output order is the CPU's.
//
// Before that, the centres, radii and infos are gathered into sorted-entry
// order (one random read per entry, written contiguously), so the tests in a
// cell read neighbouring memory instead of chasing ids across the arrays.
//
// The 8 passes of the seed exist to keep threads of one launch from updating
// one object twice; the broad phase writes no per-object state, so the 8
// type ranges run in one launch, and the list's type order keeps the output
// order of the 8 passes.
#include "broadphase/broadphase_cuda.cuh"

namespace marbles::broadphase::cuda {
namespace {

__global__ void gather_kernel(TraversalInput in, std::size_t m) {
  for (std::size_t e = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; e < m;
       e += std::size_t(gridDim.x) * blockDim.x) {
    const std::uint32_t id = value_id(in.values[e]);
    in.sorted_sphere[e] = SortedSphere{in.centre[id], in.radius[id]};
    in.sorted_info[e] = in.info[id];
  }
}

// The collision cell holding entry e, if e is an H occupant of one.
__device__ __forceinline__ bool home_cell_of(const TraversalInput& in, std::size_t e, CollisionCell& cell) {
  if (value_phantom(in.values[e])) return false;
  const std::uint32_t after = in.cell_index[e + 1];  // cells starting at or before e
  if (after == 0) return false;
  cell = in.cells[after - 1];
  return e < std::size_t(cell.start) + cell.n_home + cell.n_phantom;
}

template <class Emit>
__device__ __forceinline__ unsigned traverse_entry(const TraversalInput& in, std::size_t e, const CollisionCell& cell,
                                                   Emit&& emit) {
  const SortedSphere* rec = in.sorted_sphere + cell.start;
  const std::uint16_t* inf = in.sorted_info + cell.start;
  auto sphere = [&](std::uint32_t k) {
    const SortedSphere s = rec[k];
    return Occupant{s.centre, s.radius, inf[k]};
  };
  return traverse_home_occupant(static_cast<std::uint32_t>(e - cell.start), cell, in.values, sphere, in.margin, emit);
}

__global__ void traversal_count_kernel(TraversalInput in, std::size_t m, std::uint32_t* __restrict__ counts,
                                       unsigned long long* __restrict__ tests) {
  unsigned long long my_tests = 0;
  for (std::size_t e = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; e < m;
       e += std::size_t(gridDim.x) * blockDim.x) {
    std::uint32_t pairs = 0;
    CollisionCell cell;
    if (home_cell_of(in, e, cell)) my_tests += traverse_entry(in, e, cell, [&](std::uint32_t, std::uint32_t) { ++pairs; });
    counts[e] = pairs;
  }
  if (blockIdx.x == 0 && threadIdx.x == 0) counts[m] = 0;
  for (int o = 16; o > 0; o >>= 1) my_tests += __shfl_down_sync(0xffffffffu, my_tests, o);
  if ((threadIdx.x & 31) == 0 && my_tests) atomicAdd(tests, my_tests);
}

__global__ void traversal_write_kernel(TraversalInput in, std::size_t m, const std::uint32_t* __restrict__ offsets,
                                       IndexPair* __restrict__ pairs) {
  for (std::size_t e = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; e < m;
       e += std::size_t(gridDim.x) * blockDim.x) {
    std::uint32_t at = offsets[e];
    if (offsets[e + 1] == at) continue;  // no pairs from this entry
    CollisionCell cell;
    if (home_cell_of(in, e, cell))
      traverse_entry(in, e, cell, [&](std::uint32_t i, std::uint32_t j) { pairs[at++] = IndexPair{i, j}; });
  }
}

}  // namespace

void launch_gather(const TraversalInput& in, std::size_t m, int sm_count, cudaStream_t stream) {
  gather_kernel<<<grid_for(m, sm_count), kBlock, 0, stream>>>(in, m);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_traversal_count(const TraversalInput& in, std::size_t m, std::uint32_t* counts, unsigned long long* tests,
                            int sm_count, cudaStream_t stream) {
  traversal_count_kernel<<<grid_for(m, sm_count), kBlock, 0, stream>>>(in, m, counts, tests);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_traversal_write(const TraversalInput& in, std::size_t m, const std::uint32_t* offsets, IndexPair* pairs,
                            int sm_count, cudaStream_t stream) {
  traversal_write_kernel<<<grid_for(m, sm_count), kBlock, 0, stream>>>(in, m, offsets, pairs);
  MARBLES_CUDA_CHECK_LAUNCH();
}

}  // namespace marbles::broadphase::cuda
