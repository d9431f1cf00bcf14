// tests/sim/settings_check_test.cpp — the risky-settings warnings: each rule
// fires on a scene built to trigger it, quoting the number the test works out
// on its own, goes quiet with the setting it suggests, and every shipped scene
// is silent.
#include <gtest/gtest.h>

#include <algorithm>

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "sim/settings_check.hpp"
#include "tests/sim/test_scenes.hpp"

using namespace marbles;
using namespace marbles::testing;
using scene::Effect;

namespace {

constexpr bool kFloat = true, kDouble = false;

// Three significant digits, as the messages write numbers.
std::string sig3(double v) {
  std::ostringstream s;
  s << std::setprecision(3) << v;
  return s.str();
}

double sphere_volume(double r) { return 4.0 / 3.0 * std::numbers::pi * r * r * r; }

// The warnings, each checked to start with one of the rules' openings.
std::vector<std::string> warnings(const scene::Scene& s, const scene::GeneratedParticles& g, bool single) {
  const std::vector<std::string> w = risky_settings(s, g, single);
  for (const std::string& m : w) {
    const bool known = m.rfind("dt so large", 0) == 0 || m.rfind("stack too tall", 0) == 0 ||
                       m.rfind("substeps too coarse", 0) == 0 || m.rfind("float precision", 0) == 0 ||
                       m.rfind("spheres up to", 0) == 0 || m.rfind("radii from", 0) == 0;
    EXPECT_TRUE(known) << m;
  }
  return w;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

}  // namespace

TEST(SettingsCheck, FastMotionCountsTheFallToTheFloor) {
  const double dt = 1e-3, r = 0.004, height = 1.0;
  scene::Scene s = make_scene(dt, 1, {Effect::gravity, Effect::collisions, Effect::walls}, 0.5);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, real(height)}, real(r));

  const std::vector<std::string> w = warnings(s, g, kDouble);
  ASSERT_EQ(w.size(), 1u);
  const double move = std::sqrt(2 * 9.81 * height) * dt;  // the speed at the floor, over one substep
  EXPECT_TRUE(contains(w[0], "dt so large that the fastest sphere moves " + sig3(move) + " m (" + sig3(move / r) +
                                 " radii) per substep"))
      << w[0];
  const int substeps = static_cast<int>(std::ceil(move / r));
  EXPECT_TRUE(contains(w[0], "raise time.substeps to at least " + std::to_string(substeps))) << w[0];

  s.time.substeps = substeps;
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.time.substeps = 1;
  s.effects = {Effect::gravity, Effect::collisions};  // no wall contacts: no floor to fall to
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
}

TEST(SettingsCheck, FastMotionFromTheInitialSpeed) {
  const double dt = 0.01, r = 0.01;
  const scene::Scene s = make_scene(dt, 1, {Effect::collisions}, 1.0);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, 0}, real(r), {3, 0, 4});
  add_sphere(g, {1, 0, 0}, real(r), {0, 1, 0});

  const std::vector<std::string> w = warnings(s, g, kDouble);
  ASSERT_EQ(w.size(), 1u);
  const double move = std::hypot(3.0, 4.0) * dt;
  EXPECT_TRUE(contains(w[0], "moves " + sig3(move) + " m (" + sig3(move / r) + " radii) per substep")) << w[0];
}

// Spheres at rest, a wall driven at 30 m/s: a struck sphere can leave at
// twice that, which the rule counts (a piston at 50 m/s, dt = 1 ms, 1 cm
// spheres, once let spheres pass through each other with no warning). A
// spinning drum counts its surface speed.
TEST(SettingsCheck, FastMotionFromAMovingWall) {
  const double dt = 1e-3, r = 0.01, speed = 30;
  scene::Scene s = make_scene(dt, 1, {Effect::collisions, Effect::walls}, 0.5);
  scene::WallSpec piston = plane({-0.05, 0, 0}, {1, 0, 0});
  piston.velocity = {real(speed), 0, 0};
  s.walls.push_back(piston);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, 0}, real(r));
  add_sphere(g, {0.06, 0, 0}, real(r));

  const std::vector<std::string> w = warnings(s, g, kDouble);
  ASSERT_EQ(w.size(), 1u);
  const double move = 2 * speed * dt, stored_r = g.radius[0];  // the radius as the spheres hold it
  EXPECT_TRUE(contains(w[0], "moves " + sig3(move) + " m (" + sig3(move / stored_r) + " radii) per substep: up to " +
                                 sig3(2 * speed) + " m/s (" + sig3(2 * speed) + " m/s from a moving wall"))
      << w[0];
  s.time.substeps = static_cast<int>(std::ceil(move / stored_r));
  EXPECT_TRUE(contains(w[0], "raise time.substeps to at least " + std::to_string(s.time.substeps))) << w[0];
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.time.substeps = 1;
  s.effects = {Effect::collisions};  // without the walls effect the wall moves nothing
  EXPECT_TRUE(warnings(s, g, kDouble).empty());

  // A drum of radius 0.5 m spinning at 100 rad/s: 50 m/s at its surface.
  s.effects = {Effect::collisions, Effect::walls};
  s.walls[0] = {};
  s.walls[0].kind = scene::WallSpec::Kind::cylinder;
  s.walls[0].radius = 0.5;
  s.walls[0].angular_velocity = -100;
  const std::vector<std::string> drum = warnings(s, g, kDouble);
  ASSERT_EQ(drum.size(), 1u);
  EXPECT_TRUE(contains(drum[0], "up to " + sig3(50.0) + " m/s (" + sig3(50.0) + " m/s from a moving wall")) << drum[0];
  s.walls[0].angular_velocity = 0;
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
}

