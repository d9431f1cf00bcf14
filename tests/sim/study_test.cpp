// tests/sim/study_test.cpp — `marbles study` end to end (each setting is a
// run of the real program), the Pareto front against a second oracle, and
// float against double runs of one build.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/error.hpp"
#include "sim/study.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles {
namespace {

namespace fs = std::filesystem;
const std::string kMarbles = MARBLES_BINARY_DIR "/bin/marbles";
const std::string kValidation = MARBLES_SOURCE_DIR "/scenes/validation/";

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

class Study : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(kMarbles)) GTEST_SKIP() << kMarbles << " is not built";
  }
  // One run a setting into `out`, quietly, with the built program.
  static StudyOptions options(const std::string& scene, const std::string& out) {
    StudyOptions o;
    o.scene_path = scene;
    o.out_dir = out;
    o.repeats = 1;
    o.marbles = kMarbles;
    o.progress = false;
    return o;
  }
  StudyResult study(const std::string& scene, std::vector<std::string> vary, const test::ScratchDir& dir) {
    StudyOptions o = options(scene, dir.path());
    for (const std::string& v : vary) o.vary.push_back(parse_vary(v));
    o.backend = "cpu";
    std::ostringstream out, err;
    return run_study(o, out, err);
  }
};

// Least-squares slope of log(error) against log(dt).
double slope(const std::vector<double>& dt, const std::vector<double>& error) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double n = static_cast<double>(dt.size());
  for (std::size_t k = 0; k < dt.size(); ++k) {
    const double x = std::log(dt[k]), y = std::log(error[k]);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// The errors of symplectic Euler fall at first order in dt on the incline
// and on the bouncing ball; velocity Verlet is exact there (float rounding).
TEST_F(Study, ErrorFallsWithDtAtTheIntegratorsOrder) {
  for (const std::string scene : {"incline_slide.yaml", "bouncing_ball.yaml"}) {
    const test::ScratchDir dir("study_order");
    const StudyResult r = study(kValidation + scene,
                                {"solver.integrator=symplectic_euler,velocity_verlet", "time.dt=8e-3,4e-3,2e-3,1e-3,5e-4,2.5e-4"},
                                dir);
    ASSERT_EQ(r.rows.size(), 12u);
    std::vector<double> dt, euler;
    for (const StudyRow& row : r.rows) {
      if (row.values[0] == "symplectic_euler") {
        dt.push_back(std::stod(row.values[1]));
        euler.push_back(row.error);
      } else {
        EXPECT_LT(row.error, 1e-4) << scene << " verlet dt " << row.values[1];
      }
      EXPECT_GT(row.ms_per_simulated_second, 0);
      EXPECT_GT(row.steps, 0u);
    }
    EXPECT_NEAR(slope(dt, euler), 1.0, 0.35) << scene;
    EXPECT_LT(euler.back(), euler.front()) << scene;
    // The files: a row per setting in the CSV, the table in study.md.
    const std::string csv = slurp(dir.path() + "/study.csv");
    EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 13) << csv;
    EXPECT_EQ(csv.rfind("solver.integrator,time.dt,error,", 0), 0u) << csv;
    EXPECT_NE(slurp(dir.path() + "/study.md").find("| velocity_verlet | 5e-4 |"), std::string::npos);
  }
}

// A reference that is deliberately wrong shows as a large error in the study.
TEST_F(Study, AWrongReferenceShowsAsALargeError) {
  const test::ScratchDir dir("study_wrong");
  StudyOptions o = options(kValidation + "bouncing_ball.yaml", dir.path());
  o.set = {"reference.rebound_heights.restitution=0.7"};
  std::ostringstream out, err;
  const StudyResult r = run_study(o, out, err);
  ASSERT_EQ(r.rows.size(), 1u);
  EXPECT_GT(r.rows[0].error, 0.2);
}

