// tests/sim/cli_check_test.cpp — `marbles check SCENE` as a user runs it:
// exit 0 and a summary on stdout for every shipped scene; exit 2 and the
// loader's message on stderr for every bad-input rule and for a bad `--set`;
// risky settings as warnings on stderr, still exit 0.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tests/sim/scene_cases.hpp"

namespace marbles {
namespace {

const std::string kMarbles = MARBLES_BINARY_DIR "/bin/marbles";

struct Outcome {
  int exit_code = -1;
  std::string out, err;
};

// Single-quoted for the shell (built by appending: GCC 12 warns falsely on "'" + std::string&&).
std::string quoted(const std::string& s) {
  std::string out = "'";
  out += test::replace_all(s, "'", "'\\''");
  out += "'";
  return out;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// `marbles check SCENE [--set OVERRIDE]... [FLAGS]`
Outcome run_check(const std::string& scene, const test::ScratchDir& scratch,
                  const std::vector<std::string>& overrides = {}, const std::string& flags = "") {
  const std::string out = scratch.path() + "/stdout.txt", err = scratch.path() + "/stderr.txt";
  std::string command = quoted(kMarbles) + " check " + quoted(scene) + flags;
  for (const std::string& o : overrides) command += " --set " + quoted(o);
  command += " >" + quoted(out) + " 2>" + quoted(err);
  const int status = std::system(command.c_str());
  Outcome o;
  o.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  o.out = slurp(out);
  o.err = slurp(err);
  return o;
}

class CliCheck : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(kMarbles)) GTEST_SKIP() << kMarbles << " is not built";
  }
};

TEST_F(CliCheck, EveryShippedSceneExitsZero) {
  std::vector<std::string> scenes;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(MARBLES_SOURCE_DIR "/scenes"))
    if (entry.is_regular_file() && entry.path().extension() == ".yaml") scenes.push_back(entry.path().string());
  std::sort(scenes.begin(), scenes.end());
  ASSERT_FALSE(scenes.empty());
  const test::ScratchDir scratch("cli_good");
  for (const std::string& scene : scenes) {
    SCOPED_TRACE(scene);
    const Outcome o = run_check(scene, scratch);
    EXPECT_EQ(o.exit_code, 0) << o.err;
    EXPECT_FALSE(o.out.empty());
    EXPECT_EQ(std::count(o.out.begin(), o.out.end(), '\n'), 1) << "one summary line, got:\n" << o.out;
  }
}