// A sphere 50 times heavier than another (denser, and larger): at dt = 1 ms
// the rule fires past h x ratio = 30 ms and asks for 12 ms, so 5 substeps; a
// fixed heavy sphere is a wall and counts for nothing, nor does any ratio
// without collisions.
TEST(SettingsCheck, MassRatioWantsSubsteps) {
  const double dt = 1e-3, r = 0.01, density_ratio = 6.25, size = 2;  // 6.25 x 2^3 = 50
  scene::Scene s = make_scene(dt, 1, {Effect::collisions}, 0.5);
  s.materials.push_back(s.materials[0]);
  s.materials[1].name = "heavy";
  s.materials[1].density *= density_ratio;
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, 0}, real(r));
  add_sphere(g, {1, 0, 0}, real(size * r), {}, 1);
  add_sphere(g, {2, 0, 0}, real(r));

  const std::vector<std::string> w = warnings(s, g, kDouble);
  ASSERT_EQ(w.size(), 1u);
  const double ratio = density_ratio * size * size * size;
  EXPECT_TRUE(contains(w[0], "spheres up to " + sig3(ratio) + " times heavier than the lightest")) << w[0];
  s.time.substeps = static_cast<int>(std::ceil(dt * ratio / 12e-3));
  EXPECT_TRUE(contains(w[0], "raise time.substeps to at least " + std::to_string(s.time.substeps))) << w[0];
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.time.substeps = 1;

  g.fixed = {0, 1, 0};  // the heavy one fixed
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  g.fixed = {0, 0, 0};
  s.materials[1].density = s.materials[0].density * 32 / (size * size * size);  // 32: h x ratio = 32 ms
  ASSERT_EQ(warnings(s, g, kDouble).size(), 1u);
  s.materials[1].density = s.materials[0].density * 28 / (size * size * size);  // 28: 28 ms, within the rule
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.materials[1].density = s.materials[0].density * density_ratio;
  s.effects = {Effect::walls};
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  // Spheres of one mass (or one sphere) at a substep of 40 ms: no ratio to
  // speak of (the coarse-substep rule needs gravity, the fast-motion rule speed).
  s.effects = {Effect::collisions};
  s.time.dt = 0.04;
  s.materials[1].density = s.materials[0].density / (size * size * size);
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.materials[1].density = s.materials[0].density * 9 / (size * size * size);  // 9: below 10
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.materials[1].density = s.materials[0].density * 10 / (size * size * size);
  EXPECT_EQ(warnings(s, g, kDouble).size(), 1u);
}

// 1000 small spheres and one 4 times their radius: a cell of the larger's
// size holds about 1.15 x 4^3 = 73 of the small ones, past 64; at 3.5 times
// (49) the rule is quiet, as it is with fewer than 1000 spheres or without
// collisions (no broad phase).
TEST(SettingsCheck, RadiusSpreadCrowdsTheCells) {
  const double r = 0.01;
  scene::Scene s = make_scene(1e-4, 1, {Effect::collisions}, 0.5);  // a substep the mass ratio (64) allows
  scene::GeneratedParticles g;
  for (int k = 0; k < 999; ++k) add_sphere(g, {real(3 * r * (k % 10)), real(3 * r * (k / 10 % 10)), real(3 * r * (k / 100))}, real(r));
  add_sphere(g, {0, 0, 1}, real(4 * r));
  const std::vector<std::string> w = warnings(s, g, kDouble);
  ASSERT_EQ(w.size(), 1u);
  const double crowd = 0.6 * 6 / 3.141592653589793 * 64;
  EXPECT_TRUE(contains(w[0], "radii from " + sig3(g.radius[0]) + " to " + sig3(g.radius.back()) + " m (")) << w[0];
  EXPECT_TRUE(contains(w[0], "a cell can hold about " + sig3(crowd) + " of the smallest")) << w[0];
  g.radius.back() = real(3.5 * r);
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  g.radius.back() = real(4 * r);
  s.effects = {Effect::walls};
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.effects = {Effect::collisions};
  g.position.pop_back(), g.velocity.pop_back(), g.radius.pop_back(), g.material.pop_back();
  add_sphere(g, {0, 0, 1}, real(4 * r));
  g.position.erase(g.position.begin()), g.velocity.erase(g.velocity.begin()), g.radius.erase(g.radius.begin()),
      g.material.erase(g.material.begin());  // 999 spheres
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
}

