// narrowphase/solver_math.hpp — one contact through each solver stage,
// host and device: the loop bodies of solver.cpp and of its CUDA twin.
//
// Each function loads the two bodies' state, updates the contact and the
// bodies, and stores them back. Called for the contacts of one colour at a
// time (no two share a sphere), so calls within a colour are independent.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "core/bits.hpp"
#include "core/spheres.hpp"
#include "core/whole_record.hpp"
#include "narrowphase/contact_math.hpp"

namespace marbles::narrowphase {

// The impact stage's passes per substep at most, by default (a scene's
// solver.impact_passes sets it). A wave through a row of touching spheres
// advances about one sphere a pass, so a free row of N needs about N and a
// row against a wall 2 N (docs/solver.md).
inline constexpr int kImpactPasses = 16;

// Settings of the solver stages (the plain values every stage reads).
struct SolverSettings {
  int iterations = 10;            // velocity sweeps per substep
  int closing_iterations = 2;     // velocity Verlet's closing solve's sweeps (close_record)
  bool restitution = true;        // impact stage (without it impacts are plastic)
  int impact_passes = kImpactPasses;  // its passes, at most (solver.impact_passes)
  bool friction = false;          // Coulomb friction term
  bool rolling = false;           // rolling resistance term
  real rest_speed = real(0.01);   // m/s: slower approaches do not bounce
  real slop = real(0.005);        // fraction of the smaller radius left overlapping
  real beta = real(0.8);          // fraction of the remaining overlap removed per projection
  real max_correction = real(0.2);// fraction of the smaller radius moved per projection, at most
  int position_iterations = 6;    // projection sweeps per substep, at most, but see below
  real settled_move = real(0.001);// fraction of the smaller radius: a projection sweep in which no contact
                                  // moves its bodies further apart than this is the last (project_one)
  // Past position_iterations, the projection sweeps on, up to this many in
  // all, while a sweep still moves some contact's bodies apart by more than
  // deep_move of its smaller radius: an impact's deep overlap is removed
  // within its substep, where a pile at rest (or a stack under a heavy
  // sphere, whose projection and velocity solve would work against each
  // other) stops as before (projection_sweep_settings).
  int deep_position_iterations = 20;
  real deep_move = real(0.02);
  bool warm_start = true;         // start from the last substep's impulses
  bool impact_pass_over = true;   // the CPU's impact stage: its later passes pass over contacts no hit has
                                  // reached (solver.cpp, impact_passed_over: the same bits; false tries all)
  Vec3 wall_accel{};              // m/s^2: the spheres' acceleration seen by wall impacts (gravity under
                                  // velocity Verlet, whose impacts see half-step velocities; else 0)
};

// The projection's sweeps at most (0 without a projection).
MARBLES_HD_INLINE int projection_limit(const SolverSettings& s) {
  if (s.position_iterations <= 0) return 0;
  return s.deep_position_iterations > s.position_iterations ? s.deep_position_iterations : s.position_iterations;
}
// The settings projection sweep `it` (from 0) runs with: from the last of
// position_iterations on, a sweep is the last unless it moved some contact
// by more than deep_move (the sweeps both backends run).
MARBLES_HD_INLINE SolverSettings projection_sweep_settings(const SolverSettings& s, int it) {
  SolverSettings t = s;
  if (it + 1 >= s.position_iterations) t.settled_move = s.deep_move;
  return t;
}

// f(friction, rolling) for the terms a scene asks for, each as a
// std::bool_constant (itself a template argument: X<friction, rolling>): the
// one place the effect set picks the solver's instances (a frictionless
// scene runs no friction code), on the CPU and the GPU alike.
template <class F>
void with_terms(bool friction, bool rolling, F&& f) {
  using On = std::true_type;
  using Off = std::false_type;
  if (friction && rolling) f(On{}, On{});
  else if (friction) f(On{}, Off{});
  else if (rolling) f(Off{}, On{});
  else f(Off{}, Off{});
}

// What the impact stage reads besides the contacts and bodies.
struct ImpactParams {
  real rest_speed;  // m/s: slower approaches do not bounce
  real h;           // s, the substep
  Vec3 wall_accel;  // SolverSettings::wall_accel
  // A sphere's shift: what the substep's impacts owe its position. An impact
  // at time t changes a velocity by dv, which the integration applies for the
  // whole substep, t too long: the sphere's shift takes -dv t, so that it
  // moves as x0 + v t + shift from then on (the integration adds it:
  // integrator::drift). Zeroed before the stage; null: not kept (no lead
  // either).
  Vec3* shift = nullptr;
  // Where the impact records keep no restitution a contact (the GPU's), a
  // contact's is the pair table's for its bodies' materials (a sphere's, a
  // wall's): pair_coefficients.
  const std::uint32_t* material = nullptr;
  const WallShape* walls = nullptr;
  PairTable table{};
};

// The pair table's coefficients of the bodies a, b (b a sphere or a wall):
// make_sphere_contact and make_wall_contact copy these into a contact.
MARBLES_HD_INLINE const PairCoefficients& pair_coefficients(BodyPair ab, const std::uint32_t* material,
                                                            const WallShape* walls, const PairTable& table) {
  return table(material[ab.a], is_wall(ab.b) ? walls[ab.b & ~kWallFlag].material : material[ab.b]);
}

// The velocity state of one sphere as the velocity stages read and write it,
// packed: a contact's two random body accesses touch one 32-byte record each
// (in float) instead of four arrays, and a million of them fit in an H100's
// L2. Gathered from the world before the velocity solve, scattered after.
struct alignas(4 * sizeof(real)) SolverBody {
  Vec3 v;
  real inv_mass;
  Vec3 w;
  real inv_inertia;
};

MARBLES_HD_INLINE SolverBody gather_solver_body(const BodiesView& bodies, std::size_t i) {
  return {bodies.velocity[i], bodies.inv_mass[i], bodies.angular_velocity[i], bodies.inv_inertia[i]};
}
MARBLES_HD_INLINE void scatter_solver_body(const BodiesView& bodies, std::size_t i, const SolverBody& s) {
  bodies.velocity[i] = s.v;
  bodies.angular_velocity[i] = s.w;
}

// A body's record moves whole (two or four 16-byte words on the GPU); a
// colour has no two contacts on one sphere, so no other thread writes it.
MARBLES_HD_INLINE BodyState load_body(const SolverBody* bodies, std::uint32_t index, const Contact& c) {
  if (is_wall(index)) return {c.wall_velocity, Vec3{}, 0, 0};
  const SolverBody b = load_whole(bodies + index);
  return {b.v, b.w, b.inv_mass, b.inv_inertia};
}
MARBLES_HD_INLINE void store_body(SolverBody* bodies, std::uint32_t index, const BodyState& s) {
  if (is_wall(index)) return;
  store_whole(bodies + index, SolverBody{s.v, s.inv_mass, s.w, s.inv_inertia});
}

// Prepare: effective masses and the approach speed before the solve.
MARBLES_HD_INLINE void prepare_one(Contact& c, const SolverBody* bodies) {
  prepare_contact(c, load_body(bodies, c.a, c), load_body(bodies, c.b, c));
}

// The same from the world's arrays (the values SolverBody copies): the
// colouring prepares each contact as it moves it into colour-major order,
// so the solve does not stream the contacts once more for it.
MARBLES_HD_INLINE BodyState world_body(const BodiesView& w, std::uint32_t index, const Contact& c) {
  if (is_wall(index)) return {c.wall_velocity, Vec3{}, 0, 0};
  return {w.velocity[index], w.angular_velocity[index], w.inv_mass[index], w.inv_inertia[index]};
}
MARBLES_HD_INLINE void prepare_from_world(Contact& c, const BodiesView& w) {
  prepare_contact(c, world_body(w, c.a, c), world_body(w, c.b, c));
}
// The approach speed prepare_from_world gives c, alone.
MARBLES_HD_INLINE real approach_from_world(const Contact& c, const BodiesView& w) {
  return approach_speed_of(c, world_body(w, c.a, c), world_body(w, c.b, c));
}

// Warm start: apply the impulses the contact starts with (from the cache).
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void warm_start_one(const Contact& c, SolverBody* bodies) {
  if (c.normal_impulse <= 0) return;
  BodyState A = load_body(bodies, c.a, c);
  BodyState B = load_body(bodies, c.b, c);
  Vec3 impulse = c.normal * c.normal_impulse;
  if constexpr (Friction) impulse += c.tangent_impulse;
  apply_impulse(c, A, B, impulse);
  if constexpr (Rolling) {
    A.w += c.rolling_impulse * A.inv_inertia;
    B.w -= c.rolling_impulse * B.inv_inertia;
  }
  store_body(bodies, c.a, A);
  store_body(bodies, c.b, B);
}

// One Gauss–Seidel update of one contact: friction, rolling resistance (when
// enabled), then the normal impulse.
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void solve_states(Contact& c, BodyState& A, BodyState& B, real inv_h) {
  if constexpr (Friction) solve_friction(c, A, B);
  if constexpr (Rolling) solve_rolling(c, A, B);
  solve_normal(c, A, B, inv_h);
}
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void solve_one(Contact& c, SolverBody* bodies, real inv_h) {
  BodyState A = load_body(bodies, c.a, c);
  BodyState B = load_body(bodies, c.b, c);
  solve_states<Friction, Rolling>(c, A, B, inv_h);
  store_body(bodies, c.a, A);
  store_body(bodies, c.b, B);
}

// The local order's cube of a centre (solver.hpp LocalOrder, split_by_cube;
// the GPU's split the same): cubes of edge `edge`, 21 bits an axis, clamped
// to a million cubes either side of the origin, a non-finite coordinate in
// cube 0 of its axis. In double on both sides, so both find the same cube.
MARBLES_HD_INLINE std::uint64_t local_cube(const Vec3& p, double edge) {
  auto axis = [edge](real x) -> std::uint64_t {
    double c = floor(double(x) / edge);
    if (!(c - c == 0)) c = 0;  // NaN or an infinity
    else c = c < -1048575.0 ? -1048575.0 : (c > 1048575.0 ? 1048575.0 : c);
    return static_cast<std::uint64_t>(static_cast<std::int64_t>(c) + (1 << 20)) & 0x1fffffu;
  };
  return (axis(p.x) << 42) | (axis(p.y) << 21) | axis(p.z);
}
// The local order's cube edge: so many largest diameters (of radius 1 where
// the largest radius is 0: no spheres).
MARBLES_HD_INLINE double local_cube_edge(double diameters, real largest_radius) {
  return diameters * 2 * double(largest_radius > 0 ? largest_radius : real(1));
}

// --- the sweep's records -------------------------------------------------------
// What the stages after the warm start read of a contact (56 of its 112
// bytes in float with friction, 40 without; 16 fewer on the GPU where every
// contact has the same arms: UniformArms), as a structure of arrays of
// 4-real words: thread k of a launch reads word k of each array, so a warp's
// request is whole sectors, where a whole Contact per thread made every
// request span 32 records, and a field-by-field update of one wrote partial
// sectors. The GPU writes them once per substep as it makes the contacts in
// colour-major order (they are its only form of the contacts, with an
// approach speed each and, with impact candidates, impact words:
// ImpactRecords, impact_record, contact_of_record below); the CPU makes them
// and their impact words from
// its contacts where its search left them (ContactSolver::make_records), or
// packs them from whole contacts (pack_sweep_record). Every sweep reads and
// writes them (load_sweep_contact, store_sweep_impulses), the position
// stages read them (load_position_contact), and the impulses go into whole
// contacts only when the contacts are asked for (contact_of_record,
// unpack_sweep_impulses) or into the cache when it stores them. Each stage
// runs its per-contact function on the contact loaded from them: the same
// fields, the same arithmetic, the same bits as on the whole Contact. The
// records move with the evict-first hint (load_streaming), so the bodies
// every colour reads again stay in L2. The effective masses are not in
// them: a sweep computes the ones it needs from the two bodies it loads
// anyway (solve_record), the same expressions the prepare stage used, so a
// record is 16 bytes shorter with friction and 32 without; the sweeps are
// bound by memory, not arithmetic.
struct alignas(4 * sizeof(real)) Real4 {
  real x = 0, y = 0, z = 0, w = 0;
};
// Where every sphere has one radius R and every material pair the same
// friction and rolling friction (StepModel::uniform_pairs), every sphere
// pair's arms word is {R, R, friction, rolling friction} and every wall
// contact's {R, +0, ...}: the GPU then leaves the arms array out and a record
// takes them from here (load_record), the same bits make_sphere_contact and
// make_wall_contact copy into a contact (ra and rb are the radii, the
// coefficients the pair table's). R is the radius the substep's contacts
// were made with (read back with the contact counts).
struct UniformArms {
  real radius = 0;
  real friction = 0, rolling_friction = 0;
};

struct SweepRecords {
  // normal_impulse, tangent_impulse (read and written). Null where no
  // contact has friction: `normal` then holds the normal impulse alone (the
  // GPU's records; the tangent impulse stays +0, as no term changes it).
  Real4* impulse = nullptr;
  real* normal = nullptr;
  // rolling_impulse, twisting_friction (read and written, with rolling).
  // Null where no contact has rolling resistance (the GPU's records then
  // leave it out: nothing reads it, and the twisting friction is the pair
  // table's, as contact_of_record takes it).
  Real4* rolling = nullptr;
  Real4* geometry = nullptr;  // normal, separation
  // ra, rb, friction, rolling_friction (with friction or rolling). Null
  // where they are the same for every contact (the GPU's records then leave
  // them out and read `uniform`).
  Real4* arms = nullptr;
  // wall_velocity, written and read for wall contacts only. Null where no
  // wall moves (the GPU's records then leave it out: a wall at rest has the
  // surface velocity +0 exactly, a contact's default).
  Real4* extra = nullptr;
  BodyPair* bodies = nullptr; // a, b
  UniformArms uniform;        // the arms of every contact, where `arms` is null

