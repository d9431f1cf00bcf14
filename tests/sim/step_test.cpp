// Whole-step physics against analytic results: rebound height, momentum,
// determinism. Scenes are built in code so each test states its physics.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/simulation.hpp"
#include "sim/step_backend.hpp"
#include "sim/step_model.hpp"
#include "integrator/integrator_math.hpp"
#include "sim/watch_math.hpp"
#include "tests/sim/test_scenes.hpp"

using namespace marbles;
using marbles::testing::test_backend;

namespace {

scene::Scene base_scene(double dt, int substeps, std::vector<scene::Effect> effects, double e) {
  scene::Scene s;
  s.path = "test";
  s.name = "test";
  s.time = {1.0, dt, substeps};
  s.effects = std::move(effects);
  scene::Material m;
  m.name = "m";
  m.density = 1000;
  m.restitution = e;
  m.friction = 0;
  s.materials.push_back(m);
  return s;
}

scene::GeneratedParticles one_ball(Vec3 p, real r, Vec3 v = {}) {
  scene::GeneratedParticles g;
  g.position.push_back(p);
  g.velocity.push_back(v);
  g.radius.push_back(r);
  g.material.push_back(0);
  return g;
}

// Drop from height h0 (bottom of the ball above the plane); the first apex
// after the bounce is e^2 h0.
double first_rebound_height(double e, double dt, int substeps, double h0) {
  using scene::Effect;
  scene::Scene s = base_scene(dt, substeps, {Effect::gravity, Effect::walls, Effect::restitution}, e);
  scene::WallSpec floor;
  floor.kind = scene::WallSpec::Kind::plane;
  floor.point = {0, 0, 0};
  floor.normal = {0, 0, 1};
  s.walls.push_back(floor);
  const real r = real(0.05);
  Simulation sim(s, make_world(s, one_ball({0, 0, real(h0 + r)}, r)), test_backend());
  bool bounced = false;
  double apex = 0;
  for (int k = 0; k < 200000; ++k) {
    sim.step();
    const Vec3 v = sim.world().velocity[0];
    const double z = sim.world().position[0].z - r;
    if (!bounced && v.z > 0) bounced = true;
    if (bounced) {
      apex = std::max(apex, z);
      if (v.z < 0) break;
    }
  }
  EXPECT_TRUE(bounced);
  return apex;
}

}  // namespace

class Rebound : public ::testing::TestWithParam<std::tuple<double, double, int>> {};

TEST_P(Rebound, ReachesESquaredOfDropHeight) {
  const auto [e, dt, substeps] = GetParam();
  const double h0 = 1.0;
  const double apex = first_rebound_height(e, dt, substeps, h0);
  EXPECT_NEAR(apex, e * e * h0, 0.01 * e * e * h0) << "e=" << e << " dt=" << dt << " substeps=" << substeps;
}

// Symplectic Euler is first order: the impact speed is low by about g h / 2,
// so 1 % of e^2 h0 needs substeps h of about 1 ms or less (the cases at
// dt = 1/60 s use 16 and 32 substeps).
INSTANTIATE_TEST_SUITE_P(Restitution, Rebound,
                         ::testing::Values(std::tuple{0.8, 1e-3, 1}, std::tuple{0.5, 1e-3, 2},
                                           std::tuple{0.9, 1.0 / 240, 4}, std::tuple{1.0, 1e-3, 1},
                                           std::tuple{0.3, 2e-3, 1}, std::tuple{0.8, 1.0 / 60, 16},
                                           std::tuple{0.3, 1.0 / 60, 32}));

TEST(Rebound, InelasticBallComesToRest) {
  using scene::Effect;
  scene::Scene s = base_scene(1e-3, 1, {Effect::gravity, Effect::walls, Effect::restitution}, 0.5);
  scene::WallSpec floor;
  floor.point = {0, 0, 0};
  floor.normal = {0, 0, 1};
  s.walls.push_back(floor);
  const real r = real(0.05);
  Simulation sim(s, make_world(s, one_ball({0, 0, real(0.5)}, r)), test_backend());
  for (int k = 0; k < 5000; ++k) sim.step();
  EXPECT_LT(std::abs(sim.world().velocity[0].z), 0.02);
  EXPECT_NEAR(sim.world().position[0].z, r, 0.01 * r);
}

