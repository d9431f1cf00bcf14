// broadphase/broadphase.hpp — the broad phase as callers see it.
//
// Contract (DESIGN.md): given N spheres, emit every pair (i, j), i < j, with
//   |c_i - c_j|^2 < (r_i + r_j + margin)^2     (spheres_overlap in broadphase_math.hpp)
// each exactly once, in an order that depends only on the input. The
// subdivision backends (CPU, CUDA) and the O(N^2) oracle use the same
// predicate, so their pair sets must be equal bit for bit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "core/pair.hpp"
#include "core/spheres.hpp"

namespace marbles::broadphase {

using Pair = IndexPair;

enum class Backend { cpu, cuda };
enum class SortKind { seed, cub };  // CUDA only: the seed's radix sort or CUB's

// seed: the seed's spatial subdivision (home and phantom cells, 8 passes).
// home: one entry per sphere (its home cell), sorted, then a search of the
//       neighbouring cells (home_cell_math.hpp). Same contract, same oracle.
enum class Algorithm { seed, home };
inline const char* algorithm_name(Algorithm a) { return a == Algorithm::seed ? "seed" : "home"; }

// What the step and the command line get: the home-cell variant is faster on
// both backends (docs/broadphase.md, "Measured").
inline constexpr Algorithm kDefaultCpuAlgorithm = Algorithm::home;
inline constexpr Algorithm kDefaultCudaAlgorithm = Algorithm::home;

// Per-call figures, for the benchmark and the run summary.
struct Stats {
  double ms_cell_ids = 0, ms_sort = 0, ms_cell_list = 0, ms_traversal = 0, ms_total = 0;
  std::size_t cell_entries = 0;     // valid (non-0xffffffff) entries sorted
  std::size_t collision_cells = 0;  // cells with >= 2 occupants, >= 1 home
  std::size_t tests = 0;            // exact sphere tests made in traversal
  std::size_t pairs = 0;            // pairs emitted
  unsigned key_bits = 0;            // bits of the cell key that the sort had to look at
  double cell_size = 0;
  // Added: how the call went.
  unsigned key_width = 0;           // 32 or 64: the key type sorted
  unsigned sort_passes = 0;         // 8-bit radix passes made
  bool compressed_keys = false;     // the grid was too wide for 63 key bits: per-axis ranks were used
  std::size_t cells_per_type[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // collision cells per pass
  // Home-cell variant: cells of the grid and how their starts were found.
  std::size_t grid_cells = 0;
  bool dense_cell_starts = false;   // a lower-bound array over all cells (else binary search)
};

// A centre or radius that is not finite (a step that went non-finite):
// the step backends turn it into their non-finite flag.
class NonFiniteInput : public RuntimeFailure {
 public:
  NonFiniteInput() : RuntimeFailure("broad phase: a centre or radius is not finite, or a radius is negative") {}
};

class BroadPhase {
 public:
  virtual ~BroadPhase() = default;
  // Host arrays in, host pairs out: `out` is replaced (the CPU backends empty it where the call throws).
  virtual void find_pairs(const SpheresIn& spheres, real margin, std::vector<Pair>& out) = 0;
  virtual const Stats& last_stats() const = 0;
  virtual std::string name() const = 0;
};

// The CPU backends (OpenMP where it pays).
std::unique_ptr<BroadPhase> make_subdivision_cpu(Algorithm algorithm = kDefaultCpuAlgorithm);

// The GPU backends; `sort` picks the radix sort of either algorithm. Throws
// RuntimeFailure when the build has no CUDA backend or there is no device.
std::unique_ptr<BroadPhase> make_subdivision_cuda(Algorithm algorithm = kDefaultCudaAlgorithm,
                                                  SortKind sort = SortKind::cub);

// The home-cell variant on the CPU (home_cell_cpu.cpp); the CUDA backend's
// route for grids too wide for 62-bit keys.
std::unique_ptr<BroadPhase> make_home_cell_cpu();

// The O(N^2) oracle: same predicate, pairs in (i, j) lexicographic order.
void brute_force_pairs(const SpheresIn& spheres, real margin, std::vector<Pair>& out);

}  // namespace marbles::broadphase
