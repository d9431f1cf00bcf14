// Friction, spin and impacts against rigid-body mechanics (each within 1 %).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <numbers>

#include "tests/sim/test_scenes.hpp"

using namespace marbles;
using namespace marbles::testing;
using scene::Effect;

namespace {

constexpr double kG = 9.81;

// Acceleration along the slope of a sphere released at rest on an incline of
// angle theta with friction mu, measured over 0.5 s.
double incline_acceleration(double theta, double mu) {
  scene::Scene s = make_scene(1e-3, 4, {Effect::gravity, Effect::walls, Effect::friction}, 0.0, mu);
  s.gravity = {0, 0, real(-kG)};
  const Vec3 n(real(-std::sin(theta)), 0, real(std::cos(theta)));
  s.walls.push_back(plane({0, 0, 0}, n));
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, n * r, r);
  Simulation sim(s, make_world(s, g), test_backend());
  const Vec3 downslope(real(-std::cos(theta)), 0, real(-std::sin(theta)));
  for (int k = 0; k < 100; ++k) sim.step();  // settle into contact
  const double v0 = dot(sim.world().velocity[0], downslope);
  const double t0 = sim.time();
  for (int k = 0; k < 500; ++k) sim.step();
  return (dot(sim.world().velocity[0], downslope) - v0) / (sim.time() - t0);
}

}  // namespace

class Incline : public ::testing::TestWithParam<std::tuple<double, double>> {};

TEST_P(Incline, RollsOrSlidesAsMechanicsSays) {
  const auto [theta_deg, mu] = GetParam();
  const double theta = theta_deg * std::numbers::pi / 180;
  const bool rolls = std::tan(theta) <= 3.5 * mu;
  const double expected = rolls ? 5.0 / 7.0 * kG * std::sin(theta) : kG * (std::sin(theta) - mu * std::cos(theta));
  EXPECT_NEAR(incline_acceleration(theta, mu), expected, 0.01 * expected)
      << (rolls ? "rolling" : "sliding") << " theta=" << theta_deg << " mu=" << mu;
}

INSTANTIATE_TEST_SUITE_P(RollingAndSliding, Incline,
                         ::testing::Values(std::tuple{10.0, 0.3}, std::tuple{30.0, 0.3}, std::tuple{45.0, 0.5},
                                           std::tuple{40.0, 0.2}, std::tuple{60.0, 0.3}, std::tuple{30.0, 0.1}));

// Launched sliding without spin: friction slows it to 5/7 v0, rolling from
// t = 2 v0 / (7 mu g) on.
TEST(SlideToRoll, EndsRollingAtFiveSevenths) {
  const double v0 = 2.0, mu = 0.3;
  scene::Scene s = make_scene(1e-3, 4, {Effect::gravity, Effect::walls, Effect::friction}, 0.0, mu);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, r}, r, {real(v0), 0, 0});
  Simulation sim(s, make_world(s, g), test_backend());
  const double t_roll = 2 * v0 / (7 * mu * kG);
  double t_measured = -1;
  while (sim.time() < 2 * t_roll) {
    sim.step();
    const double slip = sim.world().velocity[0].x - sim.world().angular_velocity[0].y * r;
    if (t_measured < 0 && std::abs(slip) < 1e-3 * v0) t_measured = sim.time();
  }
  EXPECT_NEAR(sim.world().velocity[0].x, 5.0 / 7.0 * v0, 0.01 * 5.0 / 7.0 * v0);
  EXPECT_NEAR(sim.world().angular_velocity[0].y * r, 5.0 / 7.0 * v0, 0.01 * 5.0 / 7.0 * v0);
  EXPECT_NEAR(t_measured, t_roll, 0.01 * t_roll);
}

