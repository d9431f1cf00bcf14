// sim/particles.hpp — the scene's particle blocks expanded into spheres.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/vec3.hpp"
#include "sim/scene.hpp"

namespace marbles::scene {

struct GeneratedParticles {
  std::vector<Vec3> position;
  std::vector<Vec3> velocity;
  std::vector<real> radius;
  std::vector<Vec3> angular_velocity;   // rad/s
  std::vector<std::uint32_t> material;  // index into Scene::materials
  std::vector<std::uint8_t> fixed;      // 1: collides, never moves (inverse mass and inertia 0)
  std::vector<std::size_t> block_end;   // the end of each block's spheres, in the scene's order (generate_particles)
  std::size_t size() const { return position.size(); }
};

// Expands every block in order (ids follow that order). Deterministic for a
// given scene (seeded generators). Throws InputError for a missing or
// malformed CSV (file:line:column of the CSV), a block that cannot hold the
// requested count of non-overlapping spheres, or an unknown material.
GeneratedParticles generate_particles(const Scene& scene);

// Refuses (InputError at `where`, naming `key`) a total of spheres that
// would need more memory than the machine has available now (times --limit
// memory), before anything is made.
void check_sphere_budget(double total, const SourceLocation& where, const std::string& key);

// Reads `x,y,z,r[,vx,vy,vz[,wx,wy,wz]]` rows (an optional header line, '#' comments);
// used by the csv block and by `marbles pairs`.
GeneratedParticles read_spheres_csv(const std::string& path);

// The rules each value of a sphere's row holds to, alike in a scene's CSV
// block, `marbles pairs` and marbles.pairs() (column 0-9: x y z r vx vy vz
// wx wy wz): a finite number that the precision holds, and a radius > 0
// whose square the overlap test can take. What the value breaks, or "";
// the caller says where and what it got.
std::string sphere_value_problem(int column, double value);

// The same for a row's centre, velocity or spin, whose squared length the
// step takes: "too large for <precision> ...: the squared length of (`names`)
// overflows", or "".
std::string sphere_vector_problem(const Vec3& v, const std::string& names);

}  // namespace marbles::scene
