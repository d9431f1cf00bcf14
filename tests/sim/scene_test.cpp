// tests/sim/scene_test.cpp — the scene loader: values, defaults, and the exact
// message of every bad-input rule (file:line:column: key: text).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "core/format.hpp"
#include "narrowphase/solver_math.hpp"
#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles::scene {
namespace {

using test::BadScene;
using test::ScratchDir;

// --- every bad-input rule ---------------------------------------------------

class BadSceneTest : public ::testing::TestWithParam<BadScene> {};

TEST_P(BadSceneTest, ThrowsInputErrorWithExactMessage) {
  const BadScene& c = GetParam();
  const ScratchDir dir(std::string("load_") + c.name);
  const std::string path = test::write_case(c, dir);
  const std::string expected = test::expected_message(c, path, dir.path());
  try {
    const Scene scene = load_scene(path);
    generate_particles(scene);
    FAIL() << "no error; expected: " << expected;
  } catch (const InputError& e) {
    EXPECT_TRUE(test::message_matches(expected, e.what())) << "expected: " << expected << "\n     got: " << e.what();
  }
}

INSTANTIATE_TEST_SUITE_P(Rules, BadSceneTest, ::testing::ValuesIn(test::bad_scenes()),
                         [](const ::testing::TestParamInfo<BadScene>& info) { return std::string(info.param.name); });

TEST(SceneErrors, CarryLocationAndKeySeparately) {
  const ScratchDir dir("parts");
  const std::string path = dir.write("s.yaml", SCENE_TIME "materials:\n  glass: {density: 2500, restitution: 1.3}\n"
                                                SCENE_PARTICLES);
  try {
    load_scene(path);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().file, path);
    EXPECT_EQ(e.where().line, 3);
    EXPECT_EQ(e.where().column, 39);
    EXPECT_EQ(e.key(), "materials.glass.restitution");
    EXPECT_EQ(e.message(), "must be within [0, 1], got 1.3");
  }
}