// Oblique impact of a sphere without spin on a wall (no gravity). Impact
// theory: v_n' = -e v_n; the contact point sticks if (2/7)|v_t| <= mu (1+e)|v_n|
// (then v_t' = 5/7 v_t), else it slides with v_t' = v_t - mu (1+e)|v_n|.
class ObliqueImpact : public ::testing::TestWithParam<std::tuple<double, double, double>> {};

TEST_P(ObliqueImpact, FollowsRigidBodyImpactTheory) {
  const auto [e, mu, angle_deg] = GetParam();
  const double speed = 3.0, angle = angle_deg * std::numbers::pi / 180;
  const double vt = speed * std::sin(angle), vn = -speed * std::cos(angle);
  scene::Scene s = make_scene(1e-3, 1, {Effect::walls, Effect::friction, Effect::restitution}, e, mu);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, real(r + 0.1)}, r, {real(vt), 0, real(vn)});
  Simulation sim(s, make_world(s, g), test_backend());
  while (sim.world().velocity[0].z < 0 && sim.time() < 1) sim.step();
  for (int k = 0; k < 5; ++k) sim.step();  // clear of the wall
  const bool sticks = 2.0 / 7.0 * std::abs(vt) <= mu * (1 + e) * std::abs(vn);
  const double vt_expected = sticks ? 5.0 / 7.0 * vt : vt - mu * (1 + e) * std::abs(vn);
  const double spin_expected = (vt - vt_expected) * 5.0 / (2.0 * r);  // I w = r m (vt - vt')
  EXPECT_NEAR(sim.world().velocity[0].z, -e * vn, 0.01 * std::abs(e * vn) + 1e-9);
  EXPECT_NEAR(sim.world().velocity[0].x, vt_expected, 0.01 * std::abs(vt_expected));
  EXPECT_NEAR(sim.world().angular_velocity[0].y, spin_expected, 0.01 * std::abs(spin_expected));
}

INSTANTIATE_TEST_SUITE_P(StickingAndSliding, ObliqueImpact,
                         ::testing::Values(std::tuple{0.8, 0.5, 30.0}, std::tuple{0.5, 0.4, 20.0},
                                           std::tuple{0.8, 0.1, 45.0}, std::tuple{0.5, 0.05, 60.0},
                                           std::tuple{1.0, 0.2, 50.0}));

// Two equal spheres whose contact points move together (w_b = -w_a about z)
// collide head-on: no slip, so friction leaves both spins unchanged.
TEST(HeadOnSpinning, SpinsUnchanged) {
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::friction, Effect::restitution}, 0.7, 0.5);
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {real(-0.1), 0, 0}, r, {1, 0, 0});
  add_sphere(g, {real(0.1), 0, 0}, r, {-1, 0, 0});
  World w = make_world(s, g);
  w.angular_velocity[0] = {0, 0, 20};
  w.angular_velocity[1] = {0, 0, -20};
  Simulation sim(s, std::move(w), test_backend());
  for (int k = 0; k < 200; ++k) sim.step();
  EXPECT_NEAR(sim.world().velocity[0].x, -0.7, 0.007);  // they did collide
  EXPECT_NEAR(sim.world().angular_velocity[0].z, 20, 1e-4);
  EXPECT_NEAR(sim.world().angular_velocity[1].z, -20, 1e-4);
}

// Restitution is an input: an isolated impact rebounds with e whatever the
// step and the size.
class RestitutionInput : public ::testing::TestWithParam<std::tuple<double, double>> {};

TEST_P(RestitutionInput, ReboundSpeedIsEApproachSpeed) {
  const auto [dt, radius] = GetParam();
  const double e = 0.6, v = 2.0;
  scene::Scene s = make_scene(dt, 1, {Effect::collisions, Effect::restitution}, e);
  scene::GeneratedParticles g;
  add_sphere(g, {real(-radius - 0.01), 0, 0}, real(radius), {real(v), 0, 0});
  add_sphere(g, {real(radius + 0.01), 0, 0}, real(radius), {real(-v), 0, 0});
  Simulation sim(s, make_world(s, g), test_backend());
  for (int k = 0; k < 2000 && sim.world().velocity[0].x > 0; ++k) sim.step();
  ASSERT_LT(sim.world().velocity[0].x, 0) << "no impact";
  EXPECT_NEAR(sim.world().velocity[0].x, -e * v, 1e-3 * e * v);
  EXPECT_NEAR(sim.world().velocity[1].x, e * v, 1e-3 * e * v);
}

