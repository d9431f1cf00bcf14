// Tests of `marbles bench step`'s piles: the pile with friction alone
// (`--rolling off`) and the frictionless pile (`--friction off`) are settled
// and cached apart from the default one (each N, each kind its own file), the
// flags are refused where they mean nothing, and a pile counts as settled
// only once it rests without quenches (a pile whose budget ran out settles
// again under a larger one).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <unistd.h>

#include "bench/step_bench.hpp"
#include "core/error.hpp"
#include "sim/simulation.hpp"

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

// A cached pile's header: magic, version, sizeof(real), N, backend, then
// the settle's steps, last quench, bound, seconds, energy and largest
// overlap. (Its spheres follow, then an 8-byte checksum.)
constexpr std::size_t kHeader = 8 + 4 + 4 + 8 + 8 + 6 * 8;

// The spheres of a cached pile (past the header, whose settle time differs
// from run to run anyway).
std::string spheres_of(const std::string& path) {
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
    EXPECT_FALSE(row["settle"]["settled"].get<bool>());  // 60 steps: too few to rest 50 without a quench
    EXPECT_GT(row["contacts_per_sphere"].get<double>(), 1.0);  // a pile, not a gas
    EXPECT_GE(row["device_peak_bytes_per_sphere"].get<double>(), row["device_bytes_per_sphere"].get<double>());
    EXPECT_TRUE(fs::exists(path));
    EXPECT_TRUE(run_json(o)["results"][0]["settle"]["cached"].get<bool>());
    spheres.push_back(spheres_of(path));
  }
  ASSERT_EQ(spheres.size(), 3u);
  EXPECT_NE(spheres[0], spheres[1]);
  EXPECT_NE(spheres[0], spheres[2]);
  EXPECT_NE(spheres[1], spheres[2]);
}

// One timed step of the pile with friction alone, N spheres, on the CPU,
// as JSON, cached in `dir`.
StepBenchOptions one_step_pile(const TempDir& dir, std::size_t n, int warmup) {
  StepBenchOptions o;
  o.backend = "cpu";
  o.scene = "pile";
  o.rolling = false;
  o.n = {n};
  o.repeats = 1;
  o.warmup = warmup;
  o.json = true;
  o.cache_dir = dir.path.string();
  return o;
}

// A cache folder that cannot be made (here under a plain file) is a warning
// said before the settle, and the bench runs on the pile settled for it
// alone: it ended with a filesystem error after the settle.
TEST(StepBench, ACacheThatCannotBeWrittenIsAWarning) {
  TempDir dir;
  std::ofstream(dir.path / "file") << "x";
  StepBenchOptions o = one_step_pile(dir, 600, 1);
  o.settle_steps = 60;
  o.cache_dir = (dir.path / "file" / "cache").string();
  ::testing::internal::CaptureStderr();
  const nlohmann::json j = run_json(o);
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_FALSE(j["results"][0]["settle"]["cached"].get<bool>());
  EXPECT_GT(j["results"][0]["step_ms_median"].get<double>(), 0.0);
  EXPECT_NE(err.find("warning: cannot cache the settled pile in " + o.cache_dir), std::string::npos) << err;
  EXPECT_LT(err.find("warning: cannot cache"), err.find("settled on")) << err;  // said before the settle ends
  // A folder that is there but takes no file (/proc: access() said yes to root).
  o.cache_dir = "/proc";
  ::testing::internal::CaptureStderr();
  EXPECT_FALSE(run_json(o)["results"][0]["settle"]["cached"].get<bool>());
  const std::string proc = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(proc.find("warning: cannot cache the settled pile in /proc"), std::string::npos) << proc;
  EXPECT_LT(proc.find("warning: cannot cache"), proc.find("settled on")) << proc;
}

