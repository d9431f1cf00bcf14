// Tests of `marbles bench step --rolling`: the pile with rolling resistance
// off is the friction-only pile, settled and cached apart from the default
// one (each N, each kind its own file), and the flag is refused where it
// means nothing.
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

TEST(StepBench, PileWithoutRollingIsCachedApart) {
  EXPECT_NE(pile_cache_path("d", 1000, false), pile_cache_path("d", 1000, true));
  EXPECT_EQ(pile_cache_path("d", 1000), pile_cache_path("d", 1000, true));
  EXPECT_NE(pile_cache_path("d", 1000, false), pile_cache_path("d", 2000, false));
}

TEST(StepBench, FrictionOnlyPileSettlesItsOwnFile) {
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
  o.rolling = false;
  const nlohmann::json off = run_json(o);
  EXPECT_FALSE(off["rolling_resistance"].get<bool>());
  EXPECT_TRUE(fs::exists(pile_cache_path(o.cache_dir, 600, false)));
  EXPECT_FALSE(fs::exists(pile_cache_path(o.cache_dir, 600, true)));
  const nlohmann::json& row = off["results"][0];
  EXPECT_FALSE(row["settle"]["cached"].get<bool>());
  EXPECT_GT(row["contacts_per_sphere"].get<double>(), 1.0);  // a pile, not a gas

  // Again: from its file. The default pile is settled on its own.
  EXPECT_TRUE(run_json(o)["results"][0]["settle"]["cached"].get<bool>());
  o.rolling = true;
  const nlohmann::json on = run_json(o);
  EXPECT_TRUE(on["rolling_resistance"].get<bool>());
  EXPECT_FALSE(on["results"][0]["settle"]["cached"].get<bool>());
  EXPECT_TRUE(fs::exists(pile_cache_path(o.cache_dir, 600, true)));
  // The two piles' spheres (past the header, whose settle time differs
  // anyway) settled under different contacts: rolling resistance reached one
  // and not the other.
  const std::string off_file = contents(pile_cache_path(o.cache_dir, 600, false));
  const std::string on_file = contents(pile_cache_path(o.cache_dir, 600, true));
  constexpr std::size_t kHeader = 8 + 4 + 4 + 8 + 8 + 4 * 8;  // magic .. largest overlap
  ASSERT_EQ(off_file.size(), on_file.size());
  ASSERT_GT(off_file.size(), kHeader);
  EXPECT_NE(off_file.substr(kHeader), on_file.substr(kHeader));
}

TEST(StepBench, RollingOffOnlyForThePile) {
  StepBenchOptions o;
  o.scene = "gas";
  o.n = {100};
  o.rolling = false;
  std::ostringstream out;
  try {
    run_step_bench(o, out);
    FAIL() << "--rolling off accepted for the gas";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--rolling"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace marbles::bench
