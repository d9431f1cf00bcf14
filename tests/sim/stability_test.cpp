// The stability suite (ctest label `stability`): hard cases that must stay
// numerically stable. Each runs the real step pipeline, with the CPU broad
// phase or (MARBLES_TEST_BACKEND=cuda) the CUDA one.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <tuple>

#include "sim/watch_math.hpp"
#include "tests/sim/test_scenes.hpp"

using namespace marbles;
using namespace marbles::testing;
using scene::Effect;

namespace {

constexpr std::initializer_list<Effect> kGranular{Effect::gravity, Effect::collisions, Effect::walls,
                                                  Effect::restitution, Effect::friction};

double max_speed(const World& w) { return w.max_speed(); }

// Jitter floor: the kinetic energy of lifting the whole pile by 1e-5 of a
// radius. A pile that stands keeps its jitter below this or below what it had
// early on (no growth).
double jitter_floor(const World& w, double r) {
  double mass = 0;
  for (std::size_t i = 0; i < w.size(); ++i) mass += 1.0 / w.inv_mass[i];
  return 1e-5 * mass * 9.81 * r;
}

double max_drift(const World& a, const std::vector<Vec3>& reference) {
  double d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, double(length(a.position[i] - reference[i])));
  return d;
}

// Square pyramid: layer k has (base - k)^2 spheres on a square grid of pitch
// `pitch`, each layer resting in the hollows of the one below.
scene::GeneratedParticles pyramid(int base, real r, real pitch) {
  scene::GeneratedParticles g;
  const real rise = std::sqrt(std::max(real(0), pitch * pitch - pitch * pitch / 2));
  for (int k = 0; k < base; ++k)
    for (int i = 0; i < base - k; ++i)
      for (int j = 0; j < base - k; ++j)
        add_sphere(g, {r + (i + k * real(0.5)) * pitch, r + (j + k * real(0.5)) * pitch, r + k * rise}, r);
  return g;
}

// Runs `seconds` of simulated time, tracking the largest kinetic energy seen
// in the first and the last quarter.
struct Watch {
  double early_peak = 0, late_peak = 0, peak_speed = 0;
};

Watch run_for(Simulation& sim, double seconds) {
  Watch w;
  const double t0 = sim.time();
  while (sim.time() < t0 + seconds - 1e-9) {
    sim.step();
    const double f = (sim.time() - t0) / seconds;
    const double ke = sim.world().kinetic_energy();
    if (f <= 0.25) w.early_peak = std::max(w.early_peak, ke);
    if (f >= 0.75) w.late_peak = std::max(w.late_peak, ke);
    w.peak_speed = std::max(w.peak_speed, max_speed(sim.world()));
    EXPECT_EQ(sim.world().first_non_finite(), sim.world().size());
    if (sim.world().first_non_finite() != sim.world().size()) break;
  }
  return w;
}

// Settles for 0.5 s, then stands for 10 s: drift below 1 % of a radius and
// no jitter growth.
void expect_stands(Simulation& sim, double r) {
  run_for(sim, 0.5);
  const std::vector<Vec3> settled = sim.world().position;
  const Watch w = run_for(sim, 10.0);
  EXPECT_LT(max_drift(sim.world(), settled), 0.01 * r);
  EXPECT_LE(w.late_peak, std::max(w.early_peak, jitter_floor(sim.world(), r)));
}

// A floor and a vertical tube 2 % wider than spheres of radius r.
void add_tube(scene::Scene& s, real r) {
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::WallSpec tube;
  tube.kind = scene::WallSpec::Kind::cylinder;
  tube.axis = {0, 0, 1};
  tube.radius = 1.02 * r;
  tube.inside = true;
  s.walls.push_back(tube);
}

// Material 1: the first material, 100 times denser.
void add_heavy_material(scene::Scene& s) {
  scene::Material heavy = s.materials[0];
  heavy.name = "heavy";
  heavy.density *= 100;
  s.materials.push_back(heavy);
}

// The box frame that holds the bottom layer of pyramid(base, r, 2 r).
scene::WallSpec frame(int base, real r) {
  return box({0, 0, 0}, {real(2 * r * base), real(2 * r * base), real(4 * r * base)});
}

}  // namespace

// 15 spheres stacked in a tube barely wider than they are.
TEST(Stability, ColumnInTubeStands) {
  scene::Scene s = make_scene(2e-3, 2, kGranular, 0.3, 0.5);
  const real r = real(0.02);
  add_tube(s, r);
  scene::GeneratedParticles g;
  for (int k = 0; k < 15; ++k) add_sphere(g, {0, 0, r + 2 * r * k}, r);
  Simulation sim(s, make_world(s, g), test_backend());
  expect_stands(sim, r);
}