INSTANTIATE_TEST_SUITE_P(AnyStepAnySize, RestitutionInput,
                         ::testing::Combine(::testing::Values(1e-4, 1e-3, 1.0 / 60),
                                            ::testing::Values(1e-3, 0.05, 2.0)));

// A floor moving at u (a conveyor) under a sphere at rest: in the belt's
// frame the sphere is launched sliding at -u, so it ends rolling with the
// centre at u - 5/7 u = 2/7 u.
TEST(MovingWall, ConveyorCarriesASphereToTwoSevenths) {
  const double u = 1.5, mu = 0.4;
  scene::Scene s = make_scene(1e-3, 4, {Effect::gravity, Effect::walls, Effect::friction}, 0.0, mu);
  scene::WallSpec belt = plane({0, 0, 0}, {0, 0, 1});
  belt.velocity = {real(u), 0, 0};
  s.walls.push_back(belt);
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, r}, r);
  Simulation sim(s, make_world(s, g), test_backend());
  while (sim.time() < 2 * (2 * u / (7 * mu * kG))) sim.step();
  EXPECT_NEAR(sim.world().velocity[0].x, 2.0 / 7.0 * u, 0.01 * 2.0 / 7.0 * u);
  EXPECT_NEAR(sim.world().position[0].z, r, 0.01 * r);  // the belt moves along itself, not up
}

// A drum (horizontal cylinder, inside) spinning at w drags a sphere resting
// on its bottom: the contact point ends moving with the drum surface, so the
// sphere's centre, rolling without slip on the belt-like surface, moves at
// 2/7 of the surface speed w R at first.
TEST(MovingWall, SpinningDrumDragsASphere) {
  const double R = 0.5, w = 2.0, mu = 0.5;
  scene::Scene s = make_scene(1e-3, 4, {Effect::gravity, Effect::walls, Effect::friction}, 0.0, mu);
  scene::WallSpec drum;
  drum.kind = scene::WallSpec::Kind::cylinder;
  drum.base = {0, -1, 0};
  drum.axis = {0, 1, 0};
  drum.radius = R;
  drum.length = 2;
  drum.inside = true;
  drum.angular_velocity = w;  // about +y: the bottom surface moves along -x
  s.walls.push_back(drum);
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, real(-R + r)}, r);
  Simulation sim(s, make_world(s, g), test_backend());
  for (int k = 0; k < 100; ++k) sim.step();
  const double surface_speed = w * R;
  EXPECT_LT(sim.world().velocity[0].x, 0);  // dragged the way the bottom moves
  EXPECT_NEAR(sim.world().velocity[0].x, -2.0 / 7.0 * surface_speed, 0.05 * 2.0 / 7.0 * surface_speed);
  // It stays on the drum's surface.
  const Vec3 p = sim.world().position[0];
  EXPECT_NEAR(std::hypot(p.x, p.z), R - r, 0.01 * r);
}

