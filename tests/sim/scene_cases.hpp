// tests/sim/scene_cases.hpp — bad scene files and the exact message each must
// produce; shared by the loader test (scene_test.cpp) and the command-line
// test (cli_check_test.cpp).
//
// `expected` holds `{scene}` (the scene path as given) and `{dir}` (its
// folder); a trailing "..." means "starts with".
#pragma once

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>
#include <vector>

#include <unistd.h>

namespace marbles::test {

struct BadScene {
  const char* name;
  const char* yaml;      // nullptr: the scene file does not exist
  const char* expected;  // see above
  const char* csv = nullptr;  // written as data.csv beside the scene when given
};

// GoogleTest prints a case by its name.
inline void PrintTo(const BadScene& c, std::ostream* os) { *os << c.name; }

#define SCENE_TIME "time: {duration: 1, dt: 0.001}\n"
#define SCENE_MATERIALS "materials:\n  glass: {density: 2500}\n"
#define SCENE_PARTICLES "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1}\n"
#define SCENE_VALID SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES

// A valid scene but for its `count` materials m0, m1, ... (kept for the process).
inline const std::string& many_materials_scene(int count) {
  static const std::string text = [count] {
    std::string t = SCENE_TIME "materials: {";
    for (int i = 0; i < count; ++i) t += (i ? ", m" : "m") + std::to_string(i) + ": {}";
    return t + "}\n" SCENE_PARTICLES;
  }();
  return text;
}

inline const std::vector<BadScene>& bad_scenes() {
  static const std::vector<BadScene> cases = {
      {"unknown_key_near", SCENE_TIME "materials:\n  glass: {densty: 2500}\n" SCENE_PARTICLES,
       "{scene}:3:11: materials.glass: unknown key 'densty' (did you mean 'density'?)"},
      {"unknown_key_far", SCENE_VALID "colour: red\n",
       "{scene}:6:1: unknown key 'colour'; expected one of: format, name, time, solver, effects, gravity, drag, "
       "materials, contact_pairs, walls, particles, output, reference"},
      {"duplicate_key", SCENE_VALID "time: {duration: 2, dt: 0.001}\n",
       "{scene}:6:1: duplicate key 'time' (first given at line 1)"},
      {"wrong_type_sequence", "time: {duration: [1, 2], dt: 0.001}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:18: time.duration: expected a number, got a sequence"},
      {"wrong_type_text", "time: {duration: soon, dt: 0.001}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:18: time.duration: expected a number, got 'soon'"},
      {"wrong_type_map", SCENE_TIME "materials: glass\n" SCENE_PARTICLES,
       "{scene}:2:12: materials: expected a map, got 'glass'"},
      {"wrong_type_null", SCENE_VALID "gravity:\n", "{scene}:6:1: gravity: expected [x, y, z], got nothing (null)"},
      {"vector_length", SCENE_VALID "gravity: [0, -9.81]\n",
       "{scene}:6:10: gravity: expected [x, y, z], got a sequence of 2"},
      {"not_integer", "time: {duration: 1, dt: 0.001, substeps: 2.5}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:42: time.substeps: expected an integer, got 2.5"},
      {"missing_key", "time: {duration: 1}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:7: time: missing required key 'dt'"},
      {"missing_top_key", SCENE_TIME SCENE_MATERIALS, "{scene}:1:1: missing required key 'particles'"},
      {"radius_negative", SCENE_TIME SCENE_MATERIALS "particles:\n  - list: {positions: [[0, 0, 1]], radius: -0.1}\n",
       "{scene}:5:44: particles[0].list.radius: must be > 0, got -0.1"},
      {"density_zero", SCENE_TIME "materials:\n  glass: {density: 0}\n" SCENE_PARTICLES,
       "{scene}:3:20: materials.glass.density: must be > 0, got 0"},
      {"dt_zero", "time: {duration: 1, dt: 0}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:25: time.dt: must be > 0, got 0"},
      {"duration_negative", "time: {duration: -1, dt: 0.001}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:18: time.duration: must be > 0, got -1"},
      {"dt_above_duration", "time: {duration: 1, dt: 2}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:25: time.dt: a duration of 1 s is shorter than a step, time.dt = 2 s"},
      {"spacing_zero",
       SCENE_TIME SCENE_MATERIALS
       "particles:\n  - lattice: {min: [0, 0, 0], max: [1, 1, 1], spacing: 0, radius: 0.1}\n",
       "{scene}:5:56: particles[0].lattice.spacing: must be > 0, got 0"},
      {"spacing_too_small",
       SCENE_TIME SCENE_MATERIALS
       "particles:\n  - lattice: {min: [0, 0, 0], max: [1, 1, 1], spacing: 0.1, radius: 0.1}\n",
       "{scene}:5:56: particles[0].lattice.spacing: must be >= 2 * (largest radius + jitter) = 0.2 so that "
       "spheres cannot overlap, got 0.1"},
      {"count_zero",
       SCENE_TIME SCENE_MATERIALS "particles:\n  - random: {count: 0, min: [0, 0, 0], max: [1, 1, 1], radius: 0.1}\n",
       "{scene}:5:21: particles[0].random.count: must be >= 1, got 0"},
      {"substeps_zero", "time: {duration: 1, dt: 0.001, substeps: 0}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:42: time.substeps: must be >= 1, got 0"},
      {"iterations_zero", SCENE_VALID "solver: {iterations: 0}\n",
       "{scene}:6:22: solver.iterations: must be >= 1, got 0"},
      {"closing_iterations_zero", SCENE_VALID "solver: {integrator: velocity_verlet, closing_iterations: 0}\n",
       "{scene}:6:59: solver.closing_iterations: must be >= 1, got 0"},
      {"impact_passes_zero", SCENE_VALID "solver: {impact_passes: 0}\n",
       "{scene}:6:25: solver.impact_passes: must be >= 1, got 0"},
      {"impact_passes_past_limit", SCENE_VALID "solver: {impact_passes: 5000}\n",
       "{scene}:6:25: solver.impact_passes: must be <= 4096, got 5000"},
      {"unknown_integrator", SCENE_VALID "solver: {integrator: rk4}\n",
       "{scene}:6:22: solver.integrator: unknown integrator 'rk4'; expected one of: symplectic_euler, velocity_verlet"},
      {"integrator_typo", SCENE_VALID "solver: {integrator: velocity_verlett}\n",
       "{scene}:6:22: solver.integrator: unknown integrator 'velocity_verlett' (did you mean 'velocity_verlet'?)"},
      {"renumber_negative", SCENE_VALID "solver: {renumber: -1}\n",
       "{scene}:6:20: solver.renumber: must be >= 0, got -1"},
      {"unknown_order", SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES "    order: spiral\n",
       "{scene}:6:12: particles[0].order: unknown order 'spiral'; expected one of: given, cells"},
      {"order_typo", SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES "    order: cell\n",
       "{scene}:6:12: particles[0].order: unknown order 'cell' (did you mean 'cells'?)"},
      {"unknown_precision", SCENE_VALID "solver: {precision: half}\n",
       "{scene}:6:21: solver.precision: unknown precision 'half'; expected one of: float, double"},
      {"speculative_not_boolean", SCENE_VALID "solver: {speculative: maybe}\n",
       "{scene}:6:23: solver.speculative: expected true or false, got 'maybe'"},
      {"reference_unknown_kind", SCENE_VALID "reference: {bounce_height: {restitution: 0.5}}\n",
       "{scene}:6:13: reference: unknown key 'bounce_height'; expected one of: rebound_heights, time_to_rest, "
       "incline, slide_to_roll, oblique_rebound, kinetic_energy, momentum, finest"},
      {"reference_two_kinds", SCENE_VALID "reference: {momentum: conserved, kinetic_energy: conserved}\n",
       "{scene}:6:12: reference: give exactly one reference kind (2 given)"},
      {"reference_missing_restitution", SCENE_VALID "reference: {rebound_heights: {bounces: 2}}\n",
       "{scene}:6:30: reference.rebound_heights: missing required key 'restitution'"},
      {"reference_rest_elastic", SCENE_VALID "reference: {time_to_rest: {restitution: 1}}\n",
       "{scene}:6:41: reference.time_to_rest.restitution: must be < 1: with e = 1 the ball never comes to rest"},
      {"reference_incline_angle", SCENE_VALID "reference: {incline: {angle: 95, friction: 0.5}}\n",
       "{scene}:6:30: reference.incline.angle: must be within (0, 90) degrees, got 95"},
      {"reference_conserved_word", SCENE_VALID "reference: {momentum: kept}\n",
       "{scene}:6:23: reference.momentum: expected 'conserved', got 'kept'"},
      {"reference_word", SCENE_VALID "reference: finer\n",
       "{scene}:6:12: reference: expected a map {kind: {...}} or 'finest', got 'finer'; expected one of: "
       "rebound_heights, time_to_rest, incline, slide_to_roll, oblique_rebound, kinetic_energy, momentum, finest"},
      {"restitution_range", SCENE_TIME "materials:\n  glass: {density: 2500, restitution: 1.3}\n" SCENE_PARTICLES,
       "{scene}:3:39: materials.glass.restitution: must be within [0, 1], got 1.3"},
      // the key's own bounds before the precision's (they said "too small for float precision")
      {"restitution_tiny_negative",
       SCENE_TIME "materials:\n  glass: {density: 2500, restitution: -1e-300}\n" SCENE_PARTICLES,
       "{scene}:3:39: materials.glass.restitution: must be within [0, 1], got -1e-300"},
      {"density_tiny_negative", SCENE_TIME "materials:\n  glass: {density: -1e-300}\n" SCENE_PARTICLES,
       "{scene}:3:20: materials.glass.density: must be > 0, got -1e-300"},
      {"friction_negative", SCENE_TIME "materials:\n  glass: {friction: -0.2}\n" SCENE_PARTICLES,
       "{scene}:3:21: materials.glass.friction: must be >= 0, got -0.2"},
      {"no_materials", SCENE_TIME "materials: {}\n" SCENE_PARTICLES,
       "{scene}:2:12: materials: needs at least one material, e.g. `steel: {density: 7800}`"},
      {"nan", SCENE_VALID "gravity: [0, 0, .nan]\n", "{scene}:6:17: gravity[2]: must be a finite number, got .nan"},
      {"inf", "time: {duration: .inf, dt: 0.001}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:18: time.duration: must be a finite number, got .inf"},
      // Past double's range: a number too small is too small, not 0 (a
      // restitution or a coordinate of 1e-400 was taken as 0), nor infinite.
      {"underflow", "time: {duration: 1, dt: 1e-400}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:25: time.dt: too small for ..."},
      {"underflow_zero_allowed", SCENE_TIME "materials:\n  glass: {density: 2500, restitution: 1e-400}\n" SCENE_PARTICLES,
       "{scene}:3:39: materials.glass.restitution: too small for ..."},
      {"underflow_negative", SCENE_VALID "gravity: [0, 0, -1e-400]\n", "{scene}:6:17: gravity[2]: too small for ..."},
      {"overflow_negative", "time: {duration: 1, dt: -1e400}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:25: time.dt: must be a finite number, got -1e400"},
      {"not_yaml", "time: {duration: 1, dt: [0.001\nmaterials:\n",
       "{scene}:2:10: not valid YAML: end of sequence flow not found"},
      {"not_a_map", "- time\n- materials\n",
       "{scene}:1:1: a scene is a map of keys (time, materials, particles, ...), got a sequence"},
      {"radius_beyond_real", SCENE_TIME SCENE_MATERIALS "particles:\n  - list: {positions: [[0, 0, 1]], radius: 1e39}\n",
       "{scene}:5:44: particles[0].list.radius: out of range for ..."},
      {"radius_below_real", SCENE_TIME SCENE_MATERIALS "particles:\n  - list: {positions: [[0, 0, 1]], radius: 1e-320}\n",
       "{scene}:5:44: particles[0].list.radius: too small for ..."},
      {"normal_beyond_real", SCENE_VALID "walls:\n  - plane: {point: [0, 0, 0], normal: [1e39, 0, 0]}\n",
       "{scene}:7:40: walls[0].plane.normal[0]: out of range for ..."},
      {"too_many_substeps", "time: {duration: 1e9, dt: 1e-3, substeps: 4}\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:1:27: time.dt: a duration of 1e+09 s makes 4e+12 substeps (duration / time.dt x time.substeps), "
       "more than the limit 1e+10 (--limit substeps=N raises it)"},
      {"material_name_newline", SCENE_TIME "materials:\n  \"gl\\nass\": {density: 2500}\n" SCENE_PARTICLES,
       "{scene}:3:3: materials: a material name cannot hold a control character (tab, newline)"},
      {"render_too_wide", SCENE_VALID "output: {render: {width: 9000}}\n",
       "{scene}:6:26: output.render.width: must be <= 8192, got 9000"},
      {"too_many_materials", many_materials_scene(1025).c_str(),
       "{scene}:2:12: materials: 1025 materials, more than the limit 1024 (the step keeps a coefficient table of "
       "every pair; --limit materials=N raises it)"},
      {"empty_file", "", "{scene}: the scene file is empty"},
      {"only_comments", "# nothing here\n", "{scene}: the scene file is empty"},
      // YAML's null alone: a document, not a map (it was "no document could be read")
      {"null_document", "~\n", "{scene}:1:1: a scene is a map of keys (time, materials, particles, ...), got nothing (null)"},
      {"null_word", "# a scene\n---\nnull  # for now\n",
       "{scene}:1:1: a scene is a map of keys (time, materials, particles, ...), got nothing (null)"},
      {"leading_comma", ",", "{scene}:1:1: not valid YAML: no document could be read (does it begin with a stray ',', "
       "'-' or ':'?)"},
      {"leading_comma_then_map", ",a: 1\n", "{scene}:1:1: not valid YAML: no document could be read (does it begin "
       "with a stray ',', '-' or ':'?)"},
      // bytes that are no UTF-8 (a name in Latin-1, a cut character), where they stand
      {"latin1_name", SCENE_TIME "name: caf\xe9\n" SCENE_MATERIALS SCENE_PARTICLES,
       "{scene}:2:10: not UTF-8 text: \\xe9 (save the file as UTF-8)"},
      {"cut_character", SCENE_TIME SCENE_MATERIALS "# \xe2\x82\n" SCENE_PARTICLES,
       "{scene}:4:3: not UTF-8 text: \\xe2 (save the file as UTF-8)"},
      {"two_documents", SCENE_VALID "---\nname: second\n",
       "{scene}:6:1: a scene is one YAML document, this file holds more"},
      // yaml-cpp takes a quote left open where a line break ends the file, and drops tags
      {"open_quote_at_the_end", SCENE_VALID "name: \"demo\n",
       "{scene}:6:7: name: a quoted value never closed (its \" is missing)"},
      {"open_single_quote_at_the_end", SCENE_VALID "name: 'it''s\n\n",
       "{scene}:6:7: name: a quoted value never closed (its ' is missing)"},
      {"tag_on_a_number", SCENE_TIME "materials:\n  glass: {density: !!float 2500}\n" SCENE_PARTICLES,
       "{scene}:3:20: materials.glass.density: a YAML tag ('!!float'): a scene's values take none (remove it)"},
      {"tag_on_a_map", SCENE_VALID "walls:\n  - {plane: {point: [0, 0, 0], normal: [0, 0, 1]}}\n  - !box {min: [0, 0, 0]}\n",
       "{scene}:8:5: walls[1]: a YAML tag ('!box'): a scene's values take none (remove it)"},
      {"missing_file", nullptr, "{scene}: cannot open the scene file: No such file or directory"},
      {"unsupported_format", "format: 2\n" SCENE_VALID,
       "{scene}:1:9: format: unsupported scene format 2; this version reads format 1"},
      {"missing_csv", SCENE_TIME SCENE_MATERIALS "particles:\n  - csv: {path: nowhere.csv}\n",
       "{scene}:5:17: particles[0].csv.path: cannot open '{dir}/nowhere.csv': No such file or directory"},
      {"csv_bad_number", SCENE_TIME SCENE_MATERIALS "particles:\n  - csv: {path: data.csv}\n",
       "{dir}/data.csv:3:5: z: expected a number, got 'abc'", "# x,y,z,r\n0,0,0,0.1\n1,1,abc,0.1\n"},
      {"csv_bad_radius", SCENE_TIME SCENE_MATERIALS "particles:\n  - csv: {path: data.csv}\n",
       "{dir}/data.csv:3:10: r: must be > 0, got -1", "x, y, z, r\n0, 0, 0, 1\n5, 5, 5, -1\n"},
      {"csv_bad_width", SCENE_TIME SCENE_MATERIALS "particles:\n  - csv: {path: data.csv}\n",
       "{dir}/data.csv:2:1: expected 4, 7 or 10 comma-separated values (x,y,z,r[,vx,vy,vz[,wx,wy,wz]]), got 5",
       "# spheres\n0,0,0,1,2\n"},
      {"unknown_material", SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES "    material: glas\n",
       "{scene}:6:15: particles[0].material: unknown material 'glas' (did you mean 'glass'?)"},
      {"empty_material", SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES "    material: \"\"\n",
       "{scene}:6:15: particles[0].material: expected a material's name, got an empty name"},
      {"empty_pair_material", SCENE_VALID "contact_pairs:\n  - {materials: ['', glass], friction: 0.1}\n",
       "{scene}:7:18: contact_pairs[0].materials[0]: expected a material's name, got an empty name"},
      {"unknown_wall_material", SCENE_VALID "walls:\n  - plane: {point: [0, 0, 0], normal: [0, 0, 1]}\n"
                                            "    material: rubber\n",
       "{scene}:8:15: walls[0].material: unknown material 'rubber'; expected one of: glass"},
      {"box_min_max", SCENE_VALID "walls:\n  - box: {min: [0, 0, 0], max: [1, 1, 0]}\n",
       "{scene}:7:32: walls[0].box.max: must be greater than min on every axis, got max.z = 0 <= min.z = 0"},
      {"zero_normal", SCENE_VALID "walls:\n  - plane: {point: [0, 0, 0], normal: [0, 0, 0]}\n",
       "{scene}:7:39: walls[0].plane.normal: must not be the zero vector"},
      {"wall_without_shape", SCENE_VALID "walls:\n  - material: glass\n",
       "{scene}:7:5: walls[0]: missing the wall's shape: one of plane, box, cylinder, sphere"},
      {"wall_two_shapes", SCENE_VALID "walls:\n  - sphere: {centre: [0, 0, 0], radius: 1}\n    box: {min: [0, 0, 0], max: [1, 1, 1]}\n",
       "{scene}:8:5: walls[0]: a wall has one shape; got both 'sphere' and 'box'"},
      {"cylinder_radius", SCENE_VALID "walls:\n  - cylinder: {base: [0, 0, 0], axis: [0, 0, 1], radius: 0}\n",
       "{scene}:7:58: walls[0].cylinder.radius: must be > 0, got 0"},
      {"cylinder_inside_type", SCENE_VALID "walls:\n  - cylinder: {base: [0, 0, 0], axis: [0, 0, 1], radius: 1, inside: maybe}\n",
       "{scene}:7:69: walls[0].cylinder.inside: expected true or false, got 'maybe'"},
      {"cylinder_velocity", SCENE_VALID "walls:\n  - cylinder: {base: [0, 0, 0], axis: [0, 0, 1], radius: 1}\n    velocity: [1, 0, 0]\n",
       "{scene}:8:15: walls[0].velocity: a cylinder cannot translate; spin it with cylinder.angular_velocity"},
      {"sphere_center_spelling", SCENE_VALID "walls:\n  - sphere: {center: [0, 0, 0], radius: 1}\n",
       "{scene}:7:14: walls[0].sphere: unknown key 'center' (did you mean 'centre'?)"},
      {"contact_pair_material", SCENE_VALID "contact_pairs:\n  - {materials: [glass, steel], friction: 0.1}\n",
       "{scene}:7:25: contact_pairs[0].materials[1]: unknown material 'steel'; expected one of: glass"},
      {"contact_pair_empty", SCENE_VALID "contact_pairs:\n  - {materials: [glass, glass]}\n",
       "{scene}:7:5: contact_pairs[0]: give at least one of restitution, friction, rolling_friction, twisting_friction"},
      {"drag_negative", SCENE_VALID "effects: [drag]\ndrag: {linear: 0.1, quadratic: -1}\n",
       "{scene}:7:32: drag.quadratic: must be >= 0, got -1"},
      {"random_overfull",
       SCENE_TIME SCENE_MATERIALS
       "particles:\n  - random: {count: 1000, min: [0, 0, 0], max: [0.1, 0.1, 0.1], radius: 0.02}\n",
       "{scene}:5:21: particles[0].random.count: could place only ..."},
      {"random_box_too_small",
       SCENE_TIME SCENE_MATERIALS
       "particles:\n  - random: {count: 10, min: [0, 0, 0], max: [1, 1, 0.1], radius: 0.1}\n",
       "{scene}:5:46: particles[0].random.max: the box is too small on z for the largest sphere (needs 0.2, has 0.1)"},
      {"two_sources", SCENE_TIME SCENE_MATERIALS SCENE_PARTICLES "    csv: {path: data.csv}\n",
       "{scene}:6:5: particles[0]: a block has one source; got both 'list' and 'csv'"},
      {"radii_count", SCENE_TIME SCENE_MATERIALS "particles:\n  - list: {positions: [[0, 0, 1], [1, 0, 1]], radii: [0.1]}\n",
       "{scene}:5:54: particles[0].list.radii: has 1 entries but positions has 2"},
      {"unknown_effect", SCENE_VALID "effects: [gravity, colisions]\n",
       "{scene}:6:20: effects[1]: unknown effect 'colisions' (did you mean 'collisions'?)"},
      {"effect_twice", SCENE_VALID "effects: [walls, walls]\n", "{scene}:6:18: effects[1]: effect 'walls' is listed twice"},
      {"drag_without_rate", SCENE_VALID "effects: [gravity, drag]\n",
       "{scene}:6:20: effects[1]: the drag effect needs the top-level key 'drag' (linear rate 1/s, or {linear, quadratic})"},
      {"unknown_color_by", SCENE_VALID "output:\n  render: {color_by: velocity}\n",
       "{scene}:7:22: output.render.color_by: unknown color_by 'velocity'; expected one of: speed, id, radius, material"},
      {"unknown_field", SCENE_VALID "output:\n  fields: [radius, colour]\n",
       "{scene}:7:20: output.fields[1]: unknown field 'colour'; expected one of: radius, velocity, angular_velocity, id, "
       "material, speed, contacts"},
      {"movie_without_render", SCENE_VALID "output:\n  movie: {fps: 30}\n",
       "{scene}:7:10: output.movie: needs output.render: the movie is made of the rendered frames"},
      {"movie_odd_width", SCENE_VALID "output:\n  render: {width: 641}\n  movie: {fps: 30}\n",
       "{scene}:7:19: output.render.width: must be even for a movie, got 641"},
      {"camera_fov", SCENE_VALID "output:\n  render:\n    camera: {position: [1, 1, 1], look_at: [0, 0, 0], fov: 180}\n",
       "{scene}:8:60: output.render.camera.fov: must be within (0, 180) degrees, got 180"},
      {"velocity_twice",
       SCENE_TIME SCENE_MATERIALS
       "particles:\n  - list: {positions: [[0, 0, 1]], radius: 0.1, velocities: [[1, 0, 0]]}\n"
       "    velocity: [0, 0, 1]\n",
       "{scene}:6:15: particles[0].velocity: list.velocities already gives every sphere its velocity; give one or the "
       "other"},
  };
  return cases;
}

// A scratch folder for one case, removed on destruction.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& name)
      : m_path(std::filesystem::temp_directory_path() /
               ("marbles_scene_" + std::to_string(::getpid()) + "_" + name)) {
    std::filesystem::remove_all(m_path);
    std::filesystem::create_directories(m_path);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(m_path, ec);
  }
  std::string path() const { return m_path.string(); }
  std::string write(const std::string& file, const std::string& text) const {
    const std::string p = (m_path / file).string();
    std::ofstream(p, std::ios::binary) << text;
    return p;
  }

 private:
  std::filesystem::path m_path;
};

// Writes the case's files; returns the scene path.
inline std::string write_case(const BadScene& c, const ScratchDir& dir) {
  if (c.csv) dir.write("data.csv", c.csv);
  if (!c.yaml) return dir.path() + "/scene.yaml";
  return dir.write("scene.yaml", c.yaml);
}

inline std::string replace_all(std::string text, const std::string& from, const std::string& to) {
  for (std::size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size()))
    text.replace(at, from.size(), to);
  return text;
}

inline std::string expected_message(const BadScene& c, const std::string& scene_path, const std::string& dir) {
  return replace_all(replace_all(c.expected, "{scene}", scene_path), "{dir}", dir);
}

// True when `message` is what the case expects (exactly, or as a prefix for "...").
inline bool message_matches(const std::string& expected, const std::string& message) {
  const std::string dots = "...";
  if (expected.size() >= dots.size() && expected.compare(expected.size() - dots.size(), dots.size(), dots) == 0)
    return message.compare(0, expected.size() - dots.size(), expected, 0, expected.size() - dots.size()) == 0;
  return message == expected;
}

}  // namespace marbles::test