// Elastic gas with no gravity and no walls: sphere–sphere impulses are equal
// and opposite, so total momentum is conserved.
TEST(Momentum, ConservedByElasticCollisions) {
  using scene::Effect;
  scene::Scene s = base_scene(1e-3, 1, {Effect::collisions, Effect::restitution}, 1.0);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  scene::GeneratedParticles g;
  const real r = real(0.05);
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z) {
        g.position.push_back({real(x * 0.12), real(y * 0.12), real(z * 0.12)});
        g.velocity.push_back({real(u(rng) + 0.3), real(u(rng)), real(u(rng))});
        g.radius.push_back(real(r * (1 + 0.2 * u(rng))));
        g.material.push_back(0);
      }
  Simulation sim(s, make_world(s, g), test_backend());
  double p0[3], p1[3];
  sim.world().momentum(p0);
  std::uint64_t contacts = 0;
  for (int k = 0; k < 300; ++k) {
    sim.step();
    contacts += sim.last_step().contacts;
  }
  sim.world().momentum(p1);
  EXPECT_GT(contacts, 1000u);
  const double scale = std::sqrt(p0[0] * p0[0] + p0[1] * p0[1] + p0[2] * p0[2]);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(p1[a], p0[a], 1e-6 * scale) << "axis " << a;
}

// The same scene run twice gives bit-identical states.
TEST(Determinism, SameSceneSameState) {
  using scene::Effect;
  auto run = [] {
    scene::Scene s = base_scene(1e-3, 2, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution}, 0.6);
    scene::WallSpec box;
    box.kind = scene::WallSpec::Kind::box;
    box.lo = {0, 0, 0};
    box.hi = {1, 1, 2};
    s.walls.push_back(box);
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<double> u(0.1, 0.9);
    scene::GeneratedParticles g;
    for (int i = 0; i < 300; ++i) {
      g.position.push_back({real(u(rng)), real(u(rng)), real(2 * u(rng))});
      g.velocity.push_back({});
      g.radius.push_back(real(0.03));
      g.material.push_back(0);
    }
    Simulation sim(s, make_world(s, g), test_backend());
    for (int k = 0; k < 200; ++k) sim.step();
    return sim.world();
  };
  const World a = run(), b = run();
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(0, std::memcmp(a.position.data(), b.position.data(), a.size() * sizeof(Vec3)));
  EXPECT_EQ(0, std::memcmp(a.velocity.data(), b.velocity.data(), a.size() * sizeof(Vec3)));
}

// The undo causes a step reports (StepCounters::undo_causes, the bench's
// undo_causes) name each bit once, in the bits' order, and nothing else.
TEST(StepCounters, UndoCauseNamesFollowTheBits) {
  const std::vector<std::pair<UndoCause, std::string>> each{{kUndoPairs, "pairs"},
                                                            {kUndoContacts, "contacts"},
                                                            {kUndoGrid, "grid"},
                                                            {kUndoImpactWords, "impact_words"},
                                                            {kUndoArms, "arms"},
                                                            {kUndoColours, "colours"}};
  EXPECT_TRUE(undo_cause_names(0).empty());
  std::uint32_t all = 0;
  std::vector<std::string> names;
  for (const auto& [bit, name] : each) {
    EXPECT_EQ(undo_cause_names(bit), std::vector<std::string>{name});
    EXPECT_EQ(all & bit, 0u) << name << " shares a bit";
    all |= bit, names.push_back(name);
  }
  EXPECT_EQ(undo_cause_names(all), names);
  EXPECT_EQ(undo_cause_names(kUndoColours | kUndoPairs), (std::vector<std::string>{"pairs", "colours"}));
  EXPECT_TRUE(undo_cause_names(~all).empty()) << "a bit no cause has names nothing";
}