// Rolling resistance: a ball rolling on a floor with rolling-resistance
// torque mu_r r N decelerates at 5/7 mu_r g (and keeps rolling).
TEST(RollingResistance, RollingBallDeceleratesAtFiveSeventhsMuRG) {
  const double mu_r = 0.05, v0 = 1.0;
  scene::Scene s =
      make_scene(1e-3, 4, {Effect::gravity, Effect::walls, Effect::friction, Effect::rolling_resistance}, 0, 0.5, mu_r);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, r}, r, {real(v0), 0, 0});
  World w = make_world(s, g);
  w.angular_velocity[0] = {0, real(v0 / r), 0};  // already rolling
  Simulation sim(s, std::move(w), test_backend());
  for (int k = 0; k < 50; ++k) sim.step();
  const double v1 = sim.world().velocity[0].x, t1 = sim.time();
  for (int k = 0; k < 500; ++k) sim.step();
  const double a = (sim.world().velocity[0].x - v1) / (sim.time() - t1);
  EXPECT_NEAR(a, -5.0 / 7.0 * mu_r * kG, 0.01 * 5.0 / 7.0 * mu_r * kG);
  EXPECT_NEAR(sim.world().angular_velocity[0].y * r, sim.world().velocity[0].x, 1e-3);  // still rolling
}

// Twisting resistance: a ball spinning about the vertical on a floor slows at
// alpha = mu_t r m g / (2/5 m r^2) = 5/2 mu_t g / r, then stops (no reversal).
TEST(TwistingResistance, SpinDeceleratesAndStops) {
  const double mu_t = 0.02, w0 = 30.0;
  scene::Scene s = make_scene(1e-3, 4, {Effect::gravity, Effect::walls, Effect::friction, Effect::rolling_resistance},
                              0, 0.5, 0, mu_t);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {0, 0, r}, r);
  World w = make_world(s, g);
  w.angular_velocity[0] = {0, 0, real(w0)};
  Simulation sim(s, std::move(w), test_backend());
  for (int k = 0; k < 20; ++k) sim.step();
  const double w1 = sim.world().angular_velocity[0].z, t1 = sim.time();
  for (int k = 0; k < 200; ++k) sim.step();
  const double alpha = (w1 - sim.world().angular_velocity[0].z) / (sim.time() - t1);
  EXPECT_NEAR(alpha, 2.5 * mu_t * kG / r, 0.01 * 2.5 * mu_t * kG / r);
  for (int k = 0; k < 5000; ++k) sim.step();
  EXPECT_NEAR(sim.world().angular_velocity[0].z, 0, 1e-3);
}

// Newton's cradle: five touching elastic balls in a row, the first arriving
// at v0. The impacts pass the momentum down the chain as binary collisions,
// so the last ball leaves with (nearly) all the energy and the others stop.
TEST(Impacts, NewtonsCradlePassesTheEnergyToTheLastBall) {
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::restitution}, 1.0);
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {real(-0.2), 0, 0}, r, {1, 0, 0});
  for (int k = 1; k < 5; ++k) add_sphere(g, {real(2 * r * (k - 1)), 0, 0}, r);
  Simulation sim(s, make_world(s, g), test_backend());
  const double e0 = sim.world().kinetic_energy();
  for (int k = 0; k < 400; ++k) sim.step();
  const World& w = sim.world();
  const double last = 0.5 * length_squared(w.velocity[4]) / w.inv_mass[4];
  EXPECT_GE(last, 0.95 * e0) << "last ball's share of the energy";
  EXPECT_NEAR(w.kinetic_energy(), e0, 1e-3 * e0);
  EXPECT_GT(w.velocity[4].x, 0.95);
}

