// narrowphase/contact_math.hpp — per-contact math, host and device.
//
// Contact generation (exact sphere–sphere, sphere–plane, sphere–inside-of-box)
// and the impulse updates of one contact. The CPU loops in contacts.cpp and
// solver.cpp, and any CUDA kernel, call exactly these functions.
//
// Units: positions m, velocities m/s, angular velocities rad/s, impulses N s,
// angular impulses N m s.
#pragma once

#include <cmath>
#include <cstdint>

#include "core/spheres.hpp"
#include "core/vec3.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

// The velocity state of one body as the solver sees it.
struct BodyState {
  Vec3 v, w;
  real inv_mass = 0, inv_inertia = 0;
};

// Sphere a (centre pa, radius ra) against sphere b. Returns false when the gap
// is not below `margin`. Coincident centres get the normal +z, so the result
// is always finite.
MARBLES_HD_INLINE bool sphere_sphere(const Vec3& pa, real ra, const Vec3& pb, real rb, real margin,
                                     Vec3& normal, real& separation) {
  const Vec3 d = pa - pb;
  const real dist2 = length_squared(d);
  const real reach = ra + rb + margin;
  if (!(dist2 < reach * reach)) return false;
  const real dist = std::sqrt(dist2);
  const real tiny = real(1e-7) * (ra + rb);
  normal = dist > tiny ? d / dist : Vec3(0, 0, 1);
  separation = dist - ra - rb;
  return true;
}

// Two spheres apart (separation > 0) and closing take the normal of the
// line of centres at the moment tau in the substep where it matters, not at
// its start: where they touch within h, the moment they touch (an
// off-centre impact leaves along the line of centres at impact, as
// rigid-body impact theory has it; the start's line turned it by about the
// distance closed in h over R: 7.5 % of the approach speed for 5 cm
// spheres meeting off-centre at 10 m/s at dt 1 ms); else the substep's end,
// or their closest approach where it comes first. Along the start's normal
// a gap closing at the normal speed closes sooner than the spheres meet
// (their surfaces curve away), which struck an oblique pair early along
// the wrong line; along the line at tau the gap closes exactly when they
// touch, and not within h where they do not. d is the centres' offset (a's
// less b's), dv the velocities' (a's less b's), R the sum of the radii
// (|d|, dist, is taken only past the early returns). The moment of touch
// solves |d + dv t| = R, its smaller root, in the form that keeps the
// digits: with beta = -d.dv > 0, a = |dv|^2 and c = separation (dist + R) =
// |d|^2 - R^2, t = c / (beta + sqrt(beta^2 - a c)); without a root they pass
// each other, closest at beta / a. The separation is then d's along the new
// normal less R (at least +0). Left as it is where they touch already or
// move apart.
//
// `inside`: the same inside a circle of radius R (a sphere inside a drum or
// tube, across its axis: R the drum's radius less the sphere's; d the
// centre's offset from the axis, dv its velocity across it). Apart is then
// |d| < R, closing is moving outwards (beta = d.dv > 0), and the touch is the
// positive root of a t^2 - 2 beta t - c = 0 with c = R^2 - |d|^2 = separation
// (R + dist) > 0: t = c / (beta + sqrt(beta^2 + a c)), always real; the
// normal points back to the axis, and the gap along it is R less d's part
// along its outward line.
MARBLES_HD_INLINE void normal_at_touch(const Vec3& d, const Vec3& dv, real R, real h, Vec3& normal,
                                       real& separation, bool inside = false) {
  if (!(separation > 0)) return;
  const real beta = inside ? dot(d, dv) : -dot(d, dv);
  if (!(beta > 0)) return;
  const real dist = length(d);
  const real a = dot(dv, dv), c = separation * (dist + R);
  const real disc = inside ? beta * beta + a * c : beta * beta - a * c;
  real tau = h;
  if (disc >= 0) {
    const real t = c / (beta + std::sqrt(disc));
    if (t < tau) tau = t;
  } else {
    const real closest = beta / a;
    if (closest < tau) tau = closest;
  }
  const Vec3 m = d + dv * tau;
  const real len = length(m);
  if (!(len > 0)) return;
  const Vec3 out = m / len;
  const real s = dot(out, d) - R;
  normal = inside ? -out : out;
  separation = inside ? (s < 0 ? -s : real(0)) : (s > 0 ? s : real(0));
}