// A substep in which gravity alone moves a sphere past what the precision
// holds (|g| h^2 beyond an sixteenth of its largest number) is refused at
// time.dt, in either precision; just inside it, or without the gravity
// effect, or with the substeps that bring h back, the scene loads.
TEST(SceneErrors, GravitysFallInASubstepPastThePrecisionIsRefusedAtDt) {
  const ScratchDir dir("fall_past_range");
  const double most = double(std::numeric_limits<real>::max()) / 16;
  const double g = 9.81;
  const double edge = std::sqrt(most / g);  // |g| h^2 = most
  const auto scene = [&](double dt, const std::string& more) {
    return "time: {duration: " + shortest(4 * dt) + ", dt: " + shortest(dt) + more + "}\n" SCENE_MATERIALS
           "particles:\n  - list: {positions: [[0, 0, 1], [1, 0, 1]], radius: 0.1}\n";
  };
  std::vector<double> past = {1.01 * edge, 1e3 * edge};
  // In double, a fall past double's own range (said as "more than", not inf).
  if (sizeof(real) == 8) past.push_back(std::sqrt(std::numeric_limits<double>::max()));
  for (const double dt : past) {
    const std::string path = dir.write("s.yaml", scene(dt, ""));
    try {
      load_scene(path);
      ADD_FAILURE() << "dt " << dt << " loaded";
    } catch (const InputError& e) {
      EXPECT_EQ(e.where().file, path);
      EXPECT_EQ(e.where().line, 1);
      EXPECT_GT(e.where().column, 1);
      EXPECT_EQ(e.key(), "time.dt");
      EXPECT_NE(e.message().find("lets gravity move a sphere |g| h^2 = "), std::string::npos) << e.what();
      EXPECT_NE(e.message().find(std::string("more than ") + kRealName + " precision holds"), std::string::npos)
          << e.what();
      EXPECT_EQ(e.message().find("inf"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(load_scene(dir.write("s.yaml", scene(0.99 * edge, ""))));
  EXPECT_NO_THROW(load_scene(dir.write("s.yaml", scene(1e3 * edge, ", substeps: 1000000"))));
  EXPECT_NO_THROW(load_scene(dir.write("s.yaml", scene(1e3 * edge, "") + "effects: [collisions]\n")));
}

// A scene given as JSON (the Python module's dicts) nests as deep as a scene
// file may: the same document, its reference nested d levels (flow YAML is
// JSON), is refused for its depth by both readers or by neither, on either
// side of the YAML reader's bound (which the JSON reader repeats: yaml-cpp
// keeps it private).
TEST(SceneErrors, JsonNestsAsDeepAsTheYamlReaderFollows) {
  const ScratchDir dir("json_depth");
  const auto too_deep = [](auto&& load) {
    try {
      load();
    } catch (const InputError& e) {
      return e.message().find("nested deeper than the YAML reader follows") != std::string::npos;
    }
    return false;
  };
  int refused = 0, taken = 0;
  for (int d = 470; d <= 530; ++d) {
    const std::string text = R"({"time": {"duration": 1, "dt": 0.001}, "materials": {"a": {}}, )"
                             R"("particles": [{"list": {"positions": [[0, 0, 1]], "radius": 0.1}}], "reference": )" +
                             std::string(std::size_t(d), '[') + std::string(std::size_t(d), ']') + "}";
    const std::string path = dir.write("deep.yaml", text);
    const bool yaml = too_deep([&] { load_scene(path); });
    const bool json = too_deep([&] { load_scene_json(text, "dict", "deep"); });
    EXPECT_EQ(yaml, json) << d << " levels: refused by the " << (yaml ? "YAML" : "JSON") << " reader alone";
    (yaml ? refused : taken) += 1;
  }
  EXPECT_GT(refused, 0);  // the bound is within the range tried
  EXPECT_GT(taken, 0);
}

TEST(SceneErrors, RandomOverfullSaysHowManyWerePlaced) {
  const ScratchDir dir("overfull");
  const std::string path = dir.write(
      "s.yaml", SCENE_TIME SCENE_MATERIALS
      "particles:\n  - random: {count: 1000, min: [0, 0, 0], max: [0.1, 0.1, 0.1], radius: 0.02}\n");
  const Scene scene = load_scene(path);
  try {
    generate_particles(scene);
    FAIL() << "no error";
  } catch (const InputError& e) {
    const std::string m = e.message();
    EXPECT_NE(m.find("could place only "), std::string::npos) << m;
    EXPECT_NE(m.find(" of 1000 non-overlapping spheres"), std::string::npos) << m;
    EXPECT_NE(m.find("1000 attempts"), std::string::npos) << m;
  }
}

// --- values and defaults -------------------------------------------------------

TEST(SceneLoad, MinimalSceneTakesDocumentedDefaults) {
  const ScratchDir dir("defaults");
  const std::string path = dir.write("tiny.yaml", SCENE_VALID);
  const Scene s = load_scene(path);
  EXPECT_EQ(s.path, path);
  EXPECT_EQ(s.name, "tiny");
  EXPECT_DOUBLE_EQ(s.time.duration, 1);
  EXPECT_DOUBLE_EQ(s.time.dt, 0.001);
  EXPECT_EQ(s.time.substeps, 1);
  EXPECT_EQ(s.solver.iterations, 10);
  EXPECT_EQ(s.solver.impact_passes, narrowphase::kImpactPasses);  // the solver's own default
  EXPECT_EQ(s.solver.integrator, "symplectic_euler");
  const std::vector<Effect> defaults = {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction};
  EXPECT_EQ(s.effects, defaults);
  EXPECT_FLOAT_EQ(s.gravity.z, -9.81f);
  ASSERT_EQ(s.materials.size(), 1u);
  EXPECT_EQ(s.materials[0].name, "glass");
  EXPECT_DOUBLE_EQ(s.materials[0].density, 2500);
  EXPECT_DOUBLE_EQ(s.materials[0].restitution, 0.5);
  EXPECT_DOUBLE_EQ(s.materials[0].friction, 0.5);
  EXPECT_DOUBLE_EQ(s.materials[0].rolling_friction, 0);
  EXPECT_EQ(s.materials[0].where.line, 3);
  EXPECT_TRUE(s.walls.empty());
  ASSERT_EQ(s.particles.size(), 1u);
  EXPECT_EQ(s.particles[0].kind, ParticleBlock::Kind::list);
  EXPECT_EQ(s.particles[0].velocity.kind, VelocitySpec::Kind::zero);
  EXPECT_EQ(s.output.dir, "out/tiny");
  EXPECT_EQ(s.output.vtk_every, 0);
  EXPECT_FALSE(s.output.render.enabled);
  EXPECT_FALSE(s.output.movie.enabled);
  EXPECT_EQ(s.output.fields.size(), 5u);
}

TEST(SceneLoad, ReadsEverySection) {
  const ScratchDir dir("full");
  dir.write("pile.csv", "x,y,z,r\n0,0,0.5,0.05\n");
  const std::string path = dir.write("full.yaml", R"(format: 1
name: Full scene
time: {duration: 2, dt: 0.01, substeps: 4}
solver: {iterations: 25, integrator: symplectic_euler}
effects: [gravity, walls, drag]
gravity: [0, -9.8, 0]
drag: {linear: 0.25, quadratic: 0.5}
materials:
  steel: {density: 7800, restitution: 0.6, friction: 0.3, rolling_friction: 0.01}
  glass:
contact_pairs:
  - materials: [steel, glass]
    restitution: 0.9
walls:
  - plane: {point: [0, 0, 0], normal: [0, 0, 2]}
    material: glass
    velocity: [0, 0, 0.5]
  - box: {min: [-1, -1, 0], max: [1, 1, 2]}
  - cylinder: {base: [0, 0, 0], axis: [0, 0, 3], radius: 0.8, length: 2, inside: false, angular_velocity: 1.5}
  - sphere: {centre: [0, 0, 1], radius: 0.2}
particles:
  - lattice: {min: [0, 0, 0], max: [0.5, 0.5, 0.5], spacing: 0.1, radius: 0.02, jitter: 0.01, seed: 5}
    material: glass
    velocity: [1, 2, 3]
  - random: {count: 10, min: [0, 0, 1], max: [1, 1, 2], radius: {log_uniform: [0.01, 0.05]}, seed: 9}
    velocity: {random: {speed: 2, seed: 11}}
  - csv: {path: pile.csv}
output:
  dir: results
  vtk: {every: 5}
  fields: [radius, id]
  render:
    every: 3
    width: 640
    height: 480
    color_by: radius
    camera: {position: [3, 0, 1], look_at: [0, 0, 0.5], up: [0, 0, 1], fov: 50}
  movie: {fps: 24}
)");
  const Scene s = load_scene(path);
  EXPECT_EQ(s.name, "Full scene");
  EXPECT_EQ(s.time.substeps, 4);
  EXPECT_EQ(s.solver.iterations, 25);
  EXPECT_EQ(s.effects, (std::vector<Effect>{Effect::gravity, Effect::walls, Effect::drag}));
  EXPECT_TRUE(s.has(Effect::drag));
  EXPECT_FALSE(s.has(Effect::collisions));
  EXPECT_FLOAT_EQ(s.gravity.y, -9.8f);
  EXPECT_DOUBLE_EQ(s.drag, 0.25);
  EXPECT_DOUBLE_EQ(s.drag_quadratic, 0.5);
  ASSERT_EQ(s.contact_pairs.size(), 1u);
  EXPECT_EQ(s.contact_pairs[0].first, "steel");
  EXPECT_EQ(s.contact_pairs[0].second, "glass");
  EXPECT_DOUBLE_EQ(s.contact_pairs[0].restitution, 0.9);
  EXPECT_LT(s.contact_pairs[0].friction, 0);  // not given: mixing rule
  ASSERT_EQ(s.materials.size(), 2u);
  EXPECT_EQ(s.materials[0].name, "steel");  // file order
  EXPECT_EQ(s.materials[1].name, "glass");
  EXPECT_DOUBLE_EQ(s.materials[1].density, 1000);  // `glass:` alone: defaults
  EXPECT_EQ(s.material_index("glass", {}, "k"), 1u);
  EXPECT_EQ(s.material_index("", {}, "k"), 0u);
  ASSERT_EQ(s.walls.size(), 4u);
  EXPECT_EQ(s.walls[0].kind, WallSpec::Kind::plane);
  EXPECT_FLOAT_EQ(s.walls[0].normal.z, 1.0f);  // normalised
  EXPECT_EQ(s.walls[0].material, "glass");
  EXPECT_FLOAT_EQ(s.walls[0].velocity.z, 0.5f);
  EXPECT_EQ(s.walls[1].kind, WallSpec::Kind::box);
  EXPECT_FLOAT_EQ(s.walls[1].hi.z, 2.0f);
  EXPECT_EQ(s.walls[2].kind, WallSpec::Kind::cylinder);
  EXPECT_FLOAT_EQ(s.walls[2].axis.z, 1.0f);
  EXPECT_DOUBLE_EQ(s.walls[2].radius, 0.8);
  EXPECT_DOUBLE_EQ(s.walls[2].length, 2);
  EXPECT_FALSE(s.walls[2].inside);
  EXPECT_DOUBLE_EQ(s.walls[2].angular_velocity, 1.5);
  EXPECT_EQ(s.walls[3].kind, WallSpec::Kind::sphere);
  EXPECT_FLOAT_EQ(s.walls[3].centre.z, 1.0f);
  EXPECT_DOUBLE_EQ(s.walls[3].radius, 0.2);
  ASSERT_EQ(s.particles.size(), 3u);
  EXPECT_EQ(s.particles[0].kind, ParticleBlock::Kind::lattice);
  EXPECT_DOUBLE_EQ(s.particles[0].jitter, 0.01);
  EXPECT_EQ(s.particles[0].seed, 5u);
  EXPECT_EQ(s.particles[0].velocity.kind, VelocitySpec::Kind::constant);
  EXPECT_EQ(s.particles[1].radius.kind, RadiusSpec::Kind::log_uniform);
  EXPECT_DOUBLE_EQ(s.particles[1].radius.max, 0.05);
  EXPECT_EQ(s.particles[1].velocity.kind, VelocitySpec::Kind::random);
  EXPECT_EQ(s.particles[1].velocity.seed, 11u);
  EXPECT_EQ(s.particles[2].kind, ParticleBlock::Kind::csv);
  EXPECT_EQ(s.particles[2].csv_path, dir.path() + "/pile.csv");
  EXPECT_EQ(s.output.dir, "results");
  EXPECT_EQ(s.output.vtk_every, 5);
  EXPECT_EQ(s.output.fields, (std::vector<std::string>{"radius", "id"}));
  EXPECT_TRUE(s.output.render.enabled);
  EXPECT_EQ(s.output.render.every, 3);
  EXPECT_EQ(s.output.render.width, 640);
  EXPECT_EQ(s.output.render.color_by, "radius");
  EXPECT_TRUE(s.output.render.camera.given);
  EXPECT_DOUBLE_EQ(s.output.render.camera.fov, 50);
  EXPECT_TRUE(s.output.movie.enabled);
  EXPECT_DOUBLE_EQ(s.output.movie.fps, 24);

  const GeneratedParticles p = generate_particles(s);
  EXPECT_EQ(p.size(), 5u * 5u * 5u + 10u + 1u);  // (0.5 - 2 * 0.03) / 0.1 = 4.4 → 5 per axis
  EXPECT_EQ(p.material[0], 1u);
  EXPECT_EQ(p.material[125], 0u);
  EXPECT_FLOAT_EQ(p.velocity[0].y, 2.0f);
}

TEST(SceneLoad, NumbersInEveryYamlSpelling) {
  const ScratchDir dir("numbers");
  const std::string path = dir.write("n.yaml", "time: {duration: 1e1, dt: +2.5E-3, substeps: 1e1}\n" SCENE_MATERIALS
                                               SCENE_PARTICLES "gravity: [0, 0, -10]\n");
  const Scene s = load_scene(path);
  EXPECT_DOUBLE_EQ(s.time.duration, 10);
  EXPECT_DOUBLE_EQ(s.time.dt, 0.0025);
  EXPECT_EQ(s.time.substeps, 10);
}

TEST(SceneLoad, EffectNames) {
  EXPECT_STREQ(effect_name(Effect::gravity), "gravity");
  EXPECT_STREQ(effect_name(Effect::collisions), "collisions");
  EXPECT_STREQ(effect_name(Effect::walls), "walls");
  EXPECT_STREQ(effect_name(Effect::restitution), "restitution");
  EXPECT_STREQ(effect_name(Effect::friction), "friction");
  EXPECT_STREQ(effect_name(Effect::rolling_resistance), "rolling_resistance");
  EXPECT_STREQ(effect_name(Effect::drag), "drag");
}

TEST(SceneLoad, MaterialIndexThrowsAtTheGivenPlace) {
  const ScratchDir dir("material_index");
  const Scene s = load_scene(dir.write("m.yaml", SCENE_VALID));
  try {
    s.material_index("steel", SourceLocation{"x.yaml", 4, 7}, "particles[3].material");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "x.yaml:4:7: particles[3].material: unknown material 'steel'; expected one of: glass");
  }
}

// --- --set overrides -----------------------------------------------------------

#define SET_SCENE                                  \
  SCENE_TIME                                       \
  "materials:\n  glass: {density: 2500}\n"         \
  "particles:\n  - random: {count: 10, min: [0, 0, 0], max: [1, 1, 1], radius: 0.02}\n"

TEST(SceneOverrides, ChangeTheLoadedValues) {
  const ScratchDir dir("set_values");
  const std::string path = dir.write("s.yaml", SET_SCENE);
  const Scene s = load_scene(path, {"time.dt=5e-4", "particles[0].random.count=500", "materials.glass.restitution=0.9",
                                    "solver.iterations=20", "gravity=[0, 0, -1]", "time.substeps=2",
                                    "time.substeps=3", "particles[0].velocity={random: {speed: 2}}"});
  EXPECT_DOUBLE_EQ(s.time.dt, 5e-4);
  EXPECT_DOUBLE_EQ(s.time.duration, 1);  // untouched
  EXPECT_EQ(s.time.substeps, 3);         // the later override wins
  ASSERT_EQ(s.particles.size(), 1u);
  EXPECT_EQ(s.particles[0].count, 500u);
  EXPECT_EQ(s.particles[0].velocity.kind, VelocitySpec::Kind::random);
  EXPECT_DOUBLE_EQ(s.particles[0].velocity.speed, 2);
  EXPECT_DOUBLE_EQ(s.materials[0].density, 2500);
  EXPECT_DOUBLE_EQ(s.materials[0].restitution, 0.9);
  EXPECT_EQ(s.solver.iterations, 20);  // `solver:` created
  EXPECT_FLOAT_EQ(s.gravity.z, -1.0f);
  EXPECT_EQ(generate_particles(s).size(), 500u);

  const Scene plain = load_scene(path);
  EXPECT_DOUBLE_EQ(plain.time.dt, 0.001);
  EXPECT_EQ(plain.solver.iterations, 10);
}

TEST(SceneOverrides, NullValueBecomesAMap) {
  const ScratchDir dir("set_null");
  const std::string path =
      dir.write("s.yaml", SCENE_TIME "materials:\n  glass:\n" "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1}\n");
  const Scene s = load_scene(path, {"materials.glass.density=3000", "particles[0].list.positions[0]=[1, 2, 3]"});
  EXPECT_DOUBLE_EQ(s.materials[0].density, 3000);
  EXPECT_FLOAT_EQ(s.particles[0].positions[0].y, 2.0f);
}

// YAML is Unicode: a file in UTF-16 (with its byte order mark) reads as its
// UTF-8 twin; an override with bytes that are no UTF-8 is refused (yaml-cpp
// took "\xff\xfe" for a byte order mark and the value for null), named in
// printable form.
TEST(SceneLoad, UnicodeTextOnly) {
  const ScratchDir dir("unicode");
  const std::string text = SCENE_TIME "name: caf\xc3\xa9 \xe2\x82\xac\n" SCENE_MATERIALS SCENE_PARTICLES;
  std::string utf16 = "\xff\xfe";  // little-endian; every character of `text` is below U+0800
  for (std::size_t i = 0; i < text.size();) {
    const unsigned char c = text[i];
    const unsigned code = c < 0x80 ? c
                          : c < 0xe0 ? ((c & 0x1fu) << 6) | (text[i + 1] & 0x3fu)
                                     : ((c & 0x0fu) << 12) | ((text[i + 1] & 0x3fu) << 6) | (text[i + 2] & 0x3fu);
    i += c < 0x80 ? 1 : c < 0xe0 ? 2 : 3;
    utf16 += char(code & 0xff);
    utf16 += char(code >> 8);
  }
  const Scene plain = load_scene(dir.write("s.yaml", text));
  EXPECT_EQ(plain.name, "caf\xc3\xa9 \xe2\x82\xac");
  EXPECT_EQ(load_scene(dir.write("s16.yaml", utf16)).name, plain.name);
  EXPECT_EQ(load_scene(dir.write("o.yaml", SET_SCENE), {"name=caf\xc3\xa9"}).name, "caf\xc3\xa9");
  const std::pair<std::string, std::string> refused[] = {
      {"name=\xff\xfe", "--set name=\\xff\\xfe: not UTF-8 text: \\xff at byte 6"},
      {"name=ab\xff", "--set name=ab\\xff: not UTF-8 text: \\xff at byte 8"},
      {"name=caf\xe9", "--set name=caf\\xe9: not UTF-8 text: \\xe9 at byte 9"}};
  for (const auto& [bad, message] : refused) {
    try {
      load_scene(dir.write("o.yaml", SET_SCENE), {bad});
      FAIL() << "no error for " << message;
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), message);
    }
  }
}

// A quoted value is read whole where its quote closes, however it ends
// (escaped quotes and backslashes, doubled single quotes, a line break
// inside, a byte order mark before); where it does not close before the
// file ends it is refused, also where yaml-cpp took it (a line break last).
TEST(SceneLoad, QuotedValuesCloseOrAreRefused) {
  const ScratchDir dir("quotes");
  const std::pair<std::string, std::string> closed[] = {
      {R"("a\"b")", R"(a"b)"},     {R"("a\\")", R"(a\)"}, {"'it''s'", "it's"}, {"''''", "'"},
      {"\"two\n  lines\"", "two lines"}, {"|\n  \"open\n", "\"open\n"}, {"'\"'", "\""}, {"\"'\"", "'"},
      {"&n \"anchored\"", "anchored"},   {"! \"bare\"", "bare"}};
  for (const auto& [value, name] : closed)
    for (const std::string bom : {"", "\xef\xbb\xbf"}) {
      const std::string text = bom + SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES "name: " + value + "\n";
      EXPECT_EQ(load_scene(dir.write("s.yaml", text)).name, name) << value;
    }
  const std::pair<std::string, char> open[] = {{R"("a\")", '"'}, {R"("a\\\")", '"'}, {"'it''", '\''},
                                               {"'''", '\''},    {"\"'\n", '"'},     {"'\"\n\n", '\''},
                                               {"&n \"a", '"'},  {"! 'b", '\''}};
  for (const auto& [value, quote] : open)
    for (const std::string bom : {"", "\xef\xbb\xbf"}) {
      const std::string text = bom + SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES "name: " + value + "\n";
      try {
        load_scene(dir.write("s.yaml", text));
        ADD_FAILURE() << "no error for " << value;
      } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()), dir.path() + "/s.yaml:6:7: name: a quoted value never closed (its " +
                                             std::string(1, quote) + " is missing)")
            << value;
      }
    }
  // The same two checks hold a --set value.
  EXPECT_EQ(load_scene(dir.write("o.yaml", SET_SCENE), {"name='it''s'"}).name, "it's");
  const std::pair<std::string, std::string> refused[] = {
      {"name=\"x\n", R"(--set name="x\x0a: a quoted value never closed (its " is missing))"},
      {"time.dt=!!float 1e-3", "--set time.dt=!!float 1e-3: a YAML tag ('!!float'): a scene's values take none (remove it)"}};
  for (const auto& [bad, message] : refused)
    try {
      load_scene(dir.write("o.yaml", SET_SCENE), {bad});
      ADD_FAILURE() << "no error for " << bad;
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), message);
    }
}