// A row of touching elastic balls against a wall, struck at 5 m/s: the
// wave runs to the wall and back, about one ball an impact pass, so a row
// of N keeps its energy with 2 N passes (solver.impact_passes; the default
// 16 holds rows of 8) and gives most of it to the velocity solve, which is
// plastic, with fewer. Momentum into the wall is the wall's, energy never
// grows.
TEST(Impacts, ARowAgainstAWallKeepsItsEnergyWithEnoughPasses) {
  const auto run = [](int n, int passes) {
    scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::walls, Effect::restitution}, 1.0);
    if (passes > 0) s.solver.impact_passes = passes;
    const real r = real(0.01);
    s.walls.push_back(plane({real(2 * r * (n - 1) + r), 0, 0}, {-1, 0, 0}));
    scene::GeneratedParticles g;
    add_sphere(g, {real(-0.03), 0, 0}, r, {5, 0, 0});
    for (int k = 0; k < n; ++k) add_sphere(g, {real(2 * r * k), 0, 0}, r);
    Simulation sim(s, make_world(s, g), test_backend());
    const double e0 = sim.world().kinetic_energy();
    for (int k = 0; k < 100; ++k) {
      sim.step();
      EXPECT_LE(sim.world().kinetic_energy(), e0 * (1 + 1e-5)) << "row of " << n << ", step " << k;
    }
    EXPECT_LT(sim.world().velocity[0].x, 0) << "the striker goes back, row of " << n;
    return sim.world().kinetic_energy() / e0;
  };
  for (const int n : {4, 8}) EXPECT_NEAR(run(n, 0), 1.0, 1e-3) << "row of " << n << ", the default passes";
  EXPECT_NEAR(run(16, 32), 1.0, 1e-3) << "row of 16, 32 passes";
  EXPECT_LT(run(8, 4), 0.5) << "row of 8, 4 passes: the wave cannot come back";
}

// A column of touching balls dropped on a floor, e = 1: the floor's impact
// runs up the column as a chain of binary impacts within one substep, every
// one of them at the time the bottom ball touches. Under velocity Verlet
// free flight and a floor's impact are exact, so the column bounces as one
// body and keeps its energy, bounce after bounce, whatever its length, the
// drop, the radii and the step. Its oracle is the energy it started with
// (kinetic and potential). The chain's later impacts used to act from the
// substep's start (their gaps there are zero): the upper balls rose by up to
// twice their speed times the time of impact, 0.5 % of the energy a bounce
// for three balls at dt 1 ms.
TEST(Impacts, AColumnBouncingOnAFloorKeepsItsEnergy) {
  std::mt19937 rng(20261202);
  std::uniform_real_distribution<double> u(0, 1);
  const double g = 9.81;
  for (int trial = 0; trial < 6; ++trial) {
    const int n = 2 + trial % 4;
    const double dt = std::array{5e-4, 1e-3, 2e-3}[trial % 3];
    const double r = 0.02 + 0.04 * u(rng), drop = 0.1 + 0.3 * u(rng);
    scene::Scene s = make_scene(dt, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution}, 1.0);
    s.solver.integrator = "velocity_verlet";
    s.gravity = {0, 0, real(-g)};
    s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
    scene::GeneratedParticles p;
    for (int k = 0; k < n; ++k) add_sphere(p, {0, 0, real(r + drop + 2 * r * k)}, real(r));
    Simulation sim(s, make_world(s, p), test_backend());
    const auto energy = [&] {
      const World& w = sim.world();
      double e = w.kinetic_energy();
      for (std::size_t i = 0; i < w.size(); ++i) e += g * w.position[i].z / w.inv_mass[i];
      return e;
    };
    const double e0 = energy();
    const double fall = std::sqrt(2 * drop / g);  // a bounce every 2 fall
    const int steps = static_cast<int>(std::lround(6 * fall / dt));  // three bounces, to the third apex
    int bounces = 0;
    bool rising = false;
    for (int k = 0; k < steps; ++k) {
      sim.step();
      const bool up = sim.world().velocity[0].z > 0;
      bounces += up && !rising ? 1 : 0;
      rising = up;
      ASSERT_NEAR(energy() / e0, 1.0, 2e-5) << n << " balls, dt " << dt << ", r " << r << ", drop " << drop
                                            << ", step " << k << ", bounce " << bounces;
    }
    EXPECT_EQ(bounces, 3) << n << " balls, dt " << dt;  // the column came down and went up again each time
  }
}

