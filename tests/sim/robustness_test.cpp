// tests/sim/robustness_test.cpp — inputs that used to crash, hang or run
// silently wrong, each run through the real program: every one now ends with
// a message and exit code 1 or 2, quickly, and nothing is left half-written.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/stat.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "core/format.hpp"
#include "render/atomic_file.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles {
namespace {

namespace fs = std::filesystem;
const std::string kMarbles = MARBLES_BINARY_DIR "/bin/marbles";

struct Outcome {
  int exit_code = -1;
  std::string err;
};

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Runs `marbles ARGS` under bash (for ulimit), stderr captured; a run that
// hangs is stopped after 20 s (exit 124, which every test rejects).
Outcome marbles(const std::string& args, const test::ScratchDir& dir, const std::string& prefix = "") {
  const std::string err = dir.path() + "/stderr.txt";
  const std::string command = "bash -c '" + prefix + " timeout 20 \"" + kMarbles + "\" " + args + "' >/dev/null 2>'" +
                              err + "'";
  const int status = std::system(command.c_str());
  Outcome o;
  o.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  o.err = slurp(err);
  return o;
}

class Robustness : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(kMarbles)) GTEST_SKIP() << kMarbles << " is not built";
  }
};

// yaml-cpp 0.7 yields empty documents forever after a leading ','.
TEST_F(Robustness, LeadingCommaIsAnErrorNotAnEndlessAllocation) {
  const test::ScratchDir dir("robust_comma");
  const std::string scene = dir.write("s.yaml", ",");
  const Outcome o = marbles("check " + scene, dir);
  EXPECT_EQ(o.exit_code, 2) << o.err;
  EXPECT_NE(o.err.find(":1:1: not valid YAML"), std::string::npos) << o.err;
}

// A device that never ends is refused for what it is, and a plain file past
// the size limit after the limit, not when the memory runs out.
TEST_F(Robustness, EndlessFileIsRefused) {
  const test::ScratchDir dir("robust_zero");
  const Outcome device = marbles("check /dev/zero", dir);
  EXPECT_EQ(device.exit_code, 2) << device.err;
  EXPECT_NE(device.err.find("/dev/zero: is a device, not a scene file"), std::string::npos) << device.err;
  const std::string big = dir.write("big.yaml", "# " + std::string(3 << 20, 'x') + "\n");
  const Outcome large = marbles("check " + big + " --limit scene_mib=2", dir);
  EXPECT_EQ(large.exit_code, 2) << large.err;
  EXPECT_NE(large.err.find("larger than 2 MiB: not a scene file"), std::string::npos) << large.err;
  EXPECT_EQ(marbles("check " + big + " --limit scene_mib=4", dir).exit_code, 2);  // read whole: no map
}

// A pipe is read more than once (the scene for its precision, its hash and
// its text) and opening one without a writer waits: every input that names a
// file refuses a pipe up front instead of waiting (the runs are bounded by
// `timeout 20`, whose exit would be 124).
TEST_F(Robustness, PipesAreRefusedNotWaitedOn) {
  const test::ScratchDir dir("robust_fifo");
  const std::string fifo = dir.path() + "/pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string scene = dir.write(
      "s.yaml", "time: {duration: 0.01, dt: 0.001}\nmaterials: {a: }\nparticles:\n  - list: {positions: [[0, 0, 0]], "
                "radius: 0.1}\n");
  const std::string csv = dir.write(
      "c.yaml", "time: {duration: 0.01, dt: 0.001}\nmaterials: {a: }\nparticles:\n  - csv: {path: pipe}\n");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"check " + fifo, fifo + ": is a pipe, not a scene file"},
      {"run " + fifo + " --out " + dir.path() + "/o", fifo + ": is a pipe, not a scene file"},
      {"check " + csv, "particles[0].csv.path: '" + fifo + "' is a pipe, not a CSV file"},
      {"pairs " + fifo, "'" + fifo + "' is a pipe, not a CSV file of spheres"},
      {"run " + scene + " --out " + dir.path() + "/r --restart " + fifo, "--restart: is a pipe, not a checkpoint"},
  };
  for (const auto& [args, message] : cases) {
    const Outcome o = marbles(args, dir);
    EXPECT_EQ(o.exit_code, 2) << args << ": " << o.err;
    EXPECT_NE(o.err.find(message), std::string::npos) << args << ": " << o.err;
  }
  EXPECT_FALSE(fs::exists(dir.path() + "/o/summary.json"));
  EXPECT_FALSE(fs::exists(dir.path() + "/r/summary.json"));
}

// A pair set that cannot fit (coincident centres) is a message with the
// count, not std::terminate from inside an OpenMP loop.
TEST_F(Robustness, PairSetBeyondMemoryIsAMessage) {
  const test::ScratchDir dir("robust_pairs");
  std::ofstream csv(dir.path() + "/c.csv");
  for (int i = 0; i < 40000; ++i) csv << "0,0,0,0.1\n";
  csv.close();
  const Outcome o = marbles("pairs " + dir.path() + "/c.csv", dir, "ulimit -v 1500000;");
  EXPECT_EQ(o.exit_code, 1) << o.err;
  EXPECT_NE(o.err.find("out of memory for the candidate pairs: "), std::string::npos) << o.err;
  // Where the allocator would not refuse (memory overcommitted), the pair
  // lists' growth is held to the memory available (here said to be 300 MB:
  // the 8 * 10^8 pairs would take 6.4 GB), on every algorithm, and the pairs
  // found are counted (kept where a chunk's list was when it stopped).
  for (const std::string algorithm : {"home", "subdivision", "brute"}) {
    const Outcome held = marbles("pairs " + dir.path() + "/c.csv --algorithm " + algorithm, dir,
                                 "MARBLES_MEMORY_AVAILABLE=300000000");
    EXPECT_EQ(held.exit_code, 1) << algorithm << ": " << held.err;
    const std::size_t at = held.err.find("out of memory for the candidate pairs: ");
    ASSERT_NE(at, std::string::npos) << algorithm << ": " << held.err;
    const long long found = std::atoll(held.err.c_str() + at + 39);
    EXPECT_GT(found, 1000000) << algorithm << ": " << held.err;
    EXPECT_LT(found, 40000000) << algorithm << ": " << held.err;  // stopped near 300 MB, not at the end
  }
}

// A scene nested past what the YAML reader follows: said so, at the file
// (the reader's own message for it is "bad file").
TEST_F(Robustness, NestingPastTheReadersDepthIsSaid) {
  const test::ScratchDir dir("robust_deep");
  const std::string scene = dir.write(
      "deep.yaml", "time: {duration: 1, dt: 0.001}\nmaterials: {a: }\nparticles:\n"
                   "  - list: {positions: [[0, 0, 1]], radius: 0.1}\nreference: " +
                       std::string(600, '[') + std::string(600, ']') + "\n");
  const Outcome o = marbles("check " + scene, dir);
  EXPECT_EQ(o.exit_code, 2) << o.err;
  EXPECT_NE(o.err.find(scene + ":5:"), std::string::npos) << o.err;
  EXPECT_NE(o.err.find("nested deeper than the YAML reader follows"), std::string::npos) << o.err;
  // The same in an override (yaml-cpp's own word for it was "bad file").
  const Outcome set = marbles("check " MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml --set reference=" +
                                  std::string(600, '[') + std::string(600, ']'),
                              dir);
  EXPECT_EQ(set.exit_code, 2) << set.err;
  EXPECT_NE(set.err.find("--set reference=[[["), std::string::npos) << set.err;
  EXPECT_NE(set.err.find("the value is nested deeper than the YAML reader follows"), std::string::npos) << set.err;
}

