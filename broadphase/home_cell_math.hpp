// broadphase/home_cell_math.hpp — per-element arithmetic of the home-cell
// broad phase (one entry per sphere, neighbour search), shared by the CPU
// twin (home_cell_cpu.cpp) and the CUDA kernels (home_cell_cuda.cu).
//
// Grid: cell edge = (2 r_max + margin)(1 + kHomeCellSlack), at least the
// largest contact distance r_i + r_j + margin, so two spheres that overlap
// have home cells at most one apart per axis: the 27 cells around a home
// hold every partner. (The seed needs cells of 3√2 · 2 r_max so that a
// sphere reaches only its 2×2×2 block; here nothing but the centre is
// placed in the grid, so the smallest cell that bounds the contact distance
// is best: 27 cells of (2r)^3 are searched instead of 8 cells of (8.5r)^3.)
// The slack covers the rounding of the float predicate (a few ulp), so a
// pair the predicate accepts is never two cells apart.
//
// Key: the linear cell index key = x + X (y + Y z), with X, Y, Z the cells
// per axis; the origin lies two cells below the centres' box and X, Y, Z
// reach two cells above it, so a home's neighbours all exist and
// (x - 1 .. x + 1, y', z') are three consecutive keys. After sorting
// (key, id), the spheres of such a row of three cells are one contiguous
// range of sorted indices: [lb(k - 1), lb(k + 2)) where lb(k) is the first
// sorted index whose key is >= k (a dense array over all cells, or a binary
// search over the sorted keys for sparse grids).
//
// Each pair once: sorted sphere i tests (1) the rest of its own row,
// [i + 1, lb(key + 2)): later spheres of its own cell and all of cell x + 1;
// (2) the full rows of the four "forward" (dy, dz) in {(1,0), (-1,1), (0,1),
// (1,1)}. For homes A, B with (dy, dz) = (0, 0) the sphere with the smaller
// x (same cell: smaller sorted index) finds the other in its own row; else
// exactly one of (dy, dz) and (-dy, -dz) is forward. 13.5 cells are searched
// per sphere instead of 27, with no id comparison.
#pragma once

#include <cmath>
#include <cstdint>

#include "broadphase/broadphase_math.hpp"
#include "core/lower_bound.hpp"  // lower_bound_key: the lookup for grids too sparse for a dense array
#include "core/pair.hpp"

namespace marbles::broadphase {

// Relative enlargement of the cell over the largest contact distance.
inline constexpr double kHomeCellSlack = 1e-4;

struct HomeGrid {
  double origin[3] = {0, 0, 0};  // corner of cell (0, 0, 0)
  double cell = 1;
  double inv_cell = 1;
  std::uint64_t dim[3] = {1, 1, 1};  // cells per axis (X, Y, Z)
  std::uint64_t cells = 1;           // X * Y * Z: keys are [0, cells)
  std::uint32_t key_bits = 0;        // bits of cells - 1
  // Named padding: the device writes a grid whole (home_grid_kernel) and
  // blocks copy it whole (block_grid), so no byte of it is left unwritten.
  std::uint32_t padding = 0;
  std::uint64_t row_offset[4] = {0, 0, 0, 0};  // key offsets of the forward rows
};

MARBLES_HD_INLINE CellCoord home_cell(const Vec3& c, const HomeGrid& g) {
  return {cell_coord(c.x, g.origin[0], g.inv_cell), cell_coord(c.y, g.origin[1], g.inv_cell),
          cell_coord(c.z, g.origin[2], g.inv_cell)};
}

MARBLES_HD_INLINE std::uint64_t home_key(const CellCoord& c, const HomeGrid& g) {
  return static_cast<std::uint64_t>(c.x) +
         g.dim[0] * (static_cast<std::uint64_t>(c.y) + g.dim[1] * static_cast<std::uint64_t>(c.z));
}

// Forward rows (dy, dz) in {(1,0), (-1,1), (0,1), (1,1)} as key offsets.
MARBLES_HD_INLINE void set_row_offsets(HomeGrid& g) {
  const std::uint64_t X = g.dim[0], XY = g.dim[0] * g.dim[1];
  g.row_offset[0] = X;
  g.row_offset[1] = XY - X;
  g.row_offset[2] = XY;
  g.row_offset[3] = XY + X;
}

// Sets cells, key_bits and row offsets from dim; false when X * Y * Z
// exceeds 2^62 (the caller then compresses the axes).
MARBLES_HD_INLINE bool set_home_layout(HomeGrid& g) {
  const double product = double(g.dim[0]) * double(g.dim[1]) * double(g.dim[2]);
  if (!(product < 4.0e18)) return false;
  g.cells = g.dim[0] * g.dim[1] * g.dim[2];
  std::uint32_t b = 0;
  for (std::uint64_t v = g.cells - 1; v; v >>= 1) ++b;
  g.key_bits = b;
  set_row_offsets(g);
  return true;
}

// The candidate ranges of sorted sphere i with home key k: own row after i,
// then the four forward rows. visit(begin, end) is called per range in this
// order (the output order); lb(key) = first sorted index with key >= key.
template <class Key, class LowerBound, class Visit>
MARBLES_HD_INLINE void for_each_candidate_range(std::uint32_t i, Key k, const HomeGrid& g, LowerBound&& lb,
                                                Visit&& visit) {
  visit(i + 1, lb(static_cast<Key>(k + 2)));
  for (int r = 0; r < 4; ++r) {
    const Key row = static_cast<Key>(k + static_cast<Key>(g.row_offset[r]));
    visit(lb(static_cast<Key>(row - 1)), lb(static_cast<Key>(row + 2)));
  }
}

// All tests of sorted sphere i: `sphere(j)` gives the centre and radius of
// sorted sphere j (SphereRecord: centre, radius); emit(j) is called for each
// candidate j that overlaps, in range order. Returns the exact tests made.
template <class Key, class Record, class LowerBound, class SphereOf, class Emit>
MARBLES_HD_INLINE unsigned traverse_home_sphere(std::uint32_t i, Key k, const Record& own, const HomeGrid& g,
                                                LowerBound&& lb, SphereOf&& sphere, real margin, Emit&& emit) {
  unsigned tests = 0;
  for_each_candidate_range(i, k, g, lb, [&](std::uint32_t begin, std::uint32_t end) {
    for (std::uint32_t j = begin; j < end; ++j) {
      const Record o = sphere(j);
      ++tests;
      if (spheres_overlap(own.centre, own.radius, o.centre, o.radius, margin)) emit(j);
    }
  });
  return tests;
}

// The pair of original ids, smaller first.
MARBLES_HD_INLINE IndexPair ordered_pair(std::uint32_t a, std::uint32_t b) {
  return a < b ? IndexPair{a, b} : IndexPair{b, a};
}

}  // namespace marbles::broadphase