  // Real4 words that hold n reals (an array of reals that leaves the next
  // one 16-byte aligned).
  static constexpr std::size_t real_words(std::size_t n) {
    return (n * sizeof(real) + sizeof(Real4) - 1) / sizeof(Real4);
  }
  // Real4 words of the impulse array (or of the normal impulses alone).
  static constexpr std::size_t impulse_words(std::size_t n, bool friction) { return friction ? n : real_words(n); }
  // Bytes of the records of n contacts, every array 16-byte aligned.
  static constexpr std::size_t bytes_for(std::size_t n, bool extra = true, bool arms = true, bool rolling = true,
                                         bool friction = true) {
    return impulse_words(n, friction) * sizeof(Real4) +
           n * ((1 + (rolling ? 1 : 0) + (arms ? 1 : 0) + (extra ? 1 : 0)) * sizeof(Real4) + sizeof(BodyPair)) + 64;
  }
  // The arrays of n contacts laid out in `memory` (bytes_for(n, extra,
  // arms, rolling, friction) bytes, 16-byte aligned); without arms,
  // `uniform` gives them.
  static SweepRecords in(void* memory, std::size_t n, bool extra = true, bool arms = true,
                         const UniformArms& uniform = {}, bool rolling = true, bool friction = true) {
    SweepRecords s;
    auto* p = static_cast<Real4*>(memory);
    if (friction) s.impulse = p;
    else s.normal = reinterpret_cast<real*>(p);
    p += impulse_words(n, friction);
    if (rolling) s.rolling = p, p += n;
    s.geometry = p, p += n;
    if (arms) s.arms = p, p += n;
    else s.uniform = uniform;
    if (extra) s.extra = p, p += n;
    s.bodies = reinterpret_cast<BodyPair*>(p);
    return s;
  }
};

// What the position stages read of a record (load_position_contact):
// the bodies and the geometry. The CPU's projection packs only these.
MARBLES_HD_INLINE void pack_position_record(const Contact& c, const SweepRecords& s, std::uint32_t k) {
  s.geometry[k] = {c.normal.x, c.normal.y, c.normal.z, c.separation};
  s.bodies[k] = {c.a, c.b};
}

// Every word the sweeps read; they leave out what they do not read: the
// rolling word without rolling resistance (the CPU's by Rolling, the GPU's
// by its absent array), the extra word of a sphere pair, and of every
// contact when no wall moves (no extra array); the arms word where every
// contact has the same (no arms array).
template <bool Rolling = true>
MARBLES_HD_INLINE void pack_sweep_record(const Contact& c, const SweepRecords& s, std::uint32_t k) {
  if (s.impulse) s.impulse[k] = {c.normal_impulse, c.tangent_impulse.x, c.tangent_impulse.y, c.tangent_impulse.z};
  else s.normal[k] = c.normal_impulse;
  if constexpr (Rolling)
    if (s.rolling)
      s.rolling[k] = {c.rolling_impulse.x, c.rolling_impulse.y, c.rolling_impulse.z, c.coeff.twisting_friction};
  if (s.arms) s.arms[k] = {c.ra, c.rb, c.coeff.friction, c.coeff.rolling_friction};
  if (is_wall(c.b) && s.extra) s.extra[k] = {c.wall_velocity.x, c.wall_velocity.y, c.wall_velocity.z, real(0)};
  pack_position_record(c, s, k);
}

// Record k as a contact, its impulse word `i` already loaded: the bodies,
// impulses, normal and separation, with Arms the arms and the friction
// coefficients, with Rolling the rolling impulse and the twisting friction,
// and a wall's velocity; the other fields are left at their defaults.
template <bool Arms, bool Rolling>
MARBLES_HD_INLINE Contact load_record(const SweepRecords& s, std::uint32_t k, const Real4& i) {
  Contact c;
  const BodyPair ab = load_streaming(s.bodies + k);
  c.a = ab.a, c.b = ab.b;
  const Real4 g = load_streaming(s.geometry + k);
  c.normal_impulse = i.x;
  c.tangent_impulse = {i.y, i.z, i.w};
  c.normal = {g.x, g.y, g.z};
  c.separation = g.w;
  if constexpr (Arms) {
    if (s.arms) {
      const Real4 m = load_streaming(s.arms + k);
      c.ra = m.x, c.rb = m.y, c.coeff.friction = m.z, c.coeff.rolling_friction = m.w;
    } else {
      const real r = s.uniform.radius;
      c.ra = r, c.rb = is_wall(c.b) ? real(0) : r;
      c.coeff.friction = s.uniform.friction, c.coeff.rolling_friction = s.uniform.rolling_friction;
    }
  }
  if constexpr (Rolling) {
    const Real4 r = load_streaming(s.rolling + k);
    c.rolling_impulse = {r.x, r.y, r.z};
    c.coeff.twisting_friction = r.w;
  }
  if (is_wall(c.b) && s.extra) {
    const Real4 w = load_streaming(s.extra + k);
    c.wall_velocity = {w.x, w.y, w.z};
  }
  return c;
}

// Record k's impulse word; where the records keep the normal impulse alone
// (no friction), it and a tangent impulse of +0. Plainly, or streamed past
// L2 as the sweeps read it (with Friction the records hold whole words).
MARBLES_HD_INLINE Real4 impulse_word(const SweepRecords& s, std::uint32_t k) {
  return s.impulse ? s.impulse[k] : Real4{s.normal[k], real(0), real(0), real(0)};
}
template <bool Friction>
MARBLES_HD_INLINE Real4 streamed_impulse_word(const SweepRecords& s, std::uint32_t k) {
  if (Friction || s.impulse) return load_streaming(s.impulse + k);
  return Real4{load_streaming(s.normal + k), real(0), real(0), real(0)};
}

// The contact as solve_one<Friction, Rolling> reads it, less the effective
// masses (solve_record adds them).
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE Contact load_sweep_contact(const SweepRecords& s, std::uint32_t k) {
  return load_record<Friction || Rolling, Rolling>(s, k, streamed_impulse_word<Friction>(s, k));
}

// What a sweep changed: the accumulated impulses (the normal impulse alone
// where the records keep no tangent one).
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void store_sweep_impulses(const SweepRecords& s, std::uint32_t k, const Contact& c) {
  if (!Friction && !s.impulse) store_streaming(s.normal + k, c.normal_impulse);
  else
    store_streaming(s.impulse + k,
                    Real4{c.normal_impulse, c.tangent_impulse.x, c.tangent_impulse.y, c.tangent_impulse.z});
  if constexpr (Rolling)
    store_streaming(s.rolling + k, Real4{c.rolling_impulse.x, c.rolling_impulse.y, c.rolling_impulse.z,
                                         c.coeff.twisting_friction});
}

// warm_start_one on record k (the GPU's warm start, after the packing): the
// impulses first, the rest only for a contact that carries a load (about half
// of a settled pile's carry none). The arms always: the impulse's moment
// about each centre needs them, friction or not.
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void warm_start_loaded(const SweepRecords& s, std::uint32_t k, const Real4& i, SolverBody* bodies) {
  if (i.x <= 0) return;
  warm_start_one<Friction, Rolling>(load_record<true, Rolling>(s, k, i), bodies);
}
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void warm_start_record(const SweepRecords& s, std::uint32_t k, SolverBody* bodies) {
  warm_start_loaded<Friction, Rolling>(s, k, streamed_impulse_word<Friction>(s, k), bodies);
}

// --- what a sweep writes back -------------------------------------------------
// The records' sweep (the GPU's, and the CPU's for a colour's last few
// contacts) writes back only what an update changed; the CPU's lanes write
// everything: the same memory either way. What pays is a contact that
// carries no impulse and is given none, half the updates of a settled
// pile's sweeps (gaps within the contact skin that no speed closes): its
// impulses stay +0 bit for bit (an impulse an update sets to zero is +0:
// solve_normal's literal, clamp_length's + 0), so each term applies +0 - +0
// = +0, and the bodies change by signed zeros, which leave every velocity
// component other than -0 as it was (+0 plus or minus a zero is +0).
// Without these writes a step of a pile of 10^5 keeps an H100 busy 1.16 ms
// instead of 1.29, and the gas of 10^6 solves in 0.68 ms instead of 1.08
// (docs/architecture.md, "Idle contacts write nothing").
MARBLES_HD_INLINE bool is_plus_zero(real x) { return x == 0 && !sign_bit(x); }
MARBLES_HD_INLINE bool is_minus_zero(real x) { return x == 0 && sign_bit(x); }
MARBLES_HD_INLINE bool is_plus_zero(const Vec3& v) {
  return is_plus_zero(v.x) && is_plus_zero(v.y) && is_plus_zero(v.z);
}
MARBLES_HD_INLINE bool has_minus_zero(const Vec3& v) {
  return is_minus_zero(v.x) || is_minus_zero(v.y) || is_minus_zero(v.z);
}

// Every impulse the terms update is +0, bit for bit.
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE bool impulses_clear(const Contact& c) {
  bool clear = is_plus_zero(c.normal_impulse);
  if constexpr (Friction) clear = clear && is_plus_zero(c.tangent_impulse);
  if constexpr (Rolling) clear = clear && is_plus_zero(c.rolling_impulse);
  return clear;
}

// True where a body has a velocity component of -0, the one value a signed
// zero changes (-0 + +0 is +0). After an update whose impulses were and are
// clear, a body loaded without one kept every bit.
MARBLES_HD_INLINE bool has_minus_zero(const BodyState& b) { return has_minus_zero(b.v) || has_minus_zero(b.w); }

// One sweep's update of record k (the GPU's sweep kernel): solve_one on the
// loaded contact, its effective masses computed from the bodies as the
// prepare stage computed them (contact_math.hpp), only the ones the terms
// read; written back where it changed something (above).
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void solve_loaded(const SweepRecords& s, std::uint32_t k, Contact c, SolverBody* bodies,
                                    real inv_h) {
  BodyState A = load_body(bodies, c.a, c);
  BodyState B = load_body(bodies, c.b, c);
  const bool was_clear = impulses_clear<Friction, Rolling>(c);
  // Asked only where the update may leave everything as it was: a contact
  // that carried an impulse writes its bodies anyway.
  const bool a_may_flip = was_clear && has_minus_zero(A), b_may_flip = was_clear && has_minus_zero(B);
  set_masses<Friction, Rolling>(c, A, B);
  solve_states<Friction, Rolling>(c, A, B, inv_h);
  const bool clear = was_clear && impulses_clear<Friction, Rolling>(c);
  if (!clear || a_may_flip) store_body(bodies, c.a, A);
  if (!clear || b_may_flip) store_body(bodies, c.b, B);
  if (!clear) store_sweep_impulses<Friction, Rolling>(s, k, c);
}
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void solve_record(const SweepRecords& s, std::uint32_t k, SolverBody* bodies, real inv_h) {
  solve_loaded<Friction, Rolling>(s, k, load_sweep_contact<Friction, Rolling>(s, k), bodies, inv_h);
}

// The contact as the position stages read it (project_one, overlap_ratio):
// its bodies and normal.
MARBLES_HD_INLINE Contact load_position_contact(const SweepRecords& s, std::uint32_t k) {
  Contact c;
  const BodyPair ab = s.bodies[k];
  c.a = ab.a, c.b = ab.b;
  const Real4 g = load_whole(s.geometry + k);
  c.normal = {g.x, g.y, g.z};
  return c;
}
// The impulses back into the contact after the last sweep (Rolling false:
// the rolling impulse as it was, when the records were packed without it).
template <bool Rolling = true>
MARBLES_HD_INLINE void unpack_sweep_impulses(const SweepRecords& s, std::uint32_t k, Contact& c) {
  const Real4 i = impulse_word(s, k);
  c.normal_impulse = i.x;
  c.tangent_impulse = {i.y, i.z, i.w};
  if constexpr (Rolling) {
    const Real4 r = s.rolling[k];
    c.rolling_impulse = {r.x, r.y, r.z};
  }
}

// Body i's shift (ImpactParams::shift); a wall's is none.
MARBLES_HD_INLINE Vec3 shift_of(const Vec3* shift, std::uint32_t i) { return is_wall(i) ? Vec3{} : shift[i]; }
// How far two bodies' shifts move their gap along `normal` (b towards a).
MARBLES_HD_INLINE real shift_lead(const Vec3& normal, const Vec3& shift_a, const Vec3& shift_b) {
  return dot(normal, shift_a - shift_b);
}

// The impact of one contact on its loaded bodies (apply_impact), at the
// time the gap closes with the bodies' shifts so far; each body's shift then
// takes its velocity change times that time. True if it hit. `hit` as
// apply_impact's.
template <bool Friction, class Hit = NothingMore>
MARBLES_HD_INLINE bool impact_states(Contact& c, BodyState& A, BodyState& B, const ImpactParams& p, Hit&& hit = {}) {
  const bool wall = is_wall(c.b);
  const real accel_n = wall ? dot(p.wall_accel, c.normal) : real(0);
  const Vec3 shift_a = p.shift ? p.shift[c.a] : Vec3{}, shift_b = p.shift ? shift_of(p.shift, c.b) : Vec3{};
  const Vec3 va = A.v, vb = B.v;
  real toi = 0;
  if (!apply_impact<Friction>(c, A, B, p.rest_speed, p.h, accel_n, p.shift ? shift_lead(c.normal, shift_a, shift_b) : 0,
                              toi, hit))
    return false;
  if (p.shift && toi > 0) {
    p.shift[c.a] = shift_a - (A.v - va) * toi;
    if (!wall) p.shift[c.b] = shift_b - (B.v - vb) * toi;
  }
  return true;
}
template <bool Friction>
MARBLES_HD_INLINE bool impact_one(Contact& c, SolverBody* bodies, const ImpactParams& p) {
  BodyState A = load_body(bodies, c.a, c);
  BodyState B = load_body(bodies, c.b, c);
  if (!impact_states<Friction>(c, A, B, p)) return false;
  store_body(bodies, c.a, A);
  store_body(bodies, c.b, B);
  return true;
}

// --- the records as the contact's only form ------------------------------------
// The GPU keeps a substep's contacts only as the sweep's records plus what
// the impact stage keeps of each, and so does the CPU's step from the
// records' making to the store (ImpactRecords: the approach speed, and in a
// substep with impact candidates the impact impulse and the separation as
// found, which the record's own may leave for the shifted gap: shifted_gap;
// the CPU's the restitution too; the records' extra word holds only a
// moving wall's velocity, and there is no such word where no wall moves),
// made in colour-major order from the body pairs (make_sphere_contact /
// make_wall_contact, restore_impulses, prepare_from_world,
// pack_sweep_record: the CPU's functions, so its bits). The effective
// masses are computed from the bodies where a stage needs them, as the
// sweeps do.

// What the impact stage keeps beside the records, an array each (4 bytes a
// contact in float): the approach speed, always; in a substep with impact
// candidates also its impact words, the impact impulse and the separation
// as found (the GPU's 12 bytes a contact there, 4 without). The restitution is the pair table's where no
// array holds it (the GPU's: pair_coefficients, from ImpactParams); the
// CPU keeps its contacts' own. Without impact words no impact stage runs,
// so every impact impulse stays +0 and no gap is shifted.
struct ImpactRecords {
  real* approach = nullptr;
  real* impulse = nullptr;      // with impact candidates
  real* found_gap = nullptr;    // with impact candidates
  real* restitution = nullptr;  // the CPU's, with impact candidates
  MARBLES_HD_INLINE bool words() const { return impulse != nullptr; }
  // Real4 words of n contacts' arrays: the approach speeds; with `words`
  // the impact impulses and the separations as found; with `restitution`
  // (and words) the restitutions.
  static constexpr std::size_t real4_words(std::size_t n, bool words, bool restitution = false) {
    return SweepRecords::real_words(n) * (words ? (restitution ? 4 : 3) : 1);
  }
  // The arrays laid out in `memory` (real4_words(n, words, restitution)).
  static ImpactRecords in(Real4* memory, std::size_t n, bool words, bool restitution = false) {
    const std::size_t each = SweepRecords::real_words(n);
    auto array = [&](std::size_t a) { return reinterpret_cast<real*>(memory + a * each); };
    ImpactRecords r{array(0)};
    if (words) r.impulse = array(1), r.found_gap = array(2);
    if (words && restitution) r.restitution = array(3);
    return r;
  }
};
// Record k's restitution: the impact records' where they keep one (the
// CPU's), else the pair table's for its bodies' materials.
MARBLES_HD_INLINE real restitution_of(const ImpactRecords& r, std::uint32_t k, BodyPair ab,
                                      const std::uint32_t* material, const WallShape* walls, const PairTable& table) {
  return r.restitution ? r.restitution[k] : pair_coefficients(ab, material, walls, table).restitution;
}
MARBLES_HD_INLINE void pack_impact(const Contact& c, const ImpactRecords& r, std::uint32_t k) {
  r.approach[k] = c.approach_speed;
  if (!r.words()) return;
  r.impulse[k] = c.impact_impulse;
  r.found_gap[k] = c.separation;
  if (r.restitution) r.restitution[k] = c.coeff.restitution;
}

// A prepared contact into record k with its impact words: how both backends
// make the records (ContactSolver's records_made, the GPU's records_kernel).
template <bool Rolling = true>
MARBLES_HD_INLINE void pack_contact(const Contact& c, const SweepRecords& s, const ImpactRecords& impacts,
                                    std::uint32_t k) {
  pack_sweep_record<Rolling>(c, s, k);
  pack_impact(c, impacts, k);
}

// What the impact stage's levels read: the approach speed and the separation
// (is_impact_candidate, time_of_impact).
MARBLES_HD_INLINE Contact load_approach(const SweepRecords& s, const real* approach, std::uint32_t k) {
  Contact c;
  c.separation = s.geometry[k].w;
  c.approach_speed = approach[k];
  return c;
}

// impact_one on record k: the contact as apply_impact reads it (the bodies,
// geometry, arms, friction, a wall's velocity, the impact impulse so far),
// the shifts in p, and only for a contact that hits its restitution and its
// masses from the bodies (apply_impact's `hit`: a contact refused reads no
// pair table and makes no masses); writes back the impact impulse.
template <bool Friction>
MARBLES_HD_INLINE bool impact_record(const SweepRecords& s, const ImpactRecords& impacts, std::uint32_t k,
                                     SolverBody* bodies, const ImpactParams& p) {
  Contact c = load_record<true, false>(s, k, Real4{});
  c.impact_impulse = impacts.impulse[k];
  BodyState A = load_body(bodies, c.a, c);
  BodyState B = load_body(bodies, c.b, c);
  const auto hit = [&](Contact& h, const BodyState& a, const BodyState& b) {
    h.coeff.restitution = restitution_of(impacts, k, {h.a, h.b}, p.material, p.walls, p.table);
    set_masses<Friction, false>(h, a, b);
  };
  if (!impact_states<Friction>(c, A, B, p, hit)) return false;
  store_body(bodies, c.a, A);
  store_body(bodies, c.b, B);
  impacts.impulse[k] = c.impact_impulse;
  return true;
}

// After an impact stage that hit something: record k's gap as the
// integration will leave it, its bodies' shifts taken in (the lead
// impact_states takes). The velocity solve then lets it close by no more
// than that: a pair a chain's impact timed at the substep's end does not
// meet the solve as closed (its plastic impulse took a row's energy), and a
// shift that brings a pair together cannot put it into overlap. A contact
// whose bodies no impact moved keeps its bits.
MARBLES_HD_INLINE void shifted_gap(const SweepRecords& s, const Vec3* shift, std::uint32_t k) {
  const BodyPair ab = s.bodies[k];
  const Vec3 da = shift[ab.a], db = shift_of(shift, ab.b);
  if (da == Vec3{} && db == Vec3{}) return;
  Real4 g = s.geometry[k];
  g.w = g.w + shift_lead(Vec3{g.x, g.y, g.z}, da, db);
  s.geometry[k] = g;
}

// Record k as the whole contact the CPU holds after the step: every field
// the records and the impact records keep (the restitution the pair
// table's where they keep none, as make_sphere_contact and
// make_wall_contact take it; without impact words the impact impulse +0;
// without rolling words, the rolling impulse +0 and the twisting friction
// the pair table's, as those copy it), the effective masses from the
// world's inverse masses and inertias.
MARBLES_HD_INLINE Contact contact_of_record(const SweepRecords& s, const ImpactRecords& impacts, std::uint32_t k,
                                            const BodiesView& world, const PairTable& table, const WallShape* walls) {
  const Real4 i = impulse_word(s, k);
  Contact c = s.rolling ? load_record<true, true>(s, k, i)  // a wall's velocity too
                        : load_record<true, false>(s, k, i);
  // The pair table's coefficients, where the records keep some of them not.
  if (!s.rolling)
    c.coeff.twisting_friction = pair_coefficients({c.a, c.b}, world.material, walls, table).twisting_friction;
  c.approach_speed = impacts.approach[k];
  c.coeff.restitution = restitution_of(impacts, k, {c.a, c.b}, world.material, walls, table);
  if (impacts.words()) {
    c.impact_impulse = impacts.impulse[k];
    c.separation = impacts.found_gap[k];  // as found: an impact stage may have taken shifts into the record's (shifted_gap)
  }
  set_masses<true, true>(c, world_body(world, c.a, c), world_body(world, c.b, c));
  return c;
}

// A contact takes part in the impact stage's first pass when it approaches
// faster than the rest speed; its time of impact orders that pass.
MARBLES_HD_INLINE bool is_impact_candidate(const Contact& c, real rest_speed) {
  return c.approach_speed < -rest_speed;
}
MARBLES_HD_INLINE real time_of_impact(const Contact& c) {
  return c.separation > 0 ? c.separation / -c.approach_speed : real(0);
}

// Position projection of one contact at the integrated positions: remove a
// share of the overlap beyond the slop (projection_step), split by inverse
// mass. Positions only, so no kinetic energy is added. True when it moved
// the bodies apart by more than s.settled_move of the smaller radius (a
// wall contact: of the sphere's): a sweep in which no contact does so ends
// the projection.
MARBLES_HD_INLINE bool project_one(const Contact& c, const BodiesView& bodies, const WallShape* walls,
                                   const SolverSettings& s) {
  const real inv_ma = bodies.inv_mass[c.a];
  if (is_wall(c.b)) {
    if (inv_ma <= 0) return false;
    const real r = bodies.radius[c.a];
    Vec3 normal;
    real separation;
    if (!wall_gap(walls[c.b & ~kWallFlag], bodies.position[c.a], r, normal, separation)) return false;
    const real move = projection_step(separation, s.slop * r, s.beta, s.max_correction * r);
    if (move > 0) bodies.position[c.a] += normal * move;
    return move > s.settled_move * r;
  }
  const real inv_mb = bodies.inv_mass[c.b];
  const real k = inv_ma + inv_mb;
  if (k <= 0) return false;
  const real ra = bodies.radius[c.a], rb = bodies.radius[c.b];
  const Vec3 d = bodies.position[c.a] - bodies.position[c.b];
  const real dist = length(d);
  const real r_min = ra < rb ? ra : rb;
  const real move = projection_step(dist - ra - rb, s.slop * r_min, s.beta, s.max_correction * r_min);
  if (move <= 0) return false;
  const Vec3 n = dist > real(1e-7) * (ra + rb) ? d / dist : c.normal;  // only for a move (three divisions)
  bodies.position[c.a] += n * (move * inv_ma / k);
  bodies.position[c.b] -= n * (move * inv_mb / k);
  return move > s.settled_move * r_min;
}

// The gap a contact's bodies have now (a wall's from its shape: wall_gap)
// and the smaller radius (a wall contact's: the sphere's). False where a
// wall has no gap to the sphere there (wall_gap's false).
MARBLES_HD_INLINE bool gap_now(const Contact& c, const BodiesView& bodies, const WallShape* walls, real& gap,
                               real& r_min) {
  const real ra = bodies.radius[c.a];
  r_min = ra;
  if (is_wall(c.b)) {
    Vec3 normal;
    return wall_gap(walls[c.b & ~kWallFlag], bodies.position[c.a], ra, normal, gap);
  }
  const real rb = bodies.radius[c.b];
  gap = length(bodies.position[c.a] - bodies.position[c.b]) - ra - rb;
  r_min = ra < rb ? ra : rb;
  return true;
}

// How deep a contact's bodies overlap now, as a fraction of the smaller
// radius (a wall's: of the sphere's radius); 0 when apart. The step's
// max_overlap is the largest of these after the projection.
MARBLES_HD_INLINE real overlap_ratio(const Contact& c, const BodiesView& bodies, const WallShape* walls) {
  real gap, r_min;
  if (!gap_now(c, bodies, walls, gap, r_min)) return 0;
  return gap < 0 ? -gap / r_min : real(0);
}

// --- velocity Verlet's closing solve --------------------------------------------
// Velocity Verlet kicks the velocities by (h/2) g once more after the
// contacts' solve and the drift. Left so, a substep would end with every
// resting contact closing at (h/2) g: a ball at rest on a floor would report
// g h / 2 downward, and a pile at rest the kinetic energy of that speed. The
// closing solve (the second stage of RATTLE) sweeps the substep's records
// again after that kick, the projection and the cache's store (which keeps
// the first solve's impulses: each solve starts from its own): the warm
// start from the impulses the first solve found, then the sweeps, each
// record's separation the gap its bodies have at the substep's end
// (close_record), so that a resting contact ends the substep at rest. A
// contact that approaches faster than the rest speed is the next substep's
// impact, whose speed its impact stage must see: its impulses are cleared
// and its gap opened (kOpenGap), so that no sweep touches it. A resting
// contact closes at no more than the half kick, g h / 2, an eighth of the
// rest speed (4 g h: step_model.cpp), so it is never one. What the records held is kept aside (ClosingKept) and
// given back after (reopen_record): the contacts a step reports keep their
// gaps as found, and their impulses are both solves' together, the
// substep's whole impulse.
//
// kOpenGap over a tiny h may make a bound of inf; solve_normal's clamp
// still gives +0 (an approach less than inf, or NaN from 0 times inf where
// both bodies are fixed, fails its test), so nothing non-finite is left.
inline constexpr real kOpenGap = real(1e20);  // m

// A record's words while the closing solve holds the records: its
// separation, its impulse word and, with rolling resistance, its rolling word.
struct ClosingKept {
  real* gap = nullptr;
  Real4* impulse = nullptr;
  Real4* rolling = nullptr;
};

template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void close_record(const SweepRecords& s, std::uint32_t k, const SolverBody* bodies,
                                    const BodiesView& world, const WallShape* walls, real rest_speed,
                                    const ClosingKept& kept) {
  const Real4 impulse = impulse_word(s, k);
  Contact c = load_record<false, Rolling>(s, k, impulse);
  kept.gap[k] = c.separation;
  kept.impulse[k] = impulse;
  if constexpr (Rolling) kept.rolling[k] = s.rolling[k];
  const real approach = dot(load_body(bodies, c.a, c).v - load_body(bodies, c.b, c).v, c.normal);
  real gap, r_min;
  const bool near = gap_now(c, world, walls, gap, r_min);
  if (near && !(approach < -rest_speed)) {
    s.geometry[k].w = gap;
    return;
  }
  s.geometry[k].w = kOpenGap;
  c.normal_impulse = 0;
  c.tangent_impulse = Vec3{};
  c.rolling_impulse = Vec3{};
  store_sweep_impulses<Friction, Rolling>(s, k, c);
}
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void reopen_record(const SweepRecords& s, std::uint32_t k, const ClosingKept& kept) {
  const Real4 first = kept.impulse[k], closing = impulse_word(s, k);
  Contact c;
  c.normal_impulse = first.x + closing.x;
  c.tangent_impulse = Vec3{first.y, first.z, first.w} + Vec3{closing.y, closing.z, closing.w};
  if constexpr (Rolling) {
    const Real4 r1 = kept.rolling[k], r2 = s.rolling[k];
    c.rolling_impulse = Vec3{r1.x, r1.y, r1.z} + Vec3{r2.x, r2.y, r2.z};
    c.coeff.twisting_friction = r2.w;
  }
  store_sweep_impulses<Friction, Rolling>(s, k, c);
  s.geometry[k].w = kept.gap[k];
}

}  // namespace marbles::narrowphase