// A 20x20-based square pyramid (2870 spheres), friction 0.5, bottom layer held
// by a close-fitting box frame.
TEST(Stability, PyramidStands) {
  scene::Scene s = make_scene(2e-3, 2, kGranular, 0.3, 0.5);
  const real r = real(0.02);
  const int base = 20;
  s.walls.push_back(frame(base, r));
  Simulation sim(s, make_world(s, pyramid(base, r, 2 * r)), test_backend());
  expect_stands(sim, r);
}

// A sphere 100 times denser than the four it rests on.
TEST(Stability, HeavySphereOnLightOnes) {
  scene::Scene s = make_scene(2e-3, 2, kGranular, 0.3, 0.5);
  add_heavy_material(s);
  const real r = real(0.02);
  s.walls.push_back(box({0, 0, 0}, {4 * r, 4 * r, 10 * r}));
  scene::GeneratedParticles g = pyramid(2, r, 2 * r);
  g.material.back() = 1;
  Simulation sim(s, make_world(s, g), test_backend());
  expect_stands(sim, r);
}

// A pyramid built with 25 % overlaps (pitch 1.5 r instead of 2 r) pushes
// itself apart by position projection alone: no sphere gets faster than a
// free fall from the top of the pile would make it.
TEST(Stability, OverlappingPyramidSeparatesWithoutExploding) {
  scene::Scene s = make_scene(2e-3, 2, kGranular, 0.3, 0.5);
  const real r = real(0.02);
  const int base = 10;
  s.walls.push_back(frame(base, r));
  Simulation sim(s, make_world(s, pyramid(base, r, real(1.5) * r)), test_backend());
  const double height = 2 * r * base;
  const Watch w = run_for(sim, 2.0);
  EXPECT_LT(w.peak_speed, std::sqrt(2 * 9.81 * height));
  // Separated: no overlap deeper than a few per cent of a radius remains.
  double deepest = 0;
  for (std::size_t i = 0; i < sim.world().size(); ++i)
    for (std::size_t j = i + 1; j < sim.world().size(); ++j)
      deepest = std::max(deepest, 2.0 * r - length(sim.world().position[i] - sim.world().position[j]));
  EXPECT_LT(deepest, 0.05 * r);
}

// Warm starting carries last substep's impulses; when the heavy top of a
// stack disappears those impulses must not launch the spheres below.
TEST(Stability, RemovingTheHeavyTopDoesNotLaunchTheStack) {
  scene::Scene s = make_scene(2e-3, 2, kGranular, 0.3, 0.5);
  add_heavy_material(s);
  const real r = real(0.02);
  add_tube(s, r);
  scene::GeneratedParticles g;
  for (int k = 0; k < 6; ++k) add_sphere(g, {0, 0, r + 2 * r * k}, r, {}, k == 5 ? 1 : 0);
  Simulation sim(s, make_world(s, g), test_backend());
  run_for(sim, 1.0);
  const std::vector<Vec3> settled = sim.world().position;
  sim.edit_world().position[5] = {10, 10, 10};  // lift the top away
  sim.edit_world().velocity[5] = {};
  double highest_rise = 0;
  for (int k = 0; k < 500; ++k) {
    sim.step();
    for (int i = 0; i < 5; ++i) {
      highest_rise = std::max(highest_rise, double(sim.world().position[i].z - settled[i].z));
      EXPECT_LT(sim.world().velocity[i].z, 0.01) << "sphere " << i << " jumped at step " << k;
    }
  }
  // Relieved of the load the stack may expand by its compression, no more.
  EXPECT_LT(highest_rise, 0.02 * r);
}

