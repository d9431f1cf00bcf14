// tests/sim/particles_test.cpp — particle generation: counts, no overlaps
// (checked by brute force), containment, determinism by seed, the lattice's
// analytic count, CSV round trips; and every scene in scenes/ loads and
// generates.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <tuple>
#include <vector>

#include "broadphase/grid.hpp"
#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles::scene {
namespace {

using test::ScratchDir;

Scene scene_from(const ScratchDir& dir, const std::string& particles_yaml) {
  return load_scene(dir.write("s.yaml", SCENE_TIME SCENE_MATERIALS "particles:\n" + particles_yaml));
}

// Brute-force O(N^2) check in double of the stored (rounded) values.
std::size_t count_overlaps(const GeneratedParticles& p) {
  std::size_t overlaps = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    for (std::size_t j = i + 1; j < p.size(); ++j) {
      const double dx = double(p.position[i].x) - p.position[j].x;
      const double dy = double(p.position[i].y) - p.position[j].y;
      const double dz = double(p.position[i].z) - p.position[j].z;
      const double reach = double(p.radius[i]) + p.radius[j];
      if (dx * dx + dy * dy + dz * dz < reach * reach) ++overlaps;
    }
  }
  return overlaps;
}

// Whole spheres inside [lo, hi], up to rounding of the stored floats.
bool all_inside(const GeneratedParticles& p, const Vec3& lo, const Vec3& hi) {
  const double tolerance = 1e-6;
  for (std::size_t i = 0; i < p.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      if (p.position[i][a] - p.radius[i] < lo[a] - tolerance) return false;
      if (p.position[i][a] + p.radius[i] > hi[a] + tolerance) return false;
    }
  }
  return true;
}

bool same_spheres(const GeneratedParticles& a, const GeneratedParticles& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!(a.position[i] == b.position[i]) || a.radius[i] != b.radius[i] || !(a.velocity[i] == b.velocity[i]) ||
        a.material[i] != b.material[i])
      return false;
  }
  return true;
}

// --- lattice ---------------------------------------------------------------

TEST(Lattice, CountIsAnalytic) {
  const ScratchDir dir("lattice_count");
  // Per axis n = floor((L - 2 r) / spacing) + 1: x (1 - 0.04) / 0.1 → 10, y 0.46 / 0.1 → 5, z 0.26 / 0.1 → 3.
  const Scene s = scene_from(dir, "  - lattice: {min: [0, 0, 0], max: [1, 0.5, 0.3], spacing: 0.1, radius: 0.02}\n");
  const GeneratedParticles p = generate_particles(s);
  ASSERT_EQ(p.size(), 10u * 5u * 3u);
  EXPECT_TRUE(all_inside(p, {0, 0, 0}, {1, 0.5f, 0.3f}));
  EXPECT_EQ(count_overlaps(p), 0u);
  // x varies fastest, the lattice is centred: first centre at lo + r + slack / 2.
  EXPECT_NEAR(p.position[1].x - p.position[0].x, 0.1, 1e-6);
  EXPECT_NEAR(p.position[0].x, 0.02 + 0.5 * (0.96 - 0.9), 1e-6);
  EXPECT_NEAR(p.position[0].z, 0.02 + 0.5 * (0.26 - 0.2), 1e-6);
  for (std::size_t i = 0; i < p.size(); ++i) EXPECT_FLOAT_EQ(p.radius[i], 0.02f);
}

TEST(Lattice, ExactFitKeepsTheLastLayer) {
  const ScratchDir dir("lattice_fit");
  // 5 spheres of radius 0.05 touching across exactly 0.5 m.
  const Scene s = scene_from(dir, "  - lattice: {min: [0, 0, 0], max: [0.5, 0.1, 0.1], spacing: 0.1, radius: 0.05}\n");
  EXPECT_EQ(generate_particles(s).size(), 5u);
}

