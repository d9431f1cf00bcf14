// tests/sim/checkpoint_test.cpp — checkpoint and restart through the real
// program: a run resumed from any checkpoint writes the same frames (byte for
// byte), series.pvd and summary.json (all but its timings) as the run that
// was never stopped; a checkpoint of another scene, precision or a damaged
// one is refused with exit 2. checkpoint_cuda_test.cpp does it on the GPU.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "tests/sim/checkpoint_cases.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles {
namespace {

using namespace test;

// Several cut points, both precisions: the resumed run equals the whole run.
TEST_F(Checkpoints, RestartEqualsTheUninterruptedRun) {
  const test::ScratchDir dir("ck_equal");
  const std::string scene = dir.write("s.yaml", kScene);
  for (const std::string precision : {"float", "double"}) {
    const std::string whole = dir.path() + "/whole_" + precision;
    const std::string common = " --quiet --backend cpu --precision " + precision;
    ASSERT_EQ(marbles("run " + scene + common + " --out " + whole), 0);
    for (const int cut : {50, 150, 250}) {
      // Stopped after `cut` steps, then resumed in the same folder from its last checkpoint.
      const std::string resumed = dir.path() + "/resumed_" + precision + std::to_string(cut);
      ASSERT_EQ(marbles("run " + scene + common + " --out " + resumed + " --duration " + std::to_string(cut * 1e-3)), 0);
      char name[32];
      std::snprintf(name, sizeof name, "/checkpoints/step_%06d.mck", cut);
      std::string err;
      ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + resumed + " --restart " + resumed + name, &err),
                0)
          << err;  // the precision comes from the checkpoint
      expect_same_output(whole, resumed);
    }
  }
}

// The newest `keep` checkpoints stay.
TEST_F(Checkpoints, KeepsTheNewest) {
  const test::ScratchDir dir("ck_keep");
  const std::string scene = dir.write("s.yaml", kScene);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --set output.checkpoint.keep=2 --out " + dir.path() + "/o"), 0);
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir.path() + "/o/checkpoints"))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"step_000250.mck", "step_000300.mck"}));
}

// Another scene, another precision or a damaged file: exit 2 and why.
TEST_F(Checkpoints, ForeignOrDamagedCheckpointsAreRefused) {
  const test::ScratchDir dir("ck_foreign");
  const std::string scene = dir.write("s.yaml", kScene);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o"), 0);
  const std::string ck = dir.path() + "/o/checkpoints/step_000100.mck";
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --set materials.glass.friction=0.5 --restart " + ck, &err), 2);
  EXPECT_NE(err.find("belongs to another scene"), std::string::npos) << err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --precision double --restart " + ck, &err), 2);
  EXPECT_NE(err.find("is in float precision, this run in double"), std::string::npos) << err;
  const std::string bytes = slurp(ck);
  const std::string cut = dir.write("cut.mck", bytes.substr(0, bytes.size() / 2));
  EXPECT_EQ(marbles("run " + scene + " --quiet --restart " + cut, &err), 2);
  EXPECT_NE(err.find("truncated or damaged"), std::string::npos) << err;
  const std::string other = dir.write("other.mck", "not a checkpoint at all, just text");
  EXPECT_EQ(marbles("run " + scene + " --quiet --restart " + other, &err), 2);
  EXPECT_NE(err.find("is not a marbles checkpoint"), std::string::npos) << err;
}

// The watchdog: an injected non-finite velocity (test hook) is rolled back
// and the step redone; the run finishes and counts the rollback.
TEST_F(Checkpoints, WatchdogRepairsAnInjectedFault) {
  const test::ScratchDir dir("ck_watchdog");
  const std::string scene = dir.write("s.yaml", kScene);
  std::string err;
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o", &err, "MARBLES_FAULT_NAN_STEP=100"),
            0)
      << err;
  EXPECT_NE(err.find("watchdog: step 100: non-finite state (sphere 0); rolled back"), std::string::npos) << err;
  EXPECT_NE(slurp(dir.path() + "/o/summary.json").find("\"rollbacks\": 1,"), std::string::npos);
}

// A fault that every retry meets: exit 1 naming the step and the invariant,
// and a checkpoint of the last good state, from which the run (without the
// fault) goes on exactly as one that never met it.
TEST_F(Checkpoints, WatchdogGivesUpWithTheLastGoodState) {
  const test::ScratchDir dir("ck_watchdog_fail");
  const std::string scene = dir.write("s.yaml", kScene);
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o", &err,
                    "MARBLES_FAULT_NAN_STEP=120:all"),
            1);
  EXPECT_NE(err.find("watchdog: step 120: non-finite state (sphere 0) after 3 retries"), std::string::npos) << err;
  const std::string last_good = dir.path() + "/o/checkpoints/step_000119.mck";
  ASSERT_TRUE(fs::exists(last_good)) << err;
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o --restart " + last_good), 0);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/whole"), 0);
  expect_same_output(dir.path() + "/whole", dir.path() + "/o");
}

}  // namespace
}  // namespace marbles