// The model says whether a wall's surface moves (the GPU's records then keep
// each wall contact's surface velocity): a box at rest does not, a spinning
// post or a sliding plane does, and without the walls effect no wall counts.
TEST(StepModel, MovingWallsAreTheOnesWhoseSurfaceMoves) {
  using namespace marbles::testing;
  using scene::Effect;
  const auto moving = [](const scene::Scene& s) {
    return compile_step_model(s, broadphase::kDefaultCpuAlgorithm).moving_walls;
  };
  scene::Scene at_rest = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls}, 0.5);
  at_rest.walls.push_back(box({0, 0, 0}, {1, 1, 1}));
  EXPECT_FALSE(moving(at_rest));
  EXPECT_TRUE(moving(pour_scene(10, 1).first));  // its post spins
  scene::Scene sliding = at_rest;
  scene::WallSpec lid = plane({0, 0, 1}, {0, 0, -1});
  lid.velocity = {0, 0, real(-0.01)};
  sliding.walls.push_back(lid);
  EXPECT_TRUE(moving(sliding));
  sliding.effects = {Effect::gravity, Effect::collisions};
  EXPECT_FALSE(moving(sliding));
}

// The model says whether every material pair has the same friction and
// rolling friction (the arms word a contact's record carries, with one
// radius: UniformArms): one material does; a second one differing only in
// density, restitution or twisting friction does too (none of those is in
// the arms word); a different friction, rolling friction, or an explicit
// pair that changes either, does not.
TEST(StepModel, UniformPairsShareFrictionAndRollingFriction) {
  using namespace marbles::testing;
  using scene::Effect;
  const auto uniform = [](const scene::Scene& s) {
    return compile_step_model(s, broadphase::kDefaultCpuAlgorithm).uniform_pairs;
  };
  scene::Scene one = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::friction}, 0.5, 0.4, 0.02, 0.01);
  ASSERT_EQ(one.materials.size(), 1u);
  EXPECT_TRUE(uniform(one));
  scene::Scene two = one;
  scene::Material other = one.materials[0];
  other.name = "other";
  other.density *= 8;
  other.restitution = 0.1;
  other.twisting_friction = 0.3;
  two.materials.push_back(other);
  EXPECT_TRUE(uniform(two));
  for (int change = 0; change < 4; ++change) {
    scene::Scene s = two;
    if (change == 0) s.materials[1].friction = 0.41;
    if (change == 1) s.materials[1].rolling_friction = 0.03;
    if (change >= 2) {
      scene::ContactPairSpec pair;
      pair.first = "other";
      pair.second = one.materials[0].name;
      (change == 2 ? pair.friction : pair.rolling_friction) = 0.9;
      s.contact_pairs.push_back(pair);
    }
    EXPECT_FALSE(uniform(s)) << "change " << change;
  }
}

// Spheres poured into a closed box stay inside it.
TEST(Walls, BoxKeepsEverySphereInside) {
  using scene::Effect;
  scene::Scene s = base_scene(1e-3, 2, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution}, 0.3);
  scene::WallSpec box;
  box.kind = scene::WallSpec::Kind::box;
  box.lo = {0, 0, 0};
  box.hi = {0.5, 0.5, 1};
  s.walls.push_back(box);
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(0.05, 0.45), v(-2, 2);
  scene::GeneratedParticles g;
  for (int i = 0; i < 500; ++i) {
    g.position.push_back({real(u(rng)), real(u(rng)), real(2 * u(rng))});
    g.velocity.push_back({real(v(rng)), real(v(rng)), real(v(rng))});
    g.radius.push_back(real(0.02));
    g.material.push_back(0);
  }
  Simulation sim(s, make_world(s, g), test_backend());
  for (int k = 0; k < 1000; ++k) sim.step();
  for (std::size_t i = 0; i < sim.world().size(); ++i) {
    const Vec3 p = sim.world().position[i];
    const real r = sim.world().radius[i];
    EXPECT_GE(p.x, -0.1 * r); EXPECT_LE(p.x, 0.5 + 0.1 * r);
    EXPECT_GE(p.y, -0.1 * r); EXPECT_LE(p.y, 0.5 + 0.1 * r);
    EXPECT_GE(p.z, -0.1 * r); EXPECT_LE(p.z, 1.0 + 0.1 * r);
  }
}

