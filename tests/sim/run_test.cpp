// `marbles run` end to end: rendering does not change the simulation, the
// summary is written, `--set` overrides reach the run and risky settings are
// warned of. Runs the real run_scene() on a small scene written here.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include "core/format.hpp"
#include "render/frame_output.hpp"
#include "render/image.hpp"
#include "render/movie.hpp"
#include "render/renderer.hpp"
#include "render/vtk_output.hpp"
#include "sim/particles.hpp"
#include "sim/run.hpp"
#include "sim/scene.hpp"
#include "sim/world.hpp"

namespace fs = std::filesystem;
using namespace marbles;

namespace {

fs::path temp_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("marbles_run_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// A box whose floor (a plane at z = 0.05) rises at `speed` m/s, with 20
// spheres dropped from z in [low, 0.5]; `output` is the scene's output block.
std::string rising_floor_scene(double duration, double speed, double low, const std::string& output) {
  return "format: 1\ntime: {duration: " + std::to_string(duration) +
         ", dt: 1.0e-3}\neffects: [gravity, collisions, walls]\nmaterials:\n  glass: {density: 2500}\nwalls:\n"
         "  - box: {min: [0, 0, 0], max: [0.2, 0.2, 0.6]}\n"
         "  - plane: {point: [0, 0, 0.05], normal: [0, 0, 1]}\n    velocity: [0, 0, " +
         std::to_string(speed) + "]\nparticles:\n  - random: {count: 20, min: [0.02, 0.02, " + std::to_string(low) +
         "], max: [0.18, 0.18, 0.5], radius: 0.01, seed: 3}\noutput:\n" + output;
}

// Writes `yaml` to DIR/scene.yaml and runs it quietly on the CPU into DIR/out.
int run_on_cpu(const fs::path& dir, const std::string& yaml, std::string& err) {
  const fs::path scene = dir / "scene.yaml";
  std::ofstream(scene) << yaml;
  RunOptions options;
  options.scene_path = scene.string();
  options.out_dir = (dir / "out").string();
  options.backend = BackendChoice::cpu;
  options.quiet = true;
  std::ostringstream out, errors;
  const int status = run_scene(options, out, errors);
  err = errors.str();
  return status;
}

std::string read_file(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

// 200 spheres falling into a box with friction; frames every 10 steps, images
// every 10 steps when rendering is on.
fs::path write_scene(const fs::path& dir) {
  const fs::path path = dir / "scene.yaml";
  std::ofstream(path) << R"(format: 1
name: render_invariance
time: {duration: 0.2, dt: 1.0e-3, substeps: 2}
effects: [gravity, collisions, walls, restitution, friction, rolling_resistance]
materials:
  glass: {density: 2500, restitution: 0.6, friction: 0.4, rolling_friction: 0.01}
walls:
  - box: {min: [0, 0, 0], max: [0.2, 0.2, 0.6]}
particles:
  - random: {count: 200, min: [0.02, 0.02, 0.05], max: [0.18, 0.18, 0.55], radius: {uniform: [0.006, 0.01]}, seed: 3}
    velocity: {random: {speed: 0.3, seed: 4}}
output:
  vtk: {every: 10}
  render: {every: 10, width: 160, height: 96, color_by: speed}
  movie: {fps: 10}
)";
  return path;
}

}  // namespace

// A killed run leaves its temporaries (hidden names ending .tmp-PID-N) in
// each folder it was writing into; the next run into the folder removes
// those of a writer that is gone, in every such folder, and keeps those of
// a live one (this process's), and every file not named as a temporary,
// however like one (a user's `.notes.tmp-PID`).
TEST(Run, RemovesADeadRunsTemporariesInEveryFolder) {
  const fs::path dir = temp_dir("temporaries");
  const pid_t dead = ::fork();
  if (dead == 0) ::_exit(0);
  ASSERT_GT(dead, 0);
  int status = 0;
  ASSERT_EQ(::waitpid(dead, &status, 0), dead);
  const std::vector<std::string> folders = {"", "frames", "images", "contacts", "walls", "checkpoints"};
  std::vector<fs::path> stale, live;
  for (const std::string& sub : folders) {
    fs::create_directories(dir / "out" / sub);
    stale.push_back(dir / "out" / sub / (".file_000020.bin.tmp-" + std::to_string(dead) + "-3"));
    live.push_back(dir / "out" / sub / (".file_000020.bin.tmp-" + std::to_string(::getpid()) + "-3"));
    std::ofstream(stale.back()) << "half";
    std::ofstream(live.back()) << "half";
    const std::string d = std::to_string(dead);
    for (const std::string& name : {".notes.tmp-" + d, ".notes.tmp-" + d + "-", ".notes.tmp-" + d + "-3x",
                                    ".notes.tmp-" + d + "-3.bak", "notes.tmp-" + d + "-3", "..tmp-" + d + "-3"}) {
      live.push_back(dir / "out" / sub / name);
      std::ofstream(live.back()) << "a user's";
    }
  }
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, rising_floor_scene(0.01, 0, 0.1, "  vtk: {every: 5}\n"), err), 0) << err;
  for (const fs::path& p : stale) EXPECT_FALSE(fs::exists(p)) << p;
  for (const fs::path& p : live) EXPECT_TRUE(fs::exists(p)) << p;
}