// Sphere against a half-space (point on plane q, unit normal n towards free space).
MARBLES_HD_INLINE bool sphere_plane(const Vec3& p, real r, const Vec3& q, const Vec3& n, real margin,
                                    real& separation) {
  separation = dot(p - q, n) - r;
  return separation < margin;
}

// A wall as the narrow phase sees it: every wall kind of core/walls.hpp is
// flattened into these (a box is six half-spaces).
struct WallShape {
  enum class Kind : std::uint8_t { half_space, cylinder_inside, cylinder_outside, sphere };
  Kind kind = Kind::half_space;
  Vec3 point;            // plane point / cylinder base / sphere centre
  Vec3 direction{0, 0, 1};  // plane normal (towards free space) / cylinder axis
  real radius = 0;       // cylinder / sphere
  real length = 0;       // cylinder, 0 = infinite
  Vec3 velocity;         // m/s, translation
  real angular_velocity = 0;  // rad/s about `direction` through `point` (cylinders)
  std::uint32_t material = 0;
};

// Any unit vector perpendicular to unit `a` (used when a sphere sits exactly
// on a cylinder's axis, so the normal is still defined).
MARBLES_HD_INLINE Vec3 any_perpendicular(const Vec3& a) {
  const Vec3 t = std::fabs(a.x) < real(0.9) ? Vec3(1, 0, 0) : Vec3(0, 1, 0);
  const Vec3 c = cross(a, t);
  return c / length(c);
}

// A post of finite length (a cylinder's outside, `length` > 0) is a solid
// with flat ends: beside it the gap is wall_gap's radial one; past an end,
// over the end's disc, the gap to that disc (normal along the axis), and
// beyond its rim the gap to the rim's circle; a centre inside the solid goes
// out by the nearest face (side, or either end). This is the solid's exact
// distance less r, convex along any path (watch_math.hpp relies on it).
// `out` is the unit radial direction of p, `dist` its distance from the
// axis, `t` its coordinate along it.
MARBLES_HD_INLINE void post_gap(const WallShape& w, const Vec3& out, real dist, real t, real r, Vec3& normal,
                                real& separation) {
  const real L = w.length;
  if (t >= 0 && t <= L) {  // beside the post, or inside it
    const real side = w.radius - dist, top = L - t;
    if (side <= 0 || (side <= top && side <= t)) {
      normal = out;
      separation = dist - w.radius - r;
    } else if (top <= t) {
      normal = w.direction;
      separation = -top - r;
    } else {
      normal = -w.direction;
      separation = -t - r;
    }
    return;
  }
  const real beyond = t > L ? t - L : -t;  // > 0: past an end along the axis
  const Vec3 axial = t > L ? w.direction : -w.direction;
  const real radial = dist - w.radius;
  if (radial <= 0) {  // over the end's disc
    normal = axial;
    separation = beyond - r;
    return;
  }
  const Vec3 d = out * radial + axial * beyond;  // from the rim's nearest point
  const real reach = length(d);
  normal = reach > 0 ? d / reach : axial;
  separation = reach - r;
}

// Signed gap between sphere (p, r) and wall `w` and the normal from the wall
// towards the sphere. Returns false where the wall does not act on the sphere
// (beyond the open ends of a finite tube: a cylinder's inside; a finite
// post's ends are closed: post_gap).
MARBLES_HD_INLINE bool wall_gap(const WallShape& w, const Vec3& p, real r, Vec3& normal, real& separation) {
  switch (w.kind) {
    case WallShape::Kind::half_space:
      normal = w.direction;
      separation = dot(p - w.point, w.direction) - r;
      return true;
    case WallShape::Kind::sphere: {
      const Vec3 d = p - w.point;
      const real dist = length(d);
      normal = dist > real(1e-7) * (w.radius + r) ? d / dist : Vec3(0, 0, 1);
      separation = dist - w.radius - r;
      return true;
    }
    case WallShape::Kind::cylinder_inside:
    case WallShape::Kind::cylinder_outside: {
      const Vec3 q = p - w.point;
      const real t = dot(q, w.direction);
      const bool post = w.kind == WallShape::Kind::cylinder_outside && w.length > 0;
      if (w.length > 0 && !post && (t < 0 || t > w.length)) return false;
      const Vec3 rho = q - w.direction * t;
      const real dist = length(rho);
      const Vec3 out = dist > real(1e-7) * w.radius ? rho / dist : any_perpendicular(w.direction);
      if (post) {
        post_gap(w, out, dist, t, r, normal, separation);
      } else if (w.kind == WallShape::Kind::cylinder_inside) {
        normal = -out;
        separation = w.radius - dist - r;
      } else {
        normal = out;
        separation = dist - w.radius - r;
      }
      return true;
    }
  }
  return false;
}