// A finite post's ends are closed: balls dropped over its top disc (over
// the axis, near the rim) come to rest on it, one beside it falls to the
// floor, and one thrown at its side bounces off. (The ends were open: a
// ball fell into the post and was thrown out sideways.)
TEST(Walls, AFinitePostHoldsWhatFallsOnItsTop) {
  using scene::Effect;
  scene::Scene s = base_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution}, 0.3);
  s.walls.push_back(marbles::testing::plane({0, 0, 0}, {0, 0, 1}));
  scene::WallSpec post;
  post.kind = scene::WallSpec::Kind::cylinder;
  post.base = {0, 0, 0};
  post.axis = {0, 0, 1};
  post.radius = 0.2;
  post.length = 1;
  post.inside = false;
  s.walls.push_back(post);
  const real r = real(0.05);
  scene::GeneratedParticles g;
  const Vec3 starts[] = {{0, 0, real(1.5)}, {real(0.15), real(0.05), real(1.3)}, {real(0.6), 0, real(1.5)},
                         {real(-0.6), real(0.1), real(0.5)}};
  for (const Vec3& p : starts) marbles::testing::add_sphere(g, p, r);
  g.velocity[3] = {3, 0, 0};  // at the side, mid-height
  Simulation sim(s, make_world(s, g), test_backend());
  double side_x = -1;  // the thrown ball's furthest reach towards the axis
  for (int k = 0; k < 1500; ++k) {
    sim.step();
    side_x = std::max(side_x, double(sim.world().position[3].x));
  }
  const World& w = sim.world();
  for (int i : {0, 1}) {  // on the top disc, where they fell
    EXPECT_NEAR(w.position[i].z, 1 + r, 0.02 * r) << "ball " << i;
    EXPECT_NEAR(w.position[i].x, starts[i].x, 1e-4) << "ball " << i;
    EXPECT_NEAR(w.position[i].y, starts[i].y, 1e-4) << "ball " << i;
    EXPECT_LT(length(w.velocity[i]), 1e-3) << "ball " << i;
  }
  EXPECT_NEAR(w.position[2].z, r, 0.02 * r);  // beside the post, on the floor
  // The thrown ball met the side where its centre came within r of it
  // (x^2 + 0.1^2 = (0.2 + r)^2) and went back.
  EXPECT_NEAR(side_x, -std::sqrt((0.2 + r) * (0.2 + r) - 0.01), 0.05 * r);
  EXPECT_LT(w.velocity[3].x, 0);
  EXPECT_EQ(w.first_non_finite(), w.size());
}

// Off-centre impacts leave along the line of centres at the moment of touch
// (rigid-body impact theory, frictionless): random pairs of spheres of
// different sizes (so masses), restitution 1 or 0.5, approach speeds up to
// 20 m/s (0.25-1 radius a substep) and impact parameters up to 0.95 of the
// radii's sum, against the impact law at the normal found in double from
// the start (the line at the substep's start turned them by up to 15 %); and
// the same of a sphere against a fixed sphere wall.
TEST(Impacts, OffCentreImpactsLeaveAlongTheLineOfCentresAtTouch) {
  using scene::Effect;
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(0, 1);
  int oblique = 0;
  for (int trial = 0; trial < 24; ++trial) {
    const bool wall = trial % 3 == 2;
    const double e = trial % 2 ? 0.5 : 1.0;
    scene::Scene s = base_scene(1e-3, 1, {Effect::collisions, Effect::walls, Effect::restitution}, e);
    const double r1 = 0.02 + 0.06 * u(rng), r2 = 0.02 + 0.06 * u(rng), R = r1 + r2;
    const double speed = 5 + 15 * u(rng), bfrac = 0.95 * u(rng), phase = u(rng);
    // Sphere 1 moves along +x towards sphere 2 (or the wall) at (0, b, 0),
    // from a gap it closes after 10 + phase substeps.
    const double b = bfrac * R, along = std::sqrt(R * R - b * b);
    const double x1 = -(along + speed * 1e-3 * (10 + phase));
    scene::GeneratedParticles g;
    marbles::testing::add_sphere(g, {real(x1), 0, 0}, real(r1), {real(speed), 0, 0});
    if (wall) {
      scene::WallSpec rock;
      rock.kind = scene::WallSpec::Kind::sphere;
      rock.centre = {0, real(b), 0};
      rock.radius = r2;
      s.walls.push_back(rock);
    } else {
      marbles::testing::add_sphere(g, {0, real(b), 0}, real(r2));
    }
    Simulation sim(s, make_world(s, g), test_backend());
    for (int k = 0; k < 40; ++k) sim.step();
    // The impact law in double: masses from the stored radii, the normal
    // from the start as stored.
    const World& w = sim.world();
    const double m1 = 1000 * 4.0 / 3.0 * M_PI * std::pow(double(real(r1)), 3);
    const double m2 = wall ? 1e300 : 1000 * 4.0 / 3.0 * M_PI * std::pow(double(real(r2)), 3);
    const double px = double(real(x1)), py = -double(real(b)), Rs = double(real(r1)) + double(real(r2));
    const double v = double(real(speed));
    const double t = (-px - std::sqrt(Rs * Rs - py * py)) / v;  // |(px + v t, py)| = R
    const double nx = (px + v * t) / Rs, ny = py / Rs;          // from 2 to 1 at touch
    const double vn = v * nx;                                   // < 0: approaching
    const double k1 = wall ? (1 + e) : (1 + e) * m2 / (m1 + m2), k2 = (1 + e) * m1 / (m1 + m2);
    const double want1[2] = {v - k1 * vn * nx, -k1 * vn * ny}, want2[2] = {k2 * vn * nx, k2 * vn * ny};
    const std::string what = "trial " + std::to_string(trial) + (wall ? " (wall)" : "");
    EXPECT_NEAR(w.velocity[0].x, want1[0], 2e-4 * v) << what;
    EXPECT_NEAR(w.velocity[0].y, want1[1], 2e-4 * v) << what;
    if (!wall) {
      EXPECT_NEAR(w.velocity[1].x, want2[0], 2e-4 * v) << what;
      EXPECT_NEAR(w.velocity[1].y, want2[1], 2e-4 * v) << what;
    }
    oblique += bfrac > 0.5 ? 1 : 0;
  }
  EXPECT_GT(oblique, 8);
}

