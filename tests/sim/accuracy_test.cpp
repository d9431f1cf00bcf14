// tests/sim/accuracy_test.cpp — the validation scenes against their known
// answers, and the velocity Verlet integrator against its promise: exact
// free flight and exact rebounds of a dropped ball at dt = 1 ms.
//
// Every error here is measured by ReferenceProbe from the run's own states;
// the expected values come from the analytic formulas in the scene's
// `reference:` block, and a deliberately wrong reference must fail.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "sim/particles.hpp"
#include "sim/reference.hpp"
#include "sim/scene.hpp"
#include "sim/simulation.hpp"
#include "tests/sim/test_scenes.hpp"

namespace marbles {
namespace {

const std::string kValidation = MARBLES_SOURCE_DIR "/scenes/validation/";

// Runs a scene (with --set style overrides) the way `marbles run` does and
// returns what its reference probe measured.
ReferenceResult measure(const std::string& path, const std::vector<std::string>& overrides = {}) {
  const scene::Scene sc = scene::load_scene(path, overrides);
  const scene::GeneratedParticles particles = scene::generate_particles(sc);
  Simulation sim(sc, make_world(sc, particles), marbles::testing::test_backend(), broadphase::kDefaultCpuAlgorithm);
  ReferenceProbe probe(sc, sim.world());
  const auto steps = static_cast<std::uint64_t>(std::llround(sc.time.duration / sc.time.dt));
  const std::uint64_t every = probe.every(steps);
  while (sim.steps() < steps) {
    sim.step();
    if (sim.steps() % every == 0) probe.sample(sim.time(), sim.world());
  }
  return probe.finish(sim.time(), sim.world());
}

std::string fmt(double v) { return std::to_string(v); }

// The shipped validation scenes meet their references at their own settings
// (velocity Verlet where the scene says so), within what each kind allows:
// float rounding for the exact ones, the solver's rest speed for the time to
// rest (the last hops below it are not simulated).
TEST(Validation, ShippedScenesMeetTheirReferences) {
  const std::vector<std::pair<std::string, double>> cases = {
      {"bouncing_ball.yaml", 1e-4},  {"time_to_rest.yaml", 0.02}, {"incline_roll.yaml", 1e-4},
      {"incline_slide.yaml", 1e-4},  {"slide_to_roll.yaml", 1e-3}, {"oblique_impact.yaml", 1e-4},
      {"momentum_free.yaml", 1e-5},  {"head_on.yaml", 1e-4},       {"momentum_box.yaml", 1e-3}};
  for (const auto& [file, tolerance] : cases) {
    const ReferenceResult r = measure(kValidation + file);
    EXPECT_LT(r.error, tolerance) << file << ": " << r.note;
    EXPECT_EQ(r.expected.size(), r.measured.size()) << file;
  }
}

// Every scene in scenes/validation/ declares a reference.
TEST(Validation, EveryValidationSceneHasAReference) {
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kValidation)) {
    if (entry.path().extension() != ".yaml") continue;
    ++count;
    EXPECT_NE(scene::load_scene(entry.path().string()).reference.kind, scene::ReferenceSpec::Kind::none)
        << entry.path();
  }
  EXPECT_GE(count, 8);
}

// A wrong reference (e = 0.6 stated for a ball of e = 0.8; a 25 degree
// incline stated for a 20 degree one) gives a large error: the error comes
// from the run, not from the reference.
TEST(Validation, AWrongReferenceGivesALargeError) {
  const ReferenceResult ball = measure(kValidation + "bouncing_ball.yaml", {"reference.rebound_heights.restitution=0.6"});
  EXPECT_GT(ball.error, 0.3);
  const ReferenceResult slope = measure(kValidation + "incline_roll.yaml", {"reference.incline.angle=25"});
  EXPECT_GT(slope.error, 0.15);
  const ReferenceResult rest = measure(kValidation + "time_to_rest.yaml", {"reference.time_to_rest.restitution=0.8"});
  EXPECT_GT(rest.error, 0.3);
}

// The target: a ball dropped at dt = 1 ms with velocity Verlet keeps its
// first three rebound heights within 1 % and its time to rest within 2 %,
// for every e from 0.5 to 1 (time to rest only below 1).
TEST(VelocityVerlet, DroppedBallReboundsAndRestsWithinTarget) {
  for (const double e : {0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0}) {
    const std::string m = "materials.rubber.restitution=" + fmt(e);
    const ReferenceResult heights = measure(
        kValidation + "bouncing_ball.yaml",
        {m, "reference.rebound_heights.restitution=" + fmt(e), "time.duration=8", "solver.integrator=velocity_verlet"});
    EXPECT_LT(heights.error, 0.01) << "e = " << e << ": " << heights.note;
    ASSERT_EQ(heights.measured.size(), 3u) << "e = " << e;
    if (e < 1) {
      const double t_rest = std::sqrt(2 * 0.95 / 9.81) * (1 + e) / (1 - e);
      const ReferenceResult rest =
          measure(kValidation + "time_to_rest.yaml", {m, "reference.time_to_rest.restitution=" + fmt(e),
                                                      "time.duration=" + fmt(t_rest + 1),
                                                      "solver.integrator=velocity_verlet"});
      EXPECT_LT(rest.error, 0.02) << "e = " << e << ": " << rest.note;
    }
  }
}

// Free flight: Verlet is exact under gravity (float rounding only) where
// symplectic Euler is off by g h / 2 per unit time: on the incline the
// measured acceleration is a (1 + h / T) with Euler.
TEST(VelocityVerlet, ExactOnTheInclineWhereEulerIsFirstOrder) {
  const ReferenceResult verlet = measure(kValidation + "incline_slide.yaml", {"solver.integrator=velocity_verlet"});
  const ReferenceResult euler = measure(kValidation + "incline_slide.yaml", {"solver.integrator=symplectic_euler"});
  EXPECT_LT(verlet.error, 1e-5);
  const double h_over_t = 1e-3 / 1.0;
  EXPECT_NEAR(euler.error, h_over_t, 0.1 * h_over_t);
}

// Speculative contacts off: the ball finds the floor only once it overlaps
// it, so it bounces late from inside the floor and its rebounds are off by
// far more than with them on.
TEST(Speculative, OffMakesTheBounceLate) {
  const ReferenceResult on = measure(kValidation + "bouncing_ball.yaml", {"solver.speculative=true"});
  const ReferenceResult off = measure(kValidation + "bouncing_ball.yaml", {"solver.speculative=false"});
  EXPECT_LT(on.error, 1e-4);
  EXPECT_GT(off.error, 10 * on.error);
}

// A reference that the scene cannot have is refused at the block.
TEST(Validation, ReferenceThatDoesNotFitTheSceneIsRefused) {
  try {
    measure(kValidation + "bouncing_ball.yaml", {"reference.rebound_heights.sphere=3"});
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("sphere 3 does not exist"), std::string::npos) << e.what();
    EXPECT_GT(e.where().line, 0);
  }
  try {
    measure(kValidation + "oblique_impact.yaml", {"effects=[gravity, walls, restitution, friction]"});
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("without gravity"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace marbles