// A NUL byte in a scene file is refused where it stands (yaml-cpp read one
// as an escape: "unknown escape character: m").
TEST(SceneFile, ANulByteIsRefusedWhereItStands) {
  const ScratchDir dir("nul_byte");
  const std::string path = dir.write("s.yaml", std::string(SCENE_TIME) + std::string("na\0me: x\n", 9));
  try {
    load_scene(path);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ":2:3: a NUL byte: not text (a binary file?)");
  }
  // UTF-16 without a byte order mark is told by its NUL bytes, as YAML tells it: read as its UTF-8 twin.
  const std::string utf8 = SCENE_VALID;
  std::string utf16;
  for (const char c : utf8) utf16 += std::string{c, '\0'};
  EXPECT_EQ(load_scene(dir.write("wide.yaml", utf16)).fingerprint, load_scene(dir.write("narrow.yaml", utf8)).fingerprint);
}

// first_non_utf8 against RFC 3629's table: whole characters of one to four
// bytes pass; a stray continuation byte, an overlong form, a surrogate, a
// character past U+10FFFF, a byte that never occurs and a cut character are
// found where they begin.
TEST(Utf8, FindsTheFirstByteThatIsNoUtf8) {
  for (const std::string good : {"", "abc", "\xc2\x80", "\xdf\xbf", "\xe0\xa0\x80", "\xed\x9f\xbf", "\xee\x80\x80",
                                 "\xf0\x90\x80\x80", "\xf4\x8f\xbf\xbf", "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80"})
    EXPECT_EQ(first_non_utf8(good), std::string::npos) << printable(good);
  const std::pair<std::string, std::size_t> bad[] = {
      {"\x80", 0},          {"ab\xbf", 2},           {"\xc0\xaf", 0},         {"\xc1\xbf", 0},
      {"\xe0\x80\xaf", 0},  {"\xed\xa0\x80", 0},     {"\xf0\x80\x80\xaf", 0}, {"\xf4\x90\x80\x80", 0},
      {"\xf5\x80\x80\x80", 0}, {"a\xff", 1},          {"\xfe", 0},             {"x\xe2\x82", 1},
      {"\xc3", 0},          {"\xc3\xa9\xc3(", 2}};
  for (const auto& [text, at] : bad) EXPECT_EQ(first_non_utf8(text), at) << printable(text);
}

