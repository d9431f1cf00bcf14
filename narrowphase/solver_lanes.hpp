// narrowphase/solver_lanes.hpp — the velocity sweep of solver_math.hpp on
// several contacts of one colour at once (CPU, SIMD lanes).
//
// solve_one is a long chain of scalar operations per contact (about 550
// instructions with friction and rolling resistance); the contacts of one
// colour share no sphere, so W of them can run the same chain side by side,
// one per lane of a vector. Each lane performs exactly the operations of
// solve_friction, solve_rolling and solve_normal (contact_math.hpp), in the
// same order, with the branches turned into selects of values both sides
// compute; IEEE arithmetic is the same per lane as per scalar, so a lane's
// result is solve_one's bit for bit, and with it the CUDA twin's
// (tests/narrowphase/solver_lanes_test.cpp holds the two texts together on
// random and adversarial contacts).
//
// Two widths: L, 16 bytes (SSE2, which every x86-64 CPU has: 4 floats or 2
// doubles), and Wide, 32 bytes (8 floats or 4 doubles), which the solver
// runs where the CPU has AVX2 or AVX-512 (solver.cpp picks at run time and
// compiles those sweeps alone for them). The math is written once, for
// either vector type V; a Wide block moves its contacts and bodies as two L
// blocks. Every function here is always inlined, so a Wide one is compiled
// as part of its AVX caller and never on its own with a 16-byte baseline.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
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

// Moving W contacts and bodies in and out of lanes. In float a contact is
// seven 16-byte groups of four reals and a body two, so four contacts'
// group g is a 4 x 4 transpose away from four lanes of fields; in double
// (two lanes) the fields are gathered one by one (the *_each forms, which
// are also the reference the float forms are tested against).

MARBLES_LANE V3<L> lanes_of(const Vec3* v) {
  V3<L> out;
  for (std::uint32_t l = 0; l < W; ++l) out.x[l] = v[l].x, out.y[l] = v[l].y, out.z[l] = v[l].z;
  return out;
}

MARBLES_LANE ContactLanes<L> load_contacts_each(const Contact* c) {
  ContactLanes<L> k;
  Vec3 t[W], r[W], n[W];
  for (std::uint32_t l = 0; l < W; ++l) {
    k.normal_impulse[l] = c[l].normal_impulse;
    t[l] = c[l].tangent_impulse;
    r[l] = c[l].rolling_impulse;
    n[l] = c[l].normal;
    k.normal_mass[l] = c[l].normal_mass;
    k.tangent_mass[l] = c[l].tangent_mass;
    k.rolling_mass[l] = c[l].rolling_mass;
    k.separation[l] = c[l].separation;
    k.ra[l] = c[l].ra;
    k.rb[l] = c[l].rb;
    k.friction[l] = c[l].coeff.friction;
    k.rolling_friction[l] = c[l].coeff.rolling_friction;
    k.twisting_friction[l] = c[l].coeff.twisting_friction;
  }
  k.tangent_impulse = lanes_of(t);
  k.rolling_impulse = lanes_of(r);
  k.normal = lanes_of(n);
  return k;
}

MARBLES_LANE void store_impulses_each(const ContactLanes<L>& k, Contact* c) {
  for (std::uint32_t l = 0; l < W; ++l) {
    c[l].normal_impulse = k.normal_impulse[l];
    c[l].tangent_impulse = {k.tangent_impulse.x[l], k.tangent_impulse.y[l], k.tangent_impulse.z[l]};
    c[l].rolling_impulse = {k.rolling_impulse.x[l], k.rolling_impulse.y[l], k.rolling_impulse.z[l]};
  }
}

// load_body for side a (b = false) or b (b = true) of W contacts.
MARBLES_LANE BodyLanes<L> load_bodies_each(const SolverBody* bodies, const Contact* c, bool side_b) {
  BodyLanes<L> s;
  for (std::uint32_t l = 0; l < W; ++l) {
    const BodyState b = load_body(bodies, side_b ? c[l].b : c[l].a, c[l]);
    s.v.x[l] = b.v.x, s.v.y[l] = b.v.y, s.v.z[l] = b.v.z;
    s.w.x[l] = b.w.x, s.w.y[l] = b.w.y, s.w.z[l] = b.w.z;
    s.inv_mass[l] = b.inv_mass;
    s.inv_inertia[l] = b.inv_inertia;
  }
  return s;
}

