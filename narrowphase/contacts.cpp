#include "narrowphase/contacts.hpp"

#include "narrowphase/contact_math.hpp"

namespace marbles::narrowphase {

std::vector<PlaneWall> wall_half_spaces(const Walls& walls) {
  std::vector<PlaneWall> out(walls.planes.begin(), walls.planes.end());
  for (const BoxWall& box : walls.boxes) {
    out.push_back({box.lo, {1, 0, 0}, box.material});
    out.push_back({box.hi, {-1, 0, 0}, box.material});
    out.push_back({box.lo, {0, 1, 0}, box.material});
    out.push_back({box.hi, {0, -1, 0}, box.material});
    out.push_back({box.lo, {0, 0, 1}, box.material});
    out.push_back({box.hi, {0, 0, -1}, box.material});
  }
  return out;
}

void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real margin, std::vector<Contact>& out) {
  for (std::size_t k = 0; k < pair_count; ++k) {
    const IndexPair pair = pairs[k];
    Contact c;
    if (!sphere_sphere(bodies.position[pair.i], bodies.radius[pair.i], bodies.position[pair.j],
                       bodies.radius[pair.j], margin, c.normal, c.separation))
      continue;
    c.a = pair.i;
    c.b = pair.j;
    c.ra = bodies.radius[pair.i];
    c.rb = bodies.radius[pair.j];
    c.coeff = table(bodies.material[pair.i], bodies.material[pair.j]);
    out.push_back(c);
  }
}

void wall_contacts(const BodiesView& bodies, const std::vector<PlaneWall>& half_spaces,
                   const PairTable& table, real margin, std::vector<Contact>& out) {
  const std::uint32_t wall_count = static_cast<std::uint32_t>(half_spaces.size());
  for (std::size_t i = 0; i < bodies.count; ++i) {
    for (std::uint32_t w = 0; w < wall_count; ++w) {
      const PlaneWall& wall = half_spaces[w];
      Contact c;
      if (!sphere_plane(bodies.position[i], bodies.radius[i], wall.point, wall.normal, margin, c.separation))
        continue;
      c.a = static_cast<std::uint32_t>(i);
      c.b = kWallFlag | w;
      c.normal = wall.normal;
      c.ra = bodies.radius[i];
      c.rb = 0;
      c.coeff = table(bodies.material[i], wall.material);
      out.push_back(c);
    }
  }
}

}  // namespace marbles::narrowphase