TEST(Run, RenderingDoesNotChangeTheSimulation) {
  const fs::path dir = temp_dir("render");
  const fs::path scene = write_scene(dir);
  std::ostringstream out, err;
  RunOptions with;
  with.scene_path = scene.string();
  with.out_dir = (dir / "with").string();
  with.backend = BackendChoice::cpu;
  with.quiet = true;
  RunOptions without = with;
  without.out_dir = (dir / "without").string();
  without.render = false;
  ASSERT_EQ(run_scene(with, out, err), 0) << err.str();
  ASSERT_EQ(run_scene(without, out, err), 0) << err.str();

  // Every frame of the two runs holds the same state, byte for byte.
  const auto frames_with = render::read_pvd(dir / "with" / "series.pvd");
  const auto frames_without = render::read_pvd(dir / "without" / "series.pvd");
  ASSERT_EQ(frames_with.size(), 21u);
  ASSERT_EQ(frames_with.size(), frames_without.size());
  for (std::size_t k = 0; k < frames_with.size(); ++k) {
    const render::Snapshot a = render::read_vtp(frames_with[k].path);
    const render::Snapshot b = render::read_vtp(frames_without[k].path);
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      ASSERT_EQ(a.position[i], b.position[i]) << "frame " << k << " sphere " << i;
      ASSERT_EQ(a.velocity[i], b.velocity[i]) << "frame " << k << " sphere " << i;
    }
  }
  // The rendered run did render (where this build can), the other did not.
  if (render::renderer_available()) {
    EXPECT_TRUE(fs::exists(dir / "with" / "images" / "frame_000020.png"));
  }
  EXPECT_FALSE(fs::exists(dir / "without" / "images"));
  EXPECT_TRUE(fs::exists(dir / "with" / "summary.json"));
  EXPECT_NE(read_file(dir / "without" / "summary.json").find("\"steps\": 200"), std::string::npos);
  fs::remove_all(dir);
}

namespace {

// The test scene on the CPU, quiet, without rendering, output in dir/out.
RunOptions quiet_cpu_run(const fs::path& dir) {
  RunOptions options;
  options.scene_path = write_scene(dir).string();
  options.out_dir = (dir / "out").string();
  options.backend = BackendChoice::cpu;
  options.quiet = true;
  options.render = false;
  return options;
}

}  // namespace

TEST(Run, SetOverridesChangeTheRun) {
  const fs::path dir = temp_dir("set");
  RunOptions options = quiet_cpu_run(dir);
  options.overrides = {"time.duration=0.01", "time.dt=5e-4", "particles[0].random.count=20"};
  std::ostringstream out, err;
  ASSERT_EQ(run_scene(options, out, err), 0) << err.str();
  const std::string summary = read_file(dir / "out" / "summary.json");
  EXPECT_NE(summary.find("\"steps\": 20"), std::string::npos) << summary;
  EXPECT_NE(summary.find("\"spheres\": 20"), std::string::npos) << summary;
  fs::remove_all(dir);
}

TEST(Run, QuietRunStillWarnsOfRiskySettings) {
  const fs::path dir = temp_dir("warn");
  RunOptions options = quiet_cpu_run(dir);
  options.overrides = {"time.duration=0.04", "time.dt=0.02"};
  std::ostringstream out, err;
  ASSERT_EQ(run_scene(options, out, err), 0) << err.str();
  EXPECT_NE(err.str().find("warning: substeps too coarse for gravity: "), std::string::npos) << err.str();
  fs::remove_all(dir);
}

