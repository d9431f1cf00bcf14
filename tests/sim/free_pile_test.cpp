// Free piles: pyramids of touching equal spheres standing on a plane floor
// with nothing holding their bottom layer (no frame, no walls). A static
// solution needs friction and rolling resistance: without rolling resistance
// the edge of a pile is a chain of gears (the bottom sphere rolls outwards
// on the floor, each sphere above rolls on the one below, no contact slips),
// which Coulomb friction does not resist, and the velocity solve follows it
// even fully converged. With mu = 1 and mu_r = 0.1 each case below has one.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "tests/sim/test_scenes.hpp"

using namespace marbles;
using namespace marbles::testing;
using scene::Effect;

namespace {

constexpr std::initializer_list<Effect> kGranularRolling{Effect::gravity,     Effect::collisions, Effect::walls,
                                                         Effect::restitution, Effect::friction,
                                                         Effect::rolling_resistance};

double max_drift(const World& a, const std::vector<Vec3>& reference) {
  double d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, double(length(a.position[i] - reference[i])));
  return d;
}

// 2-D pyramid in the plane y = 0: a bottom row of `base` touching spheres,
// each row above nested in the hollows of the one below.
scene::GeneratedParticles triangle(int base, real r) {
  scene::GeneratedParticles g;
  const real rise = std::sqrt(real(3)) * r;
  for (int k = 0; k < base; ++k)
    for (int i = 0; i < base - k; ++i) add_sphere(g, {r + (2 * i + k) * r, 0, r + k * rise}, r);
  return g;
}

// Square pyramid: layer k has (base - k)^2 touching spheres.
scene::GeneratedParticles square_pyramid(int base, real r) {
  scene::GeneratedParticles g;
  const real pitch = 2 * r, rise = std::sqrt(real(2)) * r;
  for (int k = 0; k < base; ++k)
    for (int i = 0; i < base - k; ++i)
      for (int j = 0; j < base - k; ++j)
        add_sphere(g, {r + (i + k * real(0.5)) * pitch, r + (j + k * real(0.5)) * pitch, r + k * rise}, r);
  return g;
}

// Tetrahedral pile: triangular layers, each nested in the one below.
scene::GeneratedParticles tetrahedron(int base, real r) {
  scene::GeneratedParticles g;
  const real rise = 2 * r * std::sqrt(real(2) / 3), row = std::sqrt(real(3)) * r;
  for (int k = 0; k < base; ++k) {
    const int m = base - k;
    const real ox = k * r, oy = k * r / std::sqrt(real(3));
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m - j; ++i) add_sphere(g, {r + ox + (2 * i + j) * r, r + oy + j * row, r + k * rise}, r);
  }
  return g;
}

// Stands for `seconds` from the moment it is built: no sphere drifts by 1 %
// of a radius.
void expect_free_pile_stands(const scene::GeneratedParticles& g, real r, double dt, int substeps,
                             double seconds = 5.0) {
  scene::Scene s = make_scene(dt, substeps, kGranularRolling, 0.3, 1.0, 0.1);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  Simulation sim(s, make_world(s, g), test_backend());
  const std::vector<Vec3> start = sim.world().position;
  double worst = 0;
  while (sim.time() < seconds - 1e-9) {
    sim.step();
    ASSERT_EQ(sim.world().first_non_finite(), sim.world().size());
    worst = std::max(worst, max_drift(sim.world(), start));
  }
  EXPECT_LT(worst, 0.01 * r);
}

}  // namespace

TEST(FreePile, TwoDimensionalPyramidOfEightStands) {
  expect_free_pile_stands(triangle(8, real(0.02)), real(0.02), 2e-3, 2);
}

TEST(FreePile, TwoDimensionalPyramidStandsAtDemoSettings) {
  expect_free_pile_stands(triangle(5, real(0.02)), real(0.02), 1e-3, 1);
}

TEST(FreePile, SquarePyramidStands) {
  expect_free_pile_stands(square_pyramid(6, real(0.02)), real(0.02), 2e-3, 2);
}

TEST(FreePile, TetrahedralPileStands) {
  expect_free_pile_stands(tetrahedron(6, real(0.02)), real(0.02), 2e-3, 2);
}

// Without rolling resistance the same 2-D pyramid is a mechanism (the edge
// rolls off like a chain of gears, no contact slipping), which Coulomb
// friction does not resist once it moves. Built at rest, it may also stand:
// the contact problem with friction has a static solution too (friction 2
// here), and which one a substep finds is the solver's choice. Left at rest,
// it rolled off within the second with 10 sweeps a substep and stood with
// 9, 12, 20 or 40, so the edge sphere on the floor is nudged outwards (3
// cm/s): it then rolls off with each of 6 to 12, 15, 20 and 40 sweeps tried
// (not with 5). Kept as a record of why the cases above need mu_r.
TEST(FreePile, WithoutRollingResistanceTheEdgeRollsOff) {
  scene::Scene s = make_scene(2e-3, 2, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction}, 0.3, 2.0);
  const real r = real(0.02);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::GeneratedParticles g = triangle(5, r);
  g.velocity[4] = Vec3(real(0.03), 0, 0);  // the bottom row's last sphere, outwards
  Simulation sim(s, make_world(s, g), test_backend());
  const std::vector<Vec3> start = sim.world().position;
  while (sim.time() < 1.0 - 1e-9) sim.step();
  EXPECT_GT(max_drift(sim.world(), start), r);
}