// The count follows the numbers as written, not their rounding to the run's
// precision: 0.7 is 0.69999999 in float, and a float count dropped a row of
// a 0.7 m box at spacing 0.1 (216 spheres where the rule, and double, give
// 343). Random boxes and spacings in whole centimetres (many of them exact
// fits, whose last layer touches the wall), counted in integers.
TEST(Lattice, CountFollowsTheWrittenNumbersInEveryPrecision) {
  const ScratchDir dir("lattice_written");
  std::uint64_t state = 12345;
  auto next = [&state](int below) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return int((state >> 33) % std::uint64_t(below));
  };
  int exact_fits = 0;
  for (int round = 0; round < 60; ++round) {
    const int radius = 1 + next(4), spacing = 2 * radius + next(20);  // centimetres
    int lo[3], hi[3];
    long long expected = 1;
    bool exact = false;
    for (int a = 0; a < 3; ++a) {
      lo[a] = next(200) - 100;
      hi[a] = lo[a] + 2 * radius + next(4) * spacing + (next(3) == 0 ? 0 : next(spacing));
      const int room = hi[a] - lo[a] - 2 * radius;
      expected *= room / spacing + 1;  // centres at lo + r + k * spacing, k * spacing <= room
      exact = exact || room % spacing == 0;
    }
    exact_fits += exact ? 1 : 0;
    auto metres = [](int cm) { return std::to_string(cm / 100.0); };
    const std::string block = "  - lattice: {min: [" + metres(lo[0]) + ", " + metres(lo[1]) + ", " + metres(lo[2]) +
                              "], max: [" + metres(hi[0]) + ", " + metres(hi[1]) + ", " + metres(hi[2]) +
                              "], spacing: " + metres(spacing) + ", radius: " + metres(radius) + "}\n";
    EXPECT_EQ(generate_particles(scene_from(dir, block)).size(), std::size_t(expected)) << block;
  }
  EXPECT_GT(exact_fits, 10);  // the cases that rounding can tip
  EXPECT_EQ(generate_particles(scene_from(
                dir, "  - lattice: {min: [0, 0, 0], max: [0.7, 0.7, 0.7], spacing: 0.1, radius: 0.05}\n"))
                .size(),
            343u);
}

TEST(Lattice, JitterStaysInsideAndIsSeeded) {
  const ScratchDir dir("lattice_jitter");
  const std::string block =
      "  - lattice: {min: [0, 0, 0], max: [1, 1, 1], spacing: 0.1, radius: 0.03, jitter: 0.02, seed: SEED}\n";
  const Scene a = scene_from(dir, test::replace_all(block, "SEED", "1"));
  const Scene b = scene_from(dir, test::replace_all(block, "SEED", "1"));
  const Scene c = scene_from(dir, test::replace_all(block, "SEED", "2"));
  const GeneratedParticles pa = generate_particles(a), pb = generate_particles(b), pc = generate_particles(c);
  EXPECT_EQ(pa.size(), 10u * 10u * 10u);  // (1 - 2 * (0.03 + 0.02)) / 0.1 = 9 gaps → 10 per axis
  EXPECT_TRUE(all_inside(pa, {0, 0, 0}, {1, 1, 1}));
  EXPECT_EQ(count_overlaps(pa), 0u);
  EXPECT_TRUE(same_spheres(pa, pb));
  EXPECT_FALSE(same_spheres(pa, pc));
}

// --- random ----------------------------------------------------------------

TEST(Random, MonodisperseCountNoOverlapInside) {
  const ScratchDir dir("random_mono");
  const Scene s = scene_from(dir, "  - random: {count: 2000, min: [0, 0, 0], max: [0.5, 0.5, 0.5], radius: 0.01}\n");
  const GeneratedParticles p = generate_particles(s);
  ASSERT_EQ(p.size(), 2000u);
  EXPECT_EQ(count_overlaps(p), 0u);
  EXPECT_TRUE(all_inside(p, {0, 0, 0}, {0.5f, 0.5f, 0.5f}));
}

TEST(Random, DenseMonodisperseStillHasNoOverlap) {
  const ScratchDir dir("random_dense");
  // Volume fraction 0.21, near what random sequential addition reaches in a small box.
  const Scene s = scene_from(dir, "  - random: {count: 400, min: [0, 0, 0], max: [0.2, 0.2, 0.2], radius: 0.01}\n");
  const GeneratedParticles p = generate_particles(s);
  ASSERT_EQ(p.size(), 400u);
  EXPECT_EQ(count_overlaps(p), 0u);
  EXPECT_TRUE(all_inside(p, {0, 0, 0}, {0.2f, 0.2f, 0.2f}));
}

