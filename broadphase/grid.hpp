// broadphase/grid.hpp — choosing the grid of one call (both backends; the
// home grid also on the device, home_grid_of).
//
// The grid is rebuilt each call from the bounding box of the centres, so no
// sphere is ever outside it, however far it has travelled. Cell coordinates
// are counted from two cells below the box's lower corner (all >= 0, also
// for the neighbours); the key needs bit_width(max >> 1) bits per axis plus
// 3 type bits. KeyWidth says which key type holds them with the all-ones
// value still free for "unused".
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "broadphase/broadphase_math.hpp"
#include "broadphase/home_cell_math.hpp"
#include "core/error.hpp"
#include "core/radix_sort.hpp"
#include "core/spheres.hpp"

namespace marbles::broadphase {

// The spheres lie too far apart for their sizes: more than 2^62 cells of the
// grid (sized from the largest radius) along an axis.
class SpanTooLarge : public RuntimeFailure {
 public:
  // Why, as the messages that name the option say it (run, pairs, Python's pairs).
  static constexpr const char* kWhy =
      "the spheres span more than 2^62 cells of their largest diameter: coordinates too far apart for their radii";
  SpanTooLarge() : RuntimeFailure(std::string("broad phase: ") + kWhy) {}
};

enum class KeyWidth { bits32, bits64, too_wide };

struct Bounds {
  Vec3 lo{0, 0, 0}, hi{0, 0, 0};
  real r_max = 0;
};

struct GridChoice {
  Grid grid;
  KeyWidth width = KeyWidth::bits32;
  CellCoord max_coord;  // largest cell coordinate (neighbours included) per axis
};

// Bounding box of the centres and largest radius (host arrays; OpenMP).
// Throws RuntimeFailure on a non-finite centre or radius or a negative radius.
Bounds bounds_of(const SpheresIn& spheres);

inline KeyWidth key_width_for(std::uint32_t key_bits) {
  if (key_bits <= 31) return KeyWidth::bits32;
  if (key_bits <= 63) return KeyWidth::bits64;
  return KeyWidth::too_wide;
}

// Packs the given per-axis maxima into key shifts.
inline void set_key_layout(Grid& g, const std::uint64_t half_max[3]) {
  std::uint32_t bits = 0;
  for (int k = 0; k < 3; ++k) {
    g.shift[k] = bits;
    bits += bits_needed(half_max[k]);
  }
  g.type_shift = bits;
  g.key_bits = bits + 3;
}

// Finite centres, and a largest radius finite and >= 0 (host and device:
// the device checks the bounds it does not read back).
MARBLES_HD_INLINE bool centres_finite(const Bounds& b) { return is_finite(b.lo) && is_finite(b.hi); }
MARBLES_HD_INLINE bool radius_valid(const Bounds& b) { return std::isfinite(b.r_max) && b.r_max >= 0; }

inline void check_margin(real margin) {
  if (!(margin >= 0) || !std::isfinite(static_cast<double>(margin)))
    throw RuntimeFailure("broad phase: margin must be finite and >= 0");
}

// Both grids refuse non-finite centres, negative or non-finite radii, and a
// negative or non-finite margin (RuntimeFailure).
inline void check_inputs(const Bounds& b, real margin) {
  check_margin(margin);
  if (!centres_finite(b)) throw RuntimeFailure("broad phase: a sphere centre is not finite");
  if (!radius_valid(b)) throw RuntimeFailure("broad phase: a radius is negative or not finite");
}

inline GridChoice choose_grid(const Bounds& b, real margin) {
  check_inputs(b, margin);

  GridChoice out;
  Grid& g = out.grid;
  const double reach = static_cast<double>(b.r_max) + 0.5 * static_cast<double>(margin);
  g.cell = reach > 0 ? kCellFactor * reach : 1.0;
  g.inv_cell = 1.0 / g.cell;
  g.scaled_per_length = kSqrt2 * (1.0 + kPhantomSlack) * g.inv_cell;
  g.half_margin = 0.5 * static_cast<double>(margin);
  for (int k = 0; k < 3; ++k) g.origin[k] = static_cast<double>(b.lo[k]) - 2.0 * g.cell;

  std::uint64_t half_max[3];
  std::int64_t maxc[3];
  for (int k = 0; k < 3; ++k) {
    const double span = (static_cast<double>(b.hi[k]) - g.origin[k]) * g.inv_cell;
    if (!(span < 4.0e18)) throw SpanTooLarge();
    maxc[k] = cell_coord(b.hi[k], g.origin[k], g.inv_cell) + 1;  // the neighbour above the top cell
    half_max[k] = static_cast<std::uint64_t>(maxc[k]) >> 1;
  }
  out.max_coord = {maxc[0], maxc[1], maxc[2]};
  set_key_layout(g, half_max);
  out.width = key_width_for(g.key_bits);
  return out;
}

}  // namespace marbles::broadphase

