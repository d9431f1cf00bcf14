// integrator/integrator_math.hpp — per-body updates of the semi-implicit
// (symplectic) Euler scheme, host and device.
//
//   v(t+h) = v(t) + h a(t)          velocities first (forces, then contacts)
//   x(t+h) = x(t) + h v(t+h)        positions from the new velocities
// Symplectic: energy errors stay bounded for conservative forces instead of
// growing as with explicit Euler. Its free flight under gravity is off by
// g h^2 / 2 per substep (first order in h over a flight).
//
// Velocity Verlet (solver.integrator: velocity_verlet) is the same functions
// in kick-drift-kick order: gravity_kick(h/2), contacts, drift(h),
// gravity_kick(h/2); with drag each kick is drag_update's, gravity's half
// with drag's (drag_first_half, then drag_kick). Under constant
// forces x(t+h) = x + h v + h^2 g / 2 exactly; contacts act on the half-step
// velocity, the one the drift uses, so speculative contacts keep their
// no-tunnelling guarantee. With drag the two halves are the trapezoidal
// rule of dv/dt = g - k v (explicit, then implicit): second order, and the
// terminal speed g / k exact.
#pragma once

#include "core/vec3.hpp"

namespace marbles::integrator {

// v += h g for a movable body (inv_mass > 0); immovable bodies keep their velocity.
MARBLES_HD_INLINE Vec3 gravity_kick(const Vec3& v, const Vec3& g, real inv_mass, real h) {
  return inv_mass > 0 ? v + g * h : v;
}

// Air drag dv/dt = -(k1 + k2 |v|) v over h, backward Euler:
//   v' = v - h (k1 + k2 |v'|) v',
// solved exactly for the speed s = |v'|: h k2 s^2 + (1 + h k1) s = |v|, taken
// in the form that neither cancels nor divides by k2. It never reverses a
// velocity and never overshoots, however large h k is, and after gravity's
// kick it keeps the terminal speed (g / k1, or sqrt(g / k2)) exactly.
// Symplectic Euler's whole kick and velocity Verlet's second half. (With |v|
// of the velocity before the update instead of |v'|, as first written,
// quadratic drag settled g h / 2 off its terminal speed, alternated about it
// where stiff, and left velocity Verlet first order.)
// k1 in 1/s (linear), k2 in 1/m (quadratic).
MARBLES_HD_INLINE Vec3 drag_kick(const Vec3& v, real k1, real k2, real h) {
  const real speed = length(v);
  const real a = real(1) + h * k1;
  const real scale = real(2) / (a + std::sqrt(a * a + real(4) * h * k2 * speed));
  return v * scale;
}

// Velocity Verlet's first half kick with drag, gravity's half (gh = g h,
// zero without gravity) with it: the explicit half of the trapezoidal rule,
// v (1 - e) + gh with e = h (k1 + k2 |v|), where that keeps the velocity's
// direction (e <= 1); past it (h k > 2 for the whole step: drag stiff for
// the step) a backward-Euler half, (v + gh) / (1 + e), so that no drag
// reverses a velocity. Either way, with the second half (gravity's half kick,
// then drag_kick) the terminal speed is g / k exactly. (Both halves backward
// Euler, as first written, left the positions first order: off by v0 h / 4
// over a decay.)
MARBLES_HD_INLINE Vec3 drag_first_half(const Vec3& v, const Vec3& gh, real k1, real k2, real h) {
  const real e = h * (k1 + k2 * length(v));
  return e <= real(1) ? v * (real(1) - e) + gh : (v + gh) / (real(1) + e);
}

// A velocity kick where drag is on, gravity's (gh = g h, where `gravity`)
// taken with it in the same pass: symplectic Euler's whole kick (gravity,
// then drag_kick), or velocity Verlet's first half (drag_first_half) or
// second (gravity, then drag_kick over the half step). Without gravity nothing is added,
// so that no zero changes its sign.
enum class DragKick : unsigned char { whole, verlet_first, verlet_second };
MARBLES_HD_INLINE Vec3 drag_update(DragKick kick, const Vec3& v, bool gravity, const Vec3& gh, real k1, real k2,
                                   real h) {
  if (kick == DragKick::verlet_first) return drag_first_half(v, gravity ? gh : Vec3{}, k1, k2, h);
  const Vec3 w = gravity ? v + gh : v;
  return drag_kick(w, k1, k2, h);
}

// x += h v
MARBLES_HD_INLINE Vec3 drift(const Vec3& x, const Vec3& v, real h) { return x + v * h; }

// The same for sphere i, then its shift from the substep's impacts (a word a
// sphere, narrowphase::ImpactParams::shift; null where no impact stage ran
// or, on the CPU, none hit; +0 for a sphere no hit moved): an impact
// at time t changed its velocity, which the drift applies for the whole
// substep, t too long, and the shift takes that back. A sphere no impact
// moved (shift +0) keeps its bits.
MARBLES_HD_INLINE Vec3 drift(const Vec3& x, const Vec3& v, real h, const Vec3* shift, std::size_t i) {
  const Vec3 y = drift(x, v, h);
  if (!shift) return y;
  const Vec3 s = shift[i];
  return s == Vec3{} ? y : y + s;
}

// A sphere that moved farther than the reach its contacts were found with
// (narrowphase::contact_reach, m) by more than kUnsweptSlack of its radius:
// the solve set it moving past what the substep swept (sim/watch_math.hpp
// checks where it went).
inline constexpr real kUnsweptSlack = real(0.01);
MARBLES_HD_INLINE bool moved_past_reach(const Vec3& v, real radius, real reach, real h) {
  return length(v) * h > reach + kUnsweptSlack * radius;
}

// The non-finite check of the position stage.
MARBLES_HD_INLINE bool body_is_finite(const Vec3& x, const Vec3& v, const Vec3& w) {
  return is_finite(x) && is_finite(v) && is_finite(w);
}

// The check of a state edited from outside (arrays written through views):
// finite, and no square past the precision's range (a speed whose square
// overflows makes the kinetic energy inf, a position's the distances).
MARBLES_HD_INLINE bool body_in_range(const Vec3& x, const Vec3& v, const Vec3& w) {
  return !square_overflows(x) && !square_overflows(v) && !square_overflows(w);
}

}  // namespace marbles::integrator