TEST(SettingsCheck, TallStackWantsMoreIterations) {
  // A column of 2 x 2 x 50 touching spheres on a floor.
  const double r = 0.01;
  scene::Scene s = make_scene(1e-4, 1, {Effect::gravity, Effect::collisions, Effect::walls}, 0.5);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::GeneratedParticles g;
  for (int k = 0; k < 50; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i)
        add_sphere(g, {real(r * (1 + 2 * i)), real(r * (1 + 2 * j)), real(r * (1 + 2 * k))}, real(r));

  const std::vector<std::string> w = warnings(s, g, kDouble);
  ASSERT_EQ(w.size(), 1u);
  const double spread = 3 * r - r;  // of the centres on x and on y (here also the one-diameter minimum)
  const double layers = double(g.size()) * sphere_volume(r) / 0.6 / (spread * spread) / (2 * r);
  EXPECT_TRUE(contains(w[0], "stack too tall for the solver: about " + sig3(layers) + " layers")) << w[0];
  EXPECT_TRUE(contains(w[0], "more than twice solver.iterations = 10")) << w[0];

  s.solver.iterations = static_cast<int>(std::ceil(layers / 2));
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  s.solver.iterations = 10;
  s.effects = {Effect::gravity, Effect::walls};  // no sphere contacts: no stack
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
}

TEST(SettingsCheck, CoarseSubstepsUnderGravity) {
  const double dt = 0.01, r = 0.05;
  scene::Scene s = make_scene(dt, 1, {Effect::gravity, Effect::walls}, 0.5);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, real(r)}, real(r));  // resting on the floor

  const std::vector<std::string> w = warnings(s, g, kDouble);
  ASSERT_EQ(w.size(), 1u);
  const double sink = 9.81 * dt * dt, slop = 0.005 * r;
  EXPECT_TRUE(contains(w[0], "a resting sphere falls |g| h^2 = " + sig3(sink) + " m per substep")) << w[0];
  EXPECT_TRUE(contains(w[0], "the smallest radius = " + sig3(slop) + " m")) << w[0];

  s.time.substeps = static_cast<int>(std::ceil(std::sqrt(sink / slop)));
  EXPECT_TRUE(contains(w[0], "raise time.substeps to at least " + std::to_string(s.time.substeps))) << w[0];
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
}

TEST(SettingsCheck, FloatPrecisionOnlyInFloat) {
  const double r = 0.001, apart = 200;
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions}, 0.5);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, 0}, real(r));
  add_sphere(g, {real(apart), 0, 0}, real(r));

  const std::vector<std::string> w = warnings(s, g, kFloat);
  ASSERT_EQ(w.size(), 1u);
  const double reach = apart + r, extent = apart + 2 * r;
  EXPECT_TRUE(contains(w[0], "the scene reaches " + sig3(reach) + " m from the origin (it spans " + sig3(extent) +
                                 " m), " + sig3(reach / r) + " times"))
      << w[0];
  EXPECT_TRUE(contains(w[0], "set solver.precision: double (or --precision double), or make the scene smaller")) << w[0];
  EXPECT_TRUE(warnings(s, g, kDouble).empty());

  // Two close spheres far from the origin: rounded as coarsely as a scene that large.
  const double far = 1000;
  g = {};
  add_sphere(g, {real(far), real(-far), 0}, real(r));
  add_sphere(g, {real(far + 4 * r), real(-far), 0}, real(r));
  const std::vector<std::string> distant = warnings(s, g, kFloat);
  ASSERT_EQ(distant.size(), 1u);
  const double span = double(g.position[1].x) - double(g.position[0].x) + 2 * r;  // as the float positions hold it
  EXPECT_TRUE(contains(distant[0], "the scene reaches " + sig3(double(g.position[1].x) + r) +
                                       " m from the origin (it spans " + sig3(span) + " m)"))
      << distant[0];
  EXPECT_TRUE(contains(distant[0], "or move the scene to the origin")) << distant[0];
  EXPECT_TRUE(warnings(s, g, kDouble).empty());

  // Close spheres in a large box: the walls count too.
  g = {};
  add_sphere(g, {0, 0, 0}, real(r));
  add_sphere(g, {real(4 * r), 0, 0}, real(r));
  EXPECT_TRUE(warnings(s, g, kFloat).empty());
  s.walls.push_back(box({-300, -1, -1}, {300, 1, 1}));
  const std::vector<std::string> boxed = warnings(s, g, kFloat);
  ASSERT_EQ(boxed.size(), 1u);
  EXPECT_TRUE(contains(boxed[0], "the scene reaches " + sig3(300.0) + " m from the origin (it spans " + sig3(600.0) +
                                     " m)"))
      << boxed[0];
}