// 10,000 spheres poured into a box come to rest, and none leaves it.
TEST(Stability, TenThousandSpheresSettleInABox) {
  scene::Scene s = make_scene(2e-3, 2, kGranular, 0.3, 0.5);
  const real r = real(0.01);
  const real side = 0.6;
  s.walls.push_back(box({0, 0, 0}, {side, side, 2}));
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> jitter(-0.2 * r, 0.2 * r), vel(-0.5, 0.5);
  scene::GeneratedParticles g;
  const int per_row = static_cast<int>(side / (2.5 * r));
  for (int i = 0; i < 10000; ++i) {
    const int x = i % per_row, y = (i / per_row) % per_row, z = i / (per_row * per_row);
    add_sphere(g, {real(1.25 * r + 2.5 * r * x + jitter(rng)), real(1.25 * r + 2.5 * r * y + jitter(rng)),
                   real(1.25 * r + 2.5 * r * z + jitter(rng))}, r, {real(vel(rng)), real(vel(rng)), real(vel(rng))});
  }
  Simulation sim(s, make_world(s, g), test_backend());
  double peak = 0, last = 0;
  while (sim.time() < 4.0) {
    sim.step();
    last = sim.world().kinetic_energy();
    peak = std::max(peak, last);
  }
  EXPECT_LT(last, 1e-6 * peak);
  for (std::size_t i = 0; i < sim.world().size(); ++i) {
    const Vec3 p = sim.world().position[i];
    ASSERT_TRUE(p.x > 0 && p.x < side && p.y > 0 && p.y < side && p.z > 0 && p.z < 2) << "sphere " << i << " left";
  }
}

// A 5 cm sphere at 100 m/s with dt = 1/60 s travels 33 radii per step: it
// must stop at a wall (here the face of a 1 cm thick wall) and at another
// sphere, never pass through.
TEST(Stability, FastSphereDoesNotTunnelThroughAWall) {
  scene::Scene s = make_scene(1.0 / 60, 1, {Effect::walls, Effect::restitution}, 0.5);
  const real r = real(0.05);
  s.walls.push_back(plane({2, 0, 0}, {-1, 0, 0}));  // wall face at x = 2, 1 cm thick behind it
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, 0}, r, {100, 0, 0});
  Simulation sim(s, make_world(s, g), test_backend());
  for (int k = 0; k < 120; ++k) {
    sim.step();
    ASSERT_LT(sim.world().position[0].x + r, 2 + 0.01) << "crossed the wall at step " << k;
  }
  EXPECT_LT(sim.world().velocity[0].x, 0);  // bounced back
}

TEST(Stability, FastSphereDoesNotPassThroughAnother) {
  for (double speed : {10.0, 100.0, 1000.0}) {
    scene::Scene s = make_scene(1.0 / 60, 1, {Effect::collisions, Effect::restitution}, 0.5);
    const real r = real(0.05);
    scene::GeneratedParticles g;
    add_sphere(g, {0, 0, 0}, r, {real(speed), 0, 0});
    add_sphere(g, {3, real(0.02), 0}, r);  // slightly off-centre
    Simulation sim(s, make_world(s, g), test_backend());
    for (int k = 0; k < 60; ++k) {
      sim.step();
      ASSERT_LT(sim.world().position[0].x, sim.world().position[1].x) << "passed through at speed " << speed;
    }
  }
}

// Degenerate inputs: coincident centres, zero relative velocity, a centre
// exactly on a wall, a sphere on a tube's axis. No NaN, and they come apart.
TEST(Stability, DegenerateContactsStayFinite) {
  scene::Scene s = make_scene(1e-3, 1, kGranular, 0.5, 0.5);
  const real r = real(0.05);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::WallSpec post;
  post.kind = scene::WallSpec::Kind::cylinder;
  post.base = {1, 1, 0};
  post.axis = {0, 0, 1};
  post.radius = 0.01;
  post.inside = false;
  s.walls.push_back(post);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, 1}, r);
  add_sphere(g, {0, 0, 1}, r);          // coincident, same velocity
  add_sphere(g, {real(0.5), 0, 0}, r);  // centre exactly on the floor
  add_sphere(g, {1, 1, real(0.5)}, r);  // centre on the post's axis
  Simulation sim(s, make_world(s, g), test_backend());
  for (int k = 0; k < 2000; ++k) {
    sim.step();
    ASSERT_EQ(sim.world().first_non_finite(), sim.world().size()) << "step " << k;
  }
  EXPECT_GT(length(sim.world().position[0] - sim.world().position[1]), 1.9 * r);
  EXPECT_GT(sim.world().position[2].z, 0.95 * r);
  const Vec3 d = sim.world().position[3] - Vec3(1, 1, 0);
  EXPECT_GT(std::hypot(d.x, d.y), 0.01 + 0.95 * r);
}

