#include "narrowphase/contacts.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "core/parallel.hpp"

namespace marbles::narrowphase {

std::vector<WallShape> wall_shapes(const Walls& walls) {
  std::vector<WallShape> out;
  auto half_space = [&](const Vec3& point, const Vec3& normal, std::uint32_t material, const Vec3& velocity) {
    WallShape w;
    w.kind = WallShape::Kind::half_space;
    w.point = point;
    w.direction = normal;
    w.material = material;
    w.velocity = velocity;
    out.push_back(w);
  };
  for (const PlaneWall& p : walls.planes) half_space(p.point, p.normal, p.material, p.velocity);
  for (const BoxWall& box : walls.boxes) {
    half_space(box.lo, {1, 0, 0}, box.material, box.velocity);
    half_space(box.hi, {-1, 0, 0}, box.material, box.velocity);
    half_space(box.lo, {0, 1, 0}, box.material, box.velocity);
    half_space(box.hi, {0, -1, 0}, box.material, box.velocity);
    half_space(box.lo, {0, 0, 1}, box.material, box.velocity);
    half_space(box.hi, {0, 0, -1}, box.material, box.velocity);
  }
  for (const CylinderWall& c : walls.cylinders) {
    WallShape w;
    w.kind = c.inside ? WallShape::Kind::cylinder_inside : WallShape::Kind::cylinder_outside;
    w.point = c.base;
    w.direction = c.axis;
    w.radius = c.radius;
    w.length = c.length;
    w.angular_velocity = c.angular_velocity;
    w.material = c.material;
    out.push_back(w);
  }
  for (const SphereWall& s : walls.spheres) {
    WallShape w;
    w.kind = WallShape::Kind::sphere;
    w.point = s.centre;
    w.radius = s.radius;
    w.velocity = s.velocity;
    w.material = s.material;
    out.push_back(w);
  }
  return out;
}

std::vector<std::uint32_t> wall_shape_owners(const Walls& walls) {
  std::vector<std::uint32_t> out;
  for (const PlaneWall& p : walls.planes) out.push_back(p.index);
  for (const BoxWall& box : walls.boxes) out.insert(out.end(), 6, box.index);
  for (const CylinderWall& c : walls.cylinders) out.push_back(c.index);
  for (const SphereWall& s : walls.spheres) out.push_back(s.index);
  return out;
}

void advance_walls(std::vector<WallShape>& shapes, real h) {
  for (WallShape& w : shapes) w.point += w.velocity * h;
}

namespace {

constexpr std::size_t kParallelFrom = 20000;

// The threads' buffers of contacts of type C.
std::vector<std::vector<Contact>>& parts_of(ContactScratch& s, const Contact*) { return s.parts; }
std::vector<std::vector<FoundContact>>& parts_of(ContactScratch& s, const FoundContact*) { return s.found_parts; }

// A made contact as the list holds it.
inline const Contact& as_listed(const Contact& c, const Contact*) { return c; }
inline FoundContact as_listed(const Contact& c, const FoundContact*) { return found_of(c); }

// The per-thread buffers: `scratch`'s when given (kept between calls).
template <class C, class Make>
void collect(std::size_t count, std::vector<C>& out, ContactScratch* scratch, Make&& make) {
  ContactScratch local;
  collect_in_order(count, kParallelFrom, out, parts_of(scratch ? *scratch : local, out.data()), make);
}

// Pair k's contact, if any, appended to `to` (sphere_contacts' loop body).
// The views captured as copies (a few pointers): by reference, each
// pointer was read again after every append, whose pointer stores may
// alias them as far as the compiler knows.
template <class C>
auto sphere_contact_maker(const BodiesView& bodies, const IndexPair* pairs, const PairTable& table, real h,
                          const real* reach) {
  return [bodies, pairs, table, h, reach](std::size_t k, std::vector<C>& to) {
    Contact c;
    if (make_sphere_contact(bodies, pairs[k].i, pairs[k].j, table, h, reach, c))
      to.push_back(as_listed(c, static_cast<const C*>(nullptr)));
  };
}

template <class C>
void sphere_contacts_in_runs(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                             const PairTable& table, real h, const real* reach, std::vector<C>& out,
                             std::vector<C>& rest, ContactScratch& scratch) {
  auto& parts = parts_of(scratch, out.data());
  const int threads = collect_in_parts(pair_count, kParallelFrom, out, parts,
                                       sphere_contact_maker<C>(bodies, pairs, table, h, reach));
  if (threads == 1) {
    rest.clear();
    return;
  }
  // The second thread's buffer itself where it is the only other (rest's
  // old one to the scratch). Else rest's own elements replaced by the
  // parts, copied in on all threads.
  if (threads == 2) {
    rest.swap(parts[1]);
    return;
  }
  put_parts(rest, 0, parts, 1, threads, kParallelFrom);
}

// Spheres near[i] that some wall may not pass over, where every wall is
// passable (a half-space at rest: wall_passable), four at a time: each
// wall's pass-over test (wall_clearance, then wall_passed_over's gap and
// comparisons) in the lanes of 16-byte vectors, the same expressions in the
// same order lane by lane, so the same answers. A box's six tests a sphere
// cost most of the wall search where a sphere is near no wall: settle
// scene of 10^5, 2 threads, 1.1 ms a substep before.
void near_walls(const BodiesView& b, const std::vector<WallShape>& walls, real h, const real* reach,
                std::vector<std::uint8_t>& near) {
  typedef real V __attribute__((vector_size(16)));
  using Mask = decltype(V{} < V{});
  constexpr std::size_t w = sizeof(V) / sizeof(real);
  const std::size_t n = b.count;
  near.resize(n);
  std::uint8_t* out = near.data();
  const auto blocks = static_cast<std::ptrdiff_t>(n / w);
  const Mask magnitude = ~(Mask{} + std::numeric_limits<std::remove_cvref_t<decltype(Mask{}[0])>>::min());
  auto fabs_lanes = [&](V x) { return (V)((Mask)x & magnitude); };
#pragma omp parallel for schedule(static) if (n > kParallelFrom)
  for (std::ptrdiff_t t = 0; t < blocks; ++t) {
    const std::size_t i = static_cast<std::size_t>(t) * w;
    V px, py, pz, vx, vy, vz, r, reach_of;
    for (std::size_t l = 0; l < w; ++l) {
      px[l] = b.position[i + l].x, py[l] = b.position[i + l].y, pz[l] = b.position[i + l].z;
      vx[l] = b.velocity[i + l].x, vy[l] = b.velocity[i + l].y, vz[l] = b.velocity[i + l].z;
      r[l] = b.radius[i + l], reach_of[l] = reach[i + l];
    }
    const V skin = kContactSkin * r;
    const V clear = skin > reach_of ? skin : reach_of;
    const V closes = ((fabs_lanes(vx) + fabs_lanes(vy)) + fabs_lanes(vz)) * h * real(1.0001);
    Mask any = {};
    for (const WallShape& wall : walls) {
      const V dx = px - wall.point.x, dy = py - wall.point.y, dz = pz - wall.point.z;
      const V gap = ((dx * wall.direction.x + dy * wall.direction.y) + dz * wall.direction.z) - r;
      any |= ~((gap >= clear) & (gap >= closes));
    }
    for (std::size_t l = 0; l < w; ++l) out[i + l] = any[l] != 0;
  }
  // The last few: the sphere loop's own test decides them.
  for (std::size_t i = static_cast<std::size_t>(blocks) * w; i < n; ++i) out[i] = 1;
}

template <class C>
void wall_contacts_of(const BodiesView& bodies, const std::vector<WallShape>& walls, const PairTable& table, real h,
                      const real* reach, std::vector<C>& out, ContactScratch* scratch) {
  const auto wall_count = static_cast<std::uint32_t>(walls.size());
  // Walls at rest passed over where the whole test must refuse a sphere
  // (wall_passable, contact_math.hpp); where every wall is such, the
  // spheres near none of them are known first (near_walls) and skipped.
  std::vector<char> passable(wall_count);
  bool every_passable = wall_count > 0;
  for (std::uint32_t k = 0; k < wall_count; ++k) {
    passable[k] = wall_passable(walls[k]);
    every_passable = every_passable && passable[k];
  }
  ContactScratch local;
  std::vector<std::uint8_t>& near = (scratch ? *scratch : local).near_walls;
  if (every_passable) near_walls(bodies, walls, h, reach, near);
  const std::uint8_t* near_of = every_passable ? near.data() : nullptr;
  collect(bodies.count, out, scratch, [&](std::size_t i, std::vector<C>& to) {
    if (near_of && !near_of[i]) return;
    // One contact for all the sphere's walls: make_wall_contact writes every
    // field it sets on each call and leaves the rest (impulses, masses) at
    // their defaults, so a reused one pushes what a fresh one would.
    Contact c;
    const auto s = static_cast<std::uint32_t>(i);
    const WallClearance clearance = wall_clearance(bodies, s, h, reach);
    for (std::uint32_t k = 0; k < wall_count; ++k) {
      if (passable[k] && wall_passed_over(walls[k], bodies, s, clearance)) continue;
      if (make_wall_contact(bodies, s, walls[k], k, table, h, reach, c))
        to.push_back(as_listed(c, static_cast<const C*>(nullptr)));
    }
  });
}

}  // namespace

void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real h, const real* reach, std::vector<Contact>& out,
                     ContactScratch* scratch) {
  collect(pair_count, out, scratch, sphere_contact_maker<Contact>(bodies, pairs, table, h, reach));
}