TEST_F(CliCheck, SetOverridesTheScene) {
  const test::ScratchDir scratch("cli_set");
  const Outcome o = run_check(MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml", scratch,
                              {"time.dt=5e-4", "solver.iterations=20"});
  EXPECT_EQ(o.exit_code, 0) << o.err;
  EXPECT_NE(o.out.find("6000 steps of 0.0005 s"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find(", float)"), std::string::npos) << o.out;
  // The precision from a set in any form the loader takes (nested, quoted, by a merge key), not only
  // solver.precision=double.
  for (const char* form : {"solver.precision=double", "solver={precision: double}", "solver.precision=\"double\"",
                           "solver={<<: {precision: double}, iterations: 10}"}) {
    const Outcome d = run_check(MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml", scratch, {form});
    EXPECT_EQ(d.exit_code, 0) << d.err;
    EXPECT_NE(d.out.find(", double)"), std::string::npos) << form << ": " << d.out;
  }
}

// --pipeline adds the stages a run builds, as the run itself prints them:
// the scene's effects and settings, a --set among them.
TEST_F(CliCheck, PipelineListsTheStagesARunBuilds) {
  const test::ScratchDir scratch("cli_pipeline");
  const std::string scene = MARBLES_SOURCE_DIR "/scenes/demo.yaml";
  const Outcome o = run_check(scene, scratch, {"solver.iterations=17"}, " --pipeline");
  ASSERT_EQ(o.exit_code, 0) << o.err;
  EXPECT_NE(o.out.find("\npipeline (1 substep"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("17 sequential-impulse sweeps"), std::string::npos) << o.out;
  const std::string run_out = scratch.path() + "/run.out";
  const std::string command = quoted(kMarbles) + " run " + quoted(scene) + " --backend cpu --duration 0.001 --summary-only"
                              " --overwrite --set solver.iterations=17 --out " + quoted(scratch.path() + "/run") +
                              " > " + quoted(run_out) + " 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  const std::string ran = slurp(run_out);
  const std::size_t from = ran.find("pipeline ("), to = ran.find("\n", ran.find("  project"));
  ASSERT_NE(from, std::string::npos) << ran;
  EXPECT_NE(o.out.find(ran.substr(from, to + 1 - from)), std::string::npos) << o.out << "\nagainst\n" << ran;
  const Outcome gas = run_check(scene, scratch, {"effects=[gravity]"}, " --pipeline");
  ASSERT_EQ(gas.exit_code, 0) << gas.err;
  EXPECT_EQ(gas.out.find("contact solver"), std::string::npos) << gas.out;
}

TEST_F(CliCheck, BadSetValueExitsTwoNamingTheOverride) {
  const test::ScratchDir scratch("cli_set_bad");
  const Outcome o = run_check(MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml", scratch, {"time.dt=-1"});
  EXPECT_EQ(o.exit_code, 2);
  EXPECT_NE(o.err.find("--set time.dt=-1: time.dt: must be > 0"), std::string::npos) << o.err;
  EXPECT_TRUE(o.out.empty()) << o.out;
}

TEST_F(CliCheck, MalformedSetExitsTwo) {
  const test::ScratchDir scratch("cli_set_malformed");
  const Outcome o = run_check(MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml", scratch, {"time.dt"});
  EXPECT_EQ(o.exit_code, 2);
  EXPECT_NE(o.err.find("--set time.dt: expected key.path=value"), std::string::npos) << o.err;
}

TEST_F(CliCheck, RiskySettingsWarnOnStderrAndExitZero) {
  const test::ScratchDir scratch("cli_warn");
  const Outcome o = run_check(MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml", scratch, {"time.dt=0.01"});
  EXPECT_EQ(o.exit_code, 0) << o.err;
  EXPECT_EQ(std::count(o.out.begin(), o.out.end(), '\n'), 1) << o.out;
  EXPECT_EQ(o.err.rfind("warning: substeps too coarse for gravity: ", 0), 0u) << o.err;
}

// Spheres that start overlapping: `check` warns as `run` does, counting the
// pairs deeper than 1 % of the smaller radius (three of four here: the fourth
// pair overlaps by 0.5 %), and exits 0.
TEST_F(CliCheck, InitialOverlapsWarnOnStderrAsRunDoes) {
  const test::ScratchDir scratch("cli_overlap");
  const std::string scene = scratch.path() + "/overlap.yaml";
  std::ofstream(scene) << SCENE_TIME SCENE_MATERIALS
      "particles:\n"
      "  - list: {positions: [[0, 0, 1], [0.15, 0, 1], [0, 0, 1]], radius: 0.1}\n"
      "  - list: {positions: [[5, 0, 1], [5.1995, 0, 1]], radius: 0.1}\n";
  const Outcome o = run_check(scene, scratch);
  EXPECT_EQ(o.exit_code, 0) << o.err;
  EXPECT_NE(o.err.find("warning: 3 pair(s) of spheres start overlapping by more than 1% of the smaller radius"),
            std::string::npos)
      << o.err;

  std::ofstream(scene) << SCENE_TIME SCENE_MATERIALS
      "particles:\n"
      "  - list: {positions: [[5, 0, 1], [5.1995, 0, 1]], radius: 0.1}\n";
  const Outcome touching = run_check(scene, scratch);
  EXPECT_EQ(touching.exit_code, 0) << touching.err;
  EXPECT_EQ(touching.err.find("start overlapping"), std::string::npos) << touching.err;
}

class CliCheckBad : public ::testing::TestWithParam<test::BadScene> {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(kMarbles)) GTEST_SKIP() << kMarbles << " is not built";
  }
};

TEST_P(CliCheckBad, ExitsTwoWithTheMessageOnStderr) {
  const test::BadScene& c = GetParam();
  const test::ScratchDir dir(std::string("cli_") + c.name);
  const std::string path = test::write_case(c, dir);
  const Outcome o = run_check(path, dir);
  EXPECT_EQ(o.exit_code, 2) << o.err;
  std::string expected = test::expected_message(c, path, dir.path());
  if (expected.size() >= 3 && expected.compare(expected.size() - 3, 3, "...") == 0) expected.resize(expected.size() - 3);
  EXPECT_NE(o.err.find(expected), std::string::npos) << "expected on stderr: " << expected << "\ngot: " << o.err;
  EXPECT_TRUE(o.out.empty()) << o.out;
}

INSTANTIATE_TEST_SUITE_P(Rules, CliCheckBad, ::testing::ValuesIn(test::bad_scenes()),
                         [](const ::testing::TestParamInfo<test::BadScene>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace marbles
