// narrowphase/solver_lanes.hpp — the velocity sweep of solver_math.hpp on
// several contacts of one colour at once (CPU, SIMD lanes).
//
// solve_one is a long chain of scalar operations per contact (about 550
// instructions with friction and rolling resistance); the contacts of one
// colour share no sphere, so W of them can run the same chain side by side,
// one per lane of a 16-byte vector (SSE2, which every x86-64 CPU has: 4
// floats or 2 doubles). Each lane performs exactly the operations of
// solve_friction, solve_rolling and solve_normal (contact_math.hpp), in the
// same order, with the branches turned into selects of values both sides
// compute; IEEE arithmetic is the same per lane as per scalar, so a lane's
// result is solve_one's bit for bit, and with it the CUDA twin's
// (tests/narrowphase/solver_lanes_test.cpp holds the two texts together on
// random and adversarial contacts).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::lanes {

inline constexpr int kVectorBytes = 16;
using L = real __attribute__((vector_size(kVectorBytes)));
inline constexpr std::uint32_t W = kVectorBytes / sizeof(real);  // contacts per block
using Mask = decltype(L{} < L{});

inline L select(Mask m, L a, L b) { return m ? a : b; }
// The lanes' square roots in one instruction where there is one (SSE's
// sqrtps / sqrtpd round as sqrtss and std::sqrt do: IEEE, correctly
// rounded, so the bits are the scalar's); else lane by lane.
inline L sqrt_lanes(L x) {
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

// Vec3 of lanes, with Vec3's formulas (core/vec3.hpp).
struct V3 {
  L x, y, z;
};
inline V3 operator+(const V3& a, const V3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 operator-(const V3& a, const V3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 operator*(const V3& a, L s) { return {a.x * s, a.y * s, a.z * s}; }
inline L dot(const V3& a, const V3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 cross(const V3& a, const V3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline V3 select(Mask m, const V3& a, const V3& b) { return {select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z)}; }

// What the sweep reads of W contacts, and what it writes (the impulses).
struct ContactLanes {
  L normal_impulse;
  V3 tangent_impulse, rolling_impulse;
  L normal_mass, tangent_mass, rolling_mass, separation, ra, rb;
  V3 normal;
  L friction, rolling_friction, twisting_friction;
};

// BodyState of W bodies (a wall: its surface velocity, no spin, no inverse mass).
struct BodyLanes {
  V3 v, w;
  L inv_mass, inv_inertia;
};

// Moving W contacts and bodies in and out of lanes. In float a contact is
// seven 16-byte groups of four reals and a body two, so four contacts'
// group g is a 4 x 4 transpose away from four lanes of fields; in double
// (two lanes) the fields are gathered one by one (the *_each forms, which
// are also the reference the float forms are tested against).

inline V3 lanes_of(const Vec3* v) {
  V3 out;
  for (std::uint32_t l = 0; l < W; ++l) out.x[l] = v[l].x, out.y[l] = v[l].y, out.z[l] = v[l].z;
  return out;
}

inline ContactLanes load_contacts_each(const Contact* c) {
  ContactLanes k;
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

inline void store_impulses_each(const ContactLanes& k, Contact* c) {
  for (std::uint32_t l = 0; l < W; ++l) {
    c[l].normal_impulse = k.normal_impulse[l];
    c[l].tangent_impulse = {k.tangent_impulse.x[l], k.tangent_impulse.y[l], k.tangent_impulse.z[l]};
    c[l].rolling_impulse = {k.rolling_impulse.x[l], k.rolling_impulse.y[l], k.rolling_impulse.z[l]};
  }
}

// load_body for side a (b = false) or b (b = true) of W contacts.
inline BodyLanes load_bodies_each(const SolverBody* bodies, const Contact* c, bool side_b) {
  BodyLanes s;
  for (std::uint32_t l = 0; l < W; ++l) {
    const BodyState b = load_body(bodies, side_b ? c[l].b : c[l].a, c[l]);
    s.v.x[l] = b.v.x, s.v.y[l] = b.v.y, s.v.z[l] = b.v.z;
    s.w.x[l] = b.w.x, s.w.y[l] = b.w.y, s.w.z[l] = b.w.z;
    s.inv_mass[l] = b.inv_mass;
    s.inv_inertia[l] = b.inv_inertia;
  }
  return s;
}

inline void store_bodies_each(SolverBody* bodies, const Contact* c, bool side_b, const BodyLanes& s) {
  for (std::uint32_t l = 0; l < W; ++l)
    store_body(bodies, side_b ? c[l].b : c[l].a,
               BodyState{{s.v.x[l], s.v.y[l], s.v.z[l]}, {s.w.x[l], s.w.y[l], s.w.z[l]}, s.inv_mass[l],
                         s.inv_inertia[l]});
}

#if !defined(MARBLES_DOUBLE)
using Word = Mask;  // shuffle indices

inline L group(const void* record, int g) {
  L out;
  __builtin_memcpy(&out, static_cast<const char*>(record) + kVectorBytes * g, kVectorBytes);
  return out;
}
inline void set_group(void* record, int g, L value) {
  __builtin_memcpy(static_cast<char*>(record) + kVectorBytes * g, &value, kVectorBytes);
}
// r[i] = row i of a 4 x 4 block -> r[j] = column j (float only).
inline void transpose4(L r[4]) {
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
inline void load_group(const Contact* c, int g, L r[4]) {
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

inline ContactLanes load_contacts(const Contact* c) {
  ContactLanes k;
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
inline void store_impulses(const ContactLanes& k, Contact* c) {
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
inline BodyLanes load_bodies(const SolverBody* bodies, const Contact* c, bool side_b) {
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
  BodyLanes s;
  s.v = select(wall, V3{g[1], g[2], g[3]}, V3{r[0], r[1], r[2]});
  s.inv_mass = r[3];
  s.w = {q[0], q[1], q[2]};
  s.inv_inertia = q[3];
  return s;
}

// store_body of W contacts' side a or b (walls are not stored).
inline void store_bodies(SolverBody* bodies, const Contact* c, bool side_b, const BodyLanes& s) {
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
inline ContactLanes load_contacts(const Contact* c) { return load_contacts_each(c); }
inline void store_impulses(const ContactLanes& k, Contact* c) { store_impulses_each(k, c); }
inline BodyLanes load_bodies(const SolverBody* bodies, const Contact* c, bool side_b) {
  return load_bodies_each(bodies, c, side_b);
}
inline void store_bodies(SolverBody* bodies, const Contact* c, bool side_b, const BodyLanes& s) {
  store_bodies_each(bodies, c, side_b, s);
}
#endif

// apply_impulse
inline void apply_impulse(const ContactLanes& c, BodyLanes& A, BodyLanes& B, const V3& impulse) {
  A.v = A.v + impulse * A.inv_mass;
  A.w = A.w + cross(c.normal * (-c.ra), impulse) * A.inv_inertia;
  B.v = B.v - impulse * B.inv_mass;
  B.w = B.w - cross(c.normal * c.rb, impulse) * B.inv_inertia;
}

// clamp_length
inline V3 clamp_length(const V3& v, L limit) {
  const L len2 = dot(v, v);
  return select(len2 <= limit * limit, v, v * (limit / sqrt_lanes(len2)));
}

// solve_friction
inline void solve_friction(ContactLanes& c, BodyLanes& A, BodyLanes& B) {
  const V3 va = A.v + cross(A.w, c.normal * (-c.ra));
  const V3 vb = B.v + cross(B.w, c.normal * c.rb);
  const V3 vrel = va - vb;
  const V3 vt = vrel - c.normal * dot(vrel, c.normal);
  const V3 old = c.tangent_impulse;
  c.tangent_impulse = clamp_length(old - vt * c.tangent_mass, c.friction * c.normal_impulse);
  apply_impulse(c, A, B, c.tangent_impulse - old);
}

// solve_rolling
inline void solve_rolling(ContactLanes& c, BodyLanes& A, BodyLanes& B) {
  const L zero{};
  const V3 dw = A.w - B.w;
  const L spin = dot(dw, c.normal);
  const V3 roll = dw - c.normal * spin;
  const L r_eff = select(c.rb > zero, c.ra * c.rb / (c.ra + c.rb), c.ra);
  const V3 old = c.rolling_impulse;
  const L old_twist = dot(old, c.normal);
  const V3 old_roll = old - c.normal * old_twist;
  const V3 new_roll = clamp_length(old_roll - roll * c.rolling_mass, c.rolling_friction * r_eff * c.normal_impulse);
  const L twist_limit = c.twisting_friction * r_eff * c.normal_impulse;
  L new_twist = old_twist - spin * c.rolling_mass;
  new_twist = select(new_twist > twist_limit, twist_limit,
                     select(new_twist < -twist_limit, -twist_limit, new_twist));
  c.rolling_impulse = new_roll + c.normal * new_twist;
  const V3 d = c.rolling_impulse - old;
  A.w = A.w + d * A.inv_inertia;
  B.w = B.w - d * B.inv_inertia;
}

// solve_normal
inline void solve_normal(ContactLanes& c, BodyLanes& A, BodyLanes& B, real inv_h) {
  const L zero{};
  const L vn = dot(A.v - B.v, c.normal);
  const L allowed = select(c.separation > zero, c.separation * inv_h, zero);
  L lambda = (-c.normal_mass) * (vn + allowed);
  const L old = c.normal_impulse;
  c.normal_impulse = select(old + lambda > zero, old + lambda, zero);
  lambda = c.normal_impulse - old;
  const V3 p = c.normal * lambda;
  A.v = A.v + p * A.inv_mass;
  B.v = B.v - p * B.inv_mass;
}

// solve_one on contacts c[0, W), which share no sphere.
template <bool Friction, bool Rolling>
inline void solve_block(Contact* c, SolverBody* bodies, real inv_h) {
  ContactLanes k = load_contacts(c);
  BodyLanes A = load_bodies(bodies, c, false);
  BodyLanes B = load_bodies(bodies, c, true);
  if constexpr (Friction) solve_friction(k, A, B);
  if constexpr (Rolling) solve_rolling(k, A, B);
  solve_normal(k, A, B, inv_h);
  store_impulses(k, c);
  store_bodies(bodies, c, false, A);
  store_bodies(bodies, c, true, B);
}

}  // namespace marbles::narrowphase::lanes