TEST(Random, PolydisperseLargestFirstWithinRange) {
  const ScratchDir dir("random_poly");
  const Scene s = scene_from(
      dir, "  - random: {count: 3000, min: [-1, -1, 2], max: [0, 0, 3], radius: {uniform: [0.005, 0.04]}, seed: 3}\n"
           "  - random: {count: 1000, min: [0, 0, 0], max: [1, 1, 1], radius: {log_uniform: [0.001, 0.05]}, seed: 4}\n");
  const GeneratedParticles p = generate_particles(s);
  ASSERT_EQ(p.size(), 4000u);
  EXPECT_EQ(count_overlaps(p), 0u);
  for (std::size_t i = 0; i < 3000; ++i) {
    EXPECT_GE(p.radius[i], 0.005f);
    EXPECT_LE(p.radius[i], 0.04f);
    if (i > 0) {
      EXPECT_LE(p.radius[i], p.radius[i - 1]);
    }
  }
  double log_mean = 0;
  for (std::size_t i = 3000; i < 4000; ++i) {
    EXPECT_GE(p.radius[i], 0.001f * 0.9999f);
    EXPECT_LE(p.radius[i], 0.05f * 1.0001f);
    log_mean += std::log(p.radius[i]) / 1000;
  }
  EXPECT_NEAR(log_mean, 0.5 * (std::log(0.001) + std::log(0.05)), 0.15);  // uniform in log r
  GeneratedParticles first{}, second{};
  for (std::size_t i = 0; i < p.size(); ++i) {
    GeneratedParticles& part = i < 3000 ? first : second;
    part.position.push_back(p.position[i]);
    part.radius.push_back(p.radius[i]);
  }
  EXPECT_TRUE(all_inside(first, {-1, -1, 2}, {0, 0, 3}));
  EXPECT_TRUE(all_inside(second, {0, 0, 0}, {1, 1, 1}));
}

TEST(Random, DeterministicBySeed) {
  const ScratchDir dir("random_seed");
  const std::string block =
      "  - random: {count: 500, min: [0, 0, 0], max: [1, 1, 1], radius: {uniform: [0.01, 0.03]}, seed: SEED}\n"
      "    velocity: {random: {speed: 1, seed: SEED}}\n";
  const GeneratedParticles a = generate_particles(scene_from(dir, test::replace_all(block, "SEED", "42")));
  const GeneratedParticles b = generate_particles(scene_from(dir, test::replace_all(block, "SEED", "42")));
  const GeneratedParticles c = generate_particles(scene_from(dir, test::replace_all(block, "SEED", "43")));
  EXPECT_TRUE(same_spheres(a, b));
  EXPECT_FALSE(same_spheres(a, c));
}