// A sphere closing on a cylinder's side takes the normal of the moment of
// touch, as against a sphere: across the axis the side is a circle, so the
// problem is normal_at_touch's (a post's outside: a circle of the radius
// plus r; a drum's or tube's inside: the radius less r, `inside`), in the offset and velocity across the axis (the spin moves no
// point of the surface across it). Only where the sphere stays beside a
// finite cylinder's side for the whole substep; past an end (a post's end
// or rim, a tube's open end) the start's normal stays. `normal` and
// `separation` are wall_gap's at the start.
MARBLES_HD_INLINE void cylinder_normal_at_touch(const WallShape& w, const Vec3& p, const Vec3& v, real r, real h,
                                                Vec3& normal, real& separation) {
  if (!(separation > 0)) return;
  const Vec3 q = p - w.point, dv = v - w.velocity;
  const real t = dot(q, w.direction), vt = dot(dv, w.direction);
  if (w.length > 0) {
    const real t_end = t + vt * h;
    if (!(t >= 0 && t <= w.length && t_end >= 0 && t_end <= w.length)) return;
  }
  const Vec3 d = q - w.direction * t, across = dv - w.direction * vt;
  const bool inside = w.kind == WallShape::Kind::cylinder_inside;
  normal_at_touch(d, across, inside ? w.radius - r : w.radius + r, h, normal, separation, inside);
}

// Velocity of the wall's surface at world point x.
MARBLES_HD_INLINE Vec3 wall_surface_velocity(const WallShape& w, const Vec3& x) {
  return w.velocity + cross(w.direction * w.angular_velocity, x - w.point);
}

// True when wall_surface_velocity is +0, every component, at every point: no
// translation (each component +0: +0 plus a product of zeros of either sign
// is +0) and no spin. A contact with such a wall needs no velocity of its own.
MARBLES_HD_INLINE bool surface_at_rest(const WallShape& w) {
  const auto plus_zero = [](real v) { return v == 0 && !std::signbit(v); };
  return plus_zero(w.velocity.x) && plus_zero(w.velocity.y) && plus_zero(w.velocity.z) && w.angular_velocity == 0;
}

// Resting contacts keep a skin: a gap below kContactSkin times the smaller
// radius still counts as touching, so a contact whose gap flickers around
// zero in a resting pile is not dropped and re-made (losing its warm start).
inline constexpr real kContactSkin = real(0.005);

// Contact test of the narrow phase: touching (gap below `skin`), a gap that
// the current normal approach speed (v_n < 0) closes within the substep h, or
// a gap within `reach` (m, the pair's contact_reach summed): a gap the solve
// may close by passing a neighbour's speed on.
MARBLES_HD_INLINE bool speculative_closes(real separation, real normal_velocity, real h, real skin, real reach) {
  return separation < skin || separation < -normal_velocity * h || separation < reach;
}

// How far (m) a sphere's speculative contacts reach: its own travel |v| h,
// and at least the travel of the fastest sphere of the substep, up to half
// its radius. An impact or a push within the solve passes speed on to a
// sphere at rest, which then meets a neighbour whose gap no velocity before
// the solve would close; without that contact the two overlap by up to v h
// within one substep, and the projection, which sees only contacts, never
// separates them (docs/solver.md, "Rigid means rigid").
MARBLES_HD_INLINE real contact_reach(real speed, real max_speed, real radius, real h) {
  const real own = speed * h;
  real passed = max_speed * h;
  if (passed > real(0.5) * radius) passed = real(0.5) * radius;
  return own > passed ? own : passed;
}