// 10^5 steps of an elastic, frictionless gas in a box: energy drifts by less
// than 1.5e-4 of itself.
TEST(Stability, ElasticGasConservesEnergy) {
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::walls, Effect::restitution}, 1.0);
  const real r = real(0.02);
  s.walls.push_back(box({0, 0, 0}, {real(0.4), real(0.4), real(0.4)}));
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> vel(-1, 1);
  scene::GeneratedParticles g;
  for (int x = 0; x < 4; ++x)
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z)
        add_sphere(g, {real(0.05 + 0.1 * x), real(0.05 + 0.1 * y), real(0.05 + 0.1 * z)}, r,
                   {real(vel(rng)), real(vel(rng)), real(vel(rng))});
  Simulation sim(s, make_world(s, g), test_backend());
  const double e0 = sim.world().kinetic_energy();
  std::uint64_t contacts = 0;
  for (int k = 0; k < 100000; ++k) {
    sim.step();
    contacts += sim.last_step().contacts;
  }
  EXPECT_GT(contacts, 10000u);
  // Float's rounding gains about 1e-6 of the energy a simulated second here
  // (9.4e-5 over these 100 s with each impact along the line of centres at
  // the substep's start, 1.09e-4 along the line at the moment of touch: the
  // gas of 64 spheres run alike in double gains 1.0e-13 and 1.1e-13).
  EXPECT_NEAR(sim.world().kinetic_energy(), e0, 1.5e-4 * e0);
}

// --- Motion the substep did not sweep (sim/watch_math.hpp) -----------------

namespace {

// struck_row_scene, with the wall where it puts it.
struct StruckRow {
  scene::Scene scene;
  scene::GeneratedParticles spheres;
  real wall = 0, r = 0;  // the wall's face (x) and the spheres' radius, as the scene has them
  StruckRow() {
    std::tie(scene, spheres) = struck_row_scene();
    wall = scene.walls[0].point.x;
    r = spheres.radius[0];
  }
  // The deepest any sphere went into the wall or into another (of a radius)
  // at the end of any of `steps` steps.
  double deepest(Simulation& sim, int steps) const {
    double d = 0;
    for (int k = 0; k < steps; ++k) {
      sim.step();
      const World& w = sim.world();
      for (std::size_t i = 0; i < w.size(); ++i) {
        d = std::max(d, double((w.position[i].x + w.radius[i] - wall) / w.radius[i]));
        for (std::size_t j = i + 1; j < w.size(); ++j)
          d = std::max(d, double((w.radius[i] + w.radius[j] - length(w.position[i] - w.position[j])) / r));
      }
    }
    return d;
  }
};

}  // namespace

TEST(Stability, ASphereStruckIntoAWallWithinASubstepIsSweptAgain) {
  const StruckRow row;
  Simulation unwatched(row.scene, make_world(row.scene, row.spheres), test_backend());
  const double before = row.deepest(unwatched, 20);
  EXPECT_GT(before, 0.05) << "the case this test is about: a sphere ends a substep inside the wall";

  Simulation sim(row.scene, make_world(row.scene, row.spheres), test_backend());
  sim.set_watchdog(true);
  sim.step();
  ASSERT_GE(sim.last_rollbacks().size(), 1u);
  EXPECT_NE(sim.last_rollbacks()[0].find("set moving within a substep"), std::string::npos) << sim.last_rollbacks()[0];
  EXPECT_TRUE(sim.last_kept().empty());
  EXPECT_LT(row.deepest(sim, 19), 0.01);
  EXPECT_EQ(sim.unswept_kept(), 0u);
  EXPECT_NEAR(sim.world().kinetic_energy(), unwatched.world().kinetic_energy(),
              0.05 * unwatched.world().kinetic_energy());
}

// A sphere struck at 100 m/s with dt = 1/60 s leaves 33 radii a step: past
// what even the watchdog's finest substep sweeps. The step is kept, and
// counted, as before the rule; without the watchdog nothing is checked.
TEST(Stability, ASphereUnsweptEvenAtTheFinestSubstepIsKeptAndCounted) {
  auto [s, g] = struck_through_scene();
  Simulation unwatched(s, make_world(s, g), test_backend());
  Simulation sim(s, make_world(s, g), test_backend());
  sim.set_watchdog(true);
  for (int k = 0; k < 3; ++k) {
    unwatched.step();
    sim.step();
    EXPECT_EQ(unwatched.unswept_kept(), 0u);
    if (!sim.last_kept().empty()) {
      EXPECT_NE(sim.last_kept().find("deeper into a sphere or wall than at the substep's start"), std::string::npos)
          << sim.last_kept();
    }
  }
  EXPECT_GT(unwatched.world().position[1].x, unwatched.world().position[2].x)
      << "the case this test is about: the struck sphere passes through the third";
  EXPECT_GE(sim.unswept_kept(), 1u);
  EXPECT_GE(sim.rollbacks(), static_cast<std::uint64_t>(Simulation::kWatchdogRetries));
}