// `order: cells` numbers a block's spheres along rows of the broad phase's
// cells for them (x, then y, then z): the same spheres
// as given (each with its radius; a random block's velocities drawn in the
// new order, a list's carried with their spheres), the cells' keys never
// falling, a block before it untouched, and an unknown order refused where
// it was written (the exact messages: scene_cases.hpp).
TEST(Particles, OrderCellsRenumbersTheBlockOnly) {
  const ScratchDir dir("particles_order");
  const std::string blocks =
      "  - random: {count: 200, min: [-1, -1, -1], max: [0, 0, 0], radius: 0.02, seed: 5}\n"
      "  - random: {count: 3000, min: [0, 0, 0], max: [1, 0.5, 0.5], radius: {uniform: [0.005, 0.015]}, seed: 6}\n"
      "    velocity: {random: {speed: 1, seed: 7}}\n"
      "    ORDER\n"
      "  - list: {positions: [[5, 0, 0], [4, 0, 0], [3, 1, 0]], radii: [0.1, 0.1, 0.1], velocities: [[1, 0, 0], [2, 0, 0], [3, 0, 0]]}\n"
      "    ORDER\n";
  auto generate = [&](const std::string& order) {
    return generate_particles(scene_from(dir, test::replace_all(blocks, "ORDER", order)));
  };
  const GeneratedParticles given = generate("material: glass"), named = generate("order: given"),
                           cells = generate("order: cells");
  EXPECT_TRUE(same_spheres(given, named));
  ASSERT_EQ(cells.size(), given.size());
  EXPECT_FALSE(same_spheres(given, cells));
  auto sphere = [](const GeneratedParticles& p, std::size_t i) {
    return std::tuple(p.position[i].x, p.position[i].y, p.position[i].z, p.radius[i]);
  };
  std::vector<std::tuple<real, real, real, real>> a, b;
  for (std::size_t i = 0; i < 3200; ++i) {
    if (i < 200) {
      EXPECT_EQ(sphere(given, i), sphere(cells, i)) << i;
    }
    a.push_back(sphere(given, i));
    b.push_back(sphere(cells, i));
  }
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  EXPECT_EQ(a, b);
  // The random block's cells: the home-cell broad phase's grid for its spheres.
  const broadphase::HomeGrid grid =
      broadphase::choose_home_grid(broadphase::bounds_of({cells.position.data() + 200, cells.radius.data() + 200, 3000}),
                                   0)
          .grid;
  auto key = [&](std::size_t i) {
    const Vec3& c = cells.position[i];
    auto along = [&](real x, int a) { return std::floor((double(x) - grid.origin[a]) * grid.inv_cell); };
    return std::tuple(along(c.z, 2), along(c.y, 1), along(c.x, 0));
  };
  for (std::size_t i = 201; i < 3200; ++i) EXPECT_LE(key(i - 1), key(i)) << i;
  // The random velocities are drawn in the new order: the same draws by index.
  for (std::size_t i = 200; i < 3200; ++i) ASSERT_EQ(cells.velocity[i], given.velocity[i]) << i;
  // The list: rows of x within a row of y; each sphere keeps its velocity.
  EXPECT_EQ(cells.position[3200], Vec3(4, 0, 0));
  EXPECT_EQ(cells.position[3201], Vec3(5, 0, 0));
  EXPECT_EQ(cells.position[3202], Vec3(3, 1, 0));
  EXPECT_EQ(cells.velocity[3200], Vec3(2, 0, 0));
  EXPECT_EQ(cells.velocity[3201], Vec3(1, 0, 0));
  EXPECT_EQ(cells.velocity[3202], Vec3(3, 0, 0));
  try {
    scene_from(dir, test::replace_all(blocks, "ORDER", "order: cell"));
    ADD_FAILURE() << "order: cell was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("particles[1].order"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("unknown order 'cell'"), std::string::npos) << e.what();
  }
}

TEST(Random, HundredThousandSpheres) {
  const ScratchDir dir("random_100k");
  const Scene s = scene_from(dir, "  - random: {count: 100000, min: [0, 0, 0], max: [1, 1, 1], radius: 0.005}\n");
  const GeneratedParticles p = generate_particles(s);
  ASSERT_EQ(p.size(), 100000u);
  EXPECT_TRUE(all_inside(p, {0, 0, 0}, {1, 1, 1}));
  // Overlaps by brute force on a 2,000-sphere corner of the box.
  GeneratedParticles corner;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.position[i].x < 0.3f && p.position[i].y < 0.3f && p.position[i].z < 0.3f) {
      corner.position.push_back(p.position[i]);
      corner.radius.push_back(p.radius[i]);
    }
  }
  EXPECT_GT(corner.size(), 2000u);
  EXPECT_EQ(count_overlaps(corner), 0u);
}

// The generator's numbers are fixed by std::mt19937_64 (specified exactly by
// the standard) and a hand-written mapping to [0, 1): this value must be the
// same with every standard library.
TEST(Random, SameNumbersOnEveryPlatform) {
  const ScratchDir dir("random_golden");
  const Scene s = scene_from(dir, "  - random: {count: 1, min: [0, 0, 0], max: [1, 1, 1], radius: 0.5, seed: 5489}\n"
                                  "    velocity: {random: {speed: 1, seed: 5489}}\n");
  const GeneratedParticles p = generate_particles(s);
  // First output of mt19937_64 seeded with 5489 is 14514284786278117030 (the
  // standard's check value), so u = (that >> 11) * 2^-53 = 0.786820...;
  // the velocity's x is -1 + 2u.
  const double u = double(14514284786278117030ull >> 11) * 0x1.0p-53;
  EXPECT_FLOAT_EQ(p.velocity[0].x, float(-1 + 2 * u));
  EXPECT_FLOAT_EQ(p.position[0].x, 0.5f);  // the only place a sphere of radius 0.5 fits
}