// Two fixed spheres (a glued floor's, a peg row's: inverse masses 0) never
// move each other: they make no contact, so their overlap is no pile's and
// costs no sweep (make_sphere_contact; the run's initial-overlap warning).
MARBLES_HD_INLINE bool both_fixed(real inv_mass_a, real inv_mass_b) { return !(inv_mass_a > 0) && !(inv_mass_b > 0); }

// What a contact takes from its pair besides its geometry: the bodies, the
// arms (the radii; a wall's +0) and the pair table's coefficients. Set by
// the search (make_sphere_contact, make_wall_contact) and again from a found
// contact as its record is made (whole_contact): one text, the same bits.
MARBLES_HD_INLINE void name_sphere_pair(const BodiesView& bodies, std::uint32_t i, std::uint32_t j,
                                        const PairTable& table, Contact& c) {
  c.a = i;
  c.b = j;
  c.ra = bodies.radius[i];
  c.rb = bodies.radius[j];
  c.coeff = table(bodies.material[i], bodies.material[j]);
}
MARBLES_HD_INLINE void name_wall_pair(const BodiesView& bodies, std::uint32_t i, const WallShape& wall,
                                      std::uint32_t k, const PairTable& table, Contact& c) {
  c.a = i;
  c.b = kWallFlag | k;
  c.ra = bodies.radius[i];
  c.rb = 0;
  c.coeff = table(bodies.material[i], wall.material);
}
// The wall's surface velocity where sphere i (at p, radius r) meets it along
// `normal`. A spin about a cylinder's axis moves its surface along itself
// only, so the spin's part along the normal is taken off: at a point in the
// gap off the normal's line (a speculative contact with the normal of the
// moment of touch) it is not zero, and a frictionless sphere met a drum
// spinning at 4 m/s at 0.1 m/s off the impact law. Without spin, the
// translation as before (the same bits).
MARBLES_HD_INLINE Vec3 wall_velocity_at_sphere(const WallShape& wall, const Vec3& p, real r, const Vec3& normal) {
  if (wall.angular_velocity == 0) return wall_surface_velocity(wall, p - normal * r);
  const Vec3 spin = cross(wall.direction * wall.angular_velocity, p - normal * r - wall.point);
  return wall.velocity + (spin - normal * dot(spin, normal));
}

// One candidate pair of the broad phase -> a contact, when the spheres touch
// (gap below the skin) or their gap closes within the substep h at the
// current approach speed. The loop body of sphere_contacts (contacts.cpp) and
// of its CUDA twin.
// `reach`: contact_reach of each sphere (m).
MARBLES_HD_INLINE bool make_sphere_contact(const BodiesView& bodies, std::uint32_t i, std::uint32_t j,
                                           const PairTable& table, real h, const real* reach, Contact& c) {
  const Vec3 dv = bodies.velocity[i] - bodies.velocity[j];
  const real ri = bodies.radius[i], rj = bodies.radius[j];
  const real skin = kContactSkin * (ri < rj ? ri : rj);
  const real pair_reach = reach[i] + reach[j];
  const real closing = length(dv) * h;
  const real margin = (closing > pair_reach ? closing : pair_reach) + skin;  // no wider gap can matter
  if (!sphere_sphere(bodies.position[i], ri, bodies.position[j], rj, margin, c.normal, c.separation)) return false;
  if (!speculative_closes(c.separation, dot(dv, c.normal), h, skin, pair_reach)) return false;
  if (both_fixed(bodies.inv_mass[i], bodies.inv_mass[j])) return false;
  normal_at_touch(bodies.position[i] - bodies.position[j], dv, ri + rj, h, c.normal, c.separation);
  name_sphere_pair(bodies, i, j, table, c);
  return true;
}

