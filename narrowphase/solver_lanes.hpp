// narrowphase/solver_lanes.hpp — the velocity sweep of solver_math.hpp on
// several contacts of one colour at once (CPU, SIMD lanes).
//
// solve_record (solve_one on a contact loaded from the sweep's records) is a
// long chain of scalar operations per contact (about 550 instructions with
// friction and rolling resistance); the contacts of one colour share no
// sphere, so W of them can run the same chain side by side, one per lane of
// a vector. Each lane performs exactly the operations of the effective
// masses, solve_friction, solve_rolling and solve_normal (contact_math.hpp),
// in the same order, with the branches turned into selects of values both
// sides compute; IEEE arithmetic is the same per lane as per scalar, so a
// lane's result is solve_one's bit for bit, and with it the CUDA twin's
// (tests/narrowphase/solver_lanes_test.cpp holds the two texts together on
// random and adversarial contacts).
//
// Two widths: L, 16 bytes (SSE2, which every x86-64 CPU has: 4 floats or 2
// doubles), and Wide, 32 bytes (8 floats or 4 doubles), which the solver
// runs where the CPU has AVX2 or AVX-512 (solver.cpp picks at run time and
// compiles those sweeps alone for them). The math is written once, for
// either vector type V; a Wide block moves its contacts and bodies in
// 32-byte moves in float (load_wide_bodies and the Wide load_words below)
// and as two L blocks in double. Every function here is always inlined, so
// a Wide one is compiled as part of its AVX caller and never on its own
// with a 16-byte baseline.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "narrowphase/solver_math.hpp"

#define MARBLES_LANE [[gnu::always_inline]] inline