// time_text: the fewest characters that read back within 1e-13 of the time
// (relative), plain digits where they are no longer than the exponent form
// ("10" and "120", not "1e+01" and "1.2e+02"; "1e-05" stays, "0.00001" is
// longer). Checked against the rule itself on random multiples of steps.
TEST(TimeText, FewestCharactersWithinTheTolerance) {
  const std::pair<double, const char*> known[] = {
      {10, "10"},        {120, "120"},  {1000, "1000"}, {1e5, "1e+05"}, {0.03, "0.03"}, {1e-5, "1e-05"},
      {2.5e-7, "2.5e-07"}, {0, "0"},    {-40, "-40"},    {3 * 0.1, "0.3"}, {1e17, "1e+17"}};
  for (const auto& [t, text] : known) EXPECT_EQ(time_text(t), text) << t;
  std::mt19937_64 rng(11);
  std::uniform_int_distribution<int> steps(0, 2'000'000), exponent(-7, 1);
  for (int k = 0; k < 20000; ++k) {
    const double dt = std::pow(10.0, exponent(rng)) * (1 + (k % 7) * 0.25);
    const double t = steps(rng) * dt;
    const std::string text = time_text(t);
    ASSERT_LE(std::fabs(std::strtod(text.c_str(), nullptr) - t), 1e-13 * std::fabs(t)) << text << " for " << t;
    // No shorter text (of %g with fewer digits, or plain) is as close.
    char shorter[64];
    for (int digits = 1; digits <= 17; ++digits) {
      std::snprintf(shorter, sizeof shorter, "%.*g", digits, t);
      if (std::strlen(shorter) >= text.size()) continue;
      EXPECT_GT(std::fabs(std::strtod(shorter, nullptr) - t), 1e-13 * std::fabs(t)) << shorter << " for " << text;
    }
  }
}