// Contact output: a resting stack of 100 spheres on a floor. The floor's
// normal forces in the last contact frame carry the stack's weight (m g from
// the spheres' masses, within 1 %); every pressing contact appears once, and
// the per-sphere `contacts` field of the sphere frame counts the same contacts.
TEST(Run, ContactForcesOfARestingStackBalanceItsWeight) {
  const fs::path dir = temp_dir("contacts");
  RunOptions options;
  options.scene_path = MARBLES_SOURCE_DIR "/scenes/validation/resting_stack.yaml";
  options.out_dir = (dir / "out").string();
  options.backend = BackendChoice::cpu;
  options.quiet = true;
  options.overrides = {"time.duration=0.5", "output.contacts.every=250", "output.vtk.every=500",
                       "output.fields=[radius, contacts, speed]"};
  std::ostringstream out, err;
  ASSERT_EQ(run_scene(options, out, err), 0) << err.str();

  const scene::Scene sc = scene::load_scene(options.scene_path);
  const World world = make_world(sc, scene::generate_particles(sc));
  double weight = 0;
  for (std::size_t i = 0; i < world.size(); ++i) weight += 9.81 / world.inv_mass[i];

  const auto series = render::read_pvd(dir / "out" / "contacts.pvd");
  ASSERT_EQ(series.size(), 3u);  // steps 0, 250, 500
  EXPECT_DOUBLE_EQ(series[2].time, 0.5);
  const render::VtpArrays c = render::read_vtp_arrays(series[2].path);
  const auto& force = c.arrays.at("CellData/normal_force").values;
  const auto& normal = c.arrays.at("CellData/normal").values;
  const auto& wall = c.arrays.at("CellData/wall").values;
  const auto& a = c.arrays.at("CellData/sphere_a").values;
  const auto& b = c.arrays.at("CellData/sphere_b").values;
  ASSERT_EQ(c.points, 2 * force.size());
  double floor = 0;
  std::vector<unsigned> per_sphere(world.size(), 0);
  for (std::size_t k = 0; k < force.size(); ++k) {
    EXPECT_GE(force[k], 0.0);
    ++per_sphere.at(std::size_t(a[k]));
    if (wall[k] != 0) floor += force[k] * normal[3 * k + 2];
    else ++per_sphere.at(std::size_t(b[k]));
  }
  EXPECT_NEAR(floor, weight, 0.01 * weight);

  const render::Snapshot frame = render::read_vtp(render::read_pvd(dir / "out" / "series.pvd").back().path);
  ASSERT_EQ(frame.contacts.size(), world.size());
  for (std::size_t i = 0; i < world.size(); ++i) EXPECT_EQ(frame.contacts[i], per_sphere[i]) << "sphere " << i;
  // A sphere on the floor of the simple-cubic stack presses only the floor and
  // the sphere above: its side neighbours touch it without force or overlap.
  EXPECT_EQ(frame.contacts[0], 2u);
  fs::remove_all(dir);
}

// A frame's TimeValue is the time its .pvd line and thermo.csv's row spell,
// exactly: 175 steps of 1 ms are 0.17500000000000002 s in double arithmetic
// and 0.175 in the lists, and a join of frames to rows by time found no row.
TEST(Run, FrameTimesMatchTheSeriesAndThermoExactly) {
  const fs::path dir = temp_dir("frame_times");
  const std::string yaml = R"(format: 1
time: {duration: 0.3, dt: 1.0e-3}
effects: [gravity, collisions, walls]
materials: {a: {}}
walls: [{plane: {point: [0, 0, 0], normal: [0, 0, 1]}}]
particles:
  - list: {positions: [[0, 0, 0.5]], radius: 0.05}
output: {vtk: {every: 1}, contacts: {every: 5}}
)";
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, yaml, err), 0) << err;
  std::vector<double> rows;  // thermo.csv's times
  {
    std::ifstream thermo(dir / "out" / "thermo.csv");
    std::string line;
    std::getline(thermo, line);
    while (std::getline(thermo, line)) rows.push_back(std::strtod(line.substr(line.find(',') + 1).c_str(), nullptr));
  }
  int inexact = 0;  // frames whose step times dt is not its listed time
  for (const char* series : {"series.pvd", "walls.pvd", "contacts.pvd"}) {
    const auto entries = render::read_pvd(dir / "out" / series);
    ASSERT_GT(entries.size(), 50u) << series;
    for (const render::SeriesEntry& e : entries) {
      const render::VtpArrays frame = render::read_vtp_arrays(e.path);
      const double time = frame.arrays.at("FieldData/TimeValue").values.at(0);
      EXPECT_EQ(time, e.time) << e.path;
      EXPECT_TRUE(std::find(rows.begin(), rows.end(), time) != rows.end()) << e.path;
      const double step = frame.arrays.at("FieldData/step").values.at(0);
      inexact += step * 1e-3 != time ? 1 : 0;
    }
  }
  EXPECT_GT(inexact, 10);  // the times that differed
  fs::remove_all(dir);
}