// --- velocities and lists ----------------------------------------------------

TEST(Velocity, ConstantAndRandomInRange) {
  const ScratchDir dir("velocity");
  const Scene s = scene_from(dir,
                             "  - lattice: {min: [0, 0, 0], max: [1, 1, 1], spacing: 0.2, radius: 0.05}\n"
                             "    velocity: [1, -2, 3]\n"
                             "  - lattice: {min: [2, 0, 0], max: [3, 1, 1], spacing: 0.2, radius: 0.05}\n"
                             "    velocity: {random: {speed: 0.5, seed: 7}}\n");
  const GeneratedParticles p = generate_particles(s);
  ASSERT_EQ(p.size(), 250u);
  double mean = 0;
  for (std::size_t i = 0; i < 125; ++i) EXPECT_TRUE(p.velocity[i] == Vec3(1, -2, 3));
  for (std::size_t i = 125; i < 250; ++i) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_LE(std::fabs(p.velocity[i][a]), 0.5f);
      mean += p.velocity[i][a] / 375;
    }
  }
  EXPECT_NEAR(mean, 0, 0.05);
}

TEST(List, PositionsRadiiVelocitiesAndMaterial) {
  const ScratchDir dir("list");
  const std::string path = dir.write("s.yaml", SCENE_TIME
                                     "materials:\n  a: {}\n  b: {}\n"
                                     "particles:\n"
                                     "  - list:\n"
                                     "      positions: [[0, 0, 0], [1, 0, 0]]\n"
                                     "      radii: [0.1, 0.2]\n"
                                     "      velocities: [[0, 0, 1], [0, 0, -1]]\n"
                                     "    material: b\n");
  const GeneratedParticles p = generate_particles(load_scene(path));
  ASSERT_EQ(p.size(), 2u);
  EXPECT_TRUE(p.position[1] == Vec3(1, 0, 0));
  EXPECT_FLOAT_EQ(p.radius[1], 0.2f);
  EXPECT_TRUE(p.velocity[1] == Vec3(0, 0, -1));
  EXPECT_EQ(p.material[0], 1u);
}

// --- CSV -------------------------------------------------------------------

TEST(Csv, RoundTrip) {
  const ScratchDir dir("csv_round_trip");
  const Scene s = scene_from(
      dir, "  - random: {count: 300, min: [-1, -1, -1], max: [1, 1, 1], radius: {uniform: [0.01, 0.05]}}\n"
           "    velocity: {random: {speed: 3}}\n");
  const GeneratedParticles original = generate_particles(s);
  std::ofstream out(dir.path() + "/round.csv");
  out << "# written by the test\nx,y,z,r,vx,vy,vz\n";
  char line[256];
  for (std::size_t i = 0; i < original.size(); ++i) {
    const Vec3 &c = original.position[i], &v = original.velocity[i];
    std::snprintf(line, sizeof line, "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", c.x, c.y, c.z, original.radius[i], v.x,
                  v.y, v.z);
    out << line;
  }
  out.close();
  const GeneratedParticles back = read_spheres_csv(dir.path() + "/round.csv");
  EXPECT_TRUE(same_spheres(original, back));

  const GeneratedParticles via_scene = generate_particles(scene_from(dir, "  - csv: {path: round.csv}\n"));
  EXPECT_TRUE(same_spheres(original, via_scene));
}

TEST(Csv, HeaderInAnyOrderCommentsAndBlankLines) {
  const ScratchDir dir("csv_header");
  const std::string path = dir.write("h.csv",
                                     "\xEF\xBB\xBF# a comment (after a UTF-8 byte order mark)\n"
                                     "\n"
                                     " radius , z, y, x\n"
                                     "0.5, 3, 2, 1   # trailing comment\n"
                                     "\r\n"
                                     "0.25,6,5,4\r\n");
  const GeneratedParticles p = read_spheres_csv(path);
  ASSERT_EQ(p.size(), 2u);
  EXPECT_TRUE(p.position[0] == Vec3(1, 2, 3));
  EXPECT_FLOAT_EQ(p.radius[0], 0.5f);
  EXPECT_TRUE(p.position[1] == Vec3(4, 5, 6));
  EXPECT_TRUE(p.velocity[1] == Vec3(0, 0, 0));
}