// A damaged cache file (a flipped byte among the spheres, cut short, bytes
// added, its last byte changed) is not used: the pile is settled again, to
// the same spheres, and saved over it.
TEST(StepBench, ADamagedPileCacheIsSettledAgain) {
  TempDir dir;
  StepBenchOptions o = one_step_pile(dir, 600, 1);
  o.settle_steps = 60;
  const std::string path = pile_cache_path(o.cache_dir, 600, false, true);
  ASSERT_FALSE(run_json(o)["results"][0]["settle"]["cached"].get<bool>());
  const std::string good = contents(path);
  ASSERT_TRUE(run_json(o)["results"][0]["settle"]["cached"].get<bool>()) << "premise: the file as written loads";
  const std::vector<std::pair<const char*, std::function<void(std::string&)>>> damages{
      {"a flipped byte", [](std::string& b) { b[kHeader + 100] = static_cast<char>(b[kHeader + 100] ^ 0x40); }},
      {"cut short", [](std::string& b) { b.resize(b.size() - 12); }},
      {"bytes added", [](std::string& b) { b += "xxxx"; }},
      {"its checksum changed", [](std::string& b) { b.back() = static_cast<char>(b.back() + 1); }},
  };
  for (const auto& [what, damage] : damages) {
    SCOPED_TRACE(what);
    std::string bytes = good;
    damage(bytes);
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
    EXPECT_FALSE(run_json(o)["results"][0]["settle"]["cached"].get<bool>());
    EXPECT_EQ(spheres_of(path).substr(0, 600 * 3 * sizeof(real)), good.substr(kHeader, 600 * 3 * sizeof(real)))
        << "settled again to other spheres";
  }
}

// A settled pile is at rest by itself: the settle stops zeroing the
// velocities once the energy is below the bound, and calls the pile settled
// only when the bound holds after 50 steps or more without a quench. The
// file's velocities, read back here, give the energy the settle reports.
TEST(StepBench, ASettledPileRestsWithoutQuenches) {
  TempDir dir;
  StepBenchOptions o = one_step_pile(dir, 5000, 0);
  const int budget = o.settle_steps;

  // A budget too small to rest 50 steps after the quenches: cached, not settled.
  o.settle_steps = 60;
  const nlohmann::json cut = run_json(o)["results"][0]["settle"];
  EXPECT_FALSE(cut["settled"].get<bool>());
  EXPECT_EQ(cut["steps"].get<std::uint64_t>(), 60u);

  // The whole budget: that pile is settled again, not taken from the file.
  o.settle_steps = budget;
  const nlohmann::json settle = run_json(o)["results"][0]["settle"];
  EXPECT_FALSE(settle["cached"].get<bool>());
  const auto steps = settle["steps"].get<std::uint64_t>(), quenched = settle["quenched_until"].get<std::uint64_t>();
  EXPECT_GT(quenched, 0u);  // quenched every 10 steps until the energy was first below the bound
  EXPECT_GE(steps, quenched + 50);
  EXPECT_LT(steps, static_cast<std::uint64_t>(budget));  // the quenches stopped: it rested within the budget
  EXPECT_LT(settle["ke_per_sphere_J"].get<double>(), o.settle_ke);
  EXPECT_EQ(settle["bound_J"].get<double>(), o.settle_ke);
  EXPECT_TRUE(settle["settled"].get<bool>());

  // The energy of the file's velocities and angular velocities (after the
  // positions): radius 1 cm, density 1000, a solid sphere's inertia.
  const std::string file = contents(pile_cache_path(o.cache_dir, 5000, false, true));
  const std::size_t n = 5000;
  ASSERT_EQ(file.size(), kHeader + 10 * n * sizeof(real) + 8);  // the checksum last
  std::vector<real> motion(6 * n);
  std::memcpy(motion.data(), file.data() + kHeader + 3 * n * sizeof(real), motion.size() * sizeof(real));
  const double r = 0.01, mass = 1000 * 4.0 / 3.0 * 3.14159265358979 * r * r * r, inertia = 0.4 * mass * r * r;
  double ke = 0;
  for (std::size_t i = 0; i < 3 * n; ++i) ke += 0.5 * mass * double(motion[i]) * double(motion[i]);
  for (std::size_t i = 3 * n; i < 6 * n; ++i) ke += 0.5 * inertia * double(motion[i]) * double(motion[i]);
  EXPECT_GT(ke, 0.0);  // the pile as it rests, not zeroed
  EXPECT_LT(ke / n, o.settle_ke);
  const double reported = settle["ke_per_sphere_J"].get<double>();
  EXPECT_NEAR(ke / n, reported, 1e-3 * reported);

  // A settled pile is taken from the file.
  EXPECT_TRUE(run_json(o)["results"][0]["settle"]["cached"].get<bool>());
}