// Counts a machine cannot hold are refused up front, with the number.
TEST_F(Robustness, AbsurdCountsAreRefusedUpFront) {
  const test::ScratchDir dir("robust_count");
  const std::string scene = dir.write(
      "s.yaml",
      "time: {duration: 1, dt: 0.001}\nmaterials: {a: }\nparticles:\n"
      "  - random: {count: 9e8, min: [0, 0, 0], max: [10000, 10000, 10000], radius: 0.1}\n");
  const Outcome o = marbles("check " + scene, dir);
  EXPECT_EQ(o.exit_code, 2) << o.err;
  EXPECT_NE(o.err.find("would make 900000000 spheres, about "), std::string::npos) << o.err;
  const std::string lattice = dir.write(
      "l.yaml",
      "time: {duration: 1, dt: 0.001}\nmaterials: {a: }\nparticles:\n"
      "  - lattice: {min: [0, 0, 0], max: [1, 1, 1], spacing: 1e-30, radius: 1e-31}\n");
  const Outcome l = marbles("check " + lattice, dir);
  EXPECT_EQ(l.exit_code, 2) << l.err;
  EXPECT_NE(l.err.find("would make 1e+90 spheres"), std::string::npos) << l.err;
}

// Every guard can be raised (--limit NAME=VALUE) and lowered: the scene that
// passes is refused under a tighter limit, with the number and the flag.
TEST_F(Robustness, LimitsCanBeRaised) {
  const test::ScratchDir dir("robust_limits");
  const std::string scene = dir.write(
      "s.yaml",
      "time: {duration: 1, dt: 0.001}\nmaterials: {a: , b: }\nparticles:\n"
      "  - random: {count: 300, min: [0, 0, 0], max: [1, 1, 1], radius: 0.01}\n");
  ASSERT_EQ(marbles("check " + scene, dir).exit_code, 0);
  const std::pair<std::string, std::string> cases[] = {
      {"substeps=999", "makes 1000 substeps (duration / time.dt x time.substeps), more than the limit 999 (--limit substeps=N raises it)"},
      {"materials=1", "2 materials, more than the limit 1"},
      {"spheres=299", "must be <= 299 (--limit spheres=N raises it), got 300"},
      {"memory=1e-12", "would make 300 spheres"},
      {"memory=1e-12", " (1e-12 of the "},  // what the spheres may take, and of what
      {"scene_mib=1e-5", "larger than 1e-05 MiB"}};
  for (const auto& [limit, message] : cases) {
    const Outcome o = marbles("check " + scene + " --limit " + limit, dir);
    EXPECT_EQ(o.exit_code, 2) << limit << ": " << o.err;
    EXPECT_NE(o.err.find(message), std::string::npos) << limit << ": " << o.err;
  }
  // Raised: a run of more substeps than the default allows passes the check.
  const std::string long_run = dir.write(
      "long.yaml",
      "time: {duration: 1e8, dt: 0.001}\nmaterials: {a: }\nparticles:\n  - list: {positions: [[0, 0, 0]], radius: 0.1}\n");
  EXPECT_EQ(marbles("check " + long_run, dir).exit_code, 2);
  EXPECT_EQ(marbles("check " + long_run + " --limit substeps=1e12", dir).exit_code, 0);
  // --duration is held to the same limit, and to dt, as time.duration is.
  const Outcome longer = marbles("run " + scene + " --quiet --no-render --out " + dir.path() + "/o --duration 1e10", dir);
  EXPECT_EQ(longer.exit_code, 2) << longer.err;
  EXPECT_NE(longer.err.find("--duration: a duration of 1e+10 s makes 1e+13 substeps (duration / time.dt x "
                            "time.substeps), more than the limit 1e+10 (--limit substeps=N raises it)"),
            std::string::npos)
      << longer.err;
  const Outcome shorter = marbles("run " + scene + " --quiet --no-render --out " + dir.path() + "/o --duration 1e-4", dir);
  EXPECT_EQ(shorter.exit_code, 2) << shorter.err;
  EXPECT_NE(shorter.err.find("--duration: a duration of 1e-04 s is shorter than a step, time.dt = 0.001 s"), std::string::npos) << shorter.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path() + "/o/summary.json"));
  // --duration takes the file's place before the rules: a file whose own
  // duration they refuse runs for a --duration they allow.
  const Outcome instead =
      marbles("run " + long_run + " --quiet --summary-only --backend cpu --out " + dir.path() + "/o --duration 0.01", dir);
  EXPECT_EQ(instead.exit_code, 0) << instead.err;
  EXPECT_NE(slurp(dir.path() + "/o/summary.json").find("\"steps\": 10,"), std::string::npos);
  // The benchmarks' sphere counts are held to the same guards, before anything is made.
  for (const std::string bench : {"bench step", "bench effects", "bench broadphase"}) {
    const Outcome many = marbles(bench + " --n 3000000000", dir);
    EXPECT_EQ(many.exit_code, 2) << bench << ": " << many.err;
    EXPECT_NE(many.err.find("--n: must be <= 1e+09 (--limit spheres=N raises it), got 3000000000"), std::string::npos)
        << bench << ": " << many.err;
    const Outcome tight = marbles(bench + " --n 1000 --limit memory=1e-12", dir);
    EXPECT_EQ(tight.exit_code, 2) << bench << ": " << tight.err;
    EXPECT_NE(tight.err.find("--n: would make 1000 spheres"), std::string::npos) << bench << ": " << tight.err;
  }
  const Outcome bad = marbles("check " + scene + " --limit spheres=lots", dir);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--limit: spheres must be a positive number, got 'lots'"), std::string::npos) << bad.err;
}

// Output that cannot be written: a folder sits where summary.json goes (as
// root, permissions would not stop us): exit 1 with the path and the
// reason. An output folder that cannot be made (a file above it) is bad
// input, named where it was given (exit 2; it was exit 1 without the key).
TEST_F(Robustness, UnwritableOutputIsExitOneWithThePath) {
  const test::ScratchDir dir("robust_unwritable");
  const std::string blocker = dir.write("file", "not a folder");
  const Outcome a = marbles("run " MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml --quiet --summary-only --backend cpu "
                            "--set output.dir=" + blocker + "/out", dir);
  EXPECT_EQ(a.exit_code, 2) << a.err;
  EXPECT_NE(a.err.find("--set output.dir=" + blocker + "/out: output.dir: '" + blocker + "/out' cannot be made: '" +
                       blocker + "' is not a folder"),
            std::string::npos)
      << a.err;
  const std::string out = dir.path() + "/o";
  fs::create_directories(out + "/summary.json");
  const Outcome b = marbles("run " MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml --quiet --summary-only --backend cpu "
                            "--out " + out, dir);
  EXPECT_EQ(b.exit_code, 1) << b.err;
  EXPECT_NE(b.err.find("cannot write " + out + "/summary.json: it is a folder, not a file; nothing was replaced"),
            std::string::npos)
      << b.err;
  EXPECT_TRUE(fs::is_directory(out + "/summary.json"));
}