TEST(Csv, NoHeader) {
  const ScratchDir dir("csv_plain");
  const GeneratedParticles p = read_spheres_csv(dir.write("p.csv", "1,2,3,0.5\n-1e-3,+2,3.5e1,.25\n"));
  ASSERT_EQ(p.size(), 2u);
  EXPECT_FLOAT_EQ(p.position[1].x, -0.001f);
  EXPECT_FLOAT_EQ(p.position[1].z, 35.0f);
  EXPECT_FLOAT_EQ(p.radius[1], 0.25f);
}

TEST(Csv, Errors) {
  const ScratchDir dir("csv_errors");
  auto error_of = [&](const std::string& text) -> std::string {
    const std::string path = dir.write("e.csv", text);
    try {
      read_spheres_csv(path);
    } catch (const InputError& e) {
      return test::replace_all(e.what(), path, "e.csv");
    }
    return "no error";
  };
  EXPECT_EQ(error_of("0,0,0,1\n0,0,0\n"), "e.csv:2:1: expected 4 comma-separated values (as on line 1), got 3");
  EXPECT_EQ(error_of("0,0,0,1\n0, 0, nan, 1\n"), "e.csv:2:7: z: must be a finite number, got nan");
  EXPECT_EQ(error_of("x,y,z\n"), "e.csv:1:1: the header lacks column 'r'");
  EXPECT_EQ(error_of("x,y,z,r,speed\n"),
            "e.csv:1:9: unknown column 'speed' in the header; expected x, y, z, r (or radius) and optionally vx, vy, vz "
            "and wx, wy, wz");
  EXPECT_EQ(error_of("x,y,z,r,vx\n"), "e.csv:1:1: the header must name all of vx, vy, vz or none of them");
  EXPECT_EQ(error_of("# nothing\n"), "e.csv: holds no spheres (rows x,y,z,r[,vx,vy,vz[,wx,wy,wz]])");
  // Values as a scene's: in range, and a non-zero one not below the smallest normal, in the run's precision.
  EXPECT_EQ(error_of("0,0,0,1\n0,1e-320,0,1\n"),
            "e.csv:2:3: y: too small for " + std::string(kRealName) + " precision, got 1e-320");
  if (sizeof(real) == 4) {
    EXPECT_EQ(error_of("0,0,0,1e39\n"), "e.csv:1:7: r: out of range for float precision, got 1e39");
  }
  // A first value that begins as a number but is none the precision holds (out of double's range, hex, 400
  // digits) is a row's, refused as on any later line: it was taken for a header ("unknown column '1e400'").
  for (const std::string& v :
       std::vector<std::string>{"1e400", "-1e400", "1e-400", "0x10", "0x1p3", ".5e999", std::string(400, '9')}) {
    const std::string first = error_of(v + ",0,0,1\n");
    std::string later = error_of("0,0,0,1\n" + v + ",0,0,1\n");
    ASSERT_EQ(later.rfind("e.csv:2:", 0), 0u) << later;
    later.replace(0, 8, "e.csv:1:");
    EXPECT_EQ(first, later) << v;
    EXPECT_EQ(first.find("header"), std::string::npos) << first;
  }
  // A line longer than any row (a binary file, a stream without line ends) is refused at the bound.
  EXPECT_EQ(error_of("0,0,0,1\n#" + std::string(1048576, '7') + "\r\n"),
            "e.csv:2:1: a line longer than 1048576 bytes: not a CSV file of spheres (rows x,y,z,r[,vx,vy,vz[,wx,wy,wz]])");
  EXPECT_EQ(error_of("0,0,0,1\n" + std::string(1100000, '7') + "\n"),
            "e.csv:2:1: a line longer than 1048576 bytes: not a CSV file of spheres (rows x,y,z,r[,vx,vy,vz[,wx,wy,wz]])");
  // ... and one just within it is read (a comment), as is a last row without its line end and CRLF rows.
  const GeneratedParticles within =
      read_spheres_csv(dir.write("w.csv", "#" + std::string(1048575, 'c') + "\r\n0,0,0,1\r\n1,2,3,0.5"));
  ASSERT_EQ(within.size(), 2u);
  EXPECT_EQ(within.radius[1], real(0.5));
  if (std::filesystem::exists("/dev/zero")) {
    try {
      read_spheres_csv("/dev/zero");
      ADD_FAILURE() << "/dev/zero was read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("'/dev/zero' is a device, not a CSV file of spheres"), std::string::npos)
          << e.what();
    }
  }
  try {
    read_spheres_csv(dir.path());
    ADD_FAILURE() << "a folder was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("is a folder, not a CSV file of spheres"), std::string::npos) << e.what();
  }
  try {
    read_spheres_csv(dir.path() + "/absent.csv");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()),
              dir.path() + "/absent.csv: cannot open '" + dir.path() + "/absent.csv': No such file or directory");
  }
}