// An override's label is cut after 200 bytes, before a character's
// continuation bytes: the message stays UTF-8 text.
TEST(SceneOverrides, ALongLabelIsCutBetweenCharacters) {
  const ScratchDir dir("set_cut");
  const std::string path = dir.write("s.yaml", SET_SCENE);
  const std::string value = "time.dt=" + std::string(191, 'a') + "\xc3\xa9tail";  // the character at bytes 199-200
  try {
    load_scene(path, {value});
    FAIL() << "no error";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_EQ(first_non_utf8(m), std::string::npos) << printable(m);
    EXPECT_EQ(m.substr(0, 6 + 199 + 3), "--set " + value.substr(0, 199) + "...");
  }
}

struct BadOverride {
  const char* name;
  const char* text;
  const char* expected;  // the whole message; a trailing "..." means "starts with"
};

void PrintTo(const BadOverride& c, std::ostream* os) { *os << c.name; }

class BadOverrideTest : public ::testing::TestWithParam<BadOverride> {};

TEST_P(BadOverrideTest, NamesTheOverride) {
  const BadOverride& c = GetParam();
  const ScratchDir dir(std::string("set_") + c.name);
  const std::string path = dir.write("s.yaml", SET_SCENE);
  try {  // a valid override first: the error names the one at fault
    generate_particles(load_scene(path, {"time.substeps=2", c.text}));
    FAIL() << "no error; expected: " << c.expected;
  } catch (const InputError& e) {
    EXPECT_TRUE(test::message_matches(c.expected, e.what())) << "expected: " << c.expected << "\n     got: " << e.what();
    EXPECT_EQ(e.where().file, std::string("--set ") + c.text);
    EXPECT_EQ(e.where().line, 0);
  }
}