// Mistakes on the command line are named, exit 2: a command that is not one
// (CLI11 said only "A subcommand is required"), an option given an empty
// value (`--repeats ""` was 0 repeats past the check that refuses 0, and
// crashed; `--n ""` timed nothing), an --out or output.dir that is a file or
// a link to nothing (exit 1, without the option's name or the key's place),
// and an OMP_NUM_THREADS past --threads' bound.
// Output that standard output could not take is not a success (exit 1).
TEST_F(Robustness, CommandLineMistakesAreNamed) {
  const test::ScratchDir dir("robust_command_line");
  const std::string scene = MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml";
  const std::string file = dir.write("file", "not a folder");
  const std::string dir_scene =
      dir.write("d.yaml", "time: {duration: 0.01, dt: 0.001}\nmaterials: {a: {}}\n"
                          "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1}\noutput: {dir: " + file + "}\n");
  const std::string far_scene =
      dir.write("far.yaml", "time: {duration: 0.002, dt: 0.001}\neffects: [collisions]\nmaterials: {a: {}}\n"
                            "particles:\n  - list: {positions: [[-1e30, 0, 0], [1e30, 0, 0]], radius: 0.1}\n");
  const std::string dangling = dir.path() + "/gone";
  fs::create_symlink(dir.path() + "/nothing-here", dangling);
  const std::pair<std::string, std::string> cases[] = {
      {"runn " + scene, "marbles: unknown command 'runn' (did you mean 'run'?)"},
      {"bench bogus", "marbles bench: unknown command 'bogus'; expected one of: broadphase, step, effects"},
      {"--bogus", "marbles: unknown option '--bogus' where a command goes"},
      {"bench step --backend cpu --n 10 --repeats \"\"", "--repeats: an empty value"},
      {"bench step --backend cpu --n \"\" --repeats 1", "--n: an empty value"},
      {"bench effects --backend cpu --n 10 --repeats=", "--repeats"},
      {"run " + scene + " --backend cpu --out \"\"", "--out: an empty value"},
      {"run " + scene + " --backend cpu --quiet --out " + file, "--out: '" + file + "' exists and is not a folder"},
      {"study " + scene + " --vary time.dt=1e-3 --out \"\"", "--out: an empty value"},
      // An empty value where the option's own check would fail on it first ("Value  not in range").
      {"study " + scene + " --vary time.dt=1e-3 --repeats \"\"", "--repeats: an empty value"},
      {"pairs " + file + " --margin=", "--margin: an empty value"},
      // Arguments nobody takes, quoted: an empty one said nothing ("was not expected: ").
      {"run " + scene + " --backend cpu \"\"", "an argument that no command or option here takes: '' (an empty one)"},
      {"bench step --backend cpu --n 10 --repeats 1 extra \"\"",
       "arguments that no command or option here takes: 'extra', '' (an empty one)"},
      {"check " + scene + " --precision \"\"", "--precision: an empty value"},
      // Whole numbers in decimal, as a scene's (CLI11 read 0x10 as 16 and " 100" as 100).
      {"bench step --backend cpu --n 0x10 --repeats 1", "--n: expected a whole number, got '0x10'"},
      {"bench step --backend cpu --n \" 100\" --repeats 1", "--n: expected a whole number, got ' 100'"},
      {"study " + scene + " --vary time.dt=1e-3 --repeats 0x2", "--repeats: expected a whole number, got '0x2'"},
      {"run " + scene + " --threads 0b11", "--threads: expected a whole number, got '0b11'"},
      // Leading zeros are decimal (the conversion read 010 as octal 8): 0100000 is 100000, past render's bound.
      {"render " + dir.path() + " --width 08193", "--width: Value 8193 not in range 16 to 8192"},
      {"bench step --backend cpu --n 100 --repeats 1 --effects gravity,,collisions", "--effects: an empty item in 'gravity,,collisions'"},
      // A benchmark keeps every call's time: at most 10^6 of them (2^31 - 1 grew without bound).
      {"bench broadphase --backend cpu --n 1 --repeats 2147483647", "--repeats: Value 2147483647 not in range 1 to 1000000"},
      // The scene's output.dir a file, or a link to nothing: named where it was given (exit 1 without it before).
      {"run " + scene + " --backend cpu --quiet --set output.dir=" + file,
       "--set output.dir=" + file + ": output.dir: '" + file + "' exists and is not a folder"},
      {"run " + dir_scene + " --backend cpu --quiet", dir_scene + ":5:15: output.dir: '" + file + "' exists and is not a folder"},
      {"check " + dir_scene, dir_scene + ":5:15: output.dir: '" + file + "' exists and is not a folder"},
      // Spheres too far apart for the seed's grid: the option named up front (exit 1 at the first step before).
      {"run " + far_scene + " --backend cpu --quiet --broadphase seed --precision double --out " + dir.path() + "/far",
       "--broadphase: seed: the spheres span more than 2^62 cells"},
      {"run " + scene + " --backend cpu --quiet --out " + dangling, "--out: '" + dangling + "' is a link to nothing"},
      {"bench step --backend cpu --n 10 --write-scene " + dangling, "--write-scene: '" + dangling + "' is a link to nothing"},
      {"bench step --backend cpu --n 10 --write-scene " + file, "--write-scene: '" + file + "' exists and is not a folder"},
      {"run " + scene + " --backend cpu --quiet --set output.dir=" + dangling,
       "output.dir: '" + dangling + "' is a link to nothing"},
  };
  for (const auto& [args, said] : cases) {
    const Outcome o = marbles(args, dir);
    EXPECT_EQ(o.exit_code, 2) << args << ": " << o.err;
    EXPECT_NE(o.err.find(said), std::string::npos) << args << ": " << o.err;
  }
  // Leading zeros are decimal, as written (the conversion read 010 as octal 8): the same
  // spheres for --seed 010 as for 10, and 10 of them for --n 010.
  const auto printed = [&](const std::string& args) {
    const std::string out = dir.path() + "/stdout.txt";
    EXPECT_EQ(std::system(("'" + kMarbles + "' " + args + " > '" + out + "' 2>/dev/null").c_str()), 0) << args;
    return slurp(out);
  };
  const auto pairs_of = [](const std::string& json) { return nlohmann::json::parse(json).at("pairs").get<int>(); };
  const std::string seeds = "bench broadphase --backend cpu --n 1000 --repeats 1 --json --seed ";
  EXPECT_EQ(pairs_of(printed(seeds + "010")), pairs_of(printed(seeds + "10")));
  EXPECT_NE(pairs_of(printed(seeds + "010")), pairs_of(printed(seeds + "8"))) << "premise: the seeds' sets differ";
  EXPECT_EQ(nlohmann::json::parse(printed("bench step --backend cpu --n 010 --repeats 1 --json"))
                .at("results")[0].at("n").get<int>(),
            10);
  // A block's masses out of range through an override: named by the override, not the file's line
  // (which holds radius 0.05).
  const Outcome heavy = marbles("check " + scene + " --set particles[0].list.radius=1e38", dir);
  EXPECT_EQ(heavy.exit_code, 2) << heavy.err;
  EXPECT_EQ(heavy.err.rfind("--set particles[0].list.radius=1e38: particles[0]: sphere 0 of the block", 0), 0u)
      << heavy.err;
  // Spheres too far apart for the subdivision's grid: the option named (home and brute take them).
  const std::string spread = dir.write("spread.csv", "1e18,0,0,1e-3\n-1e18,0,0,1e-3\n0,0,0,1e-3\n0,0,0.001,1e-3\n");
  const Outcome wide = marbles("pairs " + spread + " --backend cpu --algorithm subdivision", dir);
  EXPECT_EQ(wide.exit_code, 2) << wide.err;
  EXPECT_EQ(wide.err.rfind(spread + ": --algorithm: subdivision: the spheres span more than 2^62 cells", 0),
            0u)
      << wide.err;
  EXPECT_NE(wide.err.find("; --algorithm home or brute take them"), std::string::npos) << wide.err;
  // An override elsewhere in the block (fixed) is not blamed for the file's radius.
  const std::string heavy_scene = dir.write("heavy.yaml", "time: {duration: 0.01, dt: 0.001}\nmaterials: {a: {}}\n"
                                                    "particles:\n  - list: {positions: [[0, 0, 1]], radius: 1e30}\n");
  const Outcome file_radius = marbles("check " + heavy_scene + " --set particles[0].fixed=false", dir);
  EXPECT_EQ(file_radius.exit_code, 2) << file_radius.err;
  EXPECT_EQ(file_radius.err.rfind(heavy_scene + ":4:5: particles[0]: sphere 0 of the block", 0), 0u) << file_radius.err;
  // A file's name with a line break is said in one line.
  const std::string broken = dir.write("nl\nrows.csv", "0,0,0,0.1\nnan,0,0,0.1\n");
  const Outcome named = marbles("pairs \"" + broken + "\" --backend cpu", dir);
  EXPECT_EQ(named.exit_code, 2) << named.err;
  EXPECT_NE(named.err.find(dir.path() + "/nl\\x0arows.csv:2:"), std::string::npos) << named.err;
  EXPECT_EQ(std::count(named.err.begin(), named.err.end(), '\n'), 1) << named.err;
  const Outcome missing = marbles("pairs \"" + dir.path() + "/no\nsuch.csv\" --backend cpu", dir);
  EXPECT_EQ(missing.exit_code, 2) << missing.err;
  EXPECT_EQ(std::count(missing.err.begin(), missing.err.end(), '\n'), 1) << missing.err;
  EXPECT_EQ(slurp(file), "not a folder");
  EXPECT_FALSE(fs::exists(dir.path() + "/nothing-here"));
  // The same spheres run with the default broad phase.
  EXPECT_EQ(marbles("run " + far_scene + " --backend cpu --quiet --precision double --out " + dir.path() + "/far2", dir)
                .exit_code,
            0);
  EXPECT_TRUE(fs::is_symlink(dangling));
  // OMP_NUM_THREADS is held to --threads' bound (it was taken as it was); --threads stands over it.
  const std::string run = "run " + scene + " --backend cpu --quiet --summary-only --duration 0.01 --out " + dir.path();
  const Outcome threads = marbles(run + "/t", dir, "OMP_NUM_THREADS=100000");
  EXPECT_EQ(threads.exit_code, 2) << threads.err;
  EXPECT_NE(threads.err.find("OMP_NUM_THREADS: must be <= 4096, got 100000"), std::string::npos) << threads.err;
  EXPECT_EQ(marbles(run + "/t --threads 2", dir, "OMP_NUM_THREADS=100000").exit_code, 0);
  EXPECT_EQ(marbles("bench step --backend cpu --n 100 --repeats 1", dir, "OMP_NUM_THREADS=5000").exit_code, 2);
  const Outcome full = marbles("check " + scene + " >/dev/full", dir);
  EXPECT_EQ(full.exit_code, 1) << full.err;
  EXPECT_NE(full.err.find("marbles: cannot write the standard output"), std::string::npos) << full.err;
  EXPECT_EQ(marbles("check " + scene, dir).exit_code, 0);
}