// Sphere i against wall k -> a contact under the same rule (approach speed
// relative to the wall's surface, the sphere's reach alone). The loop body of
// wall_contacts.
MARBLES_HD_INLINE bool make_wall_contact(const BodiesView& bodies, std::uint32_t i, const WallShape& wall,
                                         std::uint32_t k, const PairTable& table, real h, const real* reach,
                                         Contact& c) {
  const Vec3 p = bodies.position[i];
  const real r = bodies.radius[i];
  if (!wall_gap(wall, p, r, c.normal, c.separation)) return false;
  c.wall_velocity = wall_velocity_at_sphere(wall, p, r, c.normal);
  if (!speculative_closes(c.separation, dot(bodies.velocity[i] - c.wall_velocity, c.normal), h, kContactSkin * r,
                          reach[i]))
    return false;
  if (wall.kind == WallShape::Kind::sphere) {  // its surface velocity is its translation, whatever the normal
    normal_at_touch(p - wall.point, bodies.velocity[i] - wall.velocity, r + wall.radius, h, c.normal, c.separation);
  } else if (wall.kind != WallShape::Kind::half_space) {  // a spinning side moves where the contact is: its velocity again
    cylinder_normal_at_touch(wall, p, bodies.velocity[i], r, h, c.normal, c.separation);
    c.wall_velocity = wall_velocity_at_sphere(wall, p, r, c.normal);
  }
  name_wall_pair(bodies, i, wall, k, table, c);
  return true;
}

// The fields a found contact holds (FoundContact), copied from one form to
// the other.
template <class From, class To>
MARBLES_HD_INLINE void copy_found_fields(const From& from, To& to) {
  to.normal_impulse = from.normal_impulse;
  to.tangent_impulse = from.tangent_impulse;
  to.rolling_impulse = from.rolling_impulse;
  to.a = from.a, to.b = from.b;
  to.separation = from.separation;
  to.normal = from.normal;
}
// The search's contact as found (what make_sphere_contact or
// make_wall_contact found, the restore's impulses on it).
MARBLES_HD_INLINE FoundContact found_of(const Contact& c) {
  FoundContact f;
  copy_found_fields(c, f);
  return f;
}
// The whole contact of a found one: what the search set besides the found
// fields, made again by the search's own functions (name_sphere_pair,
// name_wall_pair, wall_velocity_at_sphere) from the bodies and walls as the
// search saw them: the same bits.
MARBLES_HD_INLINE Contact whole_contact(const FoundContact& f, const BodiesView& bodies, const PairTable& table,
                                        const WallShape* walls) {
  Contact c;
  copy_found_fields(f, c);
  if (is_wall(f.b)) {
    const std::uint32_t k = f.b & ~kWallFlag;
    c.wall_velocity = wall_velocity_at_sphere(walls[k], bodies.position[f.a], bodies.radius[f.a], c.normal);
    name_wall_pair(bodies, f.a, walls[k], k, table, c);
  } else {
    name_sphere_pair(bodies, f.a, f.b, table, c);
  }
  return c;
}

// Walls passed over. A half-space whose surface is at rest (surface_at_rest:
// +0 at every point) can be passed over where make_wall_contact must refuse
// the sphere (wall_contacts and its CUDA twin): its gap (wall_gap's, the same
// bits) at least the skin, the sphere's reach, and a bound on what its
// approach closes in h. The approach is v . n (the surface's +0 taken off v
// changes no bit) for a unit n, so |v . n| h as rounded stays below
// (|vx| + |vy| + |vz|) h as rounded and made a ten-thousandth larger (for a
// normal whose components reach 1 at most, within a millionth); a NaN gap
// or speed fails the comparisons and goes to the whole test, and an
// infinite gap, passed over, is one the whole test refuses too.
// The same contacts (Walls.PassedOverOnlyWhereTheWholeTestRefuses); about
// half the work of a box (10^5 spheres, none touching, one thread on the
// CPU: 7.0-10.3 -> 3.8-5.5 ms).
MARBLES_HD_INLINE bool wall_passable(const WallShape& w) {
  const Vec3& d = w.direction;  // unit (scene walls are made so); checked, as the bound needs it
  const real x = std::fabs(d.x), y = std::fabs(d.y), z = std::fabs(d.z);
  const real most = x > y ? (x > z ? x : z) : (y > z ? y : z);
  return w.kind == WallShape::Kind::half_space && surface_at_rest(w) && most <= real(1.000001);
}