// Under gravity, float positions so coarse that a sphere creeping at 1 % of
// sqrt(|g| r) moves less than half their spacing in a substep (and so not
// at all) are warned of, with the spacing and that speed, though the scene
// is far under 10^5 radii (a sphere rolling at 3 mm/s 10^4 radii out stood
// still); nearer the origin silent, and warned again with more substeps;
// silent in double and without gravity (no speed scale: the 10^5 rule).
TEST(SettingsCheck, FloatPositionsTooCoarseForCreepingMotion) {
  const double r = 0.01, h = 1e-3, out = 100;  // 10^4 radii
  scene::Scene s = make_scene(h, 1, {Effect::gravity, Effect::walls}, 0.5);
  s.walls.push_back(plane({0, 0, real(out - r)}, {0, 0, 1}));
  scene::GeneratedParticles g;
  add_sphere(g, {real(out), real(out), real(out)}, real(r));
  // The oracle: float's spacing at the reach, from nextafter, not ilogb.
  const auto spacing_at = [](double x) {
    const float f = static_cast<float>(x);
    return double(std::nextafter(f, 2 * f)) - double(f);
  };
  const double spacing = spacing_at(double(g.position[0].x) + r), creep = 0.01 * std::sqrt(9.81 * r);
  ASSERT_GT(spacing / (2 * h), creep);
  std::vector<std::string> w = warnings(s, g, kFloat);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_TRUE(contains(w[0], "where float positions are " + sig3(spacing) + " m apart")) << w[0];
  EXPECT_TRUE(contains(w[0], "a sphere slower than " + sig3(spacing / (2 * h)) + " m/s")) << w[0];
  EXPECT_TRUE(contains(w[0], "sqrt(|g| r) = " + sig3(creep / 0.01) + " m/s")) << w[0];
  EXPECT_TRUE(warnings(s, g, kDouble).empty());
  // Eight times nearer the origin the spacing is an eighth: silent; with 8 substeps warned again.
  g = {};
  add_sphere(g, {real(out / 8), real(out / 8), real(out / 8)}, real(r));
  s.walls[0] = plane({0, 0, real(out / 8 - r)}, {0, 0, 1});
  const double near = spacing_at(double(g.position[0].x) + r);
  ASSERT_LT(near / (2 * h), creep);
  EXPECT_TRUE(warnings(s, g, kFloat).empty());
  s.time.substeps = 8;
  ASSERT_GT(near / (2 * h / 8), creep);
  ASSERT_EQ(warnings(s, g, kFloat).size(), 1u);
  EXPECT_TRUE(contains(warnings(s, g, kFloat)[0], "a sphere slower than " + sig3(near / (2 * h / 8)) + " m/s"));
  // Without gravity no speed scale: the 10^5 radii rule alone.
  s.effects.erase(std::remove(s.effects.begin(), s.effects.end(), Effect::gravity), s.effects.end());
  EXPECT_TRUE(warnings(s, g, kFloat).empty());
}

TEST(SettingsCheck, ShippedScenesAreSilent) {
  std::vector<std::string> scenes;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(MARBLES_SOURCE_DIR "/scenes"))
    if (entry.is_regular_file() && entry.path().extension() == ".yaml") scenes.push_back(entry.path().string());
  ASSERT_FALSE(scenes.empty());
  for (const std::string& path : scenes) {
    SCOPED_TRACE(path);
    const scene::Scene s = scene::load_scene(path);
    const scene::GeneratedParticles g = scene::generate_particles(s);
    EXPECT_TRUE(warnings(s, g, kFloat).empty()) << warnings(s, g, kFloat).front();
    EXPECT_TRUE(warnings(s, g, kDouble).empty());
  }
}