// A pile settled to a loose bound (--settle-ke) is not taken as settled by
// a run that asks a stricter one: settled again to that bound, and cached.
// A run whose bound the cached pile's energy is below takes it.
TEST(StepBench, APileSettledLooselyIsSettledAgainForAStricterBound) {
  TempDir dir;
  StepBenchOptions o = one_step_pile(dir, 600, 0);
  const double strict = o.settle_ke;
  o.settle_ke = 1e30;
  const nlohmann::json loose = run_json(o)["results"][0]["settle"];
  ASSERT_TRUE(loose["settled"].get<bool>());
  ASSERT_GT(loose["ke_per_sphere_J"].get<double>(), strict) << "premise: the loose pile is not at rest";
  o.settle_ke = strict;
  const nlohmann::json again = run_json(o)["results"][0]["settle"];
  EXPECT_FALSE(again["cached"].get<bool>());
  EXPECT_LT(again["ke_per_sphere_J"].get<double>(), strict);
  EXPECT_EQ(again["bound_J"].get<double>(), strict);
  o.settle_ke = 1e30;  // the strict pile serves a looser bound
  const nlohmann::json taken = run_json(o)["results"][0]["settle"];
  EXPECT_TRUE(taken["cached"].get<bool>());
  EXPECT_EQ(taken["ke_per_sphere_J"].get<double>(), again["ke_per_sphere_J"].get<double>());
  // A stricter bound still, in too small a budget: settled again for the run, the settled pile kept in the cache.
  const std::string file = contents(pile_cache_path(o.cache_dir, 600, false, true));
  o.settle_ke = 1e-30;
  o.settle_steps = 60;
  EXPECT_FALSE(run_json(o)["results"][0]["settle"]["settled"].get<bool>());
  EXPECT_EQ(contents(pile_cache_path(o.cache_dir, 600, false, true)), file);
}