namespace marbles::broadphase {

// --- the home-cell grid (home_cell_math.hpp) ----------------------------------
// Largest span of the centres' box in cells: beyond it the cell grows, so
// that the double-precision cell coordinates of two spheres closer than one
// cell never differ by two (their rounding error stays under 2^-20 cells,
// far inside kHomeCellSlack).
inline constexpr double kHomeMaxSpanCells = 4294967296.0;  // 2^32

struct HomeGridChoice {
  HomeGrid grid;
  KeyWidth width = KeyWidth::bits32;  // bits32: cells <= 2^31; too_wide: X * Y * Z > 2^62
};

// The home grid of bounds b (finite: check_inputs) into g; too_wide where
// X * Y * Z exceeds 2^62. Host and device both (the device chooses the grid
// of a call that does not wait for its bounds: the same grid, so the same
// keys and order).
MARBLES_HD_INLINE KeyWidth home_grid_of(const Bounds& b, real margin, HomeGrid& g) {
  const double contact = 2.0 * static_cast<double>(b.r_max) + static_cast<double>(margin);
  double cell = contact > 0 ? contact * (1.0 + kHomeCellSlack) : 1.0;
  for (int k = 0; k < 3; ++k) {
    const double span = (static_cast<double>(b.hi[k]) - static_cast<double>(b.lo[k])) / kHomeMaxSpanCells;
    cell = span > cell ? span : cell;
  }
  if (!(cell <= DBL_MAX)) return KeyWidth::too_wide;  // a span past the doubles (double build): compressed keys
  g.cell = cell;
  g.inv_cell = 1.0 / cell;
  for (int k = 0; k < 3; ++k) {
    g.origin[k] = static_cast<double>(b.lo[k]) - 2.0 * cell;
    // homes are in [1, top]; two more cells above for the x + 2 lookups
    g.dim[k] = static_cast<std::uint64_t>(cell_coord(b.hi[k], g.origin[k], g.inv_cell)) + 3;
  }
  if (!set_home_layout(g)) return KeyWidth::too_wide;
  return g.cells <= (std::uint64_t{1} << 31) ? KeyWidth::bits32 : KeyWidth::bits64;
}

inline HomeGridChoice choose_home_grid(const Bounds& b, real margin) {
  check_inputs(b, margin);
  HomeGridChoice out;
  out.width = home_grid_of(b, margin, out.grid);
  return out;
}

// A dense lower-bound array (cells + 1 entries) is used when the grid is not
// much larger than the sphere count; sparser grids binary-search the keys.
MARBLES_HD_INLINE bool use_dense_cell_starts(const HomeGrid& g, std::size_t n) {
  return g.cells + 1 <= 16 * static_cast<std::uint64_t>(n) + (std::uint64_t{1} << 22);
}

// --- the plan of the GPU's home grid (broadphase_cuda.cu) -----------------------
// What a home grid chosen on the device must fit for the buffers and sort
// that the host laid out without reading the bounds: the key type (bits32:
// cells <= 2^31), the sort's bits and, with a dense lower-bound array, its
// cells (the array holds cells + 1 entries). Made from the grid of the last
// call that read its bounds.
struct HomePlan {
  bool bits32 = true;
  std::uint32_t key_bits = 0;
  bool dense = false;
  std::uint64_t cells = 0;  // with dense: the lower-bound array's cells
};

// The sort's 8-bit digits (passes) for `bits` key bits.
MARBLES_HD_INLINE std::uint32_t sort_digits(std::uint32_t bits) { return (bits + 7) / 8; }

// The plan of a grid (of `width`, not too_wide) for n spheres: its key
// type, the sort's bits rounded up to whole digits (as many passes), and a
// dense lower-bound array a quarter larger (and 1024 cells) than the grid
// needs.
MARBLES_HD_INLINE HomePlan plan_of(const HomeGrid& g, KeyWidth width, std::size_t n) {
  HomePlan p;
  p.bits32 = width == KeyWidth::bits32;
  const std::uint32_t bits = 8 * sort_digits(g.key_bits), cap = p.bits32 ? 32u : 64u;
  p.key_bits = bits < cap ? bits : cap;
  p.dense = use_dense_cell_starts(g, n);
  p.cells = p.dense ? g.cells + g.cells / 4 + 1024 : 0;
  return p;
}

// Whether grid g (of `width`) fits plan p: the same key type or a narrower
// one, no more key bits, and no more cells than a dense plan's array holds.
MARBLES_HD_INLINE bool plan_fits(const HomePlan& p, const HomeGrid& g, KeyWidth width) {
  return width != KeyWidth::too_wide && (!p.bits32 || width == KeyWidth::bits32) && g.key_bits <= p.key_bits &&
         (!p.dense || g.cells <= p.cells);
}

// Whether a plan that grid g fits is larger than g asks, by a margin: the
// plan of a grid with four times the cells (two more key bits: each axis
// about 1.6 times as long, or one axis four times) would sort fewer digits;
// 64-bit keys where four times g's cells still fit 32-bit keys; a dense
// array more than four times the one g's own plan takes; binary search where
// g at twice its cells would get an array. The plan of g itself is never
// outsized for g, and the plan an outsized grid makes has no wider keys, no
// more sort digits and no larger array (binary search may become an array),
// and is smaller or faster in one of these. The margins keep a plan from
// moving back and forth: where a grid grows back from the one that made
// the plan (up to four times the cells; twice where that would leave the
// array for binary search) past it, the plan the larger grid makes is not
// outsized for the smaller one. The host plans again (replan) where the
// device finds its plan outsized.
MARBLES_HD_INLINE bool plan_outsized(const HomePlan& p, const HomeGrid& g, std::size_t n) {
  if (!p.bits32 && g.cells <= (std::uint64_t{1} << 29)) return true;
  if (sort_digits(g.key_bits + 2) < sort_digits(p.key_bits)) return true;
  if (p.dense && p.cells / 4 > g.cells + g.cells / 4 + 1024) return true;
  if (!p.dense && 2 * g.cells + 1 <= 16 * static_cast<std::uint64_t>(n) + (std::uint64_t{1} << 22)) return true;
  return false;
}

}  // namespace marbles::broadphase