// A vector whose square overflows the run's precision (a speed, a spin, a
// gravity, a wall's velocity, a position) is an input error naming its key,
// not a run whose energies turn to inf or whose broad phase fails midway;
// in double the same values fit. The advice of a warning stays a number.
TEST_F(Robustness, VectorsWhoseSquareOverflowsAreRefused) {
  const test::ScratchDir dir("robust_square");
  const std::string scene = dir.write(
      "s.yaml", "time: {duration: 0.01, dt: 0.001}\nmaterials: {a: }\n"
                "walls:\n  - plane: {point: [0, 0, 0], normal: [0, 0, 1]}\n"
                "particles:\n  - list: {positions: [[0, 0, 1], [0.2, 0, 1]], radius: 0.05}\n");
  for (const std::string set : {"particles[0].angular_velocity=[1e38,0,0]", "particles[0].velocity=[0,2e19,0]",
                                "gravity=[0,0,-1e20]", "walls[0].velocity=[0,0,1e30]",
                                "particles[0].list.positions=[[2e38,0,1],[-2e38,0,1]]"}) {
    const Outcome f = marbles("check " + scene + " --precision float --set " + set, dir);
    EXPECT_EQ(f.exit_code, 2) << set << ": " << f.err;
    EXPECT_NE(f.err.find("too large for float precision: its squared length overflows"), std::string::npos)
        << set << ": " << f.err;
    EXPECT_NE(f.err.find(set.substr(0, set.find('='))), std::string::npos) << set << ": " << f.err;
    EXPECT_EQ(marbles("check " + scene + " --precision double --set " + set, dir).exit_code, 0) << set;
  }
  const std::string rows = dir.write("rows.csv", "x,y,z,r,vx,vy,vz\n0,0,1,0.05,0,0,0\n1,0,1,0.05,3e19,0,0\n");
  const std::string from_csv = dir.write("c.yaml", "time: {duration: 0.01, dt: 0.001}\nmaterials: {a: }\n"
                                                   "particles:\n  - csv: {path: rows.csv}\n");
  const Outcome c = marbles("check " + from_csv + " --precision float", dir);
  EXPECT_EQ(c.exit_code, 2) << c.err;
  EXPECT_NE(c.err.find("rows.csv:3:12: vx: too large for float precision: the squared length of (vx, vy, vz) overflows"),
            std::string::npos)
      << c.err;
  const Outcome fast = marbles("check " + scene + " --precision float --set 'particles[0].velocity=[1e18,0,0]'", dir);
  EXPECT_EQ(fast.exit_code, 0) << fast.err;
  EXPECT_NE(fast.err.find("raise time.substeps to at least 2e+16 (or lower time.dt)"), std::string::npos) << fast.err;
}