// The run's watchdog in the timed steps (--watchdog on) changes no step
// that passes it: the same contacts, overlaps and energy as without, bit for
// bit, with no rollback; and it did watch: its own kinetic energy at the
// last step's end is the world's, summed apart on the host.
TEST(StepBench, TheWatchdogWatchesAndChangesNoStep) {
  StepBenchOptions o;
  o.backend = "cpu";
  o.scene = "gas";
  o.n = {4000};
  o.repeats = 3;
  o.json = true;
  const nlohmann::json off = run_json(o);
  o.watchdog = true;
  const nlohmann::json on = run_json(o);
  EXPECT_FALSE(off["watchdog"].get<bool>());
  EXPECT_TRUE(on["watchdog"].get<bool>());
  const nlohmann::json& a = off["results"][0];
  const nlohmann::json& b = on["results"][0];
  EXPECT_TRUE(a["watch_ke_per_sphere_J"].is_null());
  EXPECT_EQ(b["rollbacks"].get<std::uint64_t>(), 0u);
  for (const char* key : {"candidate_pairs", "contacts", "max_overlap_pct", "ke_per_sphere_J", "colours"})
    EXPECT_EQ(a[key], b[key]) << key;
  const double ke = b["ke_per_sphere_J"].get<double>();
  ASSERT_GT(ke, 0.0);  // the gas moves
  EXPECT_NEAR(b["watch_ke_per_sphere_J"].get<double>(), ke, 1e-5 * ke);
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

// `--write-scene`: the files hold the start the benchmark times, so that
// `marbles run` of them starts from the same bits and steps as the
// benchmark's own world does: the settling lattice, the gas with every
// effect (drag and rolling resistance included), and a settled pile with
// friction alone (its spheres spin: the CSV's wx, wy, wz), timed under
// velocity Verlet (`--integrator`: its closing solve runs in the steps).
TEST(StepBench, TheSceneItWritesRunsAsTheBenchmarksOwn) {
  TempDir dir;
  StepBenchOptions settle;
  settle.scene = "settle";
  settle.repeats = 3;
  StepBenchOptions gas;
  gas.scene = "gas";
  gas.effects = {"gravity", "collisions", "walls", "restitution", "friction", "rolling_resistance", "drag"};
  StepBenchOptions pile;
  pile.scene = "pile";
  pile.rolling = false;
  pile.cache_dir = (dir.path / "cache").string();
  pile.settle_steps = 60;
  pile.integrator = "velocity_verlet";
  std::ostringstream log;
  const std::pair<StepBenchOptions, std::size_t> cases[] = {{settle, 1500}, {gas, 1000}, {pile, 600}};
  for (const auto& [options, n] : cases) {
    SCOPED_TRACE(options.scene);
    const std::string path = write_bench_scene(options, n, dir.path.string(), log);
    const std::string stem = "bench-" + options.scene + (options.scene == "pile" ? "-friction" : "") + "-n";
    EXPECT_EQ(fs::path(path).filename(), stem + std::to_string(n) + ".yaml");
    const auto [want, own] = bench_start(options, n, log);  // the pile: from the cache the writer filled
    const scene::Scene got = scene::load_scene(path);
    const int warmup = options.scene == "settle" ? 40 : options.scene == "pile" ? 5 : 2;
    EXPECT_EQ(std::llround(got.time.duration / got.time.dt), warmup + options.repeats);
    EXPECT_EQ(got.time.dt, want.time.dt);
    EXPECT_EQ(got.time.substeps, want.time.substeps);
    EXPECT_EQ(got.solver.iterations, want.solver.iterations);
    EXPECT_EQ(got.solver.integrator, options.integrator);
    EXPECT_EQ(want.solver.integrator, options.integrator);
    EXPECT_EQ(got.effects, want.effects);
    EXPECT_EQ(got.drag, want.drag);
    EXPECT_EQ(got.drag_quadratic, want.drag_quadratic);
    ASSERT_EQ(got.materials.size(), 1u);
    EXPECT_EQ(got.materials[0].restitution, want.materials[0].restitution);
    EXPECT_EQ(got.materials[0].friction, want.materials[0].friction);
    EXPECT_EQ(got.materials[0].rolling_friction, want.materials[0].rolling_friction);
    ASSERT_EQ(got.walls.size(), 1u);
    const World from_file = make_world(got, scene::generate_particles(got));
    ASSERT_EQ(from_file.size(), n);
    auto same = [](const World& a, const World& b) {
      for (std::size_t i = 0; i < a.size(); ++i)
        if (std::memcmp(&a.position[i], &b.position[i], sizeof(Vec3)) != 0 ||
            std::memcmp(&a.velocity[i], &b.velocity[i], sizeof(Vec3)) != 0 ||
            std::memcmp(&a.angular_velocity[i], &b.angular_velocity[i], sizeof(Vec3)) != 0 ||
            a.radius[i] != b.radius[i] || a.inv_mass[i] != b.inv_mass[i] || a.inv_inertia[i] != b.inv_inertia[i])
          return ::testing::AssertionFailure() << "sphere " << i << " differs";
      return ::testing::AssertionSuccess();
    };
    EXPECT_TRUE(same(from_file, own));
    if (options.scene == "pile") {  // settled with friction: some spheres turn
      EXPECT_TRUE(std::any_of(own.angular_velocity.begin(), own.angular_velocity.end(),
                              [](const Vec3& w) { return w.x != 0 || w.y != 0 || w.z != 0; }));
    }
    Simulation a(got, from_file, broadphase::Backend::cpu), b(want, own, broadphase::Backend::cpu);
    for (int k = 0; k < 5; ++k) {
      a.step();
      b.step();
    }
    EXPECT_GT(b.world().kinetic_energy(), 0.0);  // the steps moved something
    EXPECT_TRUE(same(a.world(), b.world()));
  }
  // A folder that cannot be made is refused, naming the flag.
  try {
    const std::string file = pile_cache_path(pile.cache_dir, 600, false, true);
    ASSERT_TRUE(fs::is_regular_file(file));
    write_bench_scene(gas, 10, (fs::path(file) / "x").string(), log);
    ADD_FAILURE() << "a folder under a file accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--write-scene"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace marbles::bench