// A wall contact names its wall by its place in the scene's `walls` list,
// whatever the wall's kind (the step keeps planes, box faces, cylinders and
// spheres apart, in that order): four walls listed sphere, box, cylinder,
// plane, a sphere resting on each. Each contact's wall end lies on the
// surface of the wall it names, and on no other; the walls' frame labels its
// cells with the same numbers.
TEST(Run, WallContactsNameTheirWallByItsPlaceInTheScene) {
  const fs::path dir = temp_dir("wall_index");
  // Each sphere 0.5 mm from its wall, moving into it at 0.1 m/s (a plastic
  // impact after five steps). The box holds them all; the drum acts on
  // y in [-1, 1] alone, where only sphere 2 lies.
  const std::string yaml = R"(format: 1
time: {duration: 0.01, dt: 1.0e-3}
effects: [collisions, walls]
materials: {a: {}}
walls:
  - sphere: {centre: [-2, 3, 3], radius: 1}
  - box: {min: [-5, -5, -1], max: [5, 5, 10]}
  - cylinder: {base: [2, -1, 3], axis: [0, 1, 0], radius: 0.5, length: 2, inside: true}
  - plane: {point: [0, 0, 0], normal: [0, 0, 1]}
particles:
  - list:
      positions: [[-2, 3, 4.1005], [4.8995, -3, 3], [2, 0, 2.6005], [2, 3, 0.1005]]
      velocities: [[0, 0, -0.1], [0.1, 0, 0], [0, 0, -0.1], [0, 0, -0.1]]
      radius: 0.1
output: {vtk: {every: 1}, contacts: {every: 1}}
)";
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, yaml, err), 0) << err;
  // The distance of point x from each wall's surface, from the scene above.
  auto distance = [](int wall, const double* x) {
    switch (wall) {
      case 0: return std::fabs(std::hypot(x[0] + 2, x[1] - 3, x[2] - 3) - 1);
      case 1: {
        double d = 1e30;
        const double lo[3] = {-5, -5, -1}, hi[3] = {5, 5, 10};
        for (int a = 0; a < 3; ++a) d = std::min({d, std::fabs(x[a] - lo[a]), std::fabs(hi[a] - x[a])});
        return d;
      }
      case 2: return std::fabs(std::hypot(x[0] - 2, x[2] - 3) - 0.5);
      default: return std::fabs(x[2]);
    }
  };
  // The frame of the impacts: the one with the most contacts.
  render::VtpArrays c;
  for (const render::SeriesEntry& e : render::read_pvd(dir / "out" / "contacts.pvd")) {
    render::VtpArrays frame = render::read_vtp_arrays(e.path);
    if (frame.arrays.at("CellData/wall").values.size() > c.arrays["CellData/wall"].values.size()) c = std::move(frame);
  }
  ASSERT_EQ(c.arrays.at("CellData/wall").values.size(), 4u);
  const auto& wall = c.arrays.at("CellData/wall").values;
  const auto& a = c.arrays.at("CellData/sphere_a").values;
  const auto& b = c.arrays.at("CellData/sphere_b").values;
  const auto& points = c.arrays.at("Points/Points").values;
  std::vector<int> named(4, -1);  // the wall each sphere's contact names
  for (std::size_t k = 0; k < wall.size(); ++k) {
    ASSERT_NE(wall[k], 0.0) << "the spheres lie apart";
    const double* end = &points[3 * (2 * k + 1)];  // the line's second point: on the wall
    const int w = int(b[k]);
    ASSERT_GE(w, 0);
    ASSERT_LT(w, 4);
    EXPECT_LT(distance(w, end), 1e-3) << "contact " << k << " names wall " << w;
    for (int other = 0; other < 4; ++other) {
      if (other != w) {
        EXPECT_GT(distance(other, end), 0.05) << "contact " << k << " lies on wall " << other;
      }
    }
    named.at(std::size_t(a[k])) = w;
  }
  EXPECT_EQ(named, (std::vector<int>{0, 1, 2, 3}));  // sphere i rests on wall i
  // The walls' frame: each wall's cells carry its place in the scene.
  const render::VtpArrays walls = render::read_vtp_arrays(render::read_pvd(dir / "out" / "walls.pvd").back().path);
  const auto& cell_wall = walls.arrays.at("CellData/wall").values;
  const auto& cell_points = walls.arrays.at("Points/Points").values;
  const auto& connectivity = walls.arrays.at("Polys/connectivity").values;
  const auto& offsets = walls.arrays.at("Polys/offsets").values;
  ASSERT_EQ(offsets.size(), cell_wall.size());
  for (std::size_t cell = 0, first = 0; cell < cell_wall.size(); first = std::size_t(offsets[cell++])) {
    const double* corner = &cell_points[3 * std::size_t(connectivity[first])];
    EXPECT_LT(distance(int(cell_wall[cell]), corner), 1e-4) << "cell " << cell;
  }
  fs::remove_all(dir);
}