// A mass beyond the precision of the run (radius 1e30) is an input error,
// not a run with energies of 0.
TEST_F(Robustness, MassBeyondThePrecisionIsRefused) {
  const test::ScratchDir dir("robust_mass");
  const std::string scene =
      dir.write("s.yaml", "time: {duration: 1, dt: 0.001}\nmaterials: {a: }\nparticles:\n"
                          "  - list: {positions: [[0, 0, 0]], radius: 1e30}\n");
  const Outcome o = marbles("check " + scene, dir);
  EXPECT_EQ(o.exit_code, 2) << o.err;
  EXPECT_NE(o.err.find("is out of range for float precision"), std::string::npos) << o.err;
  EXPECT_NE(o.err.find("s.yaml:4:5: particles[0]: sphere 0 of the block (radius 1e+30 m"), std::string::npos) << o.err;
  // In double the same sphere fits.
  EXPECT_EQ(marbles("check " + scene + " --precision double", dir).exit_code, 0);
}

// Masses whose contact impulses leave the precision's range are refused by
// `check` and `run` (exit 2), not run into a NaN at the first meeting (exit
// 1): two spheres of density 2e37 meeting head on at 100 m/s made an impulse
// of 7.9e38 N s, inf in float. Slower, the same spheres run; in double they
// fit. At the light end, an inverse mass past 1/8 of float's range made the
// pair's tangential effective mass 1 / inf = 0: friction silently off.
TEST_F(Robustness, ImpulsesBeyondThePrecisionAreRefused) {
  const test::ScratchDir dir("robust_impulse");
  const std::string scene =
      dir.write("s.yaml", "time: {duration: 0.3, dt: 0.001}\neffects: [collisions, restitution]\n"
                          "materials: {a: {density: 2e37, restitution: 0.5, friction: 0.5}}\nparticles:\n"
                          "  - list: {positions: [[-0.6, 0, 0], [0.6, 0, 0]], radius: 0.5, "
                          "velocities: [[50, 0, 0], [-50, 0, 0]]}\n");
  for (const std::string& command : {"check " + scene, "run " + scene + " --backend cpu --out " + dir.path() + "/o"}) {
    const Outcome o = marbles(command, dir);
    EXPECT_EQ(o.exit_code, 2) << command << ": " << o.err;
    EXPECT_NE(o.err.find("s.yaml:5:5: particles[0]: sphere 0 of the block (radius 0.5 m, density 2e+37 kg/m^3): too "
                         "heavy for the scene's speeds"),
              std::string::npos)
        << o.err;
    EXPECT_NE(o.err.find("contact impulses out of range for float precision"), std::string::npos) << o.err;
    EXPECT_NE(o.err.find("set solver.precision: double"), std::string::npos) << o.err;
  }
  EXPECT_EQ(marbles("check " + scene + " --precision double", dir).exit_code, 0);
  // In double the kinetic energy's sums overflow first (they were inf: null in summary.json).
  const Outcome e = marbles("check " + scene + " --precision double --set materials.a.density=1e302 "
                            "--set 'particles[0].list.velocities=[[1e4,0,0],[-1e4,0,0]]'", dir);
  EXPECT_EQ(e.exit_code, 2) << e.err;
  EXPECT_NE(e.err.find("a kinetic energy out of range of its sums in double"), std::string::npos) << e.err;
  const std::string slow = " --set 'particles[0].list.velocities=[[0.5,0,0],[-0.5,0,0]]'";
  EXPECT_EQ(marbles("run " + scene + slow + " --backend cpu --out " + dir.path() + "/slow", dir).exit_code, 0);

  const std::string light =
      dir.write("l.yaml", "time: {duration: 0.1, dt: 0.001}\nmaterials: {a: {density: 1.2e-38}}\nparticles:\n"
                          "  - list: {positions: [[0, 0, 0], [2, 0.7, 0]], radius: 0.7}\n");
  const Outcome l = marbles("check " + light, dir);
  EXPECT_EQ(l.exit_code, 2) << l.err;
  EXPECT_NE(l.err.find("l.yaml:4:5: particles[0]: sphere 0 of the block (radius 0.7 m, density 1.2e-38 kg/m^3): its "
                       "mass 1.72411e-38 kg or moment of inertia is out of range for float precision"),
            std::string::npos)
      << l.err;
  EXPECT_EQ(marbles("check " + light + " --precision double", dir).exit_code, 0);

  // With friction, the clamp to the cone squares the impulse: spheres of 5e29 kg in an oblique hit at 10 m/s (an
  // impulse of ~1e31 N s, its square past float's range) slid as if mu were unbounded. Refused in float, run in
  // double; without friction they run in float.
  const std::string oblique =
      dir.write("f.yaml", "time: {duration: 0.1, dt: 0.001}\neffects: [collisions, friction]\n"
                          "materials: {a: {density: 1e30, friction: 0.05}}\nparticles:\n"
                          "  - list: {positions: [[-0.6, 0.5, 0], [0.6, 0, 0]], radius: 0.5, "
                          "velocities: [[10, 0, 0], [0, 0, 0]]}\n");
  const Outcome f = marbles("check " + oblique, dir);
  EXPECT_EQ(f.exit_code, 2) << f.err;
  EXPECT_NE(f.err.find("f.yaml:5:5: particles[0]: sphere 0 of the block"), std::string::npos) << f.err;
  EXPECT_NE(f.err.find("friction impulses whose squares are out of range for float precision"), std::string::npos)
      << f.err;
  EXPECT_EQ(marbles("check " + oblique + " --precision double", dir).exit_code, 0);
  EXPECT_EQ(marbles("check " + oblique + " --set 'effects=[collisions]'", dir).exit_code, 0);
  // Where a wall's motion sets the speed, the wall's key is named, not a sphere's block (a drum spun at 1e30
  // rad/s was refused as "particles[0]: ... too heavy for the scene's speeds").
  const std::string drum =
      dir.write("d.yaml", "time: {duration: 0.1, dt: 0.001}\neffects: [gravity, collisions, walls, friction]\n"
                          "materials: {a: {density: 1000, friction: 0.5}}\n"
                          "walls:\n  - plane: {point: [0, 0, 0], normal: [0, 0, 1]}\n"
                          "  - cylinder: {base: [0, 0, 0], axis: [0, 0, 1], radius: 1, angular_velocity: 1e30}\n"
                          "particles:\n  - list: {positions: [[0, 0, 0.1]], radius: 0.05}\n");
  const Outcome d = marbles("check " + drum, dir);
  EXPECT_EQ(d.exit_code, 2) << d.err;
  EXPECT_NE(d.err.find("d.yaml:6:5: walls[1].cylinder.angular_velocity: too fast for the spheres' mass: it gives "
                       "spheres up to 1e+30 m/s"),
            std::string::npos)
      << d.err;
  EXPECT_EQ(d.err.find("particles["), std::string::npos) << d.err;
  const Outcome pushed = marbles("check " + drum + " --set walls[1].cylinder.angular_velocity=1 "
                                 "--set walls[0].velocity=[0,0,1e19]", dir);
  EXPECT_EQ(pushed.exit_code, 2) << pushed.err;
  EXPECT_NE(pushed.err.find("walls[0].velocity: too fast for the spheres' mass: it gives spheres up to 2e+19 m/s"),
            std::string::npos)
      << pushed.err;
  EXPECT_EQ(marbles("check " + drum + " --set walls[1].cylinder.angular_velocity=10", dir).exit_code, 0);
  // A slow wall beside spheres too heavy for their fall is not blamed: without its motion they are refused still.
  const Outcome heavy = marbles("check " + drum + " --set walls[1].cylinder.angular_velocity=0.01 "
                                "--set materials.a.density=1e22", dir);
  EXPECT_EQ(heavy.exit_code, 2) << heavy.err;
  EXPECT_NE(heavy.err.find("particles[0]: sphere 0 of the block"), std::string::npos) << heavy.err;
  EXPECT_NE(heavy.err.find("too heavy for the scene's speeds"), std::string::npos) << heavy.err;
  // Spheres at rest make no impulse the start can bound: the heaviest double holds is not refused (16 x its mass
  // was inf, and inf x 0 a NaN that refused it).
  EXPECT_EQ(marbles("check " + oblique + " --precision double --set materials.a.density=2.5e307 "
                    "--set 'particles[0].list.velocities=[[0,0,0],[0,0,0]]'", dir).exit_code, 0);
}