void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real h, const real* reach, std::vector<Contact>& out,
                     std::vector<Contact>& rest, ContactScratch& scratch) {
  sphere_contacts_in_runs(bodies, pairs, pair_count, table, h, reach, out, rest, scratch);
}
void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real h, const real* reach, std::vector<FoundContact>& out,
                     std::vector<FoundContact>& rest, ContactScratch& scratch) {
  sphere_contacts_in_runs(bodies, pairs, pair_count, table, h, reach, out, rest, scratch);
}

void wall_contacts(const BodiesView& bodies, const std::vector<WallShape>& walls, const PairTable& table, real h,
                   const real* reach, std::vector<Contact>& out, ContactScratch* scratch) {
  wall_contacts_of(bodies, walls, table, h, reach, out, scratch);
}
void wall_contacts(const BodiesView& bodies, const std::vector<WallShape>& walls, const PairTable& table, real h,
                   const real* reach, std::vector<FoundContact>& out, ContactScratch* scratch) {
  wall_contacts_of(bodies, walls, table, h, reach, out, scratch);
}

void contact_reaches(const BodiesView& bodies, real h, std::vector<real>& reach) {
  const auto n = static_cast<std::ptrdiff_t>(bodies.count);
  real max_speed = 0;
#pragma omp parallel for schedule(static) reduction(max : max_speed) if (n > 20000)
  for (std::ptrdiff_t i = 0; i < n; ++i) max_speed = std::max(max_speed, length(bodies.velocity[i]));
  reach.resize(bodies.count);
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t i = 0; i < n; ++i)
    reach[i] = contact_reach(length(bodies.velocity[i]), max_speed, bodies.radius[i], h);
}

}  // namespace marbles::narrowphase