// The gaps beyond which sphere i is passed over by a passable wall: `clear`
// (the skin, its reach) and `closes` (the bound on its approach in h).
struct WallClearance {
  real clear = 0;
  real closes = 0;
};
MARBLES_HD_INLINE WallClearance wall_clearance(const BodiesView& bodies, std::uint32_t i, real h, const real* reach) {
  const Vec3 v = bodies.velocity[i];
  const real skin = kContactSkin * bodies.radius[i];
  return {skin > reach[i] ? skin : reach[i], ((std::fabs(v.x) + std::fabs(v.y)) + std::fabs(v.z)) * h * real(1.0001)};
}

// True where make_wall_contact refuses sphere i at passable wall w for
// certain (so a caller may skip it).
MARBLES_HD_INLINE bool wall_passed_over(const WallShape& w, const BodiesView& bodies, std::uint32_t i,
                                        const WallClearance& clearance) {
  Vec3 normal;
  real gap = 0;
  return wall_gap(w, bodies.position[i], bodies.radius[i], normal, gap) && gap >= clearance.clear &&
         gap >= clearance.closes;
}

// Effective masses of a contact between A and B (arms ra, rb along the
// normal). Each is a function of the two bodies' inverse masses and inertias
// and the arms alone: the GPU's sweeps compute the ones they need from the
// bodies they load instead of streaming them (solver_math.hpp, solve_record),
// with these same expressions, so the bits equal the prepared ones.
MARBLES_HD_INLINE real normal_mass_of(const BodyState& A, const BodyState& B) {
  const real k_normal = A.inv_mass + B.inv_mass;
  return k_normal > 0 ? real(1) / k_normal : real(0);
}
MARBLES_HD_INLINE real tangent_mass_of(const BodyState& A, const BodyState& B, real ra, real rb) {
  const real k_tangent = (A.inv_mass + B.inv_mass) + A.inv_inertia * ra * ra + B.inv_inertia * rb * rb;
  return k_tangent > 0 ? real(1) / k_tangent : real(0);
}
MARBLES_HD_INLINE real rolling_mass_of(const BodyState& A, const BodyState& B) {
  const real k_roll = A.inv_inertia + B.inv_inertia;
  return k_roll > 0 ? real(1) / k_roll : real(0);
}

// The effective masses a stage reads: the normal one always, the tangential
// one with friction, the rolling one with rolling resistance. The stages on
// the GPU's records compute them from the bodies they load (solver_math.hpp).
template <bool Friction, bool Rolling>
MARBLES_HD_INLINE void set_masses(Contact& c, const BodyState& A, const BodyState& B) {
  c.normal_mass = normal_mass_of(A, B);
  if constexpr (Friction) c.tangent_mass = tangent_mass_of(A, B, c.ra, c.rb);
  if constexpr (Rolling) c.rolling_mass = rolling_mass_of(A, B);
}

// The normal speed at which a closes on b (< 0: approaching).
MARBLES_HD_INLINE real approach_speed_of(const Contact& c, const BodyState& A, const BodyState& B) {
  return dot(A.v - B.v, c.normal);
}

// Prepare stage: effective masses and the approach speed before the solve.
MARBLES_HD_INLINE void prepare_contact(Contact& c, const BodyState& A, const BodyState& B) {
  set_masses<true, true>(c, A, B);
  c.approach_speed = approach_speed_of(c, A, B);
}

// Relative velocity of the contact points (a minus b).
MARBLES_HD_INLINE Vec3 contact_relative_velocity(const Contact& c, const BodyState& A, const BodyState& B) {
  const Vec3 va = A.v + cross(A.w, c.normal * (-c.ra));
  const Vec3 vb = B.v + cross(B.w, c.normal * c.rb);
  return va - vb;
}

MARBLES_HD_INLINE void apply_impulse(const Contact& c, BodyState& A, BodyState& B, const Vec3& impulse) {
  A.v += impulse * A.inv_mass;
  A.w += cross(c.normal * (-c.ra), impulse) * A.inv_inertia;
  B.v -= impulse * B.inv_mass;
  B.w -= cross(c.normal * c.rb, impulse) * B.inv_inertia;
}