// A substep that moves the fastest sphere past what the precision holds (its
// speed times h beyond a sixteenth of the largest number) is refused at
// time.dt, in the precision the scene asks, with the speed and the travel
// named (a travel past double's own range as "more than", not inf); the
// substeps that bring h back make it load.
TEST_F(Robustness, TravelInASubstepPastThePrecisionIsRefusedAtDt) {
  const test::ScratchDir dir("robust_travel");
  const auto scene = [&](const std::string& precision, const std::string& speed, const std::string& dt) {
    return dir.write(precision + ".yaml", "time: {duration: " + dt + ", dt: " + dt + "}\nsolver: {precision: " +
                                              precision + "}\neffects: [collisions]\nmaterials: {a: {density: "
                                              "2500}}\nparticles:\n  - list: {positions: [[0, 0, 1], [1, 0, 1]], "
                                              "radius: 0.1, velocities: [[" + speed + ", 0, 0], [0, 0, 0]]}\n");
  };
  // float: 1e19 m/s (near the largest a velocity may be) for h = 1e19 s moves it 1e38 m, past 3.4e38 / 16.
  const std::string fast = scene("float", "1e19", "1e19");
  const Outcome f = marbles("check " + fast, dir);
  EXPECT_EQ(f.exit_code, 2) << f.err;
  EXPECT_NE(f.err.find("float.yaml:1:"), std::string::npos) << f.err;
  EXPECT_NE(f.err.find("time.dt: a substep of h = 1e+19 s moves the fastest sphere, at up to 1e+19 m/s"),
            std::string::npos) << f.err;
  EXPECT_NE(f.err.find("more than float precision holds with room for its sums (" +
                       significant(double(std::numeric_limits<float>::max()) / 16, 6) + " m)"),
            std::string::npos) << f.err;
  EXPECT_EQ(marbles("check " + fast + " --set time.substeps=100", dir).exit_code, 0);
  EXPECT_EQ(marbles("check " + fast + " --precision double", dir).exit_code, 0);
  // double: 7e153 m/s for h = 1e160 s is past double's own range.
  const Outcome d = marbles("check " + scene("double", "7e153", "1e160"), dir);
  EXPECT_EQ(d.exit_code, 2) << d.err;
  EXPECT_NE(d.err.find("moves the fastest sphere, at up to 7e+153 m/s"), std::string::npos) << d.err;
  EXPECT_NE(d.err.find("), more than " + significant(std::numeric_limits<double>::max() / 16, 6) + " m in it"),
            std::string::npos) << d.err;
  EXPECT_EQ(d.err.find("inf"), std::string::npos) << d.err;
}

// `check` holds a scene to what `run` refuses: the reference's own rules (the
// sphere it names, the effects it needs) are checked by both, with the same
// message, and `run` refuses before it prints its pipeline.
TEST_F(Robustness, CheckRefusesWhatRunRefuses) {
  const test::ScratchDir dir("robust_check_run");
  const std::string scene = MARBLES_SOURCE_DIR "/scenes/validation/bouncing_ball.yaml";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--set 'effects=[walls]'", "reference.rebound_heights: needs the gravity effect"},
      {"--set solver.iterations=1000000", "solver.iterations: must be <= 100000, got 1000000"},  // 8x of it an int
      {"--set reference.rebound_heights.sphere=5", "reference.rebound_heights.sphere: sphere 5 does not exist"},
  };
  for (const auto& [set, message] : cases) {
    const Outcome check = marbles("check " + scene + " " + set, dir);
    EXPECT_EQ(check.exit_code, 2) << set << ": " << check.err;
    EXPECT_NE(check.err.find(message), std::string::npos) << set << ": " << check.err;
    const Outcome run = marbles("run " + scene + " " + set + " --out " + dir.path() + "/o", dir);
    EXPECT_EQ(run.exit_code, 2) << set << ": " << run.err;
    EXPECT_NE(run.err.find(message), std::string::npos) << set << ": " << run.err;
  }
  EXPECT_EQ(marbles("check " + scene, dir).exit_code, 0);
}

