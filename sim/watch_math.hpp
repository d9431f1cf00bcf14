// sim/watch_math.hpp — the per-sphere figures of the watchdog's cheap
// invariants (Simulation::step), host and device: one pass over the spheres
// at the end of a step, summed by the backend (CpuStep, CudaStep).
//
//   kinetic energy   translational + rotational, J (immovable spheres: 0)
//   beyond a wall    the whole sphere lies past a wall's surface (its centre
//                    deeper than one radius into the wall): it went through
//   unswept motion   a sphere the solve set moving past the reach its
//                    contacts were found with went deeper into a sphere or
//                    wall than it was at the substep's start: a meeting no
//                    contact stood for (checked as the positions move,
//                    every substep: integrate_positions)
#pragma once

#include "core/vec3.hpp"
#include "narrowphase/contact_math.hpp"

namespace marbles::watch {

MARBLES_HD_INLINE double kinetic_energy(const Vec3& v, const Vec3& w, real inv_mass, real inv_inertia) {
  if (!(inv_mass > 0)) return 0;
  const double t = static_cast<double>(length_squared(v)) / static_cast<double>(inv_mass);
  const double r = inv_inertia > 0 ? static_cast<double>(length_squared(w)) / static_cast<double>(inv_inertia) : 0.0;
  return 0.5 * (t + r);
}

MARBLES_HD_INLINE bool beyond_walls(const Vec3& p, real r, const narrowphase::WallShape* walls, std::uint32_t n) {
  for (std::uint32_t k = 0; k < n; ++k) {
    Vec3 normal;
    real separation = 0;
    if (narrowphase::wall_gap(walls[k], p, r, normal, separation) && separation < real(-2) * r) return true;
  }
  return false;
}

// --- Motion the substep did not sweep (docs/solver.md "No tunnelling") ---
//
// The broad phase and the contact test saw each sphere grown by its reach
// (narrowphase::contact_reach), from the velocities before the solve. A
// sphere the solve sets moving faster (struck within the substep, or pushed
// by a wall) can meet a sphere or wall with no contact between them, and
// pass into it or through it. Such a sphere is found as the positions move
// (integrator::moved_past_reach), and only those, at most unswept_checked
// a substep, are checked against every sphere and wall; more than that count
// as unchecked, and the watchdog splits the step as for a meeting.
//
// How many are checked: as many as keep a substep's check within
// kUnsweptPairs pair tests (each against every sphere), at least 64 and at
// most kUnsweptListed (the GPU's list): every one of them up to 724
// spheres, 174 at 3 000, 64 from 8 192 on. On one core of the CPU 2^19
// pair tests take about 2.5 ms, a substep of a dense pile of 3 000 spheres
// (docs/solver.md "No tunnelling"); splitting the step takes two at least.
inline constexpr std::uint32_t kUnsweptListed = 4096;
inline constexpr std::uint64_t kUnsweptPairs = std::uint64_t(1) << 19;
constexpr std::uint32_t unswept_checked(std::size_t spheres) {
  const std::uint64_t fit = spheres > 0 ? kUnsweptPairs / spheres : kUnsweptListed;
  return fit < 64 ? 64u : (fit > kUnsweptListed ? kUnsweptListed : static_cast<std::uint32_t>(fit));
}

// The parameter in [0, 1] of the point of d0 + t m nearest the origin.
MARBLES_HD_INLINE real nearest_on_path(const Vec3& d0, const Vec3& m) {
  const real mm = length_squared(m);
  if (!(mm > 0)) return 0;
  const real t = -dot(d0, m) / mm;
  return t < 0 ? real(0) : (t > 1 ? real(1) : t);
}

// False where the straight path d0 + t m, t in [0, 1], stays farther than
// `touch` from the origin along some axis (so farther in all): most pairs
// of a scene, passed over without the exact test's root and division.
MARBLES_HD_INLINE bool path_may_come_within(const Vec3& d0, const Vec3& m, real touch) {
  const Vec3 d1 = d0 + m;
  const auto apart = [touch](real a, real b) { return (a > touch && b > touch) || (a < -touch && b < -touch); };
  return !(apart(d0.x, d1.x) || apart(d0.y, d1.y) || apart(d0.z, d1.z));
}

// How much deeper (of the smaller radius) spheres a and b overlapped while
// both moved on straight lines from p - v h to where they stand, p, than at
// p - v h: 0 where they came no deeper. p - v h is the substep's start, or
// for a sphere an impact moved, x0 + its shift: the path it took from its
// last impact on, drawn back to the substep's start. A contact the solve
// held never deepens (its gap closes at most to zero, and an overlap does
// not grow), so a deepening is a meeting the contacts did not see.
MARBLES_HD_INLINE real swept_deepening(const Vec3& pa, const Vec3& va, real ra, const Vec3& pb, const Vec3& vb,
                                      real rb, real h) {
  const Vec3 m = (va - vb) * h;
  const Vec3 d0 = (pa - pb) - m;
  const real touch = ra + rb;
  if (!path_may_come_within(d0, m, touch)) return 0;
  const real deepest = touch - length(d0 + m * nearest_on_path(d0, m));
  if (!(deepest > 0)) return 0;
  const real start = touch - length(d0);
  const real deeper = start > 0 ? deepest - start : deepest;
  return deeper > 0 ? deeper / (ra < rb ? ra : rb) : real(0);
}

// swept_deepening of spheres i and j of `b`; 0 for a sphere with itself and
// for two fixed spheres (they make no contact: narrowphase::both_fixed).
MARBLES_HD_INLINE real unswept_pair(const BodiesView& b, std::size_t i, std::size_t j, real h) {
  if (i == j || narrowphase::both_fixed(b.inv_mass[i], b.inv_mass[j])) return 0;
  return swept_deepening(b.position[i], b.velocity[i], b.radius[i], b.position[j], b.velocity[j], b.radius[j], h);
}

// The part [lo, hi] of the path s + t m, t in [0, 1], that a cylinder of
// finite length acts on (its points' axial coordinates within [0, length]:
// narrowphase::wall_gap); false where the path never passes beside it.
MARBLES_HD_INLINE bool beside_span(const narrowphase::WallShape& w, const Vec3& s, const Vec3& m, real& lo, real& hi) {
  const real t0 = dot(s - w.point, w.direction), dt = dot(m, w.direction);
  lo = 0;
  hi = 1;
  if (dt == 0) return t0 >= 0 && t0 <= w.length;
  real a = -t0 / dt, b = (w.length - t0) / dt;
  if (a > b) {
    const real c = a;
    a = b;
    b = c;
  }
  if (a > lo) lo = a;
  if (b < hi) hi = b;
  return lo <= hi;
}

// The same for a sphere against a wall as it stands (the substep's start:
// walls move after the spheres). Along a straight path a half-space's and a
// tube's inside are deepest at an end; a sphere's and a cylinder's outside
// where the path passes nearest their centre or axis. A cylinder of finite
// length acts only on the part of the path beside it, so there the ends are
// that part's and the nearest point is taken within it (measured as from
// the endless cylinder: a point at the part's end may round past the
// length); a finite post's closed ends make it a convex solid, searched
// along the path.
MARBLES_HD_INLINE real wall_swept_deepening(const narrowphase::WallShape& w, const Vec3& p, const Vec3& v, real r,
                                           real h) {
  using Kind = narrowphase::WallShape::Kind;
  const Vec3 m = v * h;
  const Vec3 s = p - m;
  Vec3 normal;
  real gap = 0;
  real start = 0;  // the overlap at the start (none where the wall does not act there)
  if (narrowphase::wall_gap(w, s, r, normal, gap) && gap < 0) start = -gap;
  real deepest = 0;
  if (narrowphase::wall_gap(w, p, r, normal, gap) && -gap > deepest) deepest = -gap;
  if (w.kind == Kind::cylinder_outside && w.length > 0) {
    // A finite post is a convex solid and its gap the solid's distance
    // (narrowphase::post_gap): along the path the depth is concave, its
    // largest value found by a golden-section search (48 halvings by the
    // golden ratio: below a float's resolution of [0, 1]).
    const auto depth = [&](real t) {
      narrowphase::wall_gap(w, s + m * t, r, normal, gap);
      return -gap;
    };
    const real g = real(0.3819660112501051);  // 2 - the golden ratio
    real a = 0, b = 1, x1 = g, x2 = 1 - g, f1 = depth(x1), f2 = depth(x2);
    for (int k = 0; k < 48; ++k) {
      if (f1 < f2) {
        a = x1, x1 = x2, f1 = f2;
        x2 = b - g * (b - a), f2 = depth(x2);
      } else {
        b = x2, x2 = x1, f2 = f1;
        x1 = a + g * (b - a), f1 = depth(x1);
      }
    }
    const real inner = f1 > f2 ? f1 : f2;
    if (inner > deepest) deepest = inner;
    const real deeper = deepest - start;
    return deeper > 0 ? deeper / r : real(0);
  }
  // Points of the path within [lo, hi] are measured on the endless wall
  // (the length is a cylinder's only; other kinds ignore it).
  narrowphase::WallShape endless = w;
  endless.length = 0;
  real lo = 0, hi = 1;
  // The span found from the path can round to empty where p, found beside
  // the cylinder by wall_gap, lies on an end's plane: p's depth stands.
  bool beside = true;
  if ((w.kind == Kind::cylinder_inside || w.kind == Kind::cylinder_outside) && w.length > 0) {
    beside = beside_span(w, s, m, lo, hi);
    if (beside && narrowphase::wall_gap(endless, s + m * lo, r, normal, gap) && -gap > deepest) deepest = -gap;
    if (beside && narrowphase::wall_gap(endless, s + m * hi, r, normal, gap) && -gap > deepest) deepest = -gap;
  }
  if (beside && (w.kind == Kind::sphere || w.kind == Kind::cylinder_outside)) {
    Vec3 d0 = s - w.point, dm = m;
    if (w.kind == Kind::cylinder_outside) {  // across the axis
      d0 = d0 - w.direction * dot(d0, w.direction);
      dm = dm - w.direction * dot(dm, w.direction);
    }
    real t = nearest_on_path(d0, dm);
    t = t < lo ? lo : (t > hi ? hi : t);
    if (narrowphase::wall_gap(endless, s + m * t, r, normal, gap) && -gap > deepest) deepest = -gap;
  }
  const real deeper = deepest - start;
  return deeper > 0 ? deeper / r : real(0);
}

}  // namespace marbles::watch