// Two spheres of density 1e30 meeting head on at 1000 m/s with a substep of
// 1 us: impulses of ~4e33 N s (within float) make forces of ~4e39 N, past
// float's range. The contact frames hold them finite, in Float64, and equal
// to momentum over the substep (the impact reverses each sphere's speed at
// most: |F| <= 2 m v / h).
TEST(Run, ContactForcesPastFloatsRangeAreWrittenFinite) {
  const fs::path dir = temp_dir("huge_forces");
  const std::string yaml = R"(format: 1
time: {duration: 2.0e-5, dt: 1.0e-6}
effects: [collisions]
materials: {a: {density: 1.0e30}}
particles:
  - list: {positions: [[0, 0, 0], [2.001, 0, 0]], radius: 1, velocities: [[1000, 0, 0], [-1000, 0, 0]]}
output: {contacts: {every: 1}}
)";
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, yaml, err), 0) << err;
  const double mass = 1e30 * 4.0 / 3.0 * 3.141592653589793, bound = 2 * mass * 1000 / 1e-6;
  std::size_t pressing = 0;
  for (const render::SeriesEntry& e : render::read_pvd(dir / "out" / "contacts.pvd")) {
    const render::VtpArrays c = render::read_vtp_arrays(e.path);
    for (const char* name : {"CellData/normal_force", "CellData/tangential_force", "CellData/force"})
      for (const double v : c.arrays.at(name).values) {
        ASSERT_TRUE(std::isfinite(v)) << e.path << " " << name;
        EXPECT_LE(std::fabs(v), bound * 1.01) << e.path << " " << name;
      }
    const std::string text = read_file(e.path);
    EXPECT_NE(text.find("Name=\"normal_force\""), std::string::npos);
    EXPECT_EQ(text.find("Float32\" Name=\"normal_force\""), std::string::npos) << e.path;
    for (const double v : c.arrays.at("CellData/normal_force").values)
      if (v > std::numeric_limits<float>::max()) ++pressing;  // a force float could not have held
  }
  EXPECT_GT(pressing, 0u) << "no force past float's range: the case no longer tests anything";
}

// A sphere struck at 100 m/s with dt = 1/60 s through a third sphere (the
// scene file of tests/sim/test_scenes.hpp's struck_through_scene).
const std::string kStruckThrough = R"(format: 1
time: {duration: 0.05, dt: 0.016666666666666666}
effects: [collisions, restitution]
materials: {a: {density: 1000, restitution: 0.5}}
particles:
  - list: {positions: [[1.38, 0, 0], [1.5, 0, 0], [1.7, 0.02, 0]], radius: 0.05, velocities: [[100, 0, 0], [0, 0, 0], [0, 0, 0]]}
)";

// A sphere struck at 100 m/s with dt = 1/60 s leaves past what even the
// watchdog's finest substep sweeps: the run says so on stderr, keeps the
// step and counts it in summary.json (the Stability tests hold the rule).
TEST(Run, StepsKeptUnsweptAreSaidAndCounted) {
  const fs::path dir = temp_dir("unswept");
  const std::string yaml = kStruckThrough;
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, yaml, err), 0) << err;
  const nlohmann::json summary = nlohmann::json::parse(read_file(dir / "out" / "summary.json"));
  const auto kept = summary.at("unswept_steps").get<std::uint64_t>();
  EXPECT_GE(kept, 1u);
  std::size_t said = 0;
  const std::string said_kept = "(more time.substeps sweep what the solve sets moving)";
  for (std::size_t at = err.find(said_kept); at != std::string::npos; at = err.find(said_kept, at + 1))
    ++said;
  EXPECT_EQ(said, kept) << err;
  EXPECT_NE(err.find("still at 8 substeps"), std::string::npos) << err;
  EXPECT_GE(summary.at("rollbacks").get<std::uint64_t>(), 3 * kept);
}