// A study into the folder of an earlier, larger one: the earlier runs past
// this study's count (runs/N, runs/N.log) are removed, this study's kept,
// and a file of the user's in runs/ is left alone.
TEST_F(Study, AnEarlierStudysExtraRunsAreRemoved) {
  const test::ScratchDir dir("study_again");
  const fs::path runs = fs::path(dir.path()) / "runs";
  ASSERT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=4e-3,2e-3,1e-3"}, dir).rows.size(), 3u);
  for (const char* name : {"0", "1", "2", "2.log"}) ASSERT_TRUE(fs::exists(runs / name)) << name;
  std::ofstream(runs / "notes.txt") << "mine";
  ASSERT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=4e-3,2e-3"}, dir).rows.size(), 2u);
  for (const char* name : {"0", "1", "1.log", "notes.txt"}) EXPECT_TRUE(fs::exists(runs / name)) << name;
  for (const char* name : {"2", "2.log"}) EXPECT_FALSE(fs::exists(runs / name)) << name;
}

// A study replaces only what a study wrote (its record, .marbles-study, names
// the last one's files): a user's folder runs/0 or table study.md where the
// study would write is refused up front, naming --out, with nothing touched;
// files of the user's that are past the study's count (runs/5, runs/9.log)
// stay, also when a smaller study removes the earlier study's runs/1. With
// overwrite the user's files are replaced, and its runs/N past the count go.
TEST_F(Study, AStudyReplacesOnlyWhatAStudyWrote) {
  const test::ScratchDir dir("study_users_files");
  const fs::path root = dir.path(), runs = root / "runs";
  fs::create_directories(runs / "5" / "sub");
  fs::create_directories(runs / "0");
  std::ofstream(runs / "5" / "sub" / "deep.txt") << "x";
  std::ofstream(runs / "9.log") << "y";
  std::ofstream(runs / "0" / "mine.txt") << "z";
  const std::string ball = kValidation + "bouncing_ball.yaml";
  const auto refused = [&](const std::string& name) {
    try {
      study(ball, {"time.dt=4e-3,2e-3"}, dir);
      ADD_FAILURE() << "no error for " << name;
    } catch (const InputError& e) {
      EXPECT_EQ(e.key(), "--out");
      EXPECT_NE(e.message().find((root / name).string() + " is there, and no earlier study in " + root.string() +
                                 " wrote it: a study replaces only its own files (move it, or give --overwrite)"),
                std::string::npos)
          << e.message();
    }
  };
  refused("runs/0");
  EXPECT_EQ(slurp((runs / "0" / "mine.txt").string()), "z");
  EXPECT_FALSE(fs::exists(root / "study.csv"));
  fs::remove_all(runs / "0");
  ASSERT_EQ(study(ball, {"time.dt=4e-3,2e-3"}, dir).rows.size(), 2u);
  ASSERT_EQ(study(ball, {"time.dt=4e-3"}, dir).rows.size(), 1u);
  for (const char* name : {"0", "0.log", "5/sub/deep.txt", "9.log"}) EXPECT_TRUE(fs::exists(runs / name)) << name;
  for (const char* name : {"1", "1.log"}) EXPECT_FALSE(fs::exists(runs / name)) << name;
  // A table of the user's in a folder of its own.
  const test::ScratchDir other("study_users_table");
  std::ofstream(fs::path(other.path()) / "study.md") << "my notes";
  fs::create_directories(fs::path(other.path()) / "runs" / "7");
  try {
    study(ball, {"time.dt=4e-3"}, other);
    ADD_FAILURE() << "no error for study.md";
  } catch (const InputError& e) {
    EXPECT_NE(e.message().find("/study.md is there"), std::string::npos) << e.message();
  }
  EXPECT_EQ(slurp(other.path() + "/study.md"), "my notes");
  StudyOptions o = options(ball, other.path());
  o.vary.push_back(parse_vary("time.dt=4e-3"));
  o.backend = "cpu";
  o.overwrite = true;
  std::ostringstream out, err;
  ASSERT_EQ(run_study(o, out, err).rows.size(), 1u);
  EXPECT_NE(slurp(other.path() + "/study.md"), "my notes");
  EXPECT_FALSE(fs::exists(fs::path(other.path()) / "runs" / "7"));
  // A table of the user's put there while the runs run: found before the record names it.
  const test::ScratchDir late("study_users_late_table");
  StudyOptions l = options(ball, late.path());
  l.vary.push_back(parse_vary("time.dt=4e-3"));
  l.backend = "cpu";
  l.stop = [&] {
    if (fs::exists(late.path() + "/.runs-" + std::to_string(::getpid()))) std::ofstream(late.path() + "/study.csv") << "mine";
    return false;
  };
  EXPECT_THROW(run_study(l, out, err), InputError);
  EXPECT_EQ(slurp(late.path() + "/study.csv"), "mine");
  // A `runs` that is no folder: refused before anything runs.
  const test::ScratchDir file_runs("study_runs_a_file");
  std::ofstream(fs::path(file_runs.path()) / "runs") << "x";
  try {
    study(ball, {"time.dt=4e-3"}, file_runs);
    ADD_FAILURE() << "no error for runs as a file";
  } catch (const InputError& e) {
    EXPECT_NE(e.message().find("/runs is there and is not a folder"), std::string::npos) << e.message();
  }
  EXPECT_FALSE(fs::exists(file_runs.path() + "/study.csv"));
}

