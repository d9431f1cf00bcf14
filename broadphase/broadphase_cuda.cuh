// broadphase/broadphase_cuda.cuh — the CUDA stages of the broad phase as
// free launch functions over raw device pointers, counts and a stream (the
// kernels are in cell_ids_cuda.cu, radix_sort_cuda.cu, cell_list_cuda.cu,
// traversal_cuda.cu; broadphase_cuda.cu strings them together). Only .cu
// files include this header.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "broadphase/broadphase_cuda.hpp"
#include "broadphase/broadphase_math.hpp"
#include "broadphase/grid.hpp"
#include "broadphase/home_cell_math.hpp"
#include "core/bits.hpp"
#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "core/pair.hpp"

namespace marbles::broadphase::cuda {

using ::marbles::cuda::DeviceBuffer;
using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

// --- cell IDs (cell_ids_cuda.cu) ---------------------------------------------
// Bounds of the centres as order-preserving integer encodings, so that
// atomicMin/atomicMax give the exact float (or double) extremes.
struct BoundsAccum {
  unsigned long long lo[3], hi[3], r_max;
  unsigned int bad;  // a centre or radius not finite, or a radius < 0
  unsigned int padding;  // set at the start: the host reads the accumulator whole
};
// *acc set to its start, then the bounds of the n spheres reduced into it
// (two launches: nothing copied from the host).
void launch_bounds(const Vec3* centre, const real* radius, std::size_t n, BoundsAccum* acc, int sm_count,
                   cudaStream_t stream);
// launch_bounds, then the accumulator read into *host (pinned, or any host
// memory) with a wait: the bounds, for a grid chosen on the host.
// NonFiniteInput where a centre or radius is not finite.
Bounds read_bounds(const Vec3* centre, const real* radius, std::size_t n, BoundsAccum* acc, BoundsAccum* host,
                   int sm_count, cudaStream_t stream);
// A real as an order-preserving integer (negative reals below positive
// ones, each in its order), and back.
MARBLES_HD_INLINE unsigned long long encode_ordered(real v) {
  if constexpr (sizeof(real) == 4) {
    const std::uint32_t u = bits_of_float(v);
    return (u & 0x80000000u) ? static_cast<unsigned long long>(~u) : static_cast<unsigned long long>(u | 0x80000000u);
  } else {
    const std::uint64_t u = bits_of_double(v);
    return (u & 0x8000000000000000ull) ? ~u : (u | 0x8000000000000000ull);
  }
}
MARBLES_HD_INLINE real decode_ordered(unsigned long long k) {
  if constexpr (sizeof(real) == 4) {
    const auto e = static_cast<std::uint32_t>(k);
    return float_of_bits((e & 0x80000000u) ? (e & 0x7fffffffu) : ~e);
  } else {
    return static_cast<real>(double_of_bits((k & 0x8000000000000000ull) ? (k & 0x7fffffffffffffffull) : ~k));
  }
}
MARBLES_HD_INLINE Bounds decode_bounds(const BoundsAccum& acc) {
  Bounds b;
  b.lo = Vec3(decode_ordered(acc.lo[0]), decode_ordered(acc.lo[1]), decode_ordered(acc.lo[2]));
  b.hi = Vec3(decode_ordered(acc.hi[0]), decode_ordered(acc.hi[1]), decode_ordered(acc.hi[2]));
  b.r_max = decode_ordered(acc.r_max);
  return b;
}

// *grid = the home grid of the bounds in *acc (home_grid_of, the host's
// function), or a grid with cells = 0 (kNoGrid) where the bounds are not
// finite, the grid is too wide or it does not fit `plan` (plan_fits): every
// home kernel then finds no pair. *outsized = 1 where the grid fits a plan
// larger than it asks (plan_outsized, for n spheres), else 0. One thread.
inline constexpr std::uint64_t kNoGrid = 0;
void launch_home_grid(const BoundsAccum* acc, real margin, const HomePlan& plan, std::size_t n, HomeGrid* grid,
                      std::uint32_t* outsized, cudaStream_t stream);
// counts[i] = occupied cells of sphere i, info[i] = home type and type mask.
void launch_cell_counts(const Vec3* centre, const real* radius, std::size_t n, const Grid& grid, std::uint32_t* counts,
                        std::uint16_t* info, int sm_count, cudaStream_t stream);
// Writes sphere i's entries at offsets[i] (exclusive scan of counts).
template <class Key>
void launch_cell_ids(const Vec3* centre, const real* radius, std::size_t n, const Grid& grid,
                     const std::uint32_t* offsets, Key* keys, std::uint32_t* values, int sm_count, cudaStream_t stream);

// --- sort (radix_sort_cuda.cu) -------------------------------------------------
// Both sorts are stable, sort keys[0, n) by bits [0, key_bits) and move the
// values with them; they ping-pong between (keys, values) and (keys_alt,
// values_alt) and return true when the result is in the _alt pair.
template <class Key>
bool seed_radix_sort(Key* keys, std::uint32_t* values, Key* keys_alt, std::uint32_t* values_alt, std::size_t n,
                     unsigned key_bits, DeviceBuffer& scratch, int sm_count, cudaStream_t stream);
template <class Key>
bool cub_radix_sort(Key* keys, std::uint32_t* values, Key* keys_alt, std::uint32_t* values_alt, std::size_t n,
                    unsigned key_bits, DeviceBuffer& temp, cudaStream_t stream);
// Exclusive sum of in[0, n) into out[0, n) through CUB (temp grown as needed).
void exclusive_sum(const std::uint32_t* in, std::uint32_t* out, std::size_t n, DeviceBuffer& temp,
                   cudaStream_t stream);

// --- collision-cell list (cell_list_cuda.cu) -----------------------------------
// flags[i] = 1 when a collision cell starts at sorted entry i (flags[m] = 0).
template <class Key>
void launch_cell_flags(const Key* keys, const std::uint32_t* values, std::size_t m, std::uint32_t* flags,
                       int sm_count, cudaStream_t stream);
// cells[index[i]] = the cell starting at i, for each flagged i; then
// pass_begin[t - 1] = first cell of type t (t = 1..8), pass_begin[8] = cell count
// (index[m] = cell count), all on the device.
template <class Key>
void launch_cell_write(const Key* keys, const std::uint32_t* values, std::size_t m, const std::uint32_t* index,
                       CollisionCell* cells, std::uint32_t* pass_begin, int sm_count, cudaStream_t stream);

// --- traversal (traversal_cuda.cu) ---------------------------------------------
struct alignas(sizeof(real) * 4) SortedSphere {
  Vec3 centre;
  real radius;
};
struct TraversalInput {
  const CollisionCell* cells;
  const std::uint32_t* cell_index;  // exclusive scan of the cell flags, m + 1 entries
  const std::uint32_t* values;      // sorted object-list values
  const Vec3* centre;               // by object id
  const real* radius;
  const std::uint16_t* info;
  SortedSphere* sorted_sphere;      // by sorted entry (written by launch_gather)
  std::uint16_t* sorted_info;
  real margin;
};
// sorted_sphere[e], sorted_info[e] = the sphere of sorted entry e.
void launch_gather(const TraversalInput& in, std::size_t m, int sm_count, cudaStream_t stream);
// counts[e] = pairs sorted entry e emits (counts[m] = 0); *tests += exact tests made.
void launch_traversal_count(const TraversalInput& in, std::size_t m, std::uint32_t* counts, unsigned long long* tests,
                            int sm_count, cudaStream_t stream);
// Writes entry e's pairs at offsets[e].
void launch_traversal_write(const TraversalInput& in, std::size_t m, const std::uint32_t* offsets, IndexPair* pairs,
                            int sm_count, cudaStream_t stream);

// --- home-cell variant (home_cell_cuda.cu) -------------------------------------
// keys[i] = home key of sphere i, ids[i] = i.
// `grid` on the device (launch_home_grid); with kNoGrid every key is 0.
template <class Key>
void launch_home_keys(const Vec3* centre, std::size_t n, const HomeGrid* grid, Key* keys, std::uint32_t* ids,
                      int sm_count, cudaStream_t stream);
// sorted[i] = sphere ids[i] (centre, radius); with `lb` (at least the
// grid's cells + 1 entries): lb[k] = first sorted index whose key is >= k.
template <class Key>
void launch_home_reorder(const Key* keys, const std::uint32_t* ids, std::size_t n, const Vec3* centre,
                         const real* radius, const HomeGrid* grid, SortedSphere* sorted, std::uint32_t* lb,
                         int sm_count, cudaStream_t stream);
template <class Key>
struct HomeTraversal {
  const Key* keys;             // sorted home keys
  const std::uint32_t* ids;    // sorted ids
  const SortedSphere* sphere;  // spheres in sorted order
  const std::uint32_t* lb;     // dense lower bounds, or null: binary search over keys
  const HomeGrid* grid;        // on the device (launch_home_grid); kNoGrid: no pairs
  std::uint32_t n;
  real margin;
};
// counts[i] = pairs sorted sphere i finds (counts[n] = 0); *tests += exact tests.
template <class Key>
void launch_home_count(const HomeTraversal<Key>& in, std::uint32_t* counts, unsigned long long* tests, int sm_count,
                       cudaStream_t stream);
// *count = the pairs in all (offsets[n]), or kNoPairCount where the grid
// is kNoGrid.
inline constexpr std::uint32_t kNoPairCount = SubdivisionCuda::kNoPairCount;
template <class Key>
void launch_home_pair_count(const HomeTraversal<Key>& in, const std::uint32_t* offsets, std::uint32_t* count,
                            cudaStream_t stream);
// Writes sphere i's pairs at offsets[i], unless there are more than
// `capacity` in all (offsets[n]) or the grid is kNoGrid: then it writes none.
template <class Key>
void launch_home_write(const HomeTraversal<Key>& in, const std::uint32_t* offsets, std::size_t capacity,
                       IndexPair* pairs, int sm_count, cudaStream_t stream);

}  // namespace marbles::broadphase::cuda