// Clamp a vector impulse to a disc of radius `limit`. A clamped impulse
// holds no negative zero (+ 0 turns -0 into +0 and leaves every other value
// as it is), and clamped to a zero limit it is the +0 vector whatever v is,
// so an unloaded contact's impulse keeps its bits from sweep to sweep
// (solver_math.hpp impulses_clear, solver_lanes.hpp all_idle). The zero limit is asked
// first: a v so small that its squared length underflows to 0 (|v| under
// about 4e-23 in float) would pass the test below and be kept as it is.
MARBLES_HD_INLINE Vec3 clamp_length(const Vec3& v, real limit) {
  if (limit == 0) return Vec3{};
  const real len2 = length_squared(v);
  if (len2 <= limit * limit) return v;
  return v * (limit / std::sqrt(len2)) + Vec3{};
}

// The normal speed at which a leaves b, plus the approach the gap allows
// this substep (separation / h where open): where it is >= 0 the normal
// constraint asks for no impulse.
MARBLES_HD_INLINE real normal_slack(const Contact& c, const BodyState& A, const BodyState& B, real inv_h) {
  const real vn = dot(A.v - B.v, c.normal);
  const real allowed = c.separation > 0 ? c.separation * inv_h : real(0);
  return vn + allowed;
}

// Normal constraint: the gap may close by at most max(separation, 0) this
// substep (speculative contact); accumulated impulse stays >= 0.
MARBLES_HD_INLINE void solve_normal(Contact& c, BodyState& A, BodyState& B, real inv_h) {
  real lambda = -c.normal_mass * normal_slack(c, A, B, inv_h);
  const real old = c.normal_impulse;
  c.normal_impulse = old + lambda > 0 ? old + lambda : real(0);
  lambda = c.normal_impulse - old;
  const Vec3 p = c.normal * lambda;
  A.v += p * A.inv_mass;
  B.v -= p * B.inv_mass;
}

// Coulomb friction: the tangential impulse stays in the circular cone
// |P_t| <= mu * P_n.
MARBLES_HD_INLINE void solve_friction(Contact& c, BodyState& A, BodyState& B) {
  const Vec3 vrel = contact_relative_velocity(c, A, B);
  const Vec3 vt = vrel - c.normal * dot(vrel, c.normal);
  const Vec3 old = c.tangent_impulse;
  c.tangent_impulse = clamp_length(old - vt * c.tangent_mass, c.coeff.friction * c.normal_impulse);
  apply_impulse(c, A, B, c.tangent_impulse - old);
}

// Rolling resistance: an angular impulse opposing the relative rolling
// (the tangential part of w_a - w_b), limited to mu_r * R_eff * P_n; and
// twisting resistance: one opposing the relative spin about the normal,
// limited to mu_t * R_eff * P_n. Both live in `rolling_impulse` (tangential
// and normal parts).
MARBLES_HD_INLINE void solve_rolling(Contact& c, BodyState& A, BodyState& B) {
  const Vec3 dw = A.w - B.w;
  const real spin = dot(dw, c.normal);
  const Vec3 roll = dw - c.normal * spin;
  const real r_eff = c.rb > 0 ? c.ra * c.rb / (c.ra + c.rb) : c.ra;
  const Vec3 old = c.rolling_impulse;
  const real old_twist = dot(old, c.normal);
  const Vec3 old_roll = old - c.normal * old_twist;
  const Vec3 new_roll =
      clamp_length(old_roll - roll * c.rolling_mass, c.coeff.rolling_friction * r_eff * c.normal_impulse);
  const real twist_limit = c.coeff.twisting_friction * r_eff * c.normal_impulse;
  real new_twist = old_twist - spin * c.rolling_mass;
  new_twist = new_twist > twist_limit ? twist_limit : (new_twist < -twist_limit ? -twist_limit : new_twist);
  c.rolling_impulse = new_roll + c.normal * new_twist;
  const Vec3 d = c.rolling_impulse - old;
  A.w += d * A.inv_inertia;
  B.w -= d * B.inv_inertia;
}