// Spheres placed deep in each other (twenty on one spot, a row overlapping
// by half) or a sphere placed far beyond a wall are warned of and pushed
// apart over the first steps: the watchdog's overlap rule judges the first
// step from the overlap the run starts with, so it is not taken for a blow-up
// (it was exit 1 at step 1, "overlap 1.12 of a radius after 3 retries").
TEST(Run, SpheresPlacedDeepInEachOtherAreSeparatedNotRefused) {
  const fs::path dir = temp_dir("placed_deep");
  std::string coincident, row;
  for (int k = 0; k < 20; ++k) {
    coincident += std::string(k ? ", " : "") + "[0, 0, 0]";
    row += std::string(k ? ", " : "") + "[" + std::to_string(0.01 * k) + ", 0, 0]";
  }
  const std::string head = "format: 1\ntime: {duration: 0.1, dt: 1.0e-3}\neffects: [collisions]\n"
                           "materials: {m: {density: 1000}}\nparticles:\n  - list: {radius: 0.01, positions: [";
  const std::string outside = "format: 1\ntime: {duration: 0.5, dt: 1.0e-3}\neffects: [gravity, walls]\n"
                              "materials: {m: {density: 1000}}\n"
                              "walls:\n  - box: {min: [0, 0, 0], max: [1, 1, 1]}\n"
                              "particles:\n  - list: {radius: 0.02, positions: [[0.5, 0.5, 0.5], [1.5, 0.5, 0.5]]}\n";
  const std::pair<std::string, std::string> cases[] = {
      {head + coincident + "]}\n", "190 pair(s) of spheres start overlapping"},
      {head + row + "]}\n", "19 pair(s) of spheres start overlapping"},
      {outside, "1 sphere(s) start overlapping a wall by more than 1% of their radius, up to 26 radii deep"}};
  for (const auto& [yaml, warning] : cases) {
    std::string err;
    ASSERT_EQ(run_on_cpu(dir, yaml, err), 0) << err << yaml;
    EXPECT_NE(err.find("warning: " + warning), std::string::npos) << err;
    const nlohmann::json summary = nlohmann::json::parse(read_file(dir / "out" / "summary.json"));
    EXPECT_LT(summary.at("max_overlap_end").get<double>(), 0.01) << yaml;
    EXPECT_GT(summary.at("max_overlap").get<double>(), 0.5) << yaml;  // premise: they started deep
    fs::remove_all(dir / "out");
  }
}

// A run whose spheres end deep in each other says so (exit 0: the run is
// whole): a sphere 10^6 times denser dropped on a light one on a floor
// passes into it; a ball that bounces and rests does not warn.
TEST(Run, SpheresThatEndDeepInEachOtherAreWarnedOf) {
  const fs::path dir = temp_dir("end_deep");
  const std::string crushed =
      "format: 1\ntime: {duration: 1.0, dt: 1.0e-3}\neffects: [gravity, collisions, walls, restitution, friction]\n"
      "materials:\n  light: {density: 1000, restitution: 0.5, friction: 0.5}\n"
      "  heavy: {density: 1.0e9, restitution: 0.5, friction: 0.5}\n"
      "walls:\n  - plane: {point: [0, 0, 0], normal: [0, 0, 1]}\n"
      "particles:\n  - list: {positions: [[0, 0, 0.01]], radius: 0.01}\n    material: light\n"
      "  - list: {positions: [[0, 0, 0.2]], radius: 0.01}\n    material: heavy\n";
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, crushed, err), 0) << err;
  const double end = nlohmann::json::parse(read_file(dir / "out" / "summary.json")).at("max_overlap_end").get<double>();
  ASSERT_GT(end, 0.1);  // premise: the heavy sphere went into the light one
  const std::size_t at = err.find("warning: spheres end overlapping by up to ");
  ASSERT_NE(at, std::string::npos) << err;
  EXPECT_GT(std::stod(err.substr(at + 42)), 10) << err;  // per cent, measured on the state as it ends
  fs::remove_all(dir / "out");
  ASSERT_EQ(run_on_cpu(dir, read_file(MARBLES_SOURCE_DIR "/scenes/validation/bouncing_ball.yaml"), err), 0) << err;
  EXPECT_EQ(err.find("end overlapping"), std::string::npos) << err;
  // A rough floor of glued spheres set half into the floor: neither the start nor the end is warned of (the
  // solver never moves them), and a light sphere resting on them is no concern either.
  fs::remove_all(dir / "out");
  const std::string rough =
      "format: 1\ntime: {duration: 0.3, dt: 1.0e-3}\neffects: [gravity, collisions, walls, friction]\n"
      "materials:\n  m: {density: 1000, friction: 0.5}\n"
      "walls:\n  - plane: {point: [0, 0, 0], normal: [0, 0, 1]}\n"
      "particles:\n  - list: {positions: [[0, 0, 0], [0.02, 0, 0], [0, 0.02, 0], [0.02, 0.02, 0]], radius: 0.01}\n"
      "    fixed: true\n  - list: {positions: [[0.01, 0.01, 0.03]], radius: 0.01}\n";
  ASSERT_EQ(run_on_cpu(dir, rough, err), 0) << err;
  EXPECT_EQ(err.find("warning"), std::string::npos) << err;
  const nlohmann::json summary = nlohmann::json::parse(read_file(dir / "out" / "summary.json"));
  EXPECT_GE(summary.at("max_overlap_end").get<double>(), 0.99);  // premise: the step's own figure counts the glued ones
}