const BadOverride kBadOverrides[] = {
    // invalid values: the same checks as in a file, at the override
    {"negative_dt", "time.dt=-1", "--set time.dt=-1: time.dt: must be > 0, got -1"},
    {"dt_over_duration", "time.dt=2", "--set time.dt=2: time.dt: a duration of 1 s is shorter than a step, time.dt = 2 s"},
    {"under_the_value", "materials.glass={density: -5}", "--set materials.glass={density: -5}: materials.glass.density: must be > 0, got -5"},
    {"created_key_unknown", "time.dtt=5", "--set time.dtt=5: time: unknown key 'dtt' (did you mean 'dt'?)"},
    {"created_section_unknown", "solvr.iterations=5", "--set solvr.iterations=5: unknown key 'solvr' (did you mean 'solver'?)"},
    {"short_vector", "gravity=[0, -1]", "--set gravity=[0, -1]: gravity: expected [x, y, z], got a sequence of 2"},
    // keys a merge key in the override brings: at the override, not at a place in its text taken for the file's
    {"merge_key_in_the_path", "materials.glass.<<={densty: 5}",
     "--set materials.glass.<<={densty: 5}: materials.glass: unknown key 'densty' (did you mean 'density'?)"},
    {"merge_key_in_the_value", "time={<<: {dtt: 5}}", "--set time={<<: {dtt: 5}}: time: unknown key 'dtt' ..."},
    // one item of a vector in the file: the vector is checked whole, at the override
    {"vector_item", "particles[0].random.min[2]=1e30",
     "--set particles[0].random.min[2]=1e30: particles[0].random.min: too large for float precision: ..."},
    {"empty_value", "solver.iterations=", "--set solver.iterations=: solver.iterations: expected an integer, got nothing (null)"},
    // an item of a list the scene lacks: said so (it said "expected a sequence, got a map", a map it made)
    {"item_of_a_missing_list", "walls[0].velocity=[0,0,1]",
     "--set walls[0].velocity=[0,0,1]: walls: cannot take item [0]: the scene has no list there"},
    // a key twice in the value: no file line to name (it said "first given at line 0")
    {"duplicate_in_value", "materials.glass={density: 1, density: 2}",
     "--set materials.glass={density: 1, density: 2}: materials.glass: duplicate key 'density'"},
    // whole numbers past 64 bits: the bound they pass, not "not an integer"
    {"huge_count", "time.substeps=9999999999999999999999",
     "--set time.substeps=9999999999999999999999: time.substeps: must be <= 1000000000, got 9999999999999999999999"},
    {"huge_seed", "particles[0].random.seed=1e20",
     "--set particles[0].random.seed=1e20: particles[0].random.seed: must be <= 18446744073709551615, got 1e20"},
    {"huge_negative", "solver.renumber=-1e30", "--set solver.renumber=-1e30: solver.renumber: must be >= 0, got -1e30"},
    {"found_while_generating", "particles[0].random={count: 1000, min: [0, 0, 0], max: [0.1, 0.1, 0.1], radius: 0.02}",
     "--set particles[0].random={count: 1000, min: [0, 0, 0], max: [0.1, 0.1, 0.1], radius: 0.02}: "
     "particles[0].random.count: could place only ..."},
    // paths that do not fit the tree
    {"past_the_end", "particles[1].random.count=5", "--set particles[1].random.count=5: particles: has 1 item(s); [1] is past the end"},
    {"into_a_scalar", "time.dt.x=5", "--set time.dt.x=5: time.dt: cannot hold key 'x': expected a map, got '0.001'"},
    {"index_a_map", "time[0]=5", "--set time[0]=5: time: cannot take item [0]: expected a sequence, got a map"},
    // malformed overrides
    {"no_equals", "time.dt", "--set time.dt: expected key.path=value, e.g. time.dt=5e-4"},
    {"empty_key", "=5", "--set =5: expected key.path=value, e.g. time.dt=5e-4"},
    {"bad_index", "particles[x].random.count=5", "--set particles[x].random.count=5: expected an index such as [0] after 'particles'"},
    {"unclosed_index", "particles[0=5", "--set particles[0=5: expected an index such as [0] after 'particles'"},
    {"empty_segment", "time..dt=5", "--set time..dt=5: expected a key name at character 6 of 'time..dt'"},
    {"stray_bracket", "time]=5", "--set time]=5: unexpected ']' at character 5 of 'time]'"},
    {"bad_yaml", "gravity=[0, 0", "--set gravity=[0, 0: the value is not valid YAML: end of sequence flow not found"},
};

INSTANTIATE_TEST_SUITE_P(Rules, BadOverrideTest, ::testing::ValuesIn(kBadOverrides),
                         [](const ::testing::TestParamInfo<BadOverride>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace marbles::scene