namespace marbles::narrowphase::lanes {

template <int Bytes>
struct VectorOf;
template <>
struct VectorOf<16> {
  typedef real type __attribute__((vector_size(16)));
};
template <>
struct VectorOf<32> {
  typedef real type __attribute__((vector_size(32)));
};

using L = VectorOf<16>::type;     // the baseline
using Wide = VectorOf<32>::type;  // AVX2, AVX-512
template <class V>
inline constexpr std::uint32_t width = sizeof(V) / sizeof(real);  // contacts per block
inline constexpr std::uint32_t W = width<L>;
inline constexpr int kVectorBytes = sizeof(L);
template <class V>
using MaskOf = decltype(V{} < V{});
using Mask = MaskOf<L>;

template <class V>
MARBLES_LANE V select(MaskOf<V> m, V a, V b) {
  return m ? a : b;
}

// A vector as two halves and back: shuffles, which AVX code does in
// registers (vextractf128 / vinsertf128 and their 512-bit forms); through
// memory, a 32-byte load of two 16-byte stores misses store forwarding.
template <class V>
using Half = typename VectorOf<sizeof(V) / 2>::type;
template <class H>
using Twice = typename VectorOf<sizeof(H) * 2>::type;

template <std::size_t Offset, class V, std::size_t... I>
MARBLES_LANE Half<V> part(V x, std::index_sequence<I...>) {
  return __builtin_shufflevector(x, x, (Offset + I)...);
}
template <class V>
MARBLES_LANE Half<V> low(V x) {
  return part<0>(x, std::make_index_sequence<width<V> / 2>{});
}
template <class V>
MARBLES_LANE Half<V> high(V x) {
  return part<width<V> / 2>(x, std::make_index_sequence<width<V> / 2>{});
}
template <class H, std::size_t... I>
MARBLES_LANE Twice<H> join(H lo, H hi, std::index_sequence<I...>) {
  return __builtin_shufflevector(lo, hi, I...);
}
template <class H>
MARBLES_LANE Twice<H> join(H lo, H hi) {
  return join(lo, hi, std::make_index_sequence<2 * width<H>>{});
}

// The lanes' square roots in one instruction where there is one (SSE's
// sqrtps / sqrtpd round as sqrtss and std::sqrt do: IEEE, correctly
// rounded, so the bits are the scalar's); else lane by lane. A Wide root is
// two L roots (an AVX intrinsic cannot be inlined into this baseline text).
MARBLES_LANE L sqrt_lanes(L x) {
#if defined(__SSE2__) && !defined(MARBLES_DOUBLE)
  return reinterpret_cast<L>(_mm_sqrt_ps(reinterpret_cast<__m128>(x)));
#elif defined(__SSE2__)
  return reinterpret_cast<L>(_mm_sqrt_pd(reinterpret_cast<__m128d>(x)));
#else
  L r{};
  for (std::uint32_t l = 0; l < W; ++l) r[l] = std::sqrt(x[l]);
  return r;
#endif
}
template <class V>
MARBLES_LANE V sqrt_lanes(V x) {
  return join(sqrt_lanes(low(x)), sqrt_lanes(high(x)));
}

// Vec3 of lanes, with Vec3's formulas (core/vec3.hpp).
template <class V>
struct V3 {
  V x, y, z;
};
template <class V>
MARBLES_LANE V3<V> operator+(const V3<V>& a, const V3<V>& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
template <class V>
MARBLES_LANE V3<V> operator-(const V3<V>& a, const V3<V>& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
template <class V>
MARBLES_LANE V3<V> operator*(const V3<V>& a, V s) {
  return {a.x * s, a.y * s, a.z * s};
}
template <class V>
MARBLES_LANE V dot(const V3<V>& a, const V3<V>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class V>
MARBLES_LANE V3<V> cross(const V3<V>& a, const V3<V>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class V>
MARBLES_LANE V3<V> select(MaskOf<V> m, const V3<V>& a, const V3<V>& b) {
  return {select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z)};
}
template <class H>
MARBLES_LANE V3<Twice<H>> join(const V3<H>& lo, const V3<H>& hi) {
  return {join(lo.x, hi.x), join(lo.y, hi.y), join(lo.z, hi.z)};
}
template <class V>
MARBLES_LANE V3<Half<V>> low(const V3<V>& a) {
  return {low(a.x), low(a.y), low(a.z)};
}
template <class V>
MARBLES_LANE V3<Half<V>> high(const V3<V>& a) {
  return {high(a.x), high(a.y), high(a.z)};
}

// What the sweep reads of width<V> contacts, and what it writes (the impulses).
template <class V>
struct ContactLanes {
  V normal_impulse;
  V3<V> tangent_impulse, rolling_impulse;
  V normal_mass, tangent_mass, rolling_mass, separation, ra, rb;
  V3<V> normal;
  V friction, rolling_friction, twisting_friction;
};

// BodyState of width<V> bodies (a wall: its surface velocity, no spin, no
// inverse mass).
template <class V>
struct BodyLanes {
  V3<V> v, w;
  V inv_mass, inv_inertia;
};

// Moving W contacts and bodies in and out of lanes. The sweep reads the
// sweep's records (solver_math.hpp: SweepRecords, a structure of arrays of
// 4-real words), as the GPU's does: 48 bytes a contact with friction where a
// whole Contact is 112, and 16 written where a Contact's impulses are 32.
// In float four contacts' words of one array are a 4 x 4 transpose away
// from four lanes of fields, and a body's record two words; in double (two
// lanes) the fields are gathered one by one (the *_each forms, which are
// also the reference the float forms are tested against). A block's body b
// may be a wall: its lane holds the wall's velocity (the record's extra
// word, read only for walls), zero spin and zero inverse mass and inertia.

// x in every lane, its bits kept (x + V{} would turn a -0 into +0), as one
// shuffle of lane 0: filled lane by lane, or from a braced list, GCC stored
// pairs of lanes and loaded the vector back, a stall on store forwarding in
// every block.
template <class V, std::size_t... I>
MARBLES_LANE V splat(real x, std::index_sequence<I...>) {
  const L first{x};
  return __builtin_shufflevector(first, first, (I * 0)...);
}
template <class V>
MARBLES_LANE V splat(real x) {
  return splat<V>(x, std::make_index_sequence<width<V>>{});
}

// The contact of a block that lane l holds in a Wide block's moves (float:
// load_words and the wide body moves below).
inline constexpr std::uint32_t kWideLane[8] = {0, 2, 4, 6, 1, 3, 5, 7};
// The record of a block that lane l of V's moves holds.
template <class V>
MARBLES_LANE std::uint32_t lane_of(std::uint32_t l) {
  if constexpr (sizeof(V) == sizeof(L)) return l;
  else return kWideLane[l];
}

// The arms and friction coefficients of records k.. where the records leave
// them out (no arms array: every contact has the same, SweepRecords::
// uniform): ra the radius, rb the radius or +0 where body b is a wall, the
// pair table's coefficients, as load_record gives them; lane l holds record
// k + lane_of<V>(l). The walls are read lane by lane: read as two vectors
// of body pairs and shuffled, the compiler kept the sweep's body pairs in
// mask registers, and the sweep was no faster than with the arms words.
template <class V>
MARBLES_LANE void uniform_arms(const SweepRecords& s, std::uint32_t k, ContactLanes<V>& c) {
  MaskOf<V> wall;
  for (std::uint32_t l = 0; l < width<V>; ++l) wall[l] = is_wall(s.bodies[k + lane_of<V>(l)].b) ? -1 : 0;
  const V r = splat<V>(s.uniform.radius);
  c.ra = r, c.rb = (V)((MaskOf<V>)r & ~wall);  // +0 for a wall
  c.friction = splat<V>(s.uniform.friction), c.rolling_friction = splat<V>(s.uniform.rolling_friction);
}

// Record k as the sweep's contact (load_sweep_contact, solver_math.hpp).
template <bool Arms, bool Rolling>
MARBLES_LANE ContactLanes<L> load_records_each(const SweepRecords& s, std::uint32_t k) {
  ContactLanes<L> c{};
  for (std::uint32_t l = 0; l < W; ++l) {
    const Real4 i = s.impulse[k + l], g = s.geometry[k + l];
    c.normal_impulse[l] = i.x;
    c.tangent_impulse.x[l] = i.y, c.tangent_impulse.y[l] = i.z, c.tangent_impulse.z[l] = i.w;
    c.normal.x[l] = g.x, c.normal.y[l] = g.y, c.normal.z[l] = g.z;
    c.separation[l] = g.w;
    if constexpr (Arms) {
      if (s.arms) {
        const Real4 m = s.arms[k + l];
        c.ra[l] = m.x, c.rb[l] = m.y, c.friction[l] = m.z, c.rolling_friction[l] = m.w;
      }
    }
    if constexpr (Rolling) {
      const Real4 r = s.rolling[k + l];
      c.rolling_impulse.x[l] = r.x, c.rolling_impulse.y[l] = r.y, c.rolling_impulse.z[l] = r.z;
      c.twisting_friction[l] = r.w;
    }
  }
  if constexpr (Arms)
    if (!s.arms) uniform_arms(s, k, c);
  return c;
}

// store_sweep_impulses of records k..k+W.
template <bool Rolling>
MARBLES_LANE void store_record_impulses_each(const ContactLanes<L>& c, const SweepRecords& s, std::uint32_t k) {
  for (std::uint32_t l = 0; l < W; ++l) {
    s.impulse[k + l] = {c.normal_impulse[l], c.tangent_impulse.x[l], c.tangent_impulse.y[l], c.tangent_impulse.z[l]};
    if constexpr (Rolling)
      s.rolling[k + l] = {c.rolling_impulse.x[l], c.rolling_impulse.y[l], c.rolling_impulse.z[l],
                          c.twisting_friction[l]};
  }
}

MARBLES_LANE std::uint32_t body_of(const SweepRecords& s, std::uint32_t k, bool side_b) {
  const BodyPair ab = s.bodies[k];
  return side_b ? ab.b : ab.a;
}

// load_body for side a (side_b false) or b of records k..k+W.
MARBLES_LANE BodyLanes<L> load_bodies_each(const SolverBody* bodies, const SweepRecords& s, std::uint32_t k,
                                           bool side_b) {
  BodyLanes<L> out;
  for (std::uint32_t l = 0; l < W; ++l) {
    const std::uint32_t index = body_of(s, k + l, side_b);
    Contact wall;  // load_body reads only a wall's velocity of it
    if (is_wall(index)) wall.wall_velocity = {s.extra[k + l].x, s.extra[k + l].y, s.extra[k + l].z};
    const BodyState b = load_body(bodies, index, wall);
    out.v.x[l] = b.v.x, out.v.y[l] = b.v.y, out.v.z[l] = b.v.z;
    out.w.x[l] = b.w.x, out.w.y[l] = b.w.y, out.w.z[l] = b.w.z;
    out.inv_mass[l] = b.inv_mass;
    out.inv_inertia[l] = b.inv_inertia;
  }
  return out;
}

MARBLES_LANE void store_bodies_each(SolverBody* bodies, const SweepRecords& s, std::uint32_t k, bool side_b,
                                    const BodyLanes<L>& b) {
  for (std::uint32_t l = 0; l < W; ++l)
    store_body(bodies, body_of(s, k + l, side_b),
               BodyState{{b.v.x[l], b.v.y[l], b.v.z[l]}, {b.w.x[l], b.w.y[l], b.w.z[l]}, b.inv_mass[l],
                         b.inv_inertia[l]});
}

#if !defined(MARBLES_DOUBLE)
using Word = Mask;  // shuffle indices

MARBLES_LANE L group(const void* record, int g) {
  L out;
  __builtin_memcpy(&out, static_cast<const char*>(record) + kVectorBytes * g, kVectorBytes);
  return out;
}
MARBLES_LANE void set_group(void* record, int g, L value) {
  __builtin_memcpy(static_cast<char*>(record) + kVectorBytes * g, &value, kVectorBytes);
}
// r[i] = row i of a 4 x 4 block -> r[j] = column j (float only).
MARBLES_LANE void transpose4(L r[4]) {
  const L t0 = __builtin_shuffle(r[0], r[1], Word{0, 4, 1, 5});
  const L t1 = __builtin_shuffle(r[0], r[1], Word{2, 6, 3, 7});
  const L t2 = __builtin_shuffle(r[2], r[3], Word{0, 4, 1, 5});
  const L t3 = __builtin_shuffle(r[2], r[3], Word{2, 6, 3, 7});
  r[0] = __builtin_shuffle(t0, t2, Word{0, 1, 4, 5});
  r[1] = __builtin_shuffle(t0, t2, Word{2, 3, 6, 7});
  r[2] = __builtin_shuffle(t1, t3, Word{0, 1, 4, 5});
  r[3] = __builtin_shuffle(t1, t3, Word{2, 3, 6, 7});
}
// Words p[0, 4) transposed: field j of the four in r[j]; and back.
MARBLES_LANE void load_words(const Real4* p, L r[4]) {
  for (int l = 0; l < 4; ++l) r[l] = group(p + l, 0);
  transpose4(r);
}
MARBLES_LANE void store_words(Real4* p, L r[4]) {
  transpose4(r);
  for (int l = 0; l < 4; ++l) set_group(p + l, 0, r[l]);
}

// Eight contacts in one 32-byte vector (float, compiled in the AVX2 and
// AVX-512 sweeps). Each load takes two contacts' words of an array (or one
// body's whole record) at once, and the transposes work within each
// 16-byte half (transpose_halves: unpacks and in-lane shuffles), never
// across: lane i holds contact kWideLane[i] = 0, 2, 4, 6, 1, 3, 5, 7 of the
// block, the records' and the bodies' alike, and each store moves them back
// the same way. Lane by lane the arithmetic is the same whichever contact a
// lane holds. Against two L blocks joined (16-byte loads, 4 x 4 transposes,
// a join a field), the sweep takes about a quarter fewer instructions
// (docs/architecture.md "The CPU sweep's wide moves, and the walls four at
// a time").

MARBLES_LANE Wide wide_at(const void* p) {
  Wide out;
  __builtin_memcpy(&out, p, sizeof(Wide));
  return out;
}
MARBLES_LANE void set_wide(void* p, Wide value) { __builtin_memcpy(p, &value, sizeof(Wide)); }
// Within each half, r[i] = row i of a 4 x 4 block -> r[j] = column j (its own inverse).
MARBLES_LANE void transpose_halves(Wide r[4]) {
  const Wide t0 = __builtin_shufflevector(r[0], r[1], 0, 8, 1, 9, 4, 12, 5, 13);
  const Wide t1 = __builtin_shufflevector(r[0], r[1], 2, 10, 3, 11, 6, 14, 7, 15);
  const Wide t2 = __builtin_shufflevector(r[2], r[3], 0, 8, 1, 9, 4, 12, 5, 13);
  const Wide t3 = __builtin_shufflevector(r[2], r[3], 2, 10, 3, 11, 6, 14, 7, 15);
  r[0] = __builtin_shufflevector(t0, t2, 0, 1, 8, 9, 4, 5, 12, 13);
  r[1] = __builtin_shufflevector(t0, t2, 2, 3, 10, 11, 6, 7, 14, 15);
  r[2] = __builtin_shufflevector(t1, t3, 0, 1, 8, 9, 4, 5, 12, 13);
  r[3] = __builtin_shufflevector(t1, t3, 2, 3, 10, 11, 6, 7, 14, 15);
}
// Words p[0, 8): field j of the eight in r[j], in kWideLane's order; and back.
MARBLES_LANE void load_words(const Real4* p, Wide r[4]) {
  for (int j = 0; j < 4; ++j) r[j] = wide_at(p + 2 * j);
  transpose_halves(r);
}
MARBLES_LANE void store_words(Real4* p, Wide r[4]) {
  transpose_halves(r);
  for (int j = 0; j < 4; ++j) set_wide(p + 2 * j, r[j]);
}

static_assert(sizeof(Real4) == sizeof(L) && sizeof(SolverBody) == 2 * sizeof(L),
              "in float a record word is four reals, a SolverBody two words");

// Records k.. as lanes: V = L (four contacts), or Wide (eight, in
// kWideLane's order).
template <bool Arms, bool Rolling, class V = L>
MARBLES_LANE ContactLanes<V> load_records(const SweepRecords& s, std::uint32_t k) {
  ContactLanes<V> c{};
  V r[4];
  load_words(s.impulse + k, r);
  c.normal_impulse = r[0], c.tangent_impulse = {r[1], r[2], r[3]};
  load_words(s.geometry + k, r);
  c.normal = {r[0], r[1], r[2]}, c.separation = r[3];
  if constexpr (Arms) {
    if (s.arms) {
      load_words(s.arms + k, r);
      c.ra = r[0], c.rb = r[1], c.friction = r[2], c.rolling_friction = r[3];
    } else {
      uniform_arms(s, k, c);
    }
  }
  if constexpr (Rolling) {
    load_words(s.rolling + k, r);
    c.rolling_impulse = {r[0], r[1], r[2]}, c.twisting_friction = r[3];
  }
  return c;
}

template <bool Rolling, class V = L>
MARBLES_LANE void store_record_impulses(const ContactLanes<V>& c, const SweepRecords& s, std::uint32_t k) {
  V r[4] = {c.normal_impulse, c.tangent_impulse.x, c.tangent_impulse.y, c.tangent_impulse.z};
  store_words(s.impulse + k, r);
  if constexpr (Rolling) {
    V q[4] = {c.rolling_impulse.x, c.rolling_impulse.y, c.rolling_impulse.z, c.twisting_friction};
    store_words(s.rolling + k, q);
  }
}

MARBLES_LANE BodyLanes<L> load_bodies(const SolverBody* bodies, const SweepRecords& s, std::uint32_t k,
                                      bool side_b) {
  alignas(16) static constexpr SolverBody kNone{};
  L r[4], q[4];
  for (int l = 0; l < 4; ++l) {
    const std::uint32_t index = body_of(s, k + l, side_b);
    if (is_wall(index)) {
      // The wall's velocity, its fourth real (+0) made the zero inverse mass.
      r[l] = __builtin_shuffle(group(s.extra + k + l, 0), L{}, Word{0, 1, 2, 4});
      q[l] = group(&kNone, 1);
    } else {
      r[l] = group(bodies + index, 0);
      q[l] = group(bodies + index, 1);
    }
  }
  transpose4(r);
  transpose4(q);
  return {{r[0], r[1], r[2]}, {q[0], q[1], q[2]}, r[3], q[3]};
}

// store_body of side a or b (walls are not stored).
MARBLES_LANE void store_bodies(SolverBody* bodies, const SweepRecords& s, std::uint32_t k, bool side_b,
                               const BodyLanes<L>& b) {
  L r[4] = {b.v.x, b.v.y, b.v.z, b.inv_mass};
  L q[4] = {b.w.x, b.w.y, b.w.z, b.inv_inertia};
  transpose4(r);
  transpose4(q);
  for (int l = 0; l < 4; ++l) {
    const std::uint32_t index = body_of(s, k + l, side_b);
    if (is_wall(index)) continue;
    set_group(bodies + index, 0, r[l]);
    set_group(bodies + index, 1, q[l]);
  }
}

// The bodies of side a or b, eight at once, each record whole (velocity
// and inverse mass, spin and inverse inertia: one 32-byte load), a pair's
// velocity halves and spin halves put side by side, then transposed within
// halves. A wall's lane: its velocity (the record's extra word), no spin,
// no inverse mass or inertia. Stored back the same way (walls are not).
MARBLES_LANE BodyLanes<Wide> load_wide_bodies(const SolverBody* bodies, const SweepRecords& s, std::uint32_t k,
                                              bool side_b, const BodyPair* ab) {
  Wide whole[8];
  for (std::uint32_t l = 0; l < 8; ++l) {
    const std::uint32_t index = side_b ? ab[l].b : ab[l].a;
    if (is_wall(index)) {
      const L velocity = __builtin_shuffle(group(s.extra + k + l, 0), L{}, Word{0, 1, 2, 4});
      whole[l] = join(velocity, L{});
    } else {
      whole[l] = wide_at(bodies + index);
    }
  }
  Wide v[4], w[4];
  for (int j = 0; j < 4; ++j) {
    v[j] = __builtin_shufflevector(whole[2 * j], whole[2 * j + 1], 0, 1, 2, 3, 8, 9, 10, 11);
    w[j] = __builtin_shufflevector(whole[2 * j], whole[2 * j + 1], 4, 5, 6, 7, 12, 13, 14, 15);
  }
  transpose_halves(v);
  transpose_halves(w);
  return {{v[0], v[1], v[2]}, {w[0], w[1], w[2]}, v[3], w[3]};
}

MARBLES_LANE void store_wide_bodies(SolverBody* bodies, bool side_b, const BodyPair* ab, const BodyLanes<Wide>& b) {
  Wide v[4] = {b.v.x, b.v.y, b.v.z, b.inv_mass};
  Wide w[4] = {b.w.x, b.w.y, b.w.z, b.inv_inertia};
  transpose_halves(v);
  transpose_halves(w);
  for (int j = 0; j < 4; ++j) {
    const BodyPair &p = ab[2 * j], &q = ab[2 * j + 1];
    const std::uint32_t first = side_b ? p.b : p.a, second = side_b ? q.b : q.a;
    if (!is_wall(first)) set_wide(bodies + first, __builtin_shufflevector(v[j], w[j], 0, 1, 2, 3, 8, 9, 10, 11));
    if (!is_wall(second)) set_wide(bodies + second, __builtin_shufflevector(v[j], w[j], 4, 5, 6, 7, 12, 13, 14, 15));
  }
}

// The wide form of BlockBodies (below): the block's body pairs read once.
template <class V>
struct BlockBodies;
template <>
struct BlockBodies<Wide> {
  BodyPair ab[8];
  MARBLES_LANE BlockBodies(const SweepRecords& s, std::uint32_t k) { __builtin_memcpy(ab, s.bodies + k, sizeof ab); }
  MARBLES_LANE BodyLanes<Wide> load(const SolverBody* bodies, const SweepRecords& s, std::uint32_t k,
                                    bool side_b) const {
    return load_wide_bodies(bodies, s, k, side_b, ab);
  }
  MARBLES_LANE void store(SolverBody* bodies, const SweepRecords&, std::uint32_t, bool side_b,
                          const BodyLanes<Wide>& b) const {
    store_wide_bodies(bodies, side_b, ab, b);
  }
};

#else
template <bool Arms, bool Rolling>
MARBLES_LANE ContactLanes<L> load_records(const SweepRecords& s, std::uint32_t k) {
  return load_records_each<Arms, Rolling>(s, k);
}
template <bool Rolling>
MARBLES_LANE void store_record_impulses(const ContactLanes<L>& c, const SweepRecords& s, std::uint32_t k) {
  store_record_impulses_each<Rolling>(c, s, k);
}
MARBLES_LANE BodyLanes<L> load_bodies(const SolverBody* bodies, const SweepRecords& s, std::uint32_t k,
                                      bool side_b) {
  return load_bodies_each(bodies, s, k, side_b);
}
MARBLES_LANE void store_bodies(SolverBody* bodies, const SweepRecords& s, std::uint32_t k, bool side_b,
                               const BodyLanes<L>& b) {
  store_bodies_each(bodies, s, k, side_b, b);
}
#endif

// The moves of wider blocks: the first half of a block's contacts in the
// low halves of the lanes, the second in the high ones (down to L's moves).
template <bool Arms, bool Rolling, class V>
MARBLES_LANE ContactLanes<V> load_records_of(const SweepRecords& s, std::uint32_t k) {
  if constexpr (sizeof(V) == sizeof(L)) {
    return load_records<Arms, Rolling>(s, k);
#if !defined(MARBLES_DOUBLE)
  } else if constexpr (sizeof(V) == sizeof(Wide)) {
    return load_records<Arms, Rolling, Wide>(s, k);
#endif
  } else {
    using H = Half<V>;
    const ContactLanes<H> a = load_records_of<Arms, Rolling, H>(s, k);
    const ContactLanes<H> b = load_records_of<Arms, Rolling, H>(s, k + width<H>);
    return {join(a.normal_impulse, b.normal_impulse),
            join(a.tangent_impulse, b.tangent_impulse),
            join(a.rolling_impulse, b.rolling_impulse),
            join(a.normal_mass, b.normal_mass),
            join(a.tangent_mass, b.tangent_mass),
            join(a.rolling_mass, b.rolling_mass),
            join(a.separation, b.separation),
            join(a.ra, b.ra),
            join(a.rb, b.rb),
            join(a.normal, b.normal),
            join(a.friction, b.friction),
            join(a.rolling_friction, b.rolling_friction),
            join(a.twisting_friction, b.twisting_friction)};
  }
}
template <bool Rolling, class V>
MARBLES_LANE void store_record_impulses_of(const ContactLanes<V>& c, const SweepRecords& s, std::uint32_t k) {
  if constexpr (sizeof(V) == sizeof(L)) {
    store_record_impulses<Rolling>(c, s, k);
#if !defined(MARBLES_DOUBLE)
  } else if constexpr (sizeof(V) == sizeof(Wide)) {
    store_record_impulses<Rolling, Wide>(c, s, k);
#endif
  } else {
    using H = Half<V>;
    ContactLanes<H> lo{}, hi{};
    lo.normal_impulse = low(c.normal_impulse), hi.normal_impulse = high(c.normal_impulse);
    lo.tangent_impulse = low(c.tangent_impulse), hi.tangent_impulse = high(c.tangent_impulse);
    lo.rolling_impulse = low(c.rolling_impulse), hi.rolling_impulse = high(c.rolling_impulse);
    lo.twisting_friction = low(c.twisting_friction), hi.twisting_friction = high(c.twisting_friction);
    store_record_impulses_of<Rolling, H>(lo, s, k);
    store_record_impulses_of<Rolling, H>(hi, s, k + width<H>);
  }
}
template <class V>
MARBLES_LANE BodyLanes<V> load_bodies_of(const SolverBody* bodies, const SweepRecords& s, std::uint32_t k,
                                         bool side_b) {
  if constexpr (sizeof(V) == sizeof(L)) {
    return load_bodies(bodies, s, k, side_b);
#if !defined(MARBLES_DOUBLE)
  } else if constexpr (sizeof(V) == sizeof(Wide)) {
    return BlockBodies<Wide>(s, k).load(bodies, s, k, side_b);
#endif
  } else {
    using H = Half<V>;
    const BodyLanes<H> a = load_bodies_of<H>(bodies, s, k, side_b);
    const BodyLanes<H> b = load_bodies_of<H>(bodies, s, k + width<H>, side_b);
    return {join(a.v, b.v), join(a.w, b.w), join(a.inv_mass, b.inv_mass), join(a.inv_inertia, b.inv_inertia)};
  }
}
template <class V>
MARBLES_LANE void store_bodies_of(SolverBody* bodies, const SweepRecords& s, std::uint32_t k, bool side_b,
                                  const BodyLanes<V>& b) {
  if constexpr (sizeof(V) == sizeof(L)) {
    store_bodies(bodies, s, k, side_b, b);
#if !defined(MARBLES_DOUBLE)
  } else if constexpr (sizeof(V) == sizeof(Wide)) {
    BlockBodies<Wide>(s, k).store(bodies, s, k, side_b, b);
#endif
  } else {
    using H = Half<V>;
    store_bodies_of<H>(bodies, s, k, side_b, BodyLanes<H>{low(b.v), low(b.w), low(b.inv_mass), low(b.inv_inertia)});
    store_bodies_of<H>(bodies, s, k + width<H>, side_b,
                       BodyLanes<H>{high(b.v), high(b.w), high(b.inv_mass), high(b.inv_inertia)});
  }
}

// The arms and friction coefficients of records k.. into c (the idle test
// reads none of them: about half the blocks of a settling pile are idle);
// with Uniform, from SweepRecords::uniform (the records have no arms).
template <class V, bool Uniform = false>
MARBLES_LANE void load_arms_of(const SweepRecords& s, std::uint32_t k, ContactLanes<V>& c) {
#if !defined(MARBLES_DOUBLE)
  constexpr bool in_words = sizeof(V) <= sizeof(Wide);  // load_words' forms (float)
#else
  constexpr bool in_words = false;
#endif
  if constexpr (Uniform && in_words) {
    uniform_arms(s, k, c);
  } else if constexpr (in_words) {
    V r[4];
    load_words(s.arms + k, r);
    c.ra = r[0], c.rb = r[1], c.friction = r[2], c.rolling_friction = r[3];
  } else {
    const ContactLanes<V> a = load_records_of<true, false, V>(s, k);
    c.ra = a.ra, c.rb = a.rb, c.friction = a.friction, c.rolling_friction = a.rolling_friction;
  }
}

// A block's bodies in and out (load_bodies_of, store_bodies_of). The
// wide form (above) reads the block's body pairs once for its four moves:
// read again for each, after the stores into the bodies (which may alias
// them, as far as the compiler knows), they cost a load, a test and a shift
// a lane each time (settle scene of 10^5: the sweeps 5 % faster).
template <class V>
struct BlockBodies {
  MARBLES_LANE BlockBodies(const SweepRecords&, std::uint32_t) {}
  MARBLES_LANE BodyLanes<V> load(const SolverBody* bodies, const SweepRecords& s, std::uint32_t k,
                                 bool side_b) const {
    return load_bodies_of<V>(bodies, s, k, side_b);
  }
  MARBLES_LANE void store(SolverBody* bodies, const SweepRecords& s, std::uint32_t k, bool side_b,
                          const BodyLanes<V>& b) const {
    store_bodies_of<V>(bodies, s, k, side_b, b);
  }
};

// The effective masses (normal_mass_of, tangent_mass_of, rolling_mass_of of
// contact_math.hpp: the same expressions, a lane whose sum is not positive
// gets zero).
template <class V>
MARBLES_LANE V inverse_or_zero(V k) {
  const V zero{};
  return select<V>(k > zero, (zero + real(1)) / k, zero);
}
template <class V>
MARBLES_LANE V normal_mass_of(const BodyLanes<V>& A, const BodyLanes<V>& B) {
  return inverse_or_zero<V>(A.inv_mass + B.inv_mass);
}
template <class V>
MARBLES_LANE V tangent_mass_of(const BodyLanes<V>& A, const BodyLanes<V>& B, V ra, V rb) {
  return inverse_or_zero<V>((A.inv_mass + B.inv_mass) + A.inv_inertia * ra * ra + B.inv_inertia * rb * rb);
}
template <class V>
MARBLES_LANE V rolling_mass_of(const BodyLanes<V>& A, const BodyLanes<V>& B) {
  return inverse_or_zero<V>(A.inv_inertia + B.inv_inertia);
}

// apply_impulse
template <class V>
MARBLES_LANE void apply_impulse(const ContactLanes<V>& c, BodyLanes<V>& A, BodyLanes<V>& B, const V3<V>& impulse) {
  A.v = A.v + impulse * A.inv_mass;
  A.w = A.w + cross(c.normal * (-c.ra), impulse) * A.inv_inertia;
  B.v = B.v - impulse * B.inv_mass;
  B.w = B.w - cross(c.normal * c.rb, impulse) * B.inv_inertia;
}

// clamp_length
template <class V>
MARBLES_LANE V3<V> clamp_length(const V3<V>& v, V limit) {
  const V len2 = dot(v, v);
  const V3<V> clamped = select(len2 <= limit * limit, v, v * (limit / sqrt_lanes(len2)) + V3<V>{});
  return select(limit == V{}, V3<V>{}, clamped);
}

// solve_friction
template <class V>
MARBLES_LANE void solve_friction(ContactLanes<V>& c, BodyLanes<V>& A, BodyLanes<V>& B) {
  const V3<V> va = A.v + cross(A.w, c.normal * (-c.ra));
  const V3<V> vb = B.v + cross(B.w, c.normal * c.rb);
  const V3<V> vrel = va - vb;
  const V3<V> vt = vrel - c.normal * dot(vrel, c.normal);
  const V3<V> old = c.tangent_impulse;
  c.tangent_impulse = clamp_length(old - vt * c.tangent_mass, c.friction * c.normal_impulse);
  apply_impulse(c, A, B, c.tangent_impulse - old);
}

// solve_rolling
template <class V>
MARBLES_LANE void solve_rolling(ContactLanes<V>& c, BodyLanes<V>& A, BodyLanes<V>& B) {
  const V zero{};
  const V3<V> dw = A.w - B.w;
  const V spin = dot(dw, c.normal);
  const V3<V> roll = dw - c.normal * spin;
  const V r_eff = select<V>(c.rb > zero, c.ra * c.rb / (c.ra + c.rb), c.ra);
  const V3<V> old = c.rolling_impulse;
  const V old_twist = dot(old, c.normal);
  const V3<V> old_roll = old - c.normal * old_twist;
  const V3<V> new_roll = clamp_length(old_roll - roll * c.rolling_mass, c.rolling_friction * r_eff * c.normal_impulse);
  const V twist_limit = c.twisting_friction * r_eff * c.normal_impulse;
  V new_twist = old_twist - spin * c.rolling_mass;
  new_twist = select<V>(new_twist > twist_limit, twist_limit,
                        select<V>(new_twist < -twist_limit, -twist_limit, new_twist));
  c.rolling_impulse = new_roll + c.normal * new_twist;
  const V3<V> d = c.rolling_impulse - old;
  A.w = A.w + d * A.inv_inertia;
  B.w = B.w - d * B.inv_inertia;
}

// normal_slack
template <class V>
MARBLES_LANE V normal_slack(const ContactLanes<V>& c, const BodyLanes<V>& A, const BodyLanes<V>& B, real inv_h) {
  const V zero{};
  const V vn = dot(A.v - B.v, c.normal);
  const V allowed = select<V>(c.separation > zero, c.separation * inv_h, zero);
  return vn + allowed;
}

// solve_normal
template <class V>
MARBLES_LANE void solve_normal(ContactLanes<V>& c, BodyLanes<V>& A, BodyLanes<V>& B, real inv_h) {
  const V zero{};
  V lambda = (-c.normal_mass) * normal_slack(c, A, B, inv_h);
  const V old = c.normal_impulse;
  c.normal_impulse = select<V>(old + lambda > zero, old + lambda, zero);
  lambda = c.normal_impulse - old;
  const V3<V> p = c.normal * lambda;
  A.v = A.v + p * A.inv_mass;
  B.v = B.v - p * B.inv_mass;
}

// An idle update known before its arithmetic: a contact whose impulses are
// +0 (solver_math.hpp impulses_clear), whose bodies hold no -0 velocity
// component (has_minus_zero), and whose normal term asks for no impulse
// (normal_slack >= 0) keeps every bit of its impulses and its bodies through
// the whole update. Its friction and rolling terms, solved first, are
// clamped to limits of mu * +0 = +0 (the pair table's coefficients are
// finite), so clamp_length gives +0 and the twist's clamp a zero, each term
// applying a zero that changes no velocity component but a -0; the bodies'
// velocities are then the loaded ones, so the normal term sees this same
// slack, and -m * slack (m >= 0) is not > 0: it sets the literal +0 and
// applies a zero. In a settled pile about half the updates are such
// (in-plane neighbours whose gaps no speed closes); a block all of whose
// lanes are skips its effective masses and terms (all_idle), the same bits.
// The GPU's sweep does not ask (solve_loaded): measured on the H200 it
// gained nothing there (the warps' updates are idle and not idle side by
// side) and cost the widest sweep kernel 8 bytes of spilled registers. The
// test lane by lane, on the bits: +0 is the word 0 and -0 the word with the
// sign bit alone.
template <class V>
MARBLES_LANE MaskOf<V> bits_of(V x) {
  return (MaskOf<V>)x;  // the same bits as integer lanes
}
template <class V>
MARBLES_LANE MaskOf<V> is_plus_zero(const V3<V>& v) {
  return (bits_of(v.x) | bits_of(v.y) | bits_of(v.z)) == MaskOf<V>{};
}
template <class V>
MARBLES_LANE MaskOf<V> has_minus_zero(const V3<V>& v) {
  using Bits = std::remove_cvref_t<decltype(MaskOf<V>{}[0])>;
  const MaskOf<V> minus_zero = MaskOf<V>{} + std::numeric_limits<Bits>::min();
  return (bits_of(v.x) == minus_zero) | (bits_of(v.y) == minus_zero) | (bits_of(v.z) == minus_zero);
}
// True where every lane's update is known idle: the block then writes
// nothing and does no arithmetic past this test.
template <bool Friction, bool Rolling, class V>
MARBLES_LANE bool all_idle(const ContactLanes<V>& c, const BodyLanes<V>& A, const BodyLanes<V>& B, real inv_h) {
  MaskOf<V> idle = bits_of(c.normal_impulse) == MaskOf<V>{};
  for (std::uint32_t l = 0; l < width<V>; ++l)  // a lane with a load: busy (the loaded part's blocks, at once)
    if (!idle[l]) return false;
  if constexpr (Friction) idle &= is_plus_zero(c.tangent_impulse);
  if constexpr (Rolling) idle &= is_plus_zero(c.rolling_impulse);
  idle &= ~(has_minus_zero(A.v) | has_minus_zero(A.w) | has_minus_zero(B.v) | has_minus_zero(B.w));
  idle &= normal_slack(c, A, B, inv_h) >= V{};
  for (std::uint32_t l = 0; l < width<V>; ++l)
    if (!idle[l]) return false;
  return true;
}

// solve_record on records k..k + width<V>, whose contacts share no sphere;
// Uniform: the records have no arms (SweepRecords::uniform gives them). The
// sweep picks the form once a colour (with a test in every block the
// sweeps of the settle scene took 19.0 ms a step against 17.3 with the
// arms words); solve_block picks it a block.
template <bool Friction, bool Rolling, class V, bool Uniform>
MARBLES_LANE void solve_block_as(const SweepRecords& s, std::uint32_t k, SolverBody* bodies, real inv_h) {
  ContactLanes<V> c = load_records_of<false, Rolling, V>(s, k);  // the arms once the block is known busy
  const BlockBodies<V> block(s, k);
  BodyLanes<V> A = block.load(bodies, s, k, false);
  BodyLanes<V> B = block.load(bodies, s, k, true);
  if (all_idle<Friction, Rolling>(c, A, B, inv_h)) return;
  if constexpr (Friction || Rolling) load_arms_of<V, Uniform>(s, k, c);
  c.normal_mass = normal_mass_of(A, B);
  if constexpr (Friction) c.tangent_mass = tangent_mass_of(A, B, c.ra, c.rb);
  if constexpr (Rolling) c.rolling_mass = rolling_mass_of(A, B);
  if constexpr (Friction) solve_friction(c, A, B);
  if constexpr (Rolling) solve_rolling(c, A, B);
  solve_normal(c, A, B, inv_h);
  block.store(bodies, s, k, false, A);
  block.store(bodies, s, k, true, B);
  store_record_impulses_of<Rolling, V>(c, s, k);
}
template <bool Friction, bool Rolling, class V = L>
MARBLES_LANE void solve_block(const SweepRecords& s, std::uint32_t k, SolverBody* bodies, real inv_h) {
  if (s.arms) solve_block_as<Friction, Rolling, V, false>(s, k, bodies, inv_h);
  else solve_block_as<Friction, Rolling, V, true>(s, k, bodies, inv_h);
}

}  // namespace marbles::narrowphase::lanes

#undef MARBLES_LANE