// Non-finite numbers on the command line are bad arguments (exit 2).
TEST_F(Robustness, NanArgumentsAreBadArguments) {
  const test::ScratchDir dir("robust_nan");
  const Outcome run = marbles("run " MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml --duration nan", dir);
  EXPECT_EQ(run.exit_code, 2) << run.err;
  EXPECT_NE(run.err.find("--duration: must be a finite number, got nan"), std::string::npos) << run.err;
  const Outcome pairs = marbles("pairs " MARBLES_SOURCE_DIR "/scenes/spheres.csv --margin nan", dir);
  EXPECT_EQ(pairs.exit_code, 2) << pairs.err;
  // A movie's rate that is not a number or that no encoder takes, on the
  // command line or in a scene.
  for (const std::string fps : {"nan", "1e300", "1e-300", "inf"}) {
    const Outcome render = marbles("render " + dir.path() + " --fps " + fps, dir);
    EXPECT_EQ(render.exit_code, 2) << fps << ": " << render.err;
    EXPECT_NE(render.err.find("--fps"), std::string::npos) << fps << ": " << render.err;
  }
  const Outcome movie = marbles("check " MARBLES_SOURCE_DIR "/scenes/demo.yaml --set output.movie.fps=5000", dir);
  EXPECT_EQ(movie.exit_code, 2) << movie.err;
  EXPECT_NE(movie.err.find("output.movie.fps: must be within [0.01, 1000] frames per second, got 5000"),
            std::string::npos)
      << movie.err;
  // Numbers the step takes in its precision, and folders that are files:
  // refused by their argument (exit 2) before any work, not failing later.
  const std::string file = dir.write("afile", "");
  const std::string csv = MARBLES_SOURCE_DIR "/scenes/spheres.csv";
  // Two spheres on one spot, too small for the overlap test's squares: refused, not found apart.
  const std::string tiny = dir.write("tiny.csv", "0,0,0,1e-25\n0,0,0,1e-25\n");
  // A NUL in a row: shown as \x00, the message whole after it.
  const std::string nul = dir.write("nul.csv", std::string("0,0,1,0.1\0junk\n", 15));
  const std::string ball = MARBLES_SOURCE_DIR "/scenes/validation/bouncing_ball.yaml";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"bench effects --n 100 --volume-fraction nan", "--volume-fraction: must be a finite number"},
      {"bench broadphase --n 100 --margin 1e300", "--margin: out of range for float precision"},
      {"pairs " + csv + " --margin=1e39", "--margin: out of range for float precision"},
      {"pairs " + csv + " --margin=0x10", "--margin: expected a number, got 0x10"},  // not CLI11's 16
      {"pairs " + nul, "nul.csv:1:7: r: expected a number, got '0.1\\x00junk'"},
      {"pairs " + tiny, "tiny.csv:1:7: r: too small for float precision: the overlap test squares it (smallest 1.0842022e-19), got 1e-25"},
      {"bench step --scene pile --n 10 --cache " + file, "--cache: '" + file + "' exists and is not a folder"},
      {"bench step --settle-ke nan", "--settle-ke: must be a finite number"},
      {"study " + ball + " --out " + file, "--out: '" + file + "' exists and is not a folder"},
      // Each combination's scene is checked before the first run (no run's log left behind).
      {"study " + ball + " --vary time.dt=1e-3,-1 --out " + dir.path() + "/s", "time.dt: must be > 0, got -1 (study run time.dt=-1)"},
      {"study " + ball + " --vary 'gravity=[0,0,-9.81],[0,0,0]' --out " + dir.path() + "/s",  // held as check holds it
       "needs the gravity effect and a non-zero gravity (study run gravity=[0,0,0])"},
      {"study " + ball + " --out " + file + "/sub", "--out: '" + file + "/sub' cannot be made: '" + file + "' is not a folder"},
      {"render " + dir.path() + "/absent", "Directory does not exist"},
      // Options that meant nothing where given, or given twice, and ranges in plain words.
      {"bench step --scene pile --n 10 --effects gravity", "--effects: is for --scene gas only"},
      {"bench step --n 10 --effects gravity,walls,gravity", "--effects: 'gravity' is given twice"},
      {"bench step --effects , --n 10", "--effects: names nothing in ','"},  // not an effect named --n
      {"bench step --n 10 --effects=", "--effects: names nothing in ''"},
      {"bench step --n 99999999999999999999", "--n: must be <= 1e+09 (--limit spheres=N raises it), got 99999999999999999999"},
      {"bench broadphase --n 100 --sort cub", "--sort: chooses the GPU's sort: give --backend cuda"},
      {"bench broadphase --n 100 --seed -1", "--seed: must be a whole number from 0 to 18446744073709551615"},
      {"bench broadphase --n 100 --seed 18446744073709551616", "--seed: must be a whole number"},
      {"run " + ball + " --duration 0", "--duration: must be > 0, got 0"},
      {"bench broadphase --margin -1", "--margin: must be >= 0, got -1"},
  };
  for (const auto& [args, message] : cases) {
    const Outcome o = marbles(args, dir);
    EXPECT_EQ(o.exit_code, 2) << args << ": " << o.err;
    EXPECT_NE(o.err.find(message), std::string::npos) << args << ": " << o.err;
  }
}

// summary.json stays valid JSON for a scene path with a tab, a quote and a
// byte that is not UTF-8 (replaced by U+FFFD; the rest of the path kept).
TEST_F(Robustness, SummaryEscapesControlCharacters) {
  const test::ScratchDir dir("robust_json");
  const std::string scene = dir.path() + "/ball\t\"x\xff.yaml";
  fs::copy_file(MARBLES_SOURCE_DIR "/scenes/validation/bouncing_ball.yaml", scene);
  std::string quoted = scene;  // for bash -c '...': inside double quotes, a quote is \"
  quoted.replace(quoted.find('"'), 1, "\\\"");
  const Outcome o = marbles("run \"" + quoted + "\" --quiet --summary-only --backend cpu --out " + dir.path() + "/out",
                            dir);
  ASSERT_EQ(o.exit_code, 0) << o.err;
  const std::string summary = slurp(dir.path() + "/out/summary.json");
  EXPECT_EQ(summary.find('\t'), std::string::npos) << summary;
  nlohmann::json j;
  ASSERT_NO_THROW(j = nlohmann::json::parse(summary)) << summary;
  EXPECT_EQ(j.at("scene"), dir.path() + "/ball\t\"x\xef\xbf\xbd.yaml");
}

// summary.json names the scene as the run printed it: its `name`, else the
// file's stem; a --set of the name wins.
TEST_F(Robustness, SummaryNamesTheScene) {
  const test::ScratchDir dir("robust_scene_name");
  std::string text = slurp(MARBLES_SOURCE_DIR "/scenes/validation/bouncing_ball.yaml");
  const std::size_t at = text.find("\nname: ");
  ASSERT_NE(at, std::string::npos);
  text.erase(at + 1, text.find('\n', at + 1) - at);
  std::ofstream(dir.path() + "/drop_42.yaml") << text;
  for (const auto& [set, name] : {std::pair<std::string, std::string>{"", "drop_42"}, {" --set name=pour_7", "pour_7"}}) {
    const Outcome o = marbles("run " + dir.path() + "/drop_42.yaml --quiet --summary-only --backend cpu --duration 0.01"
                              " --overwrite --out " + dir.path() + "/out" + set, dir);
    ASSERT_EQ(o.exit_code, 0) << o.err;
    const nlohmann::json j = nlohmann::json::parse(slurp(dir.path() + "/out/summary.json"));
    EXPECT_EQ(j.at("scene_name"), name) << set;
  }
}

