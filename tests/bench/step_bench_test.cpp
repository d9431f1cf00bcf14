// Tests of `marbles bench step --rolling` and `--friction`: the pile with
// friction alone and the frictionless pile are settled and cached apart from
// the default one (each N, each kind its own file), and the flags are
// refused where they mean nothing.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>
#include <unistd.h>

#include "bench/step_bench.hpp"
#include "core/error.hpp"

namespace marbles::bench {
namespace {

namespace fs = std::filesystem;

struct TempDir {
  fs::path path;
  TempDir()
      : path(fs::temp_directory_path() / ("marbles-step-bench-" + std::to_string(::getpid()) + "-" +
                                          ::testing::UnitTest::GetInstance()->current_test_info()->name())) {
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
};

std::string contents(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

nlohmann::json run_json(const StepBenchOptions& options) {
  std::ostringstream out;
  EXPECT_EQ(run_step_bench(options, out), 0);
  return nlohmann::json::parse(out.str());
}

TEST(StepBench, EachPileIsCachedApart) {
  const std::string kinds[] = {pile_cache_path("d", 1000, true, true), pile_cache_path("d", 1000, false, true),
                               pile_cache_path("d", 1000, false, false)};
  EXPECT_NE(kinds[0], kinds[1]);
  EXPECT_NE(kinds[0], kinds[2]);
  EXPECT_NE(kinds[1], kinds[2]);
  EXPECT_EQ(pile_cache_path("d", 1000), kinds[0]);
  EXPECT_NE(pile_cache_path("d", 1000, false), pile_cache_path("d", 2000, false));
}

// The spheres of a cached pile (past the header, whose settle time differs
// from run to run anyway).
std::string spheres_of(const std::string& path) {
  constexpr std::size_t kHeader = 8 + 4 + 4 + 8 + 8 + 4 * 8;  // magic .. largest overlap
  const std::string file = contents(path);
  EXPECT_GT(file.size(), kHeader) << path;
  return file.size() > kHeader ? file.substr(kHeader) : std::string();
}

// The default pile, the pile with friction alone and the frictionless one:
// each settles into its own file, the JSON names its terms, and the three
// settle to different spheres (the terms reached each scene); the second
// run of a kind comes from its file.
TEST(StepBench, EachPileSettlesItsOwnFile) {
  TempDir dir;
  StepBenchOptions o;
  o.backend = "cpu";
  o.scene = "pile";
  o.n = {600};
  o.repeats = 2;
  o.warmup = 1;
  o.json = true;
  o.cache_dir = dir.path.string();
  o.settle_steps = 60;
  struct Kind {
    bool rolling, friction;
  };
  std::vector<std::string> spheres;
  for (const Kind kind : {Kind{false, true}, Kind{false, false}, Kind{true, true}}) {
    SCOPED_TRACE(std::string("rolling ") + (kind.rolling ? "on" : "off") + ", friction " + (kind.friction ? "on" : "off"));
    o.rolling = kind.rolling;
    o.friction = kind.friction;
    const std::string path = pile_cache_path(o.cache_dir, 600, kind.rolling, kind.friction);
    EXPECT_FALSE(fs::exists(path));
    const nlohmann::json first = run_json(o);
    EXPECT_EQ(first["rolling_resistance"].get<bool>(), kind.rolling);
    EXPECT_EQ(first["friction"].get<bool>(), kind.friction);
    const nlohmann::json& row = first["results"][0];
    EXPECT_FALSE(row["settle"]["cached"].get<bool>());
    EXPECT_GT(row["contacts_per_sphere"].get<double>(), 1.0);  // a pile, not a gas
    EXPECT_TRUE(fs::exists(path));
    EXPECT_TRUE(run_json(o)["results"][0]["settle"]["cached"].get<bool>());
    spheres.push_back(spheres_of(path));
  }
  ASSERT_EQ(spheres.size(), 3u);
  EXPECT_NE(spheres[0], spheres[1]);
  EXPECT_NE(spheres[0], spheres[2]);
  EXPECT_NE(spheres[1], spheres[2]);
}

// What the flags cannot mean is refused, naming the flag.
TEST(StepBench, PileTermsRefusedWhereTheyMeanNothing) {
  auto refused = [](StepBenchOptions o, const std::string& flag) {
    o.n = {100};
    std::ostringstream out;
    try {
      run_step_bench(o, out);
      ADD_FAILURE() << flag << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(flag), std::string::npos) << e.what();
    }
  };
  StepBenchOptions gas;
  gas.scene = "gas";
  gas.rolling = false;
  refused(gas, "--rolling");
  gas.rolling = true;
  gas.friction = false;
  refused(gas, "--friction");
  StepBenchOptions pile;
  pile.scene = "pile";
  pile.friction = false;  // rolling resistance left on
  refused(pile, "--friction");
}

}  // namespace
}  // namespace marbles::bench
