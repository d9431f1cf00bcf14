// tests/sim/test_scenes.hpp — scenes built in code, so each test states its
// own physics in a few lines.
#pragma once

#include <cstdlib>
#include <cstring>
#include <cstdint>
#include <initializer_list>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/simulation.hpp"

namespace marbles::testing {

// The broad phase the whole-step tests run on: the CPU backend, or the CUDA
// one when MARBLES_TEST_BACKEND=cuda (scripts/gpu-check runs the stability
// suite both ways).
inline broadphase::Backend test_backend() {
  const char* v = std::getenv("MARBLES_TEST_BACKEND");
  return v != nullptr && std::strcmp(v, "cuda") == 0 ? broadphase::Backend::cuda : broadphase::Backend::cpu;
}

// The environment variable `name` set to `value` while it lives, then as it
// was (for the switches a step or solver reads when made).
class ScopedEnvironment {
 public:
  ScopedEnvironment(const char* name, const std::string& value) : m_name(name) {
    if (const char* was = std::getenv(name)) m_was = was;
    setenv(name, value.c_str(), 1);
  }
  ~ScopedEnvironment() {
    if (m_was) setenv(m_name, m_was->c_str(), 1);
    else unsetenv(m_name);
  }
  ScopedEnvironment(const ScopedEnvironment&) = delete;
  ScopedEnvironment& operator=(const ScopedEnvironment&) = delete;

 private:
  const char* m_name;
  std::optional<std::string> m_was;
};

// MARBLES_SOLVE_ORDER (narrowphase/solver.hpp: LocalOrder) set to `value`
// while it lives, then as it was (a solver reads it when made).
class SolveOrder : public ScopedEnvironment {
 public:
  explicit SolveOrder(const std::string& value) : ScopedEnvironment("MARBLES_SOLVE_ORDER", value) {}
};

inline scene::Scene make_scene(double dt, int substeps, std::initializer_list<scene::Effect> effects,
                               double restitution, double friction = 0, double rolling_friction = 0,
                               double twisting_friction = 0) {
  scene::Scene s;
  s.path = s.name = "test";
  s.time = {1.0, dt, substeps};
  s.effects = effects;
  scene::Material m;
  m.name = "m";
  m.density = 1000;
  m.restitution = restitution;
  m.friction = friction;
  m.rolling_friction = rolling_friction;
  m.twisting_friction = twisting_friction;
  s.materials.push_back(m);
  return s;
}

inline scene::WallSpec plane(Vec3 point, Vec3 normal) {
  scene::WallSpec w;
  w.kind = scene::WallSpec::Kind::plane;
  w.point = point;
  w.normal = normal / length(normal);
  return w;
}

inline scene::WallSpec box(Vec3 lo, Vec3 hi) {
  scene::WallSpec w;
  w.kind = scene::WallSpec::Kind::box;
  w.lo = lo;
  w.hi = hi;
  return w;
}

inline void add_sphere(scene::GeneratedParticles& g, Vec3 p, real r, Vec3 v = {}, std::uint32_t material = 0) {
  g.position.push_back(p);
  g.velocity.push_back(v);
  g.radius.push_back(r);
  g.material.push_back(material);
}

// FNV-1a over the bytes of every position, velocity and angular velocity:
// two states with the same hash are (all but surely) equal bit for bit.
inline std::uint64_t state_hash(const World& w) {
  std::uint64_t h = 1469598103934665603ull;
  auto mix = [&](const std::vector<Vec3>& v) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(v.data());
    for (std::size_t k = 0; k < v.size() * sizeof(Vec3); ++k) h = (h ^ bytes[k]) * 1099511628211ull;
  };
  mix(w.position);
  mix(w.velocity);
  mix(w.angular_velocity);
  return h;
}