// A stop while the settings are checked ends the study there, with nothing
// run or written (a cross product of 10^4 settings takes seconds to check).
TEST_F(Study, AStopWhileTheSettingsAreCheckedRunsNothing) {
  const test::ScratchDir dir("study_stopped_checking");
  StudyOptions o = options(kValidation + "bouncing_ball.yaml", dir.path() + "/out");
  o.vary.push_back(parse_vary("time.dt=4e-3,2e-3,1e-3"));
  o.backend = "cpu";
  int asked = 0;
  o.stop = [&] { return ++asked >= 2; };
  std::ostringstream out, err;
  try {
    run_study(o, out, err);
    ADD_FAILURE() << "the study ran to its end";
  } catch (const StudyStopped& e) {
    EXPECT_EQ(std::string(e.what()),
              "the study was stopped while its settings were checked (2 of 3); nothing was run or written");
  }
  EXPECT_FALSE(fs::exists(dir.path() + "/out"));
}

// More runs than the limit (combinations x repeats) are refused before any
// setting is checked, naming --vary and the limit that raises it.
TEST_F(Study, MoreRunsThanTheLimitAreRefusedUpFront) {
  const test::ScratchDir dir("study_too_many");
  StudyOptions o = options(kValidation + "bouncing_ball.yaml", dir.path() + "/out");
  std::string iterations = "solver.iterations=1", substeps = "time.substeps=1";
  for (int k = 2; k <= 101; ++k) (iterations += ',') += std::to_string(k);  // (GCC 12 warns falsely on "," + string)
  for (int k = 2; k <= 50; ++k) (substeps += ',') += std::to_string(k);
  o.vary = {parse_vary(iterations), parse_vary(substeps)};
  o.repeats = 2;
  std::ostringstream out, err;
  try {
    run_study(o, out, err);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.key(), "--vary");
    EXPECT_EQ(e.message(), "10100 runs (the settings' combinations x --repeats 2), more than the limit 10000 "
                           "(--limit study_runs=N raises it)");
  }
  EXPECT_FALSE(fs::exists(dir.path() + "/out"));
  o.repeats = 1;  // 5 050 runs: within it (stopped at once, while checked)
  o.stop = [] { return true; };
  EXPECT_THROW(run_study(o, out, err), StudyStopped);
}

// Each run's summary names the program as the study was typed (argv[0]),
// not the path the study starts it by (/proc/self/exe), so a run's
// command_line can be typed again.
TEST_F(Study, RunsNameTheProgramAsTyped) {
  const test::ScratchDir dir("study_argv0");
  const std::string command = "'" + kMarbles + "' study " + kValidation +
                              "bouncing_ball.yaml --vary time.dt=4e-3 --repeats 1 --backend cpu --quiet --out " +
                              dir.path() + " > /dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  const auto summary = nlohmann::json::parse(slurp(dir.path() + "/runs/0/summary.json"));
  const std::string line = summary.at("command_line").get<std::string>();
  EXPECT_EQ(line.rfind(kMarbles + " run " + kValidation + "bouncing_ball.yaml ", 0), 0u) << line;
  EXPECT_EQ(line.find("/proc/"), std::string::npos) << line;
  // and the folder the run ends in, where its summary lies: typed again, the line runs.
  const std::string out = " --out " + dir.path() + "/runs/0";
  EXPECT_EQ(line.size() - line.rfind(out), out.size()) << line;
  const test::ScratchDir again("study_argv0_again");
  std::string retyped = line.substr(0, line.rfind(out)) + " --out " + again.path() + " > /dev/null 2>&1";
  ASSERT_EQ(std::system(retyped.c_str()), 0) << retyped;
  const auto second = nlohmann::json::parse(slurp(again.path() + "/summary.json"));
  EXPECT_EQ(second.at("steps"), summary.at("steps"));
  EXPECT_EQ(second.at("kinetic_energy_end"), summary.at("kinetic_energy_end"));
}