// The same against a cylinder's side, across its axis: a post (its outside,
// infinite or finite with the path beside its side) and a drum (its inside,
// infinite or a finite tube, spinning in some trials: frictionless, so the
// spin gives no impulse). A sphere moving along +x meets the side where its
// centre is R from the axis (the post's radius plus r, the drum's less r)
// and leaves by the impact law at the normal there.
TEST(Impacts, OffCentreImpactsOnACylindersSideLeaveAlongItsNormalAtTouch) {
  using scene::Effect;
  std::mt19937_64 rng(37);
  std::uniform_real_distribution<double> u(0, 1);
  int oblique = 0;
  for (int trial = 0; trial < 24; ++trial) {
    const bool drum = trial % 4 >= 2, finite = trial % 2 == 1;
    const double e = trial % 3 ? 0.5 : 1.0;
    scene::Scene s = base_scene(1e-3, 1, {Effect::collisions, Effect::walls, Effect::restitution}, e);
    const double r1 = 0.02 + 0.06 * u(rng), speed = 5 + 10 * u(rng), bfrac = 0.95 * u(rng), phase = u(rng);
    scene::WallSpec side;
    side.kind = scene::WallSpec::Kind::cylinder;
    side.inside = drum;
    side.radius = drum ? 0.6 : 0.02 + 0.06 * u(rng);
    side.length = finite ? 2 : 0;
    side.angular_velocity = drum && trial % 3 == 2 ? 7 : 0;
    const double R = drum ? double(real(side.radius)) - double(real(r1)) : double(real(side.radius)) + double(real(r1));
    const double b = bfrac * R;  // the axis at (0, b) for a post, the path at y = b in a drum
    side.base = {0, drum ? real(0) : real(b), real(finite ? -1 : 0)};
    s.walls.push_back(side);
    // At touch the centre is at (x_t, y_t) from the axis: a post's outside
    // from the left, a drum's inside from within.
    const double x_t = drum ? std::sqrt(R * R - b * b) : -std::sqrt(R * R - b * b), y_t = drum ? b : -b;
    const double x1 = x_t - speed * 1e-3 * (5 + phase);
    scene::GeneratedParticles g;
    marbles::testing::add_sphere(g, {real(x1), drum ? real(b) : real(0), 0}, real(r1), {real(speed), 0, 0});
    Simulation sim(s, make_world(s, g), test_backend());
    for (int k = 0; k < 12; ++k) sim.step();
    const World& w = sim.world();
    const double v = double(real(speed));
    const double nx = (drum ? -x_t : x_t) / R, ny = (drum ? -y_t : y_t) / R;  // towards the sphere's side
    const double vn = v * nx;                                                  // < 0: approaching
    const std::string what = "trial " + std::to_string(trial) + (drum ? " (drum" : " (post") +
                             (finite ? ", finite)" : ")");
    ASSERT_LT(vn, 0) << what;
    EXPECT_NEAR(w.velocity[0].x, v - (1 + e) * vn * nx, 2e-4 * v) << what;
    EXPECT_NEAR(w.velocity[0].y, -(1 + e) * vn * ny, 2e-4 * v) << what;
    EXPECT_NEAR(w.velocity[0].z, 0, 1e-6 * v) << what;
    oblique += bfrac > 0.5 ? 1 : 0;
  }
  EXPECT_GT(oblique, 8);
}

