// broadphase/broadphase_math.hpp — per-element arithmetic of the broad phase,
// shared by the CPU loops (broadphase_cpu.cpp) and the CUDA kernels
// (*_cuda.cu), so that CI, which has no GPU, tests what the GPU computes.
//
// Units: lengths in the scene's unit (m); cell coordinates are integers,
// counted from the grid origin, which lies two cells below the lower corner
// of the centres' bounding box, so every coordinate (and every neighbour's)
// is >= 0.
//
// The cell key is type-major: key = (type - 1) << type_shift
//                                  | (x >> 1) << shift[0] | (y >> 1) << shift[1] | (z >> 1) << shift[2].
// (type - 1) holds the three parities, so (type, x >> 1, y >> 1, z >> 1) is a
// bijection of (x, y, z): keys never collide. Sorting by this key also
// sorts the collision cells by type, so the 8 per-type lists of the seed are
// 8 contiguous ranges of one list.
#pragma once

#include <cmath>
#include <cstdint>

#include "core/config.hpp"
#include "core/vec3.hpp"

namespace marbles::broadphase {

// Objects are packed with 4 flag bits into a 32-bit object-list value.
inline constexpr std::uint32_t kMaxObjects = 1u << 28;
inline constexpr std::uint32_t kInvalidKey32 = 0xffffffffu;
inline constexpr std::uint64_t kInvalidKey64 = ~std::uint64_t{0};
// Cell edge = kCellFactor * (r_max + margin / 2): 1.5 x the sqrt(2)-scaled diameter.
inline constexpr double kSqrt2 = 1.4142135623730951;
inline constexpr double kCellFactor = 1.5 * 2.0 * kSqrt2;
// The scaled radius is enlarged by this relative amount when phantom cells
// are chosen: it covers the rounding of the float overlap predicate; extra
// phantom cells cost tests, never correctness (see docs/broadphase.md).
inline constexpr double kPhantomSlack = 1e-4;

// The uniform grid of one call. Plain values: passed by value to kernels.
struct Grid {
  double origin[3] = {0, 0, 0};  // world position of the corner of cell (0, 0, 0)
  double cell = 1;               // cell edge
  double inv_cell = 1;
  double scaled_per_length = 0;  // sqrt(2) * (1 + slack) / cell: scaled radius in cells per unit of length
  double half_margin = 0;        // margin / 2, added to every radius
  std::uint32_t shift[3] = {0, 0, 0};  // bit position of x >> 1, y >> 1, z >> 1 in the key
  std::uint32_t type_shift = 0;        // bit position of (type - 1)
  std::uint32_t key_bits = 3;          // type_shift + 3: bits the key uses
};

struct CellCoord {
  std::int64_t x = 0, y = 0, z = 0;
};

// The 2x2x2 block of cells a sphere can touch: its home cell and, per axis,
// the neighbour on the side nearer to the centre. Bit o of `occupied`
// (o = 0..7, bit k of o = step along axis k) is set when the scaled sphere
// overlaps that cell; bit 0 (the home cell) is always set.
struct Neighbourhood {
  CellCoord home;
  int step[3] = {1, 1, 1};
  unsigned occupied = 1;
};

MARBLES_HD_INLINE std::int64_t cell_coord(real p, double origin, double inv_cell) {
  return static_cast<std::int64_t>(floor((static_cast<double>(p) - origin) * inv_cell));
}

// 1 + (x & 1) + 2 (y & 1) + 4 (z & 1): cells of one type are never neighbours.
MARBLES_HD_INLINE unsigned cell_type(std::int64_t x, std::int64_t y, std::int64_t z) {
  return 1u + static_cast<unsigned>(x & 1) + 2u * static_cast<unsigned>(y & 1) + 4u * static_cast<unsigned>(z & 1);
}
MARBLES_HD_INLINE unsigned cell_type(const CellCoord& c) { return cell_type(c.x, c.y, c.z); }

MARBLES_HD_INLINE std::uint64_t pack_key(const CellCoord& c, const Grid& g) {
  return (static_cast<std::uint64_t>(cell_type(c) - 1u) << g.type_shift) |
         (static_cast<std::uint64_t>(c.x >> 1) << g.shift[0]) |
         (static_cast<std::uint64_t>(c.y >> 1) << g.shift[1]) |
         (static_cast<std::uint64_t>(c.z >> 1) << g.shift[2]);
}

// The type of the cells a key stands for (1..8).
MARBLES_HD_INLINE unsigned key_type(std::uint64_t key, const Grid& g) {
  return 1u + static_cast<unsigned>((key >> g.type_shift) & 7u);
}

MARBLES_HD_INLINE CellCoord neighbour_cell(const Neighbourhood& nb, unsigned o) {
  return {nb.home.x + ((o & 1u) ? nb.step[0] : 0), nb.home.y + ((o & 2u) ? nb.step[1] : 0),
          nb.home.z + ((o & 4u) ? nb.step[2] : 0)};
}

// Home cell and phantom cells of the sphere (centre c, radius r) scaled by
// sqrt(2): a neighbour of the block is occupied when the distance from c to
// that cell is <= the scaled radius (exact sphere-box test, per axis the
// distance to the shared face). The cell edge is >= 3 sqrt(2) r, so the
// scaled sphere (radius <= cell / 3) reaches at most one neighbour per axis.
MARBLES_HD_INLINE Neighbourhood sphere_neighbourhood(const Vec3& c, real r, const Grid& g) {
  Neighbourhood nb;
  const double s = (static_cast<double>(r) + g.half_margin) * g.scaled_per_length;  // in cells
  const double s2 = s * s + 1e-18;
  double gap[3];
  std::int64_t home[3];
  for (int k = 0; k < 3; ++k) {
    const double u = (static_cast<double>(c[k]) - g.origin[k]) * g.inv_cell;
    const double fl = floor(u);
    const double f = u - fl;  // position inside the home cell, [0, 1)
    home[k] = static_cast<std::int64_t>(fl);
    nb.step[k] = f < 0.5 ? -1 : 1;
    gap[k] = f < 0.5 ? f : 1.0 - f;
  }
  nb.home = {home[0], home[1], home[2]};
  for (unsigned o = 1; o < 8; ++o) {
    double d2 = 0;
    for (int k = 0; k < 3; ++k)
      if (o & (1u << k)) d2 += gap[k] * gap[k];
    if (d2 <= s2) nb.occupied |= 1u << o;
  }
  return nb;
}

// Bit (type - 1) set for each cell type the sphere occupies (H and P).
MARBLES_HD_INLINE unsigned type_mask(const Neighbourhood& nb) {
  unsigned mask = 0;
  for (unsigned o = 0; o < 8; ++o)
    if (nb.occupied & (1u << o)) mask |= 1u << (cell_type(neighbour_cell(nb, o)) - 1u);
  return mask;
}

MARBLES_HD_INLINE unsigned occupied_count(unsigned occupied) {
  unsigned n = 0;
  for (unsigned o = 0; o < 8; ++o) n += (occupied >> o) & 1u;
  return n;
}

// One sphere's 8 cell-ID entries in the seed's layout: entry 0 the home
// cell, then its phantom cells, unused entries all-ones (sorted last).
struct SphereCellIds {
  std::uint64_t key[8];
  unsigned count = 0;      // used entries
  unsigned home_type = 1;  // 1..8
  unsigned mask = 0;       // type mask
};

MARBLES_HD_INLINE SphereCellIds sphere_cell_ids(const Vec3& c, real r, const Grid& g) {
  const Neighbourhood nb = sphere_neighbourhood(c, r, g);
  SphereCellIds ids;
  for (unsigned o = 0; o < 8; ++o) {
    if (nb.occupied & (1u << o)) ids.key[ids.count++] = pack_key(neighbour_cell(nb, o), g);
  }
  for (unsigned e = ids.count; e < 8; ++e) ids.key[e] = kInvalidKey64;
  ids.home_type = cell_type(nb.home);
  ids.mask = type_mask(nb);
  return ids;
}

// Object-list value: object id, H/P flag, cell type.
MARBLES_HD_INLINE std::uint32_t make_value(std::uint32_t id, bool phantom, unsigned type) {
  return (id << 4) | (phantom ? 8u : 0u) | (type - 1u);
}
MARBLES_HD_INLINE std::uint32_t value_id(std::uint32_t v) { return v >> 4; }
MARBLES_HD_INLINE bool value_phantom(std::uint32_t v) { return (v & 8u) != 0; }
MARBLES_HD_INLINE unsigned value_type(std::uint32_t v) { return (v & 7u) + 1u; }

// Per-sphere record used by the traversal: home cell type and type mask.
MARBLES_HD_INLINE std::uint16_t make_info(unsigned home_type, unsigned mask) {
  return static_cast<std::uint16_t>((home_type << 8) | mask);
}
MARBLES_HD_INLINE unsigned info_home_type(std::uint16_t info) { return info >> 8; }
MARBLES_HD_INLINE unsigned info_mask(std::uint16_t info) { return info & 0xffu; }

// The skip rule: in pass T the pair (A, B) was already tested in an earlier
// pass T' when the home type T' of A or of B is < T and T' is in both masks.
MARBLES_HD_INLINE bool tested_in_earlier_pass(unsigned pass_type, std::uint16_t info_a, std::uint16_t info_b) {
  const unsigned common = info_mask(info_a) & info_mask(info_b);
  const unsigned ta = info_home_type(info_a), tb = info_home_type(info_b);
  return (ta < pass_type && ((common >> (ta - 1u)) & 1u)) || (tb < pass_type && ((common >> (tb - 1u)) & 1u));
}

// In a cell, H object at position a is tested against the object at
// position b != a when b is P, or b is H and comes after a (H-H once).
MARBLES_HD_INLINE bool cell_tests_pair(bool b_phantom, std::uint32_t pos_a, std::uint32_t pos_b) {
  return b_phantom || pos_b > pos_a;
}

// The exact predicate: |ci - cj|^2 < (ri + rj + margin)^2, evaluated in the
// same order with the same roundings on host and device: on the device each
// product and sum is an explicitly rounded operation, so the compiler cannot
// fuse them into FMAs (which round once, and would flip exactly-touching
// pairs against the CPU oracle).
MARBLES_HD_INLINE real mul_rn(real a, real b) {
#if defined(__CUDA_ARCH__)
  if constexpr (sizeof(real) == 4) return __fmul_rn(a, b); else return __dmul_rn(a, b);
#else
  return a * b;
#endif
}
MARBLES_HD_INLINE real add_rn(real a, real b) {
#if defined(__CUDA_ARCH__)
  if constexpr (sizeof(real) == 4) return __fadd_rn(a, b); else return __dadd_rn(a, b);
#else
  return a + b;
#endif
}
MARBLES_HD_INLINE bool spheres_overlap(const Vec3& ci, real ri, const Vec3& cj, real rj, real margin) {
  const real dx = ci.x - cj.x, dy = ci.y - cj.y, dz = ci.z - cj.z;
  const real d2 = add_rn(add_rn(mul_rn(dx, dx), mul_rn(dy, dy)), mul_rn(dz, dz));
  const real reach = add_rn(add_rn(ri, rj), margin);
  return d2 < mul_rn(reach, reach);
}

// A collision cell: a run of equal keys in the sorted cell-ID array with at
// least two occupants, at least one of them H.
struct CollisionCell {
  std::uint32_t start = 0;    // first entry in the sorted arrays
  std::uint32_t n_home = 0;   // H occupants
  std::uint32_t n_phantom = 0;  // P occupants
};

// The work of one H occupant (position a in its collision cell; the pass T
// is the cell's type): tested against every other occupant that is P, or H
// further on (so an H-H pair once), unless the skip rule says the pair was
// tested in an earlier pass; then the exact test. `sphere(k)` gives the
// centre, radius and info of the cell's k-th occupant. emit(i, j) is called
// with i < j for each overlapping pair; returns the exact tests made.
struct Occupant {
  Vec3 centre;
  real radius;
  std::uint16_t info;
};

template <class SphereOf, class Emit>
MARBLES_HD_INLINE unsigned traverse_home_occupant(std::uint32_t a, const CollisionCell& cell,
                                                  const std::uint32_t* values, SphereOf&& sphere, real margin,
                                                  Emit&& emit) {
  const std::uint32_t n = cell.n_home + cell.n_phantom;
  const std::uint32_t va = values[cell.start + a];
  const unsigned pass_type = value_type(va);
  const std::uint32_t ia = value_id(va);
  const Occupant oa = sphere(a);
  unsigned tests = 0;
  for (std::uint32_t b = 0; b < n; ++b) {
    if (b == a) continue;
    const std::uint32_t vb = values[cell.start + b];
    if (!cell_tests_pair(value_phantom(vb), a, b)) continue;
    const Occupant ob = sphere(b);
    if (tested_in_earlier_pass(pass_type, oa.info, ob.info)) continue;
    ++tests;
    if (spheres_overlap(oa.centre, oa.radius, ob.centre, ob.radius, margin)) {
      const std::uint32_t ib = value_id(vb);
      if (ia < ib)
        emit(ia, ib);
      else
        emit(ib, ia);
    }
  }
  return tests;
}

// One collision cell: each H occupant in order. Entries of a cell are in
// object-id order (stable sort of entries written in id order), so the
// order of emission depends only on the input.
template <class Emit>
MARBLES_HD_INLINE unsigned traverse_cell(const CollisionCell& cell, const std::uint32_t* values, const Vec3* centre,
                                         const real* radius, const std::uint16_t* info, real margin, Emit&& emit) {
  const std::uint32_t n = cell.n_home + cell.n_phantom;
  auto sphere = [&](std::uint32_t k) {
    const std::uint32_t id = value_id(values[cell.start + k]);
    return Occupant{centre[id], radius[id], info[id]};
  };
  unsigned tests = 0;
  for (std::uint32_t a = 0; a < n; ++a)
    if (!value_phantom(values[cell.start + a])) tests += traverse_home_occupant(a, cell, values, sphere, margin, emit);
  return tests;
}

}  // namespace marbles::broadphase