MARBLES_LANE void store_bodies_each(SolverBody* bodies, const Contact* c, bool side_b, const BodyLanes<L>& s) {
  for (std::uint32_t l = 0; l < W; ++l)
    store_body(bodies, side_b ? c[l].b : c[l].a,
               BodyState{{s.v.x[l], s.v.y[l], s.v.z[l]}, {s.w.x[l], s.w.y[l], s.w.z[l]}, s.inv_mass[l],
                         s.inv_inertia[l]});
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
// Group g of contacts c[0, 4), transposed: field j of the group in r[j].
MARBLES_LANE void load_group(const Contact* c, int g, L r[4]) {
  for (int l = 0; l < 4; ++l) r[l] = group(c + l, g);
  transpose4(r);
}

static_assert((offsetof(Contact, tangent_impulse) == 4 && offsetof(Contact, rolling_impulse) == 16 &&
                           offsetof(Contact, normal_mass) == 32 && offsetof(Contact, a) == 48 &&
                           offsetof(Contact, separation) == 56 && offsetof(Contact, normal) == 64 &&
                           offsetof(Contact, ra) == 76 && offsetof(Contact, rb) == 80 &&
                           offsetof(Contact, wall_velocity) == 84 && offsetof(Contact, coeff) == 96 &&
                           sizeof(Contact) == 112 && sizeof(SolverBody) == 32),
              "the float Contact is seven groups of four reals, a SolverBody two");

MARBLES_LANE ContactLanes<L> load_contacts(const Contact* c) {
  ContactLanes<L> k;
  L r[4];
  load_group(c, 0, r);
  k.normal_impulse = r[0], k.tangent_impulse = {r[1], r[2], r[3]};
  load_group(c, 1, r);
  k.rolling_impulse = {r[0], r[1], r[2]};
  load_group(c, 2, r);
  k.normal_mass = r[0], k.tangent_mass = r[1], k.rolling_mass = r[2];
  load_group(c, 3, r);
  k.separation = r[2];
  load_group(c, 4, r);
  k.normal = {r[0], r[1], r[2]}, k.ra = r[3];
  load_group(c, 5, r);
  k.rb = r[0];
  load_group(c, 6, r);
  k.friction = r[1], k.rolling_friction = r[2], k.twisting_friction = r[3];
  return k;
}

// Writes the impulses back: groups 0 and 1 whole (the impact impulse, the
// last real of group 1, as it was).
MARBLES_LANE void store_impulses(const ContactLanes<L>& k, Contact* c) {
  L r[4] = {k.normal_impulse, k.tangent_impulse.x, k.tangent_impulse.y, k.tangent_impulse.z};
  transpose4(r);
  for (int l = 0; l < 4; ++l) set_group(c + l, 0, r[l]);
  for (int l = 0; l < 4; ++l) r[l] = group(c + l, 1);
  transpose4(r);
  r[0] = k.rolling_impulse.x, r[1] = k.rolling_impulse.y, r[2] = k.rolling_impulse.z;
  transpose4(r);
  for (int l = 0; l < 4; ++l) set_group(c + l, 1, r[l]);
}

// load_body of W contacts' side a (side_b false) or b: a wall's lane holds
// the contact's wall velocity, zero spin and zero inverse mass and inertia.
MARBLES_LANE BodyLanes<L> load_bodies(const SolverBody* bodies, const Contact* c, bool side_b) {
  alignas(16) static constexpr SolverBody kNone{};
  Mask wall{};
  L r[4], q[4];
  for (int l = 0; l < 4; ++l) {
    const std::uint32_t index = side_b ? c[l].b : c[l].a;
    wall[l] = is_wall(index) ? -1 : 0;
    const SolverBody* b = is_wall(index) ? &kNone : bodies + index;
    r[l] = group(b, 0);
    q[l] = group(b, 1);
  }
  transpose4(r);
  transpose4(q);
  L g[4];
  load_group(c, 5, g);  // rb, wall velocity
  BodyLanes<L> s;
  s.v = select(wall, V3<L>{g[1], g[2], g[3]}, V3<L>{r[0], r[1], r[2]});
  s.inv_mass = r[3];
  s.w = {q[0], q[1], q[2]};
  s.inv_inertia = q[3];
  return s;
}

// store_body of W contacts' side a or b (walls are not stored).
MARBLES_LANE void store_bodies(SolverBody* bodies, const Contact* c, bool side_b, const BodyLanes<L>& s) {
  L r[4] = {s.v.x, s.v.y, s.v.z, s.inv_mass};
  L q[4] = {s.w.x, s.w.y, s.w.z, s.inv_inertia};
  transpose4(r);
  transpose4(q);
  for (int l = 0; l < 4; ++l) {
    const std::uint32_t index = side_b ? c[l].b : c[l].a;
    if (is_wall(index)) continue;
    set_group(bodies + index, 0, r[l]);
    set_group(bodies + index, 1, q[l]);
  }
}

#else
MARBLES_LANE ContactLanes<L> load_contacts(const Contact* c) { return load_contacts_each(c); }
MARBLES_LANE void store_impulses(const ContactLanes<L>& k, Contact* c) { store_impulses_each(k, c); }
MARBLES_LANE BodyLanes<L> load_bodies(const SolverBody* bodies, const Contact* c, bool side_b) {
  return load_bodies_each(bodies, c, side_b);
}
MARBLES_LANE void store_bodies(SolverBody* bodies, const Contact* c, bool side_b, const BodyLanes<L>& s) {
  store_bodies_each(bodies, c, side_b, s);
}
#endif

// The moves of wider blocks: the first half of a block's contacts in the
// low halves of the lanes, the second in the high ones (down to L's moves).
template <class V>
MARBLES_LANE ContactLanes<V> load_contacts_of(const Contact* c) {
  if constexpr (sizeof(V) == sizeof(L)) {
    return load_contacts(c);
  } else {
    using H = Half<V>;
    const ContactLanes<H> a = load_contacts_of<H>(c), b = load_contacts_of<H>(c + width<H>);
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
template <class V>
MARBLES_LANE void store_impulses_of(const ContactLanes<V>& k, Contact* c) {
  if constexpr (sizeof(V) == sizeof(L)) {
    store_impulses(k, c);
  } else {
    using H = Half<V>;
    ContactLanes<H> lo{}, hi{};
    lo.normal_impulse = low(k.normal_impulse), hi.normal_impulse = high(k.normal_impulse);
    lo.tangent_impulse = low(k.tangent_impulse), hi.tangent_impulse = high(k.tangent_impulse);
    lo.rolling_impulse = low(k.rolling_impulse), hi.rolling_impulse = high(k.rolling_impulse);
    store_impulses_of<H>(lo, c);
    store_impulses_of<H>(hi, c + width<H>);
  }
}
template <class V>
MARBLES_LANE BodyLanes<V> load_bodies_of(const SolverBody* bodies, const Contact* c, bool side_b) {
  if constexpr (sizeof(V) == sizeof(L)) {
    return load_bodies(bodies, c, side_b);
  } else {
    using H = Half<V>;
    const BodyLanes<H> a = load_bodies_of<H>(bodies, c, side_b), b = load_bodies_of<H>(bodies, c + width<H>, side_b);
    return {join(a.v, b.v), join(a.w, b.w), join(a.inv_mass, b.inv_mass), join(a.inv_inertia, b.inv_inertia)};
  }
}
template <class V>
MARBLES_LANE void store_bodies_of(SolverBody* bodies, const Contact* c, bool side_b, const BodyLanes<V>& s) {
  if constexpr (sizeof(V) == sizeof(L)) {
    store_bodies(bodies, c, side_b, s);
  } else {
    using H = Half<V>;
    store_bodies_of<H>(bodies, c, side_b, BodyLanes<H>{low(s.v), low(s.w), low(s.inv_mass), low(s.inv_inertia)});
    store_bodies_of<H>(bodies, c + width<H>, side_b,
                       BodyLanes<H>{high(s.v), high(s.w), high(s.inv_mass), high(s.inv_inertia)});
  }
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
  return select(len2 <= limit * limit, v, v * (limit / sqrt_lanes(len2)));
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

// solve_normal
template <class V>
MARBLES_LANE void solve_normal(ContactLanes<V>& c, BodyLanes<V>& A, BodyLanes<V>& B, real inv_h) {
  const V zero{};
  const V vn = dot(A.v - B.v, c.normal);
  const V allowed = select<V>(c.separation > zero, c.separation * inv_h, zero);
  V lambda = (-c.normal_mass) * (vn + allowed);
  const V old = c.normal_impulse;
  c.normal_impulse = select<V>(old + lambda > zero, old + lambda, zero);
  lambda = c.normal_impulse - old;
  const V3<V> p = c.normal * lambda;
  A.v = A.v + p * A.inv_mass;
  B.v = B.v - p * B.inv_mass;
}

// solve_one on contacts c[0, width<V>), which share no sphere.
template <bool Friction, bool Rolling, class V = L>
MARBLES_LANE void solve_block(Contact* c, SolverBody* bodies, real inv_h) {
  ContactLanes<V> k = load_contacts_of<V>(c);
  BodyLanes<V> A = load_bodies_of<V>(bodies, c, false);
  BodyLanes<V> B = load_bodies_of<V>(bodies, c, true);
  if constexpr (Friction) solve_friction(k, A, B);
  if constexpr (Rolling) solve_rolling(k, A, B);
  solve_normal(k, A, B, inv_h);
  store_impulses_of<V>(k, c);
  store_bodies_of<V>(bodies, c, false, A);
  store_bodies_of<V>(bodies, c, true, B);
}

}  // namespace marbles::narrowphase::lanes

#undef MARBLES_LANE
