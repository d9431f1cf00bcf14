// tests/sim/scene_features_test.cpp — initial angular velocity (per block and
// per CSV row), fixed spheres (collide, never move) and YAML merge keys.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "core/error.hpp"
#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/simulation.hpp"
#include "sim/world.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles {
namespace {

using test::ScratchDir;

std::string load_error(const std::string& path, const std::vector<std::string>& overrides = {}) {
  try {
    const scene::Scene s = scene::load_scene(path, overrides);
    scene::generate_particles(s);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(SceneFeatures, AngularVelocityPerBlockAndPerCsvRow) {
  const ScratchDir dir("features_spin");
  dir.write("rows.csv", "1,0,0,0.1,0,0,0,4,5,6\n3,0,0,0.1,0,0,0,-1,0,0.5\n");
  dir.write("named.csv", "wz,x,y,z,r,wx,wy\n7,0,2,0,0.1,8,9\n");
  const std::string path = dir.write("s.yaml", SCENE_TIME SCENE_MATERIALS
                                     "particles:\n"
                                     "  - list: {positions: [[0, 0, 5], [1, 0, 5]], radius: 0.1}\n"
                                     "    angular_velocity: [1, 2, 3]\n"
                                     "  - csv: {path: rows.csv}\n"
                                     "  - csv: {path: named.csv}\n");
  const scene::Scene s = scene::load_scene(path);
  const World w = make_world(s, scene::generate_particles(s));
  ASSERT_EQ(w.size(), 5u);
  const Vec3 expected[] = {{1, 2, 3}, {1, 2, 3}, {4, 5, 6}, {-1, 0, real(0.5)}, {8, 9, 7}};
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(w.angular_velocity[i].x, expected[i].x) << i;
    EXPECT_EQ(w.angular_velocity[i].y, expected[i].y) << i;
    EXPECT_EQ(w.angular_velocity[i].z, expected[i].z) << i;
  }
  // Half the columns, or both sources, are errors naming where.
  dir.write("half.csv", "x,y,z,r,wx\n0,0,0,0.1,1\n");
  EXPECT_NE(load_error(dir.write("h.yaml", SCENE_TIME SCENE_MATERIALS "particles:\n  - csv: {path: half.csv}\n"))
                .find("half.csv:1:1: the header must name all of wx, wy, wz or none of them"),
            std::string::npos);
  const std::string both = load_error(dir.write(
      "b.yaml", SCENE_TIME SCENE_MATERIALS "particles:\n  - csv: {path: rows.csv}\n    angular_velocity: [0, 0, 1]\n"));
  EXPECT_NE(both.find("b.yaml:6:23: particles[0].angular_velocity: '" + dir.path() +
                      "/rows.csv' gives every sphere its angular velocity"),
            std::string::npos)
      << both;
  // The same through an override (which has no line in the file): the
  // file's spins were kept and the override dropped without a word.
  const std::string csv_only =
      dir.write("c.yaml", SCENE_TIME SCENE_MATERIALS "particles:\n  - csv: {path: rows.csv}\n");
  EXPECT_EQ(load_error(csv_only), "");
  const std::string by_override = load_error(csv_only, {"particles[0].angular_velocity=[0,0,1]"});
  EXPECT_NE(by_override.find("particles[0].angular_velocity: '" + dir.path() +
                             "/rows.csv' gives every sphere its angular velocity"),
            std::string::npos)
      << by_override;
  EXPECT_NE(load_error(csv_only, {"particles[0].velocity=[0,0,1]"})
                .find("particles[0].velocity: '" + dir.path() + "/rows.csv' gives every sphere its velocity"),
            std::string::npos);
}

// Pegs: a fixed row under a falling sphere hold it up, and never move (bit
// for bit); the same sphere without the pegs falls through their place.
TEST(SceneFeatures, FixedSpheresCollideButNeverMove) {
  const ScratchDir dir("features_fixed");
  const std::string common = "time: {duration: 1, dt: 0.001, substeps: 2}\n"
                             "effects: [gravity, collisions, restitution, friction]\n"
                             "materials:\n  glass: {density: 2500, restitution: 0.3, friction: 0.5}\n"
                             "particles:\n"
                             "  - list: {positions: [[0.02, 0.01, 0.3]], radius: 0.05}\n";
  const std::string pegs = "  - lattice: {min: [-0.3, -0.3, -0.05], max: [0.3, 0.3, 0.05], spacing: 0.1, radius: 0.05}\n"
                           "    fixed: true\n";
  for (const bool with_pegs : {true, false}) {
    const scene::Scene s = scene::load_scene(dir.write("s.yaml", common + (with_pegs ? pegs : "")));
    World start = make_world(s, scene::generate_particles(s));
    Simulation sim(s, start, broadphase::Backend::cpu);
    for (int k = 0; k < 1000; ++k) sim.step();
    const World& w = sim.world();
    ASSERT_FALSE(sim.non_finite());
    if (!with_pegs) {
      EXPECT_LT(w.position[0].z, -3.0);  // free fall: 0.3 - g / 2
      continue;
    }
    ASSERT_GT(w.size(), 1u);
    for (std::size_t i = 1; i < w.size(); ++i) {
      EXPECT_EQ(w.position[i].x, start.position[i].x);
      EXPECT_EQ(w.position[i].y, start.position[i].y);
      EXPECT_EQ(w.position[i].z, start.position[i].z);
      EXPECT_EQ(length_squared(w.velocity[i]), 0);
      EXPECT_EQ(length_squared(w.angular_velocity[i]), 0);
    }
    EXPECT_GT(w.position[0].z, 0.05);  // resting on the pegs (their tops at z = 0.05)
    EXPECT_LT(w.position[0].z, 0.16);
  }
  // A fixed block given a velocity is a contradiction.
  EXPECT_NE(load_error(dir.write("v.yaml", common + pegs + "    velocity: [0, 0, 1]\n"))
                .find("particles[1].fixed: fixed spheres never move: give them no velocity"),
            std::string::npos);
}

// A glued floor: fixed spheres overlapping each other by more than a radius
// make no contact between themselves (no impulse moves either), so under the
// watchdog a sphere dropped on them comes to rest, and the step's largest
// overlap and contacts are the free sphere's alone; the same floor made of
// free spheres (no gravity, so they stay put until pushed) is all contacts.
TEST(SceneFeatures, FixedSpheresMakeNoContactsBetweenThemselves) {
  const ScratchDir dir("features_glued");
  std::string floor = "  - list:\n      radius: 0.05\n      positions: [";
  for (int x = -4; x <= 4; ++x)
    for (int y = -4; y <= 4; ++y) {
      std::ostringstream at;
      at << "[" << 0.04 * x << ", " << 0.04 * y << ", 0]" << (x == 4 && y == 4 ? "]\n" : ", ");
      floor += at.str();
    }
  for (const bool fixed : {true, false}) {
    const scene::Scene s = scene::load_scene(
        dir.write("s.yaml", std::string("time: {duration: 1, dt: 0.001}\n") +
                                (fixed ? "" : "gravity: [0, 0, 0]\n") +
                                "effects: [gravity, collisions, friction]\n"
                                "materials:\n  glass: {density: 2500, friction: 0.5}\n"
                                "particles:\n"
                                "  - list: {positions: [[0.02, 0.02, 0.2]], radius: 0.05}\n" +  // over a pocket of four
                                floor + (fixed ? "    fixed: true\n" : "")));
    const World start = make_world(s, scene::generate_particles(s));
    const std::size_t n = start.size();
    ASSERT_GT(n, 50u);
    Simulation sim(s, start, broadphase::Backend::cpu);
    if (!fixed) {
      sim.step();
      // Every neighbour along an axis overlaps (0.04 apart, radius 0.05), and more.
      EXPECT_GT(sim.last_step().contacts, 2 * (n - 1));
      EXPECT_GT(sim.last_step().max_overlap, 1.0f);
      continue;
    }
    sim.set_watchdog(true);
    real deepest = 0;
    std::size_t most = 0;
    for (int k = 0; k < 600; ++k) {
      ASSERT_NO_THROW(sim.step()) << "step " << k;
      deepest = std::max(deepest, sim.last_step().max_overlap);
      most = std::max<std::size_t>(most, sim.last_step().contacts);
    }
    EXPECT_EQ(sim.rollbacks(), 0u);
    EXPECT_LE(most, 8u);  // the free sphere's contacts with the floor's tops
    EXPECT_LT(deepest, 0.05f);
    const World& w = sim.world();
    EXPECT_GT(w.position[0].z, 0.05);  // on the floor, whose tops are at z = 0.05
    EXPECT_LT(w.position[0].z, 0.12);
    EXPECT_LT(length(w.velocity[0]), 0.01f);  // at rest in the pocket
  }
}

// YAML merge keys: `<<: *anchor` (and a list of them) supply the keys a map
// does not give itself; errors in merged values still name their lines.
TEST(SceneFeatures, MergeKeysSupplyDefaults) {
  const ScratchDir dir("features_merge");
  const std::string path = dir.write("s.yaml", SCENE_TIME
                                     "materials:\n"
                                     "  base: &glass {density: 2500, restitution: 0.6, friction: 0.4}\n"
                                     "  sticky:\n"
                                     "    <<: *glass\n"
                                     "    friction: 0.9\n"
                                     "  heavy: {<<: [*glass], density: 7800}\n"
                                     "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1}\n");
  const scene::Scene s = scene::load_scene(path);
  ASSERT_EQ(s.materials.size(), 3u);
  EXPECT_EQ(s.materials[1].name, "sticky");
  EXPECT_DOUBLE_EQ(s.materials[1].density, 2500);
  EXPECT_DOUBLE_EQ(s.materials[1].restitution, 0.6);
  EXPECT_DOUBLE_EQ(s.materials[1].friction, 0.9);
  EXPECT_DOUBLE_EQ(s.materials[2].density, 7800);
  EXPECT_DOUBLE_EQ(s.materials[2].friction, 0.4);
  const std::string bad = dir.write("bad.yaml", SCENE_TIME
                                    "materials:\n"
                                    "  base: &glass {density: 2500, restitution: 1.6}\n"
                                    "  other: {<<: *glass, friction: 0.2}\n"
                                    "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1}\n");
  EXPECT_NE(load_error(bad).find("bad.yaml:3:45: materials.base.restitution: must be within [0, 1]"), std::string::npos)
      << load_error(bad);
  const std::string scalar = dir.write("scalar.yaml", SCENE_TIME "materials:\n  a: {<<: 3, density: 1}\n"
                                       "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1}\n");
  EXPECT_NE(load_error(scalar).find("scalar.yaml:3:11: materials.a.<<: a merge key takes a map or a list of maps"),
            std::string::npos)
      << load_error(scalar);
  // A merge key in a --set value is resolved as one in the file is.
  const scene::Scene over = scene::load_scene(path, {"materials.heavy={<<: {density: 5, friction: 0.2}, density: 7}"});
  EXPECT_DOUBLE_EQ(over.materials[2].density, 7);
  EXPECT_DOUBLE_EQ(over.materials[2].friction, 0.2);
  try {
    scene::load_scene(path, {"materials.heavy={<<: 3, density: 7}"});
    ADD_FAILURE() << "a scalar merged through --set was taken";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("materials.heavy.<<: a merge key takes a map or a list of maps"),
              std::string::npos)
        << e.what();
  }
}

// An override changes the one place it names: a value the file shares
// through an alias (`b: *a`, a merge key's values, `friction: *d`) keeps
// its other places, and an error names the place overridden; what the
// override copied on its way keeps its lines in the file.
TEST(SceneFeatures, OverridesChangeOnePlaceOfAnAlias) {
  const ScratchDir dir("features_alias_override");
  const std::string path = dir.write("s.yaml",
                                     "time: {duration: &d 0.5, dt: 0.001}\n"
                                     "materials:\n"
                                     "  a: &g {density: 2500, restitution: 0.9, friction: *d}\n"
                                     "  b: *g\n"
                                     "  c: {<<: *g, rolling_friction: 0.01}\n"
                                     "particles:\n"
                                     "  - {list: {positions: &p [[0, 0, 1], [1, 0, 1]], radius: 0.1}, material: a}\n"
                                     "  - {list: {positions: *p, radius: 0.1}, material: b}\n"
                                     "  - {list: &l {positions: [[5, 0, 1]], radius: 0.1}, material: c}\n"
                                     "  - {list: *l, material: c}\n");
  const scene::Scene plain = scene::load_scene(path);
  ASSERT_EQ(plain.materials.size(), 3u);
  for (const scene::Material& m : plain.materials) {
    EXPECT_DOUBLE_EQ(m.density, 2500);
    EXPECT_DOUBLE_EQ(m.friction, 0.5);
  }
  const auto materials = [](const scene::Scene& s, auto figure) {
    std::vector<double> out;
    for (const scene::Material& m : s.materials) out.push_back(figure(m));
    return out;
  };
  const auto density = [](const scene::Material& m) { return m.density; };
  const auto friction = [](const scene::Material& m) { return m.friction; };
  EXPECT_EQ(materials(scene::load_scene(path, {"materials.b.density=7"}), density), (std::vector<double>{2500, 7, 2500}));
  EXPECT_EQ(materials(scene::load_scene(path, {"materials.c.density=7"}), density), (std::vector<double>{2500, 2500, 7}));
  EXPECT_EQ(materials(scene::load_scene(path, {"materials.a.density=7"}), density), (std::vector<double>{7, 2500, 2500}));
  const scene::Scene longer = scene::load_scene(path, {"time.duration=2"});
  EXPECT_DOUBLE_EQ(longer.time.duration, 2);
  EXPECT_EQ(materials(longer, friction), (std::vector<double>{0.5, 0.5, 0.5}));
  const scene::Scene rough = scene::load_scene(path, {"materials.b.friction=0.25"});
  EXPECT_DOUBLE_EQ(rough.time.duration, 0.5);
  EXPECT_EQ(materials(rough, friction), (std::vector<double>{0.5, 0.25, 0.5}));
  // A shared list of positions, and an item of it.
  const auto xs = [](const scene::Scene& s) {
    std::vector<double> out;
    for (const Vec3& p : scene::generate_particles(s).position) out.push_back(p.x);
    return out;
  };
  EXPECT_EQ(xs(plain), (std::vector<double>{0, 1, 0, 1, 5, 5}));
  EXPECT_EQ(xs(scene::load_scene(path, {"particles[1].list.positions[1][0]=3"})),
            (std::vector<double>{0, 1, 0, 3, 5, 5}));
  EXPECT_EQ(xs(scene::load_scene(path, {"particles[3].list.positions=[[9, 0, 1]]"})),
            (std::vector<double>{0, 1, 0, 1, 5, 9}));
  EXPECT_EQ(xs(scene::load_scene(path, {"particles[0].list.positions[0][0]=2", "particles[0].list.positions[1][0]=4"})),
            (std::vector<double>{2, 4, 0, 1, 5, 5}));
  // Errors name the place overridden, not another place of the alias.
  for (const std::string set : {"materials.b.density=-1", "materials.c.density=-1"}) {
    const std::string error = load_error(path, {set});
    EXPECT_NE(error.find(set.substr(0, set.find('=')) + ": must be > 0"), std::string::npos) << set << ": " << error;
  }
  // In a tree that shares nodes, an item of a list the scene lacks is refused
  // as such (it was yaml-cpp's "invalid node", exit 1), and a later override
  // through an earlier one's value names that override, not a place in its
  // text taken for the file's.
  EXPECT_EQ(load_error(path, {"walls[0].velocity=[0,0,1]"}),
            "--set walls[0].velocity=[0,0,1]: walls: cannot take item [0]: the scene has no list there");
  EXPECT_EQ(load_error(path, {"materials.x={density: -1, restitution: 0.5}", "materials.x.friction=0.2"}),
            "--set materials.x={density: -1, restitution: 0.5}: materials.x.density: must be > 0, got -1");
  // A map the override copied keeps its place in the file: a key it lacks is
  // reported at the map's line and column, as without the override.
  const std::string lacking = dir.write("lacking.yaml", SCENE_TIME SCENE_MATERIALS
                                        "particles:\n"
                                        "  - list: &l {radius: 0.1}\n"
                                        "  - list: *l\n");
  const std::string error = load_error(lacking, {"particles[1].list.radius=0.2"});
  EXPECT_NE(error.find("lacking.yaml:5:"), std::string::npos) << error;
}

// A map that merges itself, or one around it, and a map that holds itself
// through an alias are refused with the merge key's (or the node's) place,
// not followed until the stack runs out.
TEST(SceneFeatures, MergeKeysThatHoldThemselvesAreRefused) {
  const ScratchDir dir("features_merge_cycle");
  const std::string particles = "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1}\n";
  struct Case {
    const char* name;
    const char* materials;
    const char* expected;
  };
  for (const Case& c : {
           Case{"self.yaml", "  a: &x {<<: *x}\n", "self.yaml:3:10: materials.a.<<: a merge key names a map that holds it"},
           Case{"keys.yaml", "  a: &x {density: 5, <<: *x}\n",
                "keys.yaml:3:22: materials.a.<<: a merge key names a map that holds it"},
           Case{"list.yaml", "  c: &y {<<: [{density: 5}, *y]}\n",
                "list.yaml:3:10: materials.c.<<: a merge key names a map that holds it"},
           Case{"outer.yaml", "  d: &o {e: {<<: *o}}\n", "outer.yaml:3:14: materials.d.e.<<: a merge key names a map"},
           Case{"alias.yaml", "  f: &z {density: 5, g: *z, <<: {friction: 0.1}}\n",
                "...: nested more than 1,000 levels deep (an alias inside the node it names?)"},
       }) {
    const std::string path = dir.write(c.name, std::string(SCENE_TIME "materials:\n") + c.materials + particles);
    const std::string error = load_error(path);
    EXPECT_NE(error.find(c.expected), std::string::npos) << c.name << ": " << error;
    EXPECT_NE(error.find(std::string(c.name) + ":3:"), std::string::npos) << c.name << ": " << error;
  }
  EXPECT_NE(load_error(dir.path() + "/alias.yaml").find(": materials.f.g.g.g.g.g.g.g.g.g.g"), std::string::npos);
  // ... and the same maps without the cycle load.
  const std::string fine = dir.write("fine.yaml", std::string(SCENE_TIME "materials:\n"
                                                              "  b: &x {density: 5, restitution: 0.5}\n"
                                                              "  c: {<<: [*x], friction: 0.2}\n") +
                                                      particles);
  EXPECT_EQ(scene::load_scene(fine).materials.size(), 2u);
}

}  // namespace
}  // namespace marbles