// Impact stage: a contact still approaching faster than `rest_speed` whose
// gap closes within the substep h collides as a binary impact,
//   P_n = (1 + e) m_n |v_n|   along the normal, then, with friction, a
//   tangential impulse that stops the slip, limited to mu P_n (circular cone),
// as rigid-body impact theory has it. Returns true if it hit. Impacts are
// applied in time-of-impact order with the velocities left by the earlier
// ones, so a chain (Newton's cradle) or a triple collision resolves as a
// sequence of binary impacts: with e = 1 each conserves energy exactly.
//
// `accel_n`: the pair's relative acceleration along the normal during the
// substep (gravity against a wall under velocity Verlet, whose v_n is the
// half-step velocity; 0 otherwise). The impact then happens at the time the
// accelerated gap closes, with the speed it has then, and the bodies leave
// with the velocity and gap that the exact motion reaches at the end of the
// substep: a ball bouncing on a floor keeps its rebound heights exactly.
//
// `lead`: how far the substep's earlier impacts of either body have moved
// the gap along the normal (dot(n, shift_a - shift_b), impact_states): a
// body whose velocity changed at time t moves as x0 + v t + shift, so the
// gap is separation + lead + v_n t, and this impact happens when that
// closes. In a chain (a column of touching balls on a floor) the impacts
// after the first happen at the first one's time, not at the substep's
// start. `toi` is set to the time of impact (0 for a contact already
// closed).
//
// `hit(c, A, B)` runs only past the refusal, before anything else reads the
// contact: it may fill in what only a hit reads (the restitution, the
// effective masses), so that a contact refused costs none of that.
struct NothingMore {
  MARBLES_HD_INLINE void operator()(Contact&, const BodyState&, const BodyState&) const {}
};
template <bool Friction, class Hit = NothingMore>
MARBLES_HD_INLINE bool apply_impact(Contact& c, BodyState& A, BodyState& B, real rest_speed, real h, real accel_n,
                                    real lead, real& toi, Hit&& hit = {}) {
  const real vn = dot(A.v - B.v, c.normal);
  const real gap = c.separation + lead;
  if (vn > -rest_speed || !(gap < -vn * h)) return false;
  hit(c, static_cast<const BodyState&>(A), static_cast<const BodyState&>(B));
  const real e = c.coeff.restitution;
  real target = -e * vn;  // the normal velocity after the impact
  toi = gap > 0 ? gap / -vn : real(0);
  if (accel_n != 0 && gap > 0) {
    const real half = real(0.5) * h;
    const real vs = vn - accel_n * half;  // at the start of the substep
    const real disc = vs * vs - 2 * accel_n * gap;
    toi = disc > 0 ? 2 * gap / (-vs + std::sqrt(disc)) : gap / -vn;
    if (!(toi >= 0)) toi = 0;
    if (toi > h) toi = h;
    const real v_hit = vn + accel_n * (toi - half);  // < 0
    target = -e * v_hit + accel_n * (half - toi);
  }
  const real lambda = c.normal_mass * (target - vn);
  c.impact_impulse += lambda;
  apply_impulse(c, A, B, c.normal * lambda);
  if constexpr (Friction) {
    const Vec3 vrel = contact_relative_velocity(c, A, B);
    const Vec3 vt = vrel - c.normal * dot(vrel, c.normal);
    apply_impulse(c, A, B, clamp_length(vt * (-c.tangent_mass), c.coeff.friction * lambda));
  }
  // Time of impact: the bodies meet at toi into the substep and separate at
  // the target speed from then on; with the new velocity acting over the
  // whole substep they would end (target - v_n) toi too far apart ((1 + e)
  // gap without acceleration). The bodies' shifts (impact_states) take that
  // back at the integration.
  return true;
}

// Position projection: move the bodies apart along the normal to remove a
// fraction `beta` of the overlap beyond `slop`, at most `max_step` per call.
// Only positions change, never velocities, so no kinetic energy is added.
MARBLES_HD_INLINE real projection_step(real separation, real slop, real beta, real max_step) {
  const real error = separation + slop;  // < 0 when overlapping more than slop
  if (error >= 0) return 0;
  const real step = -beta * error;
  return step < max_step ? step : max_step;
}

}  // namespace marbles::narrowphase