// The rule never ends a run that ran before it: where the first try is
// broken by the unswept rule alone and the finer retries by another rule
// (here a NaN put into every retry, not the first), the first try is done
// again and kept, the state the unwatched step gives.
TEST(Stability, AFirstTryBrokenOnlyUnsweptIsKeptWhereTheRetriesBreakMore) {
  auto [s, g] = struck_through_scene();
  Simulation unwatched(s, make_world(s, g), test_backend());
  Simulation sim(s, make_world(s, g), test_backend());
  sim.set_watchdog(true);
  sim.inject_fault_at(1, false, Simulation::Fault::nan, true);
  unwatched.step();
  ASSERT_NO_THROW(sim.step());
  EXPECT_EQ(sim.unswept_kept(), 1u);
  EXPECT_NE(sim.last_kept().find("the first try kept"), std::string::npos) << sim.last_kept();
  ASSERT_EQ(sim.last_rollbacks().size(), static_cast<std::size_t>(Simulation::kWatchdogRetries + 1));
  EXPECT_NE(sim.last_rollbacks()[0].find("set moving within a substep"), std::string::npos) << sim.last_rollbacks()[0];
  EXPECT_EQ(sim.last_rollbacks()[1].rfind("non-finite state", 0), 0u) << sim.last_rollbacks()[1];
  EXPECT_EQ(state_hash(sim.world()), state_hash(unwatched.world()));
  EXPECT_EQ(sim.world().first_non_finite(), sim.world().size());
}

// Without collisions spheres pass through each other by design: only the
// walls are checked. A floor rising at 5 m/s under two spheres that share a
// place set the lower one moving within the substep, past its reach (0: it
// was at rest), deeper into the other, and no step is split for the pair.
TEST(Stability, SpheresWithoutCollisionsAreCheckedAgainstWallsAlone) {
  scene::Scene s = make_scene(1e-3, 1, {Effect::walls, Effect::restitution}, 1.0);
  scene::WallSpec floor = plane({0, 0, 0}, {0, 0, 1});
  floor.velocity = {0, 0, 5};
  s.walls.push_back(floor);
  const real r = real(0.01);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, real(0.0101)}, r);
  add_sphere(g, {0, real(0.002), real(0.025)}, r);  // above the first, through it, the floor not yet under it
  Simulation sim(s, make_world(s, g), test_backend());
  sim.set_watchdog(true);
  for (int k = 0; k < 5; ++k) sim.step();
  EXPECT_GT(sim.world().velocity[0].z, 1) << "the floor set the spheres moving";
  EXPECT_EQ(sim.rollbacks(), 0u);
  EXPECT_EQ(sim.unswept_kept(), 0u);
}

// Many rows struck at once, each sending its last sphere past its reach:
// 70 rows (more than 64 such spheres, each still checked in a scene this
// small: the step is split for the meeting it finds), and 480 rows (more
// than watch::unswept_checked at 2 400 spheres, 218: the step is split
// unchecked). Either way the split steps sweep them all, and no sphere ends
// a step in the wall.
TEST(Stability, ManySpheresPastTheirReachSplitTheStep) {
  for (const int rows : {70, 480}) {
    auto [s, g] = struck_row_scene(rows);
    const std::uint32_t checked = watch::unswept_checked(g.position.size());
    const bool unchecked = static_cast<std::uint32_t>(rows) > checked;
    ASSERT_EQ(unchecked, rows == 480) << "the case this test is about: " << checked << " checked of " << rows;
    Simulation sim(s, make_world(s, g), test_backend());
    sim.set_watchdog(true);
    sim.step();
    ASSERT_GE(sim.last_rollbacks().size(), 1u) << rows;
    const std::string reason = sim.last_rollbacks()[0];
    const std::string said = unchecked ? "more than " + std::to_string(checked) + " spheres moved past the reach"
                                       : "a sphere set moving within a substep past the reach";
    EXPECT_EQ(reason.rfind(said, 0), 0u) << rows << ": " << reason;
    for (int k = 0; k < 19; ++k) sim.step();
    EXPECT_EQ(sim.unswept_kept(), 0u) << rows;
    const World& w = sim.world();
    for (std::size_t i = 0; i < w.size(); ++i)
      EXPECT_LT(w.position[i].x + w.radius[i], s.walls[0].point.x + real(1e-4)) << rows << " rows, sphere " << i;
  }
}
