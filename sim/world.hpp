// sim/world.hpp — the state of every sphere, as a structure of arrays.
//
// The world owns the arrays; stages get a BodiesView (core/spheres.hpp) of
// raw pointers. Mass properties are derived once from radius and density:
//   m = rho (4/3) pi r^3,   I = (2/5) m r^2   (solid sphere)
#pragma once

#include <cstdint>
#include <vector>

#include "core/spheres.hpp"
#include "core/vec3.hpp"

namespace marbles {

namespace scene {
struct Scene;
struct GeneratedParticles;
}  // namespace scene

struct World {
  std::vector<Vec3> position;          // m
  std::vector<Vec3> velocity;          // m/s
  std::vector<Vec3> angular_velocity;  // rad/s
  std::vector<real> radius;            // m
  std::vector<real> inv_mass;          // 1/kg
  std::vector<real> inv_inertia;       // 1/(kg m^2)
  std::vector<std::uint32_t> material; // index into the scene's materials

  std::size_t size() const { return position.size(); }
  BodiesView view() {
    return {position.data(), velocity.data(), angular_velocity.data(), radius.data(),
            inv_mass.data(),  inv_inertia.data(), material.data(), size()};
  }

  // Sum of (1/2) m v^2 + (1/2) I w^2 over movable spheres, J (in double).
  double kinetic_energy() const;
  // The two sums apart and the largest speed |v| of any sphere (in double):
  // a pile at rest may keep spheres spinning where nothing resists it (about
  // a lone contact's normal without twisting friction), so its rest shows in
  // the translational part and the largest speed. thermo.csv's columns and
  // summary.json's figures at the end.
  struct Motion {
    double translational = 0, rotational = 0, max_speed = 0;
  };
  Motion motion() const;
  // Total linear momentum, kg m/s (in double).
  void momentum(double out[3]) const;
  // Largest |v|, m/s.
  real max_speed() const;
  // Index of the first sphere with a non-finite position or velocity, or size().
  std::size_t first_non_finite() const;
  // The first sphere whose position, velocity or spin is not finite or
  // squares past the precision's range (integrator::body_in_range), or size().
  std::size_t first_out_of_range() const;
};

// from[order[i]] for each i: an array in a new order of its items.
template <class T>
std::vector<T> gathered(const T* from, const std::vector<std::uint32_t>& order) {
  std::vector<T> to(order.size());
  for (std::size_t i = 0; i < order.size(); ++i) to[i] = from[order[i]];
  return to;
}

// Sphere order[i] of `w` as sphere i, every array with it (order: a
// permutation of [0, w.size())).
World permuted(const World& w, const std::vector<std::uint32_t>& order);
// True where order[i] == i for every i.
bool is_identity(const std::vector<std::uint32_t>& order);
// The inverse of a permutation: inverse[order[i]] == i (in parallel;
// std::out_of_range where an index is past the order's length). `order`
// must be a permutation (the step's orders are; a checkpoint's numbering
// is checked as one when read).
std::vector<std::uint32_t> inverse_of(const std::vector<std::uint32_t>& order);
// The same into `inverse`, whose memory is kept where it is large enough.
void inverse_into(const std::vector<std::uint32_t>& order, std::vector<std::uint32_t>& inverse);

// The order (new index -> old) that numbers the spheres along rows of the
// home-cell broad phase's cells for them (x, then y, then z; a cell's
// spheres as they were): the order in which it finds their pairs. Identity
// where the grid is too wide for one key.
std::vector<std::uint32_t> cell_order(const Vec3* position, const real* radius, std::size_t n);
inline std::vector<std::uint32_t> cell_order(const World& w) {
  return cell_order(w.position.data(), w.radius.data(), w.size());
}

// Builds the world from the scene's materials and its generated particles.
World make_world(const scene::Scene& scene, const scene::GeneratedParticles& particles);

// A sphere's inverse mass and inertia as make_world makes them: both 0 (a
// fixed sphere), or both in the precision's usable range (from its smallest
// normal number to an eighth of its largest) with the inertia a solid
// sphere's of that mass and radius (2/5 m r^2, to a part in 10^4). A
// checkpoint's spheres are held to it (sim/checkpoint.cpp).
bool masses_as_made(real radius, real inv_mass, real inv_inertia);

}  // namespace marbles