// A striker at 9.9 m/s, 0.2 mm off a row of four touching spheres of 1 cm, the
// last 7.5 mm from a wall at x = 0.0775, dt = 1 ms, e = 1: the wave leaves
// the last sphere at nearly the striker's speed within the substep, past the
// reach its contacts were found with (half a radius), and it ends the
// substep inside the wall (sim/watch_math.hpp, the unswept check). `copies`
// rows side by side, 5 cm apart in y.
inline std::pair<scene::Scene, scene::GeneratedParticles> struck_row_scene(int copies = 1) {
  using scene::Effect;
  std::pair<scene::Scene, scene::GeneratedParticles> out{
      make_scene(1e-3, 1, {Effect::collisions, Effect::walls, Effect::restitution}, 1.0), {}};
  out.first.walls.push_back(plane({real(0.0775), 0, 0}, {-1, 0, 0}));
  const real r = real(0.01);
  for (int c = 0; c < copies; ++c) {
    const real y = real(0.05 * c);
    add_sphere(out.second, {real(-0.0202), y, 0}, r, {real(9.9), 0, 0});  // 0.2 mm off: struck at once
    for (int k = 0; k < 4; ++k) add_sphere(out.second, {real(0.02 * k), y, 0}, r);
  }
  return out;
}

// A 5 cm sphere at 100 m/s into one at rest 2 cm ahead, dt = 1/60 s, e =
// 0.5; a third sphere lies where the struck one goes, 2 radii past it
// (beyond the reach its contacts are found with) and off-centre: struck
// 0.2 ms into the step, the struck sphere leaves at 75 m/s, 25 radii in the
// rest of the step, and passes through it, past what even the watchdog's
// finest substep sweeps.
inline std::pair<scene::Scene, scene::GeneratedParticles> struck_through_scene() {
  using scene::Effect;
  std::pair<scene::Scene, scene::GeneratedParticles> out{
      make_scene(1.0 / 60, 1, {Effect::collisions, Effect::restitution}, 0.5), {}};
  const real r = real(0.05);
  add_sphere(out.second, {real(1.38), 0, 0}, r, {100, 0, 0});
  add_sphere(out.second, {real(1.5), 0, 0}, r);
  add_sphere(out.second, {real(1.5 + 4 * r), real(0.02), 0}, r);
  return out;
}

// Scenes that exercise every stage, for the determinism and backend-parity
// tests: a polydisperse pour of two materials into a box with every effect,
// over a fixed sphere and past a spinning post, under air drag.
inline std::pair<scene::Scene, scene::GeneratedParticles> pour_scene(int count, std::uint64_t seed) {
  using scene::Effect;
  scene::Scene s = make_scene(1e-3, 2,
                              {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                               Effect::friction, Effect::rolling_resistance, Effect::drag},
                              0.6, 0.4, 0.02, 0.01);
  scene::Material heavy = s.materials[0];
  heavy.name = "heavy";
  heavy.density = 7800;
  heavy.restitution = 0.3;
  s.materials.push_back(heavy);
  s.drag = 0.05;
  s.walls.push_back(box({0, 0, 0}, {real(0.3), real(0.3), real(1.0)}));
  scene::WallSpec post;
  post.kind = scene::WallSpec::Kind::cylinder;
  post.base = {real(0.2), real(0.15), 0};
  post.radius = 0.02;
  post.length = 0.3;
  post.inside = false;
  post.angular_velocity = 3;
  s.walls.push_back(post);
  scene::WallSpec rock;
  rock.kind = scene::WallSpec::Kind::sphere;
  rock.centre = {real(0.1), real(0.15), real(0.05)};
  rock.radius = 0.04;
  s.walls.push_back(rock);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  scene::GeneratedParticles g;
  const int side = 8;
  for (int k = 0; k < count; ++k) {
    const int x = k % side, y = (k / side) % side, z = k / (side * side);
    const real r = real(0.008 + 0.006 * u(rng));
    add_sphere(g, {real(0.03 + 0.03 * x + 0.004 * u(rng)), real(0.03 + 0.03 * y + 0.004 * u(rng)),
                   real(0.15 + 0.03 * z)},
               r, {real(u(rng) - 0.5), real(u(rng) - 0.5), real(-u(rng))}, static_cast<std::uint32_t>(k % 2));
  }
  return {s, g};
}

}  // namespace marbles::testing
