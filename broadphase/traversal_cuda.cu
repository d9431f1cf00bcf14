// broadphase/traversal_cuda.cu — the 8-pass traversal, one thread per
// collision cell (grid-stride), run twice: count the pairs of each cell,
// then (after an exclusive scan) write them. The per-cell work is
// traverse_cell() of broadphase_math.hpp, the same code the CPU runs; the
// pass T of a cell is its type. The 8 passes of the seed exist to keep
// threads of one launch from updating one object twice; the broad phase
// writes no per-object state, so the 8 type ranges run in one launch, and
// the list's type order keeps the output order of the 8 passes.
#include "broadphase/broadphase_cuda.cuh"

namespace marbles::broadphase::cuda {
namespace {

__global__ void traversal_count_kernel(TraversalInput in, std::uint32_t* __restrict__ counts,
                                       unsigned long long* __restrict__ tests) {
  unsigned long long my_tests = 0;
  for (std::size_t c = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; c < in.cell_count;
       c += std::size_t(gridDim.x) * blockDim.x) {
    std::uint32_t pairs = 0;
    my_tests += traverse_cell(in.cells[c], in.values, in.centre, in.radius, in.info, in.margin,
                              [&](std::uint32_t, std::uint32_t) { ++pairs; });
    counts[c] = pairs;
  }
  if (blockIdx.x == 0 && threadIdx.x == 0) counts[in.cell_count] = 0;
  for (int o = 16; o > 0; o >>= 1) my_tests += __shfl_down_sync(0xffffffffu, my_tests, o);
  if ((threadIdx.x & 31) == 0 && my_tests) atomicAdd(tests, my_tests);
}

__global__ void traversal_write_kernel(TraversalInput in, const std::uint32_t* __restrict__ offsets,
                                       IndexPair* __restrict__ pairs) {
  for (std::size_t c = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; c < in.cell_count;
       c += std::size_t(gridDim.x) * blockDim.x) {
    std::uint32_t at = offsets[c];
    traverse_cell(in.cells[c], in.values, in.centre, in.radius, in.info, in.margin,
                  [&](std::uint32_t i, std::uint32_t j) { pairs[at++] = IndexPair{i, j}; });
  }
}

}  // namespace

void launch_traversal_count(const TraversalInput& in, std::uint32_t* counts, unsigned long long* tests, int sm_count,
                            cudaStream_t stream) {
  traversal_count_kernel<<<grid_for(in.cell_count, sm_count), kBlock, 0, stream>>>(in, counts, tests);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_traversal_write(const TraversalInput& in, const std::uint32_t* offsets, IndexPair* pairs, int sm_count,
                            cudaStream_t stream) {
  traversal_write_kernel<<<grid_for(in.cell_count, sm_count), kBlock, 0, stream>>>(in, offsets, pairs);
  MARBLES_CUDA_CHECK_LAUNCH();
}

}  // namespace marbles::broadphase::cuda
