// tests/sim/checkpoint_cases.hpp — what the checkpoint tests share: the
// scene, running the program, comparing two output folders.
#pragma once

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace marbles::test {

namespace fs = std::filesystem;
inline const std::string kMarbles = MARBLES_BINARY_DIR "/bin/marbles";

// 300 spheres poured into a box onto a rising floor (a moving wall), with
// friction and rolling resistance: 300 steps, frames every 20, checkpoints every 50.
inline const char* kScene = R"(format: 1
name: restart
time: {duration: 0.3, dt: 1.0e-3, substeps: 2}
effects: [gravity, collisions, walls, restitution, friction, rolling_resistance]
materials:
  glass: {density: 2500, restitution: 0.6, friction: 0.4, rolling_friction: 0.01}
walls:
  - box: {min: [0, 0, 0], max: [0.2, 0.2, 0.6]}
  - plane: {point: [0, 0, 0.05], normal: [0, 0, 1]}
    velocity: [0, 0, 0.02]
particles:
  - random: {count: 300, min: [0.02, 0.02, 0.08], max: [0.18, 0.18, 0.55], radius: {uniform: [0.006, 0.01]}, seed: 3}
    velocity: {random: {speed: 0.3, seed: 4}}
reference: finest
output:
  vtk: {every: 20}
  checkpoint: {every: 50, keep: 10}
)";

inline std::string slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Runs `marbles ARGS` with `env` (NAME=VALUE ...) set; stderr into *err_text.
inline int marbles(const std::string& args, std::string* err_text = nullptr, const std::string& env = "") {
  const std::string err = fs::temp_directory_path() / ("marbles_ck_err_" + std::to_string(::getpid()));
  const int status = std::system((env + " '" + kMarbles + "' " + args + " >/dev/null 2>'" + err + "'").c_str());
  if (err_text) *err_text = slurp(err);
  std::error_code ignored;
  fs::remove(err, ignored);  // one a call would pile up in the temporary folder
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// A summary.json, parsed (a file that is not JSON fails the test that reads it).
inline nlohmann::ordered_json summary_of(const fs::path& summary) {
  return nlohmann::ordered_json::parse(slurp(summary));
}

// A summary.json without what the process and its clock add (wall time,
// ms per step, command line, date, threads), as text: equal for equal physics.
inline std::string physics_of(const fs::path& summary) {
  nlohmann::ordered_json j = summary_of(summary);
  for (const char* key : {"wall_time", "mean_ms_per_step", "command_line", "date", "threads"}) j.erase(key);
  return j.dump(1);
}

inline void expect_same_output(const fs::path& a, const fs::path& b) {
  EXPECT_EQ(physics_of(a / "summary.json"), physics_of(b / "summary.json"));
  EXPECT_EQ(fs::exists(a / "frames"), fs::exists(b / "frames"));
  if (!fs::exists(a / "frames")) return;  // a build without VTK writes no frames
  int frames = 0;
  for (const auto& entry : fs::directory_iterator(a / "frames")) {
    ++frames;
    EXPECT_TRUE(slurp(entry.path()) == slurp(b / "frames" / entry.path().filename()))
        << entry.path().filename() << " differs";
  }
  EXPECT_GT(frames, 0);
  EXPECT_EQ(slurp(a / "series.pvd"), slurp(b / "series.pvd"));
}

class Checkpoints : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(kMarbles)) GTEST_SKIP() << kMarbles << " is not built";
  }
};

}  // namespace marbles::test