// The run's closing line says what the watchdog did, where it did anything.
TEST(Run, TheClosingLineSaysWhatTheWatchdogDid) {
  const fs::path dir = temp_dir("closing_line");
  const std::string yaml = kStruckThrough;
  for (const bool struck : {true, false}) {
    std::ofstream(dir / "scene.yaml") << (struck ? yaml : yaml.substr(0, yaml.find("[100, 0, 0]")) + "[1, 0, 0], [0, 0, 0], [0, 0, 0]]}\n");
    RunOptions options;
    options.scene_path = (dir / "scene.yaml").string();
    const fs::path out_dir = dir / (struck ? "struck" : "gentle");
    options.out_dir = out_dir.string();
    options.backend = BackendChoice::cpu;
    options.quiet = true;
    std::ostringstream out, errors;
    ASSERT_EQ(run_scene(options, out, errors), 0) << errors.str();
    const nlohmann::json summary = nlohmann::json::parse(read_file(out_dir / "summary.json"));
    const std::string said = "; watchdog: " + std::to_string(summary.at("rollbacks").get<std::uint64_t>()) +
                             " rollback(s), " + std::to_string(summary.at("unswept_steps").get<std::uint64_t>()) +
                             " step(s) kept unswept\n";
    if (struck) EXPECT_NE(out.str().find(said), std::string::npos) << out.str();
    else EXPECT_EQ(out.str().find("watchdog"), std::string::npos) << out.str();
  }
}

// The images a run draws as it goes and the images `marbles render` draws
// afterwards from its frames are the same pixels, moving walls included (the
// run moves the scene's walls to each frame's time; the frames' walls are
// already there and are drawn where they are, not moved again).
TEST(Run, ImagesOfTheRunEqualImagesRenderedFromItsFrames) {
  if (!render::renderer_available() || !render::png_available()) GTEST_SKIP() << "skipped: built without OSMesa or libpng";
  const fs::path dir = temp_dir("images_equal");
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, rising_floor_scene(0.2, 0.5, 0.3,
                                               "  vtk: {every: 100}\n"
                                               "  render: {every: 100, width: 96, height: 64, color_by: id,\n"
                                               "           camera: {position: [1.0, -1.2, 0.6], look_at: [0.1, 0.1, 0.2], "
                                               "fov: 40}}\n"),
                       err),
            0)
      << err;
  auto image = [&](int k) { return render::read_png(dir / "out" / "images" / ("frame_00000" + std::to_string(k) + ".png")); };
  std::vector<render::Image> during;
  for (int k = 0; k < 3; ++k) during.push_back(image(k));
  render::RenderOptions o;
  o.width = 96, o.height = 64, o.color_by = render::ColorBy::id;
  o.camera = render::Camera{Vec3(1.0f, -1.2f, 0.6f), Vec3(0.1f, 0.1f, 0.2f), Vec3(0, 0, 1), 40};
  render::MovieOptions no_movie;
  no_movie.enabled = false;
  std::ostringstream log;
  ASSERT_EQ(render::render_output_dir((dir / "out").string(), o, no_movie, false, log), 0) << log.str();
  for (int k = 0; k < 3; ++k) {
    const render::Image after = image(k);
    EXPECT_TRUE(after.rgb == during[k].rgb) << "frame " << k;
    if (k > 0) {
      EXPECT_FALSE(during[k].rgb == during[0].rgb);  // the floor moved (0.05 m per frame)
    }
  }
  fs::remove_all(dir);
}