// --- The unswept check's geometry (sim/watch_math.hpp) against paths
// sampled finely: the deepest point of each straight path, less the depth
// at its start. Random paths, many of them grazing, through or past.
namespace {

// The depth of a path sampled at `samples` + 1 points (oracle).
template <class Depth>
double sampled_deepening(Depth depth_at, int samples = 20000) {
  double deepest = 0;
  for (int k = 0; k <= samples; ++k) deepest = std::max(deepest, depth_at(double(k) / samples));
  const double start = std::max(0.0, depth_at(0.0));
  return std::max(0.0, deepest - start);
}

// The same of a sphere's path against a wall as it stands.
double sampled_wall_deepening(const narrowphase::WallShape& w, const Vec3& p, const Vec3& v, real r, real h) {
  return sampled_deepening([&](double t) {
    Vec3 normal;
    real gap = 0;
    if (!narrowphase::wall_gap(w, p - v * real(h * (1 - t)), r, normal, gap)) return 0.0;
    return -double(gap) / r;
  });
}

}  // namespace

TEST(Unswept, SphereDeepeningIsTheDeepestPointOfTheSampledPaths) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1), radius(0.5, 2);
  int met = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const real ra = real(radius(rng)), rb = real(radius(rng)), h = real(0.01);
    const Vec3 pa(real(3 * u(rng)), real(3 * u(rng)), real(3 * u(rng))), pb(real(u(rng)), real(u(rng)), real(u(rng)));
    const Vec3 va(real(400 * u(rng)), real(400 * u(rng)), real(400 * u(rng))), vb(real(50 * u(rng)), real(50 * u(rng)), 0);
    const double got = watch::swept_deepening(pa, va, ra, pb, vb, rb, h);
    const double want = sampled_deepening([&](double t) {
      const Vec3 a = pa - va * real(h * (1 - t)), b = pb - vb * real(h * (1 - t));
      return (double(ra) + rb - double(length(a - b))) / std::min(ra, rb);
    });
    EXPECT_NEAR(got, want, 1e-3 * (1 + want)) << "trial " << trial;
    met += want > 0.01 ? 1 : 0;
  }
  EXPECT_GT(met, 200);  // the paths meet often enough to test the depth
}

TEST(Unswept, WallDeepeningIsTheDeepestPointOfTheSampledPaths) {
  using Kind = narrowphase::WallShape::Kind;
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u(-1, 1), radius(0.2, 1);
  for (const Kind kind : {Kind::half_space, Kind::sphere, Kind::cylinder_inside, Kind::cylinder_outside}) {
    int met = 0, finite_met = 0;
    for (int trial = 0; trial < 1000; ++trial) {
      narrowphase::WallShape w;
      w.kind = kind;
      w.point = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
      const Vec3 d(real(u(rng)), real(u(rng)), real(u(rng)) + real(2));
      w.direction = d / length(d);
      w.radius = kind == Kind::cylinder_inside ? real(4) : real(1.5);
      // Half the cylinders have a length: the path passes beside them only in part.
      const bool cylinder = kind == Kind::cylinder_inside || kind == Kind::cylinder_outside;
      w.length = cylinder && trial % 2 == 0 ? real(2) : real(0);
      const real r = real(radius(rng)), h = real(0.01);
      const Vec3 p(real(3 * u(rng)), real(3 * u(rng)), real(3 * u(rng))),
          v(real(400 * u(rng)), real(400 * u(rng)), real(400 * u(rng)));
      const double got = watch::wall_swept_deepening(w, p, v, r, h);
      const double want = sampled_wall_deepening(w, p, v, r, h);
      EXPECT_NEAR(got, want, 1e-3 * (1 + want)) << "kind " << int(kind) << " trial " << trial << " length " << w.length;
      met += want > 0.01 ? 1 : 0;
      finite_met += want > 0.01 && w.length > 0 ? 1 : 0;
    }
    EXPECT_GT(met, 50) << "kind " << int(kind);
    if (kind == Kind::cylinder_inside || kind == Kind::cylinder_outside) {
      EXPECT_GT(finite_met, 25) << "kind " << int(kind);
    }
  }
}