// A full disk (simulated: MARBLES_FAULT_TRUNCATE cuts the file in half
// before it is checked) is exit 1 with the path, and nothing incomplete under
// a final name.
TEST_F(Robustness, IncompleteFilesAreNeverCommitted) {
  const test::ScratchDir dir("robust_disk");
  for (const std::string victim : {"summary", "frame_000002"}) {
    const std::string out = dir.path() + "/" + victim;
    const Outcome o = marbles("run " MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml --quiet --no-render --backend cpu "
                              "--out " + out, dir, "MARBLES_FAULT_TRUNCATE=" + victim);
    if (victim == "frame_000002" && o.err.find("VTK") != std::string::npos) continue;  // a build without VTK
    EXPECT_EQ(o.exit_code, 1) << o.err;
    EXPECT_NE(o.err.find("the file was left incomplete (disk full?)"), std::string::npos) << o.err;
    EXPECT_NE(o.err.find(victim), std::string::npos) << o.err;
    for (const auto& entry : fs::recursive_directory_iterator(out)) {
      const std::string name = entry.path().filename().string();
      EXPECT_EQ(name.find(victim), std::string::npos) << "left behind: " << entry.path();
    }
  }
}

// `marbles render` reads a run's folder: what is wrong in it (no series, a
// series of no frames, a frame missing or cut short) is bad input, exit 2
// naming the file, as a frame without radii is; never exit 1 or a crash.
TEST_F(Robustness, DamagedRunFoldersAreBadInputToRender) {
  const test::ScratchDir dir("robust_render");
  const Outcome empty = marbles("render " + dir.path() + " --no-movie", dir);
  EXPECT_EQ(empty.exit_code, 2) << empty.err;
  EXPECT_NE(empty.err.find(dir.path() + "/series.pvd: not found"), std::string::npos) << empty.err;

  const std::string out = dir.path() + "/o";
  const Outcome run = marbles("run " MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml --quiet --no-render --backend cpu "
                              "--duration 0.05 --out " + out, dir);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  if (!fs::exists(out + "/series.pvd")) GTEST_SKIP() << "a build without VTK output";
  const Outcome whole = marbles("render " + out + " --no-movie --width 16 --height 16", dir);
  if (whole.err.find("OSMesa") != std::string::npos) GTEST_SKIP() << "a build without OSMesa";
  ASSERT_EQ(whole.exit_code, 0) << whole.err;

  const std::string frame = out + "/frames/frame_000002.vtp";
  const std::string bytes = slurp(frame);
  std::ofstream(frame, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  const Outcome cut = marbles("render " + out + " --no-movie --width 16 --height 16", dir);
  EXPECT_EQ(cut.exit_code, 2) << cut.err;
  EXPECT_NE(cut.err.find(frame + ": "), std::string::npos) << cut.err;

  fs::remove(frame);
  const Outcome missing = marbles("render " + out + " --no-movie --width 16 --height 16", dir);
  EXPECT_EQ(missing.exit_code, 2) << missing.err;
  EXPECT_NE(missing.err.find(frame + ": no such file"), std::string::npos) << missing.err;

  std::ofstream(out + "/series.pvd") << "<VTKFile type=\"Collection\"><Collection></Collection></VTKFile>\n";
  const Outcome none = marbles("render " + out + " --no-movie", dir);
  EXPECT_EQ(none.exit_code, 2) << none.err;
  EXPECT_NE(none.err.find(out + "/series.pvd: lists no frames"), std::string::npos) << none.err;
}

// Mutation test of `marbles pairs` input: 300 mutants of scenes/spheres.csv
// (bytes flipped, replaced by separators, digits, signs, exponents and
// non-finite spellings, lines cut or doubled) each end with exit 0 or 2 and,
// for exit 2, a message naming the file; never a crash, a hang or exit 1.
TEST_F(Robustness, MutatedCsvNeverCrashes) {
  const test::ScratchDir dir("robust_csv");
  const std::string original = slurp(MARBLES_SOURCE_DIR "/scenes/spheres.csv");
  std::mt19937 rng(2026);
  const std::vector<std::string> pieces = {",", "\n", "-", "e", "e999", "nan", "inf", "1e-400", "0x1p3", " ",
                                           "\r\n", "#", "\"", "9999999999999999999", ".", "+", "\t", "\0"};
  for (int k = 0; k < 300; ++k) {
    std::string text = original;
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits && !text.empty(); ++e) {
      const std::size_t at = rng() % text.size();
      switch (rng() % 4) {
        case 0: text[at] = static_cast<char>(rng() % 256); break;
        case 1: text.insert(at, pieces[rng() % pieces.size()]); break;
        case 2: text.erase(at, 1 + rng() % 8); break;
        case 3: text.insert(at, text.substr(at, 1 + rng() % 40)); break;
      }
    }
    const std::string csv = dir.write("m.csv", text);
    const Outcome o = marbles("pairs " + csv, dir);
    ASSERT_TRUE(o.exit_code == 0 || o.exit_code == 2) << "mutant " << k << " exit " << o.exit_code << ": " << o.err
                                                      << "\n--- input:\n" << text;
    if (o.exit_code == 2) {
      EXPECT_NE(o.err.find("m.csv"), std::string::npos) << o.err;
    }
  }
}

// The movie check: an MP4 without its index (moov box) is incomplete, and
// so is one whose last box is cut short, also where the index comes first
// (ffmpeg's +faststart, which the movie is made with: a cut mdat passed).
TEST(CompleteChecks, Mp4NeedsItsIndex) {
  const test::ScratchDir dir("robust_mp4");
  auto box = [](const std::string& type, std::size_t payload) {
    const std::size_t size = 8 + payload;
    std::string b{char(size >> 24), char(size >> 16), char(size >> 8), char(size)};
    return b + type + std::string(payload, 'x');
  };
  const std::string whole = box("ftyp", 12) + box("mdat", 100) + box("moov", 40);
  const std::string good = dir.write("good.mp4", whole);
  const std::string cut = dir.write("cut.mp4", whole.substr(0, whole.size() - 20));
  const std::string none = dir.write("none.mp4", box("ftyp", 12) + box("mdat", 100));
  EXPECT_TRUE(render::mp4_has_index()(good));
  EXPECT_FALSE(render::mp4_has_index()(cut));
  EXPECT_FALSE(render::mp4_has_index()(none));
  const std::string fast = box("ftyp", 12) + box("moov", 40) + box("mdat", 100);
  EXPECT_TRUE(render::mp4_has_index()(dir.write("fast.mp4", fast)));
  EXPECT_FALSE(render::mp4_has_index()(dir.write("fast_cut.mp4", fast.substr(0, fast.size() - 20))));
  EXPECT_FALSE(render::mp4_has_index()(dir.write("fast_tail.mp4", fast + "xyz")));  // a box header cut short
  std::string to_end = box("ftyp", 12) + box("moov", 40) + box("mdat", 100);  // mdat's size 0: to the file's end
  to_end.replace(12 + 8 + 40 + 8, 4, std::string(4, '\0'));
  EXPECT_TRUE(render::mp4_has_index()(dir.write("to_end.mp4", to_end)));
  EXPECT_TRUE(render::ends_with("</VTKFile>")(dir.write("a.vtp", "<VTKFile>...</VTKFile>\n")));
  EXPECT_FALSE(render::ends_with("</VTKFile>")(dir.write("b.vtp", "<VTKFile>...</VTKF")));
}

}  // namespace
}  // namespace marbles