TEST(Csv, VelocityColumnsAndBlockVelocityConflict) {
  const ScratchDir dir("csv_velocity");
  dir.write("v.csv", "0,0,0,1,1,2,3\n");
  const std::string path = dir.write("s.yaml", SCENE_TIME SCENE_MATERIALS
                                     "particles:\n  - csv: {path: v.csv}\n    velocity: [0, 0, 1]\n");
  const Scene s = load_scene(path);
  try {
    generate_particles(s);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ":6:15: particles[0].velocity: '" + dir.path() +
                                         "/v.csv' gives every sphere its velocity (vx,vy,vz); give one or the other");
  }
}

TEST(Csv, ExampleForPairs) {
  const GeneratedParticles p = read_spheres_csv(MARBLES_SOURCE_DIR "/scenes/spheres.csv");
  ASSERT_EQ(p.size(), 10u);
  std::size_t overlaps = count_overlaps(p);
  EXPECT_EQ(overlaps, 4u);  // as its comment says
}

// --- the shipped scenes -------------------------------------------------------

std::vector<std::string> shipped_scenes() {
  std::vector<std::string> paths;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(MARBLES_SOURCE_DIR "/scenes"))
    if (entry.is_regular_file() && entry.path().extension() == ".yaml") paths.push_back(entry.path().string());
  std::sort(paths.begin(), paths.end());
  return paths;
}

TEST(Scenes, EveryShippedSceneLoadsAndGenerates) {
  const std::vector<std::string> paths = shipped_scenes();
  EXPECT_GE(paths.size(), 4u);
  for (const std::string& path : paths) {
    SCOPED_TRACE(path);
    try {
      const Scene s = load_scene(path);
      const GeneratedParticles p = generate_particles(s);
      EXPECT_GT(p.size(), 0u);
      for (std::size_t i = 0; i < p.size(); ++i) {
        ASSERT_TRUE(is_finite(p.position[i]));
        ASSERT_GT(p.radius[i], 0);
        ASSERT_LT(p.material[i], s.materials.size());
      }
    } catch (const InputError& e) {
      ADD_FAILURE() << e.what();
    }
  }
}

TEST(Scenes, NamedScenesHaveTheirShape) {
  const Scene ball = load_scene(MARBLES_SOURCE_DIR "/scenes/bouncing_ball.yaml");
  EXPECT_EQ(ball.effects, (std::vector<Effect>{Effect::gravity, Effect::collisions, Effect::walls,
                                               Effect::restitution}));
  EXPECT_DOUBLE_EQ(ball.materials.at(0).restitution, 0.8);
  const GeneratedParticles one = generate_particles(ball);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_FLOAT_EQ(one.position[0].z, 1.0f);

  EXPECT_EQ(generate_particles(load_scene(MARBLES_SOURCE_DIR "/scenes/settle_10k.yaml")).size(), 10000u);
  EXPECT_EQ(generate_particles(load_scene(MARBLES_SOURCE_DIR "/scenes/rain.yaml")).size(), 100000u);

  const Scene demo = load_scene(MARBLES_SOURCE_DIR "/scenes/demo.yaml");
  EXPECT_TRUE(demo.output.render.enabled);
  EXPECT_TRUE(demo.output.render.camera.given);
  EXPECT_TRUE(demo.output.movie.enabled);
  EXPECT_DOUBLE_EQ(demo.output.movie.fps, 30);
  EXPECT_GT(demo.output.vtk_every, 0);
  const GeneratedParticles poured = generate_particles(demo);
  EXPECT_GE(poured.size(), 2000u);
  EXPECT_EQ(count_overlaps(poured), 0u);  // across blocks too
}

}  // namespace
}  // namespace marbles::scene