// A study that fails midway leaves the earlier study in its folder whole:
// its tables and all of its runs, none of the failed study's. The next study
// clears the failed one's runs away.
TEST_F(Study, AFailedStudyLeavesTheEarlierOneWhole) {
  const test::ScratchDir dir("study_failed");
  const fs::path runs = fs::path(dir.path()) / "runs";
  ASSERT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=4e-3,2e-3,1e-3"}, dir).rows.size(), 3u);
  const std::string table = slurp(dir.path() + "/study.csv"), first = slurp((runs / "0" / "summary.json").string());
  ASSERT_FALSE(table.empty());
  ASSERT_FALSE(first.empty());
  ::setenv("MARBLES_FAULT_NAN_STEP", "3:all", 1);  // every run's step 3 fails every try: exit 1
  EXPECT_THROW(study(kValidation + "bouncing_ball.yaml", {"time.dt=2e-3,1e-3"}, dir), RuntimeFailure);
  ::unsetenv("MARBLES_FAULT_NAN_STEP");
  EXPECT_EQ(slurp(dir.path() + "/study.csv"), table);
  EXPECT_EQ(slurp((runs / "0" / "summary.json").string()), first);
  for (const char* name : {"0.log", "1", "2", "2.log"}) EXPECT_TRUE(fs::exists(runs / name)) << name;
  // The failed study's folder is removed at the next start, as is any study's that no longer runs; a live one's
  // (process 1's) and folders of other names (a dead one's with a suffix too) are left alone.
  const pid_t dead = ::fork();
  if (dead == 0) ::_exit(0);
  ASSERT_GT(dead, 0);
  ::waitpid(dead, nullptr, 0);
  const fs::path root(dir.path());
  for (const std::string& name : {".runs-" + std::to_string(dead), std::string(".runs-1"), std::string(".runs-notes"),
                                   ".runs-" + std::to_string(dead) + ".bak"})
    fs::create_directories(root / name);
  ASSERT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=4e-3"}, dir).rows.size(), 1u);
  std::vector<std::string> left;
  for (const fs::directory_entry& e : fs::directory_iterator(root))
    if (e.path().filename().string().starts_with(".runs-")) left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  std::vector<std::string> kept{".runs-" + std::to_string(dead) + ".bak", ".runs-1", ".runs-notes"};
  std::sort(kept.begin(), kept.end());
  EXPECT_EQ(left, kept);
  EXPECT_NE(slurp(dir.path() + "/study.csv"), table);
  EXPECT_FALSE(fs::exists(runs / "1"));
}

// A study asked to stop (StudyOptions::stop: the Python module's interrupt)
// ends its running run and throws StudyStopped, naming the run and where its
// runs so far are; an earlier study is left whole, and no run is left.
TEST_F(Study, AStoppedStudyEndsItsRunAndLeavesTheEarlierOneWhole) {
  const test::ScratchDir dir("study_stopped");
  ASSERT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=4e-3,2e-3"}, dir).rows.size(), 2u);
  const std::string table = slurp(dir.path() + "/study.csv");
  StudyOptions o = options(kValidation + "bouncing_ball.yaml", dir.path());
  o.vary.push_back(parse_vary("time.dt=2e-5,1e-5"));
  o.set = {"time.duration=600"};  // runs of minutes: only a stop ends them
  o.backend = "cpu";
  int asked = 0;
  o.stop = [&] { return ++asked >= 5; };  // two looks while the settings are checked, then about 100 ms into the first run
  std::ostringstream out, err;
  try {
    run_study(o, out, err);
    ADD_FAILURE() << "the study ran to its end";
  } catch (const StudyStopped& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("the study was stopped during run time.dt=2e-5 (1 of 2); its runs so far are in " +
                        dir.path() + "/.runs-" + std::to_string(::getpid())),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("left whole"), std::string::npos) << what;
  }
  EXPECT_EQ(asked, 5);
  EXPECT_EQ(slurp(dir.path() + "/study.csv"), table);
  errno = 0;
  EXPECT_EQ(::waitpid(-1, nullptr, WNOHANG), -1) << "a run is left";  // no child, running or unreaped
  EXPECT_EQ(errno, ECHILD);
}