// Velocity Verlet ends each substep with its second half kick, (h/2) g; its
// closing solve then takes that kick out of every resting contact, as the
// contacts' impulses would over the next half substep. A ball resting on a
// floor, a ball resting on top of a fixed sphere (which no kick moves) and a
// lattice resting in a box (friction, spheres and walls, dt from 0.5 to 4
// ms) must end their steps at rest: their largest speed a hundredth of the
// kick at most. Without the closing solve each ends every step at g h / 2
// downward. The contacts a step reports carry the whole weight (both
// solves' impulses: the closing solve's alone carry about half of it).
TEST(Verlet, RestingSpheresEndTheirStepsAtRest) {
  const double g = 9.81;
  enum class Setup { floor, fixed_sphere, lattice };
  for (const double dt : {5e-4, 1e-3, 2e-3, 4e-3}) {
    for (const Setup setup : {Setup::floor, Setup::fixed_sphere, Setup::lattice}) {
      const char* name = setup == Setup::floor          ? "ball on a floor"
                         : setup == Setup::fixed_sphere ? "ball on a fixed sphere"
                                                        : "lattice";
      scene::Scene s = make_scene(dt, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::friction,
                                          Effect::restitution},
                                  0.5, 0.5);
      s.solver.integrator = "velocity_verlet";
      s.gravity = {0, 0, real(-g)};
      const real r = real(0.01);
      scene::GeneratedParticles p;
      if (setup == Setup::lattice) {
        const int side = 4, layers = 5;
        s.walls.push_back(box({0, 0, 0}, {real(2 * r * side), real(2 * r * side), real(1)}));
        for (int z = 0; z < layers; ++z)
          for (int y = 0; y < side; ++y)
            for (int x = 0; x < side; ++x) add_sphere(p, {r * (2 * x + 1), r * (2 * y + 1), r * (2 * z + 1)}, r);
      } else if (setup == Setup::fixed_sphere) {
        s.walls.push_back(plane({0, 0, -1}, {0, 0, 1}));  // far below: no contact
        add_sphere(p, {0, 0, 0}, 2 * r);
        add_sphere(p, {0, 0, 3 * r}, r);
        p.fixed = {1, 0};
      } else {
        s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
        add_sphere(p, {0, 0, r}, r);
      }
      Simulation sim(s, make_world(s, p), test_backend());
      const int steps = static_cast<int>(std::lround(0.5 / dt));
      for (int k = 0; k < steps; ++k) sim.step();  // settled
      double fastest = 0;
      for (int k = 0; k < steps; ++k) {
        sim.step();
        for (const Vec3& v : sim.world().velocity) fastest = std::max(fastest, double(length(v)));
      }
      const double kick = g * dt / 2;
      EXPECT_LT(fastest, 1e-2 * kick) << name << ", dt " << dt << ": " << fastest << " m/s against the kick's "
                                      << kick;
      // What carries the movable spheres: the walls, and the fixed sphere.
      const World& w = sim.world();
      double weight = 0, carried = 0;
      for (std::size_t i = 0; i < w.size(); ++i)
        if (w.inv_mass[i] > 0) weight += g / w.inv_mass[i];
      for (const narrowphase::Contact& c : sim.contacts()) {
        const Vec3 impulse = c.normal * (c.normal_impulse + c.impact_impulse) + c.tangent_impulse;
        if (narrowphase::is_wall(c.b) || w.inv_mass[c.b] == 0) carried += impulse.z / dt;  // on a
        else if (w.inv_mass[c.a] == 0) carried -= impulse.z / dt;                            // on b
      }
      EXPECT_NEAR(carried / weight, 1.0, 1e-3) << name << ", dt " << dt;
    }
  }
}

