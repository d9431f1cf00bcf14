// tests/sim/test_scenes.hpp — scenes built in code, so each test states its
// own physics in a few lines.
#pragma once

#include <cstdlib>
#include <cstring>
#include <initializer_list>

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

}  // namespace marbles::testing