// `marbles study` stopped by Ctrl-C in a terminal (SIGINT to its process
// group, so to its run as well, which may end first): "stopped by SIGINT",
// exit 1, not "study run ... failed"; no run is left, the earlier study whole.
TEST_F(Study, CtrlCStopsTheCommandsStudy) {
  const test::ScratchDir dir("study_ctrl_c");
  ASSERT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=4e-3"}, dir).rows.size(), 1u);
  const std::string table = slurp(dir.path() + "/study.csv");
  const std::string err_path = dir.path() + "/err.txt";
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::setpgid(0, 0);
    const int fd = ::open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 2);
    const std::string scene = kValidation + "bouncing_ball.yaml";
    ::execl(kMarbles.c_str(), kMarbles.c_str(), "study", scene.c_str(), "--vary", "time.dt=2e-5,1e-5", "--set",
            "time.duration=600", "--backend", "cpu", "--repeats", "1", "--quiet", "--out", dir.path().c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::setpgid(child, child);
  // Once its first run has started (its log is there), Ctrl-C.
  const fs::path first_log = fs::path(dir.path()) / (".runs-" + std::to_string(child)) / "0.log";
  for (int k = 0; k < 600 && !fs::exists(first_log); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_TRUE(fs::exists(first_log));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the run under way (not timed: either way it stops)
  ASSERT_EQ(::kill(-child, SIGINT), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  const std::string text = slurp(err_path);
  EXPECT_NE(text.find("marbles: stopped by SIGINT: the study was stopped during run time.dt=2e-5 (1 of 2)"),
            std::string::npos)
      << text;
  EXPECT_EQ(text.find("failed"), std::string::npos) << text;
  EXPECT_EQ(::kill(-child, 0), -1) << "a run of the study is left";
  EXPECT_EQ(slurp(dir.path() + "/study.csv"), table);
}

// One study at a time in a folder (as one run at a time): while another
// process holds the folder's lock, a study there is refused and touches
// nothing; once it is let go, the study runs.
TEST_F(Study, OneStudyAtATimeInAFolder) {
  const test::ScratchDir dir("study_lock");
  ASSERT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=4e-3"}, dir).rows.size(), 1u);
  const std::string table = slurp(dir.path() + "/study.csv");
  const int fd = ::open((dir.path() + "/.marbles-run.lock").c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);  // another open file: refused even in this process
  try {
    study(kValidation + "bouncing_ball.yaml", {"time.dt=2e-3"}, dir);
    ADD_FAILURE() << "a study ran in a folder another held";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--out: " + dir.path() + " is being written by another marbles command"),
              std::string::npos)
        << e.what();
  }
  ::close(fd);
  EXPECT_EQ(slurp(dir.path() + "/study.csv"), table);
  EXPECT_EQ(study(kValidation + "bouncing_ball.yaml", {"time.dt=2e-3"}, dir).rows.size(), 1u);
  EXPECT_FALSE(fs::exists(dir.path() + "/.marbles-run.lock"));
}

// The scene's name and the output folder are data to the plot, never
// commands: a name and a folder that close gnuplot's quotes (and the shell's)
// and call system() or `...` draw a plot titled with them, and run nothing;
// a folder named with a line break, a quote and a backslash has its plot too.
// Without gnuplot the study.gp written is checked alone.
TEST_F(Study, NamesAndPathsAreNeverRunAsCommands) {
  const test::ScratchDir dir("study_quotes");
  const std::string marker = dir.path() + "/ran";
  std::string scene = slurp(kValidation + "bouncing_ball.yaml");
  const std::size_t name = scene.find("name: bouncing_ball");
  ASSERT_NE(name, std::string::npos);
  scene.replace(name, 19, "name: \"x'; print system('touch " + marker + "'); set title '`touch " + marker + "`\"");
  const std::string path = dir.write("named.yaml", scene);
  const std::string out = dir.path() + "/o';touch " + marker + ";'\n\"`touch " + marker + "`\\\"";
  std::ostringstream text, err;
  const StudyResult r = run_study(options(path, out), text, err);
  ASSERT_EQ(r.rows.size(), 1u);
  EXPECT_FALSE(fs::exists(marker)) << err.str();
  EXPECT_FALSE(fs::exists(out + "/study.png.tmp"));
  const std::string gp = slurp(out + "/study.gp");
  EXPECT_NE(gp.find("set title \"x'; print system('touch " + marker + "'); set title '\\140touch " + marker +
                    "\\140: error against cost"),
            std::string::npos)
      << gp;
  EXPECT_NE(gp.find("o';touch " + marker + ";'\\012\\\"\\140touch " + marker + "\\140\\\\\\\"/study.png.tmp\""),
            std::string::npos)
      << gp;
  if (std::system("gnuplot --version >/dev/null 2>&1") == 0) {
    EXPECT_TRUE(r.plotted) << err.str();
    EXPECT_TRUE(fs::exists(out + "/study.png")) << err.str();
  }
}

// A scene without a reference is a located error (file:line:col).
TEST_F(Study, MissingReferenceIsALocatedError) {
  const test::ScratchDir dir("study_missing");
  try {
    study(MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml", {"time.dt=1e-3"}, dir);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().line, 1);
    EXPECT_EQ(e.where().column, 1);
    EXPECT_NE(std::string(e.what()).find("bouncing_ball.yaml:1:1: reference:"), std::string::npos) << e.what();
  }
}

// `reference: finest`: the finest setting is the reference, its own error 0.
TEST_F(Study, FinestSettingIsTheReference) {
  const test::ScratchDir dir("study_finest");
  const StudyResult r = study(kValidation + "free_fall.yaml", {"time.dt=4e-3,1e-3"}, dir);
  ASSERT_EQ(r.rows.size(), 2u);
  EXPECT_EQ(r.finest, "time.dt=1e-3");
  EXPECT_EQ(r.rows[1].error, 0.0);
  EXPECT_GT(r.rows[0].error, 0.0);
}

// The Pareto front against a second oracle: sorted by cost, a row is on the
// front when it is strictly more accurate than every cheaper row and no row
// of equal cost is more accurate.
// A varied key's values split at the commas outside brackets and braces;
// an empty value, an unbalanced bracket or a value given twice (1e-3 and
// 0.001 too) is a located error, and a key varied twice (on the command
// line) is refused.
TEST(Vary, ValuesSplitOutsideBrackets) {
  EXPECT_EQ(parse_vary("time.dt=1e-3,5e-4").values, (std::vector<std::string>{"1e-3", "5e-4"}));
  EXPECT_EQ(parse_vary("time.dt= 1e-3 , 5e-4").values, (std::vector<std::string>{"1e-3", "5e-4"}));
  // Values are numbers as the scene reads them: a hexadecimal text is none
  // (the scene refuses it, naming it), so not the same setting as its value.
  EXPECT_EQ(parse_vary("time.dt=0x1p-10,0.0009765625").values,
            (std::vector<std::string>{"0x1p-10", "0.0009765625"}));
  // Past double's range above, of either sign, and below (0): three settings (each refused by the scene, named).
  EXPECT_EQ(parse_vary("time.dt=1e-400,1e400,-1e400").values.size(), 3u);
  const StudyVary g = parse_vary("gravity=[0,0,-1],[0,0,-2],[0, 0, -9.81]");
  EXPECT_EQ(g.key, "gravity");
  EXPECT_EQ(g.values, (std::vector<std::string>{"[0,0,-1]", "[0,0,-2]", "[0, 0, -9.81]"}));
  EXPECT_EQ(parse_vary("materials.a={density: 5, friction: 1},{density: 6}").values,
            (std::vector<std::string>{"{density: 5, friction: 1}", "{density: 6}"}));
  for (const std::string bad : {"time.dt=1e-3,,5e-4", "time.dt=1e-3,", "gravity=[0,0,-1", "gravity=0,0]", "time.dt=",
                                "=1,2", "time.dt=1e-3,5e-4,1e-3", "time.dt=1e-3,0.001", "time.dt=1e-3,0.001 ", "time.dt=1e-3, ",
                                "time.dt=+1e-3,0.001",
                                "gravity=[0,0,-1],[0,0,-1]"}) {
    try {
      parse_vary(bad);
      ADD_FAILURE() << bad << " was taken";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--vary " + bad), std::string::npos) << e.what();
    }
  }
  const std::string command = kMarbles + " study " MARBLES_SOURCE_DIR
                              "/scenes/validation/bouncing_ball.yaml --vary time.dt=4e-3 --vary time.dt=2e-3 "
                              "--quiet --out " + ::testing::TempDir() + "/vary_twice > /dev/null 2> " +
                              ::testing::TempDir() + "/vary_twice.err";
  const int status = std::system(command.c_str());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << command;
  std::ifstream in(::testing::TempDir() + "/vary_twice.err");
  const std::string err((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(err.find("--vary time.dt=2e-3: time.dt: varied twice"), std::string::npos) << err;
}

// Values that differ as text but make one scene (true and yes, a vector
// with and without blanks, a name quoted or not) are refused before
// anything runs, naming both settings; values that make different scenes run.
TEST_F(Study, SettingsThatMakeOneSceneAreRefused) {
  const test::ScratchDir dir("study_same_scene");
  for (const std::string vary : {"solver.speculative=true,yes", "gravity=[0,0,-9.81],[0, 0, -9.81]",
                                 "solver.integrator=symplectic_euler,\"symplectic_euler\""}) {
    StudyOptions o = options(kValidation + "bouncing_ball.yaml", dir.path() + "/out");
    o.vary.push_back(parse_vary(vary));
    o.backend = "cpu";
    std::ostringstream out, err;
    try {
      run_study(o, out, err);
      ADD_FAILURE() << vary << " ran";
    } catch (const InputError& e) {
      EXPECT_EQ(e.key(), "--vary");
      EXPECT_NE(e.message().find(" make the same scene: each setting runs once"), std::string::npos) << e.message();
    }
    EXPECT_FALSE(fs::exists(dir.path() + "/out")) << vary;
  }
  EXPECT_EQ(study(kValidation + "bouncing_ball.yaml", {"solver.speculative=true,no"}, dir).rows.size(), 2u);
}

TEST(Pareto, EqualsTheSweepOracle) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> pick(0, 5);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<StudyRow> rows(1 + trial % 12);
    for (StudyRow& r : rows) {
      r.error = std::pow(10.0, -pick(rng));
      r.ms_per_simulated_second = 1 + pick(rng);
    }
    mark_pareto(rows);
    for (const StudyRow& r : rows) {
      bool front = true;
      for (const StudyRow& o : rows) {
        if (o.ms_per_simulated_second < r.ms_per_simulated_second && o.error <= r.error) front = false;
        if (o.ms_per_simulated_second == r.ms_per_simulated_second && o.error < r.error) front = false;
      }
      EXPECT_EQ(r.pareto, front) << "trial " << trial;
    }
  }
}

// Float and double runs of one program agree within float rounding, and the
// summary says which ran.
TEST_F(Study, FloatAndDoubleRunsAgree) {
  const test::ScratchDir dir("study_precision");
  std::map<std::string, nlohmann::json> summaries;
  for (const std::string p : {"float", "double"}) {
    const std::string out = dir.path() + "/" + p;
    const std::string command = "'" + kMarbles + "' run " + kValidation +
                                "slide_to_roll.yaml --quiet --summary-only --backend cpu --precision " + p +
                                " --out '" + out + "' >/dev/null 2>&1";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    summaries[p] = nlohmann::json::parse(slurp(out + "/summary.json"));
    EXPECT_EQ(summaries[p].at("precision"), p);
  }
  auto measured = [](const nlohmann::json& s) { return s.at("reference").at("measured").at(0).get<double>(); };
  const double f = measured(summaries["float"]), d = measured(summaries["double"]);
  EXPECT_NEAR(f, d, 1e-5 * d);
  EXPECT_NE(f, d);  // really two precisions
}

}  // namespace
}  // namespace marbles