// Gravity and drag against the closed forms, through the step. Linear drag,
// dv/dt = g - k v, a sphere launched sideways at v0:
//   v(t) = v0 e^{-kt} + (g / k)(1 - e^{-kt}),  x(t) = v0 (1 - e^{-kt}) / k + (g / k)(t - (1 - e^{-kt}) / k).
// Quadratic drag, dv/dt = g - k2 |v| v, falling from rest with c = sqrt(g / k2):
//   v(t) = -c tanh(t sqrt(g k2)),  z(t) = -(c / sqrt(g k2)) ln cosh(t sqrt(g k2)).
// Velocity Verlet's two half kicks are the trapezoidal rule: its errors fall
// four times when h halves; symplectic Euler's twice. Both keep the terminal
// speed exactly, linear drag's g / k also where drag is stiff for the step
// (h k = 20), and quadratic drag's c (each ends on drag_kick, implicit in the
// new speed).
TEST(Drag, VelocityVerletIsSecondOrderWithDrag) {
  const double k = 2.0, k2 = 0.5, t_end = 0.5, v0 = 3.0, g = 9.81;
  const auto run = [&](const std::string& integrator, double dt, double linear, double quadratic, double vx0,
                       double duration) {
    scene::Scene s = make_scene(dt, 1, {Effect::gravity, Effect::drag}, 0.0);
    s.gravity = {0, 0, real(-g)};
    s.drag = linear;
    s.drag_quadratic = quadratic;
    s.solver.integrator = integrator;
    scene::GeneratedParticles p;
    add_sphere(p, {0, 0, 0}, real(0.05), {real(vx0), 0, 0});
    Simulation sim(s, make_world(s, p), test_backend());
    for (int n = 0; n < static_cast<int>(std::lround(duration / dt)); ++n) sim.step();
    return std::pair{sim.world().position[0], sim.world().velocity[0]};
  };
  const double decay = std::exp(-k * t_end);
  const double vx = v0 * decay, vz = -(g / k) * (1 - decay);
  const double x = v0 * (1 - decay) / k, z = -(g / k) * (t_end - (1 - decay) / k);
  const double c = std::sqrt(g / k2), rate = std::sqrt(g * k2);
  const double quadratic_vz = -c * std::tanh(rate * t_end);
  const double quadratic_z = -(c / rate) * std::log(std::cosh(rate * t_end));
  for (const std::string integrator : {"velocity_verlet", "symplectic_euler"}) {
    std::vector<double> linear_errors, quadratic_errors;
    for (double dt : {0.04, 0.02, 0.01}) {
      const auto [pos, vel] = run(integrator, dt, k, 0, v0, t_end);
      linear_errors.push_back(std::abs(vel.x - vx) + std::abs(vel.z - vz) + std::abs(pos.x - x) +
                              std::abs(pos.z - z));
      const auto [qpos, qvel] = run(integrator, dt, 0, k2, 0, t_end);
      quadratic_errors.push_back(std::abs(qvel.z - quadratic_vz) + std::abs(qpos.z - quadratic_z));
    }
    for (const std::vector<double>& errors : {linear_errors, quadratic_errors}) {
      const double order = std::log2(errors[1] / errors[2]);
      if (integrator == "velocity_verlet") {
        EXPECT_GT(std::log2(errors[0] / errors[1]), 1.8) << errors[0] << " " << errors[1];
        EXPECT_GT(order, 1.8) << errors[1] << " " << errors[2];
      } else {
        EXPECT_NEAR(order, 1.0, 0.2) << errors[1] << " " << errors[2];
      }
    }
    const auto [far, terminal] = run(integrator, 0.02, 0, k2, 0, 8.0);  // fallen long enough
    EXPECT_NEAR(terminal.z, -c, 1e-5 * c) << integrator;
    // Stiff drag: k = 2000 / s at dt = 10 ms. The terminal speed within float's rounding.
    const auto [pos, vel] = run(integrator, 0.01, 2000.0, 0, v0, 0.1);
    EXPECT_NEAR(vel.z, -g / 2000.0, 1e-6 * g / 2000.0) << integrator;
    EXPECT_GT(vel.x, 0) << integrator;  // never reversed
  }
}