// Walls in the output: a rising floor (a plane moving at 0.02 m/s) and a box,
// drawn in walls/walls_NNNNNN.vtp beside every sphere frame; the floor of
// frame k has risen by 0.02 t, and `marbles render` finds the walls there.
TEST(Run, MovingWallsMoveInTheWallSeries) {
  const fs::path dir = temp_dir("walls");
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, rising_floor_scene(0.1, 0.02, 0.1, "  vtk: {every: 25}\n"), err), 0) << err;
  const auto frames = render::read_pvd(dir / "out" / "series.pvd");
  const auto walls = render::read_pvd(dir / "out" / "walls.pvd");
  ASSERT_EQ(walls.size(), frames.size());
  ASSERT_EQ(walls.size(), 5u);
  for (std::size_t k = 0; k < walls.size(); ++k) {
    EXPECT_EQ(walls[k].time, frames[k].time);
    const Walls w = render::read_walls_vtp(walls[k].path);
    ASSERT_EQ(w.planes.size(), 1u);
    ASSERT_EQ(w.boxes.size(), 1u);
    EXPECT_NEAR(w.planes[0].point.z, 0.05 + 0.02 * walls[k].time, 1e-6) << "frame " << k;
    EXPECT_EQ(w.boxes[0].hi.z, real(0.6));
    // The drawn floor (planes are drawn first) sits at the plane's height.
    const render::VtpArrays surfaces = render::read_vtp_arrays(walls[k].path);
    const auto& wall = surfaces.arrays.at("CellData/wall").values;
    const auto& points = surfaces.arrays.at("Points/Points").values;
    ASSERT_EQ(wall[0], 1.0);  // the plane's square comes first, labelled by its place in the scene (after the box)
    for (int corner = 0; corner < 4; ++corner) EXPECT_NEAR(points[3 * corner + 2], w.planes[0].point.z, 1e-6);
  }
  fs::remove_all(dir);
}

// summary.json's figures of the end apart: two glass spheres in free flight
// (no gravity, far apart), one moving at v and one spinning at w, give
// (1/2) m v^2 and (1/2) I w^2 with m and I from the density and radius
// (I = 2/5 m r^2), and the largest speed |v|; they sum to the kinetic energy.
TEST(Run, SummarySplitsTheEndsEnergyAndGivesTheFastestSphere) {
  const fs::path dir = temp_dir("motion");
  const std::string yaml = R"(format: 1
time: {duration: 0.01, dt: 1.0e-3}
effects: [collisions]
materials:
  glass: {density: 2500}
particles:
  - list: {positions: [[0, 0, 0]], radius: 0.01}
    velocity: [0.3, -0.4, 1.2]
  - list: {positions: [[1, 0, 0]], radius: 0.02}
    angular_velocity: [0, 5, 0]
)";
  std::string err;
  ASSERT_EQ(run_on_cpu(dir, yaml, err), 0) << err;
  const nlohmann::json s = nlohmann::json::parse(read_file(dir / "out" / "summary.json"));
  const double pi = 3.14159265358979323846;
  const double m1 = 2500 * 4.0 / 3.0 * pi * 0.01 * 0.01 * 0.01, m2 = 2500 * 4.0 / 3.0 * pi * 0.02 * 0.02 * 0.02;
  const double v2 = 0.3 * 0.3 + 0.4 * 0.4 + 1.2 * 1.2, i2 = 0.4 * m2 * 0.02 * 0.02;
  const double translational = s.at("kinetic_energy_end_translational").get<double>();
  const double rotational = s.at("kinetic_energy_end_rotational").get<double>();
  EXPECT_NEAR(translational, 0.5 * m1 * v2, 1e-6 * 0.5 * m1 * v2);
  EXPECT_NEAR(rotational, 0.5 * i2 * 25, 1e-6 * 0.5 * i2 * 25);
  EXPECT_NEAR(s.at("max_speed_end").get<double>(), std::sqrt(v2), 1e-6);
  const double total = s.at("kinetic_energy_end").get<double>();
  EXPECT_NEAR(translational + rotational, total, 1e-12 * total);
  fs::remove_all(dir);
}