// Finite cylinders where random paths seldom go: a path square to the axis,
// one along it (entering the span from past an end), and paths that end
// exactly on an end's plane coming from beyond it (the span found from the
// path may round to empty there, where the end point is beside the post).
TEST(Unswept, FiniteCylindersAtTheirEndsAndAlongTheirAxis) {
  using Kind = narrowphase::WallShape::Kind;
  const real r = real(0.3), h = real(0.01);
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> u(-1, 1);
  int met = 0;
  for (const Kind kind : {Kind::cylinder_outside, Kind::cylinder_inside}) {
    narrowphase::WallShape w;
    w.kind = kind;
    w.point = Vec3(0, 0, 0);
    w.direction = Vec3(0, 0, 1);
    w.radius = kind == Kind::cylinder_inside ? real(4) : real(1.5);
    w.length = real(2);
    const auto check = [&](const Vec3& p, const Vec3& v, const std::string& what) {
      const double got = watch::wall_swept_deepening(w, p, v, r, h);
      const double want = sampled_wall_deepening(w, p, v, r, h);
      EXPECT_NEAR(got, want, 1e-3 * (1 + want)) << "kind " << int(kind) << ": " << what;
      met += want > 0.01 ? 1 : 0;
    };
    const real inside_wall = kind == Kind::cylinder_inside ? real(3.9) : real(1.6);  // a radius the sphere overlaps at
    for (int k = 0; k < 200; ++k) {
      const real z = real(0.1 + 1.8 * (k + 0.5) / 200);
      // Square to the axis, at height z, across the wall's surface.
      const real angle = real(0.0314 * k);
      const Vec3 out(std::cos(angle), std::sin(angle), 0);
      check(out * inside_wall + Vec3(0, 0, z), out * real(kind == Kind::cylinder_inside ? 30 : -30), "square to the axis");
      // Along the axis, from past the lower end into the span.
      check(out * inside_wall + Vec3(0, 0, z), Vec3(0, 0, real(100 + 50 * u(rng))), "along the axis");
      // Ending on the upper end's plane, coming down and in from beyond it.
      const Vec3 v(real(40 * u(rng)), real(40 * u(rng)), -real(20 + 100 * (u(rng) + 1)));
      check(out * inside_wall + Vec3(0, 0, w.length), v, "ending on the end's plane");
    }
  }
  EXPECT_GT(met, 400);
}

// How many spheres past their reach a substep checks: all of a small scene,
// at least 64, never past the GPU's list, and the pair tests bounded.
TEST(Unswept, TheSpheresCheckedKeepTheCheckBounded) {
  std::uint32_t last = watch::kUnsweptListed;
  for (std::size_t n = 1; n < 5000000; n += 1 + n / 7) {
    const std::uint32_t checked = watch::unswept_checked(n);
    EXPECT_GE(checked, 64u) << n;
    EXPECT_LE(checked, watch::kUnsweptListed) << n;
    EXPECT_LE(checked, last) << n;  // fewer as the scene grows
    if (n * n <= watch::kUnsweptPairs) {
      EXPECT_GE(checked, n) << n;  // a small scene's every sphere
    }
    if (checked > 64) {
      EXPECT_LE(std::uint64_t(checked) * n, watch::kUnsweptPairs) << n;
    }
    last = checked;
  }
}

TEST(Unswept, MovedPastReachIsTheTravelBeyondTheReachAndSlack) {
  const real r = real(0.01), h = real(0.001), reach = real(0.005);
  const real edge = (reach + integrator::kUnsweptSlack * r) / h;  // m/s
  EXPECT_FALSE(integrator::moved_past_reach({real(0.999) * edge, 0, 0}, r, reach, h));
  EXPECT_TRUE(integrator::moved_past_reach({0, real(1.001) * edge, 0}, r, reach, h));
  EXPECT_FALSE(integrator::moved_past_reach({0, 0, 0}, r, 0, h));
}

