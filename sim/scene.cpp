// sim/scene.cpp — YAML scene (format v1) → marbles::scene::Scene.
//
// One function per section of the file, each reading its keys through
// MapFields (unknown keys, duplicates, types, ranges) so that every problem
// is reported once, at the node that caused it, as
// `file:line:column: dotted.key: message`. Checks that span sections
// (a block naming a material, dt against duration, movie needing render)
// run after the section they depend on. `--set` overrides are applied to the
// YAML tree first (sim/scene_overrides.cpp), so they pass the same checks.
// The format is described for users in docs/scene-format.md; keep the two in step.
#include "sim/scene.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>

#include <nlohmann/json.hpp>
#include <yaml-cpp/depthguard.h>

#include "core/files.hpp"
#include "core/format.hpp"
#include "core/hash.hpp"
#include "sim/limits.hpp"
#include "sim/scene_overrides.hpp"
#include "sim/scene_yaml.hpp"

namespace marbles::scene {

using detail::Field;
using detail::MapFields;

namespace {

constexpr int kFormatVersion = 1;

const std::vector<std::string> kEffectNames = {"gravity",  "collisions",         "walls", "restitution",
                                               "friction", "rolling_resistance", "drag"};
const std::vector<Effect> kDefaultEffects = {Effect::gravity, Effect::collisions, Effect::walls,
                                             Effect::restitution, Effect::friction};
const std::vector<std::string> kIntegrators = {"symplectic_euler", "velocity_verlet"};
const std::vector<std::string> kPrecisions = {"float", "double"};
const std::vector<std::string> kColorBy = {"speed", "id", "radius", "material"};
const std::vector<std::string> kOutputFields = {"radius", "velocity", "angular_velocity", "id", "material", "speed",
                                                "contacts"};

std::string axis_name(int axis) { return axis == 0 ? "x" : (axis == 1 ? "y" : "z"); }

// min < max on every axis; the error points at `max`.
void check_box(const Vec3& lo, const Vec3& hi, const Field& max_field) {
  for (int a = 0; a < 3; ++a) {
    if (!(lo[a] < hi[a]))
      max_field.fail("must be greater than min on every axis, got max." + axis_name(a) + " = " +
                     shortest(hi[a]) + " <= min." + axis_name(a) + " = " + shortest(lo[a]));
  }
}

// What is wrong with a run of `duration` seconds (finite, > 0) at `time`'s
// step and substeps, or empty: the rules of time.duration and run --duration.
std::string duration_problem(double duration, const TimeSpec& time) {
  if (duration < time.dt)
    return "a duration of " + shortest(duration) + " s is shorter than a step, time.dt = " +
           shortest(time.dt) + " s";
  const double substeps = duration / time.dt * time.substeps;
  if (!(substeps <= limits().substeps))
    return "a duration of " + shortest(duration) + " s makes " + shortest(substeps) +
           " substeps (duration / time.dt x time.substeps), more than the limit " +
           shortest(limits().substeps) + " (--limit substeps=N raises it)";
  return {};
}

// `duration`: run --duration's, in the place of the file's (which must
// still be a number > 0) and held to the same rules under its own name.
TimeSpec read_time(const Field& field, std::optional<double> duration, SourceLocation& dt_where) {
  const MapFields map(field, {"duration", "dt", "substeps"});
  TimeSpec time;
  time.duration = map.required("duration").positive();
  const Field dt = map.required("dt");
  time.dt = dt.positive();
  dt_where = dt.where();
  if (auto f = map.optional("substeps")) time.substeps = f->integer_at_least(1);
  if (duration) {  // the command line took it finite and > 0
    if (const std::string why = duration_problem(*duration, time); !why.empty())
      throw InputError(SourceLocation{}, "--duration", why);
    time.duration = *duration;
  } else if (const std::string why = duration_problem(time.duration, time); !why.empty()) {
    dt.fail(why);
  }
  if (!(static_cast<real>(time.dt / time.substeps) > 0))
    dt.fail("the substep dt / substeps rounds to 0 in " + std::string(kRealName) + " precision");
  return time;
}

SolverSpec read_solver(const Field& field) {
  const MapFields map(field, {"iterations", "closing_iterations", "impact_passes", "integrator", "speculative",
                              "precision", "renumber"});
  SolverSpec solver;
  if (auto f = map.optional("iterations")) solver.iterations = f->integer_at_least(1, SolverSpec::kMostIterations);
  if (auto f = map.optional("closing_iterations"))
    solver.closing_iterations = f->integer_at_least(1, SolverSpec::kMostIterations);
  if (auto f = map.optional("impact_passes")) solver.impact_passes = f->integer_at_least(1, SolverSpec::kMostImpactPasses);
  if (auto f = map.optional("integrator")) {
    solver.integrator = f->word();
    if (std::find(kIntegrators.begin(), kIntegrators.end(), solver.integrator) == kIntegrators.end())
      f->fail("unknown integrator '" + solver.integrator + "'" + detail::suggestion(solver.integrator, kIntegrators));
  }
  if (auto f = map.optional("speculative")) solver.speculative = f->boolean();
  if (auto f = map.optional("renumber")) solver.renumber = f->integer_at_least(0);
  if (auto f = map.optional("precision")) {
    solver.precision = f->word();
    solver.precision_where = f->where();
    if (std::find(kPrecisions.begin(), kPrecisions.end(), solver.precision) == kPrecisions.end())
      f->fail("unknown precision '" + solver.precision + "'" + detail::suggestion(solver.precision, kPrecisions));
  }
  return solver;
}

const std::vector<std::string> kReferenceKinds = {"rebound_heights", "time_to_rest",    "incline",  "slide_to_roll",
                                                   "oblique_rebound", "kinetic_energy", "momentum", "finest"};

// `reference:` is one kind: a map {kind: {parameters}}, `kind: conserved`
// for the conservation kinds, or the word `finest`.
ReferenceSpec read_reference(const Field& field) {
  using Kind = ReferenceSpec::Kind;
  ReferenceSpec ref;
  ref.where = field.where();
  if (field.is_scalar()) {
    if (field.word() != "finest")
      field.fail("expected a map {kind: {...}} or 'finest', got " + field.description() +
                 detail::suggestion(field.word(), kReferenceKinds));
    ref.kind = Kind::finest;
    return ref;
  }
  const MapFields top(field, kReferenceKinds);
  if (top.entries().size() != 1)
    field.fail("give exactly one reference kind (" + std::to_string(top.entries().size()) + " given)");
  const MapFields::Entry& e = top.entries().front();
  const Field& value = e.value;
  const std::size_t kind_index =
      std::find(kReferenceKinds.begin(), kReferenceKinds.end(), e.name) - kReferenceKinds.begin();
  ref.kind = static_cast<Kind>(kind_index + 1);
  if (ref.kind == Kind::kinetic_energy || ref.kind == Kind::momentum) {
    if (!value.is_scalar() || value.word() != "conserved") value.fail("expected 'conserved', got " + value.description());
    return ref;
  }
  if (ref.kind == Kind::finest) value.fail("'finest' takes no parameters: write `reference: finest`");
  if (value.node().IsNull()) {
    if (ref.kind != Kind::slide_to_roll) value.fail("needs its parameters (docs/accuracy.md)");
    return ref;
  }
  std::vector<std::string> allowed{"sphere"};
  switch (ref.kind) {
    case Kind::rebound_heights: allowed.insert(allowed.end(), {"restitution", "floor", "bounces"}); break;
    case Kind::time_to_rest: allowed.insert(allowed.end(), {"restitution", "floor"}); break;
    case Kind::incline: allowed.insert(allowed.end(), {"angle", "friction"}); break;
    case Kind::oblique_rebound: allowed.insert(allowed.end(), {"restitution", "friction"}); break;
    default: break;
  }
  const MapFields map(value, allowed);
  if (auto f = map.optional("sphere")) ref.sphere = static_cast<std::uint32_t>(f->integer_at_least(0, 4'000'000'000));
  if (map.has("restitution") || ref.kind == Kind::rebound_heights || ref.kind == Kind::time_to_rest ||
      ref.kind == Kind::oblique_rebound) {
    const Field f = map.required("restitution");
    ref.restitution = f.within(0, 1);
    if (ref.kind == Kind::time_to_rest && !(ref.restitution < 1))
      f.fail("must be < 1: with e = 1 the ball never comes to rest");
    if (ref.kind == Kind::rebound_heights && !(ref.restitution > 0)) f.fail("must be > 0: with e = 0 nothing rebounds");
  }
  if (ref.kind == Kind::incline || ref.kind == Kind::oblique_rebound) ref.friction = map.required("friction").non_negative();
  if (ref.kind == Kind::incline) {
    const Field f = map.required("angle");
    ref.angle = f.number();
    if (!(ref.angle > 0 && ref.angle < 90)) f.fail("must be within (0, 90) degrees, got " + f.node().Scalar());
  }
  if (auto f = map.optional("floor")) ref.floor = f->number();
  if (auto f = map.optional("bounces")) ref.bounces = f->integer_at_least(1, 50);
  return ref;
}

std::vector<Effect> read_effects(const Field& field) {
  std::vector<Effect> effects;
  for (const Field& item : field.items()) {
    const std::string name = item.word();
    const auto it = std::find(kEffectNames.begin(), kEffectNames.end(), name);
    if (it == kEffectNames.end()) item.fail("unknown effect '" + name + "'" + detail::suggestion(name, kEffectNames));
    const Effect e = static_cast<Effect>(it - kEffectNames.begin());
    if (std::find(effects.begin(), effects.end(), e) != effects.end())
      item.fail("effect '" + name + "' is listed twice");
    effects.push_back(e);
  }
  return effects;
}

std::vector<Material> read_materials(const Field& field) {
  const MapFields map(field, std::vector<std::string>{});
  if (field.origins()) field.origins()->ordered(field.key());  // their order is their numbering
  std::vector<Material> materials;
  for (const MapFields::Entry& entry : map.entries()) {
    Material m;
    m.name = entry.name;
    m.where = entry.name_where;
    if (m.name.empty()) throw InputError(entry.name_where, field.key(), "a material needs a name");
    if (std::any_of(m.name.begin(), m.name.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20; }))
      throw InputError(entry.name_where, field.key(), "a material name cannot hold a control character (tab, newline)");
    if (!entry.value.node().IsNull()) {  // `glass:` alone takes every default
      const MapFields props(entry.value,
                            {"density", "restitution", "friction", "rolling_friction", "twisting_friction"});
      if (auto f = props.optional("density")) m.density = f->positive();
      if (auto f = props.optional("restitution")) m.restitution = f->within(0, 1);
      if (auto f = props.optional("friction")) m.friction = f->non_negative();
      if (auto f = props.optional("rolling_friction")) m.rolling_friction = f->non_negative();
      if (auto f = props.optional("twisting_friction")) m.twisting_friction = f->non_negative();
    }
    materials.push_back(std::move(m));
  }
  if (materials.empty()) field.fail("needs at least one material, e.g. `steel: {density: 7800}`");
  if (static_cast<double>(materials.size()) > limits().materials)
    field.fail(std::to_string(materials.size()) + " materials, more than the limit " + shortest(limits().materials) +
               " (the step keeps a coefficient table of every pair; --limit materials=N raises it)");
  return materials;
}

// A material named where one is referred to: a name, not empty (an empty
// name stands for "none given" in Scene::material_index, the first material).
std::string material_name(const Field& field) {
  std::string name = field.word();
  if (name.empty()) field.fail("expected a material's name, got an empty name");
  return name;
}

// Reads `material: NAME` of a wall or block and checks that the material exists.
void read_material_ref(const Scene& scene, const MapFields& map, std::string& name, SourceLocation& where) {
  where.file = scene.path;
  if (auto f = map.optional("material")) {
    name = material_name(*f);
    where = f->where();
    scene.material_index(name, where, f->key());
  }
}

Vec3 unit_vector(const Field& field) {
  const Vec3 v = field.vec3();
  const double len = std::sqrt(double(v.x) * v.x + double(v.y) * v.y + double(v.z) * v.z);
  if (!(len > 0)) field.fail("must not be the zero vector");
  return Vec3(real(v.x / len), real(v.y / len), real(v.z / len));
}

std::vector<WallSpec> read_walls(const Scene& scene, const Field& field) {
  static const std::vector<std::string> shapes = {"plane", "box", "cylinder", "sphere"};
  std::vector<WallSpec> walls;
  for (const Field& item : field.items()) {
    const MapFields map(item, {"plane", "box", "cylinder", "sphere", "material", "velocity"});
    WallSpec wall;
    wall.where = item.where();
    const MapFields::Entry* shape = nullptr;
    for (const MapFields::Entry& e : map.entries()) {
      if (std::find(shapes.begin(), shapes.end(), e.name) == shapes.end()) continue;
      if (shape)
        throw InputError(e.name_where, item.key(), "a wall has one shape; got both '" + shape->name + "' and '" + e.name + "'");
      shape = &e;
    }
    if (!shape) item.fail("missing the wall's shape: one of plane, box, cylinder, sphere");
    if (shape->name == "plane") {
      wall.kind = WallSpec::Kind::plane;
      const MapFields spec(shape->value, {"point", "normal"});
      wall.point = spec.required("point").vec3();
      wall.normal = unit_vector(spec.required("normal"));
    } else if (shape->name == "box") {
      wall.kind = WallSpec::Kind::box;
      const MapFields spec(shape->value, {"min", "max"});
      wall.lo = spec.required("min").vec3();
      const Field max = spec.required("max");
      wall.hi = max.vec3();
      check_box(wall.lo, wall.hi, max);
    } else if (shape->name == "cylinder") {
      wall.kind = WallSpec::Kind::cylinder;
      const MapFields spec(shape->value, {"base", "axis", "radius", "length", "inside", "angular_velocity"});
      wall.base = spec.required("base").vec3();
      wall.axis = unit_vector(spec.required("axis"));
      wall.radius = spec.required("radius").positive();
      if (auto f = spec.optional("length")) wall.length = f->non_negative();
      if (auto f = spec.optional("inside")) wall.inside = f->boolean();
      if (auto f = spec.optional("angular_velocity")) wall.angular_velocity = f->number();
    } else {
      wall.kind = WallSpec::Kind::sphere;
      const MapFields spec(shape->value, {"centre", "radius"});
      wall.centre = spec.required("centre").vec3();
      wall.radius = spec.required("radius").positive();
    }
    if (auto f = map.optional("velocity")) {
      if (wall.kind == WallSpec::Kind::cylinder)
        f->fail("a cylinder cannot translate; spin it with cylinder.angular_velocity");
      wall.velocity = f->vec3();
    }
    read_material_ref(scene, map, wall.material, wall.material_where);
    walls.push_back(std::move(wall));
  }
  return walls;
}

std::vector<ContactPairSpec> read_contact_pairs(const Scene& scene, const Field& field) {
  std::vector<ContactPairSpec> pairs;
  for (const Field& item : field.items()) {
    const MapFields map(item, {"materials", "restitution", "friction", "rolling_friction", "twisting_friction"});
    ContactPairSpec pair;
    pair.where = item.where();
    const Field names = map.required("materials");
    if (!names.is_sequence() || names.node().size() != 2)
      names.fail("expected [material, material], got " +
                 (names.is_sequence() ? "a sequence of " + std::to_string(names.node().size()) : names.description()));
    const std::vector<Field> two = names.items();
    pair.first = material_name(two[0]);
    pair.second = material_name(two[1]);
    scene.material_index(pair.first, two[0].where(), two[0].key());
    scene.material_index(pair.second, two[1].where(), two[1].key());
    if (auto f = map.optional("restitution")) pair.restitution = f->within(0, 1);
    if (auto f = map.optional("friction")) pair.friction = f->non_negative();
    if (auto f = map.optional("rolling_friction")) pair.rolling_friction = f->non_negative();
    if (auto f = map.optional("twisting_friction")) pair.twisting_friction = f->non_negative();
    if (pair.restitution < 0 && pair.friction < 0 && pair.rolling_friction < 0 && pair.twisting_friction < 0)
      item.fail("give at least one of restitution, friction, rolling_friction, twisting_friction");
    for (const ContactPairSpec& other : pairs) {
      if ((other.first == pair.first && other.second == pair.second) ||
          (other.first == pair.second && other.second == pair.first))
        names.fail("the pair " + pair.first + "/" + pair.second + " is already given" +
                   (other.where.line > 0 ? " at line " + std::to_string(other.where.line) : " earlier in the list"));
    }
    pairs.push_back(std::move(pair));
  }
  return pairs;
}

// `radius: 0.01` or `radius: {constant: r}`, `{uniform: [a, b]}`, `{log_uniform: [a, b]}`.
RadiusSpec read_radius(const Field& field) {
  RadiusSpec radius;
  if (field.is_scalar()) {
    radius.value = field.positive();
    return radius;
  }
  if (!field.is_map())
    field.fail("expected a number or one of {constant: r}, {uniform: [min, max]}, {log_uniform: [min, max]}, got " +
               field.description());
  const MapFields map(field, {"constant", "uniform", "log_uniform"});
  if (map.entries().size() != 1)
    field.fail("give exactly one of constant, uniform, log_uniform");
  const MapFields::Entry& entry = map.entries().front();
  if (entry.name == "constant") {
    radius.value = entry.value.positive();
    return radius;
  }
  radius.kind = entry.name == "uniform" ? RadiusSpec::Kind::uniform : RadiusSpec::Kind::log_uniform;
  if (!entry.value.is_sequence() || entry.value.node().size() != 2)
    entry.value.fail("expected [min, max], got " + (entry.value.is_sequence()
                                                       ? "a sequence of " + std::to_string(entry.value.node().size())
                                                       : entry.value.description()));
  const std::vector<Field> range = entry.value.items();
  radius.min = range[0].positive();
  radius.max = range[1].positive();
  if (radius.min > radius.max)
    range[1].fail("must be >= the minimum radius " + shortest(radius.min) + ", got " + range[1].node().Scalar());
  return radius;
}

double largest(const RadiusSpec& r) { return r.kind == RadiusSpec::Kind::constant ? r.value : r.max; }

VelocitySpec read_velocity(const Field& field) {
  VelocitySpec velocity;
  if (field.is_sequence()) {
    velocity.kind = VelocitySpec::Kind::constant;
    velocity.value = field.vec3();
    return velocity;
  }
  if (!field.is_map()) field.fail("expected [vx, vy, vz] or {random: {speed, seed}}, got " + field.description());
  const MapFields map(field, {"random"});
  const MapFields random(map.required("random"), {"speed", "seed"});
  velocity.kind = VelocitySpec::Kind::random;
  velocity.speed = random.required("speed").non_negative();
  if (auto f = random.optional("seed")) velocity.seed = f->seed();
  return velocity;
}

void read_list(ParticleBlock& block, const Field& field) {
  const MapFields map(field, {"positions", "radii", "radius", "velocities"});
  const Field positions = map.required("positions");
  for (const Field& p : positions.items()) block.positions.push_back(p.vec3());
  if (block.positions.empty()) positions.fail("needs at least one position");
  const std::size_t n = block.positions.size();
  const bool radii = map.has("radii"), radius = map.has("radius");
  if (radii == radius)
    field.fail(radii ? "give either 'radii' (one per sphere) or 'radius' (for all), not both"
                     : "missing 'radii' (one per sphere) or 'radius' (for all)");
  if (radii) {
    const Field list = map.required("radii");
    for (const Field& r : list.items()) block.radii.push_back(r.positive());
    if (block.radii.size() != n)
      list.fail("has " + std::to_string(block.radii.size()) + " entries but positions has " + std::to_string(n));
  } else {
    block.radii.assign(n, map.required("radius").positive());
  }
  if (auto f = map.optional("velocities")) {
    for (const Field& v : f->items()) block.velocities.push_back(v.vec3());
    if (block.velocities.size() != n)
      f->fail("has " + std::to_string(block.velocities.size()) + " entries but positions has " + std::to_string(n));
  }
}

void read_lattice(ParticleBlock& block, const Field& field) {
  const MapFields map(field, {"min", "max", "spacing", "radius", "jitter", "seed"});
  block.lo_written = map.required("min").triple();
  block.lo = detail::vec3_of(block.lo_written);
  const Field max = map.required("max");
  block.hi_written = max.triple();
  block.hi = detail::vec3_of(block.hi_written);
  check_box(block.lo, block.hi, max);
  const Field spacing = map.required("spacing");
  block.spacing = spacing.positive();
  block.radius = read_radius(map.required("radius"));
  if (auto f = map.optional("jitter")) block.jitter = f->non_negative();
  if (auto f = map.optional("seed")) block.seed = f->seed();
  const double margin = largest(block.radius) + block.jitter;
  if (block.spacing < 2 * margin)
    spacing.fail("must be >= 2 * (largest radius + jitter) = " + shortest(2 * margin) +
                 " so that spheres cannot overlap, got " + spacing.node().Scalar());
  for (int a = 0; a < 3; ++a) {
    // within the count's tolerance (particles.cpp): 0.64 - 0.58 is 0.0599...94
    const double room = block.hi_written[a] - block.lo_written[a];
    if (room < 2 * margin * (1 - 1e-9))
      max.fail("the box is too small on " + axis_name(a) + " for one sphere (needs " + shortest(2 * margin) +
               " = 2 * (largest radius + jitter), has " + shortest(room) + ")");
  }
}

void read_random(ParticleBlock& block, const Field& field) {
  const MapFields map(field, {"count", "min", "max", "radius", "seed"});
  const Field count = map.required("count");
  const long long n = count.integer();
  if (n < 1) count.fail("must be >= 1, got " + count.node().Scalar());
  if (static_cast<double>(n) > limits().spheres)
    count.fail("must be <= " + shortest(limits().spheres) + " (--limit spheres=N raises it), got " +
               count.node().Scalar());
  block.count = static_cast<std::size_t>(n);
  block.count_where = count.where();
  block.lo = map.required("min").vec3();
  const Field max = map.required("max");
  block.hi = max.vec3();
  check_box(block.lo, block.hi, max);
  block.radius = read_radius(map.required("radius"));
  if (auto f = map.optional("seed")) block.seed = f->seed();
  const double r = largest(block.radius);
  for (int a = 0; a < 3; ++a) {
    if (block.hi[a] - block.lo[a] < 2 * r)
      max.fail("the box is too small on " + axis_name(a) + " for the largest sphere (needs " + shortest(2 * r) +
               ", has " + shortest(block.hi[a] - block.lo[a]) + ")");
  }
}

void read_csv(ParticleBlock& block, const Field& field, const std::string& scene_path) {
  const MapFields map(field, {"path"});
  const Field path = map.required("path");
  const std::string given = path.word();
  if (given.empty()) path.fail("must not be empty");
  std::filesystem::path resolved(given);
  if (resolved.is_relative()) resolved = std::filesystem::path(scene_path).parent_path() / resolved;
  block.csv_path = resolved.lexically_normal().string();
  block.csv_path_where = path.where();
  if (const char* what = not_a_plain_file(block.csv_path))
    path.fail("'" + printable_path(block.csv_path) + "' is " + what + ", not a CSV file");
  std::ifstream probe(block.csv_path);
  if (!probe) path.fail("cannot open '" + printable_path(block.csv_path) + "': " + std::strerror(errno));
}

std::vector<ParticleBlock> read_particles(const Scene& scene, const Field& field) {
  static const std::vector<std::string> kinds = {"list", "lattice", "random", "csv"};
  std::vector<ParticleBlock> blocks;
  for (const Field& item : field.items()) {
    const MapFields map(
        item, {"list", "lattice", "random", "csv", "material", "velocity", "angular_velocity", "fixed", "order"});
    ParticleBlock block;
    block.where = item.where();
    const MapFields::Entry* source = nullptr;
    for (const MapFields::Entry& e : map.entries()) {
      if (std::find(kinds.begin(), kinds.end(), e.name) == kinds.end()) continue;
      if (source)
        throw InputError(e.name_where, item.key(),
                         "a block has one source; got both '" + source->name + "' and '" + e.name + "'");
      source = &e;
    }
    if (!source) item.fail("missing the block's source: one of list, lattice, random, csv");
    // A block a --set changed in what makes its spheres (its source's radius,
    // its material) is named by that override in what is checked of the whole
    // block (its spheres' masses, a random block's fill), not by the file's
    // line, which holds another value.
    if (const detail::Origins* origins = item.origins(); origins && !item.from_override()) {
      const std::string* by = origins->find_under(item.key() + "." + source->name);
      if (!by) by = origins->find_under(item.key() + ".material");
      if (by) block.where = SourceLocation{*by, 0, 0};
    }
    const Field& spec = source->value;
    if (source->name == "list") {
      block.kind = ParticleBlock::Kind::list;
      read_list(block, spec);
    } else if (source->name == "lattice") {
      block.kind = ParticleBlock::Kind::lattice;
      read_lattice(block, spec);
    } else if (source->name == "random") {
      block.kind = ParticleBlock::Kind::random;
      read_random(block, spec);
    } else {
      block.kind = ParticleBlock::Kind::csv;
      read_csv(block, spec, scene.path);
    }
    read_material_ref(scene, map, block.material, block.material_where);
    block.velocity_where.file = scene.path;
    if (auto f = map.optional("velocity")) {
      block.velocity = read_velocity(*f);
      block.velocity_where = f->where();
      if (!block.velocities.empty())
        f->fail("list.velocities already gives every sphere its velocity; give one or the other");
    }
    block.angular_velocity_where.file = scene.path;
    if (auto f = map.optional("angular_velocity")) {
      block.angular_velocity = f->vec3();
      block.angular_velocity_given = true;
      block.angular_velocity_where = f->where();
    }
    block.fixed_where.file = scene.path;
    if (auto f = map.optional("fixed")) {
      block.fixed = f->boolean();
      block.fixed_where = f->where();
      if (block.fixed) {
        if (map.optional("velocity") || !block.velocities.empty())
          f->fail("fixed spheres never move: give them no velocity");
        if (map.optional("angular_velocity")) f->fail("fixed spheres never move: give them no angular_velocity");
      }
    }
    if (auto f = map.optional("order")) {
      static const std::vector<std::string> kOrders = {"given", "cells"};
      const std::string order = f->word();
      if (std::find(kOrders.begin(), kOrders.end(), order) == kOrders.end())
        f->fail("unknown order '" + order + "'" + detail::suggestion(order, kOrders));
      block.order_cells = order == "cells";
    }
    blocks.push_back(std::move(block));
  }
  if (blocks.empty()) field.fail("needs at least one block (list, lattice, random or csv)");
  return blocks;
}

CameraSpec read_camera(const Field& field) {
  const MapFields map(field, {"position", "look_at", "up", "fov"});
  CameraSpec camera;
  camera.given = true;
  camera.position = map.required("position").vec3();
  const Field look_at = map.required("look_at");
  camera.look_at = look_at.vec3();
  const Vec3 view = camera.look_at - camera.position;
  if (!(length(view) > 0)) look_at.fail("must differ from the camera position");
  if (auto f = map.optional("up")) {
    camera.up = f->vec3();
    if (!(length(camera.up) > 0)) f->fail("must not be the zero vector");
    if (!(length(cross(view, camera.up)) > 1e-6 * length(view) * length(camera.up)))
      f->fail("must not be parallel to the viewing direction (look_at - position)");
  } else if (!(length(cross(view, camera.up)) > 1e-6 * length(view))) {
    field.fail("the default up [0, 0, 1] is parallel to the viewing direction; give camera.up");
  }
  if (auto f = map.optional("fov")) {
    camera.fov = f->number();
    if (!(camera.fov > 0 && camera.fov < 180))
      f->fail("must be within (0, 180) degrees, got " + f->node().Scalar());
  }
  return camera;
}

OutputSpec read_output(const Field& field, const std::string& stem) {
  const MapFields map(field, {"dir", "vtk", "fields", "render", "movie", "checkpoint", "contacts"});
  OutputSpec output;
  output.dir = "out/" + stem;
  if (auto f = map.optional("dir")) {
    output.dir = f->word();
    output.dir_where = f->where();
    if (output.dir.empty()) f->fail("must not be empty");
  }
  if (auto f = map.optional("checkpoint")) {
    const MapFields checkpoint(*f, {"every", "keep"});
    output.checkpoint_every = checkpoint.required("every").integer_at_least(1);
    if (auto k = checkpoint.optional("keep")) output.checkpoint_keep = k->integer_at_least(1, 1000000);
  }
  if (auto f = map.optional("vtk")) {
    const MapFields vtk(*f, {"every"});
    output.vtk_every = 1;
    if (auto e = vtk.optional("every")) output.vtk_every = e->integer_at_least(1);
  }
  if (auto f = map.optional("contacts")) {
    const MapFields contacts(*f, {"every"});
    output.contacts_every = 1;
    if (auto e = contacts.optional("every")) output.contacts_every = e->integer_at_least(1);
  }
  if (auto f = map.optional("fields")) {
    output.fields.clear();
    for (const Field& item : f->items()) {
      const std::string name = item.word();
      if (std::find(kOutputFields.begin(), kOutputFields.end(), name) == kOutputFields.end())
        item.fail("unknown field '" + name + "'" + detail::suggestion(name, kOutputFields));
      if (std::find(output.fields.begin(), output.fields.end(), name) != output.fields.end())
        item.fail("field '" + name + "' is listed twice");
      output.fields.push_back(name);
    }
  }
  std::optional<Field> width, height;
  if (auto f = map.optional("render")) {
    const MapFields render(*f, {"every", "width", "height", "color_by", "camera"});
    output.render.enabled = true;
    if (auto e = render.optional("every")) output.render.every = e->integer_at_least(1);
    width = render.optional("width");
    height = render.optional("height");
    if (width) output.render.width = width->integer_at_least(16, 8192);
    if (height) output.render.height = height->integer_at_least(16, 8192);
    if (auto e = render.optional("color_by")) {
      output.render.color_by = e->word();
      if (std::find(kColorBy.begin(), kColorBy.end(), output.render.color_by) == kColorBy.end())
        e->fail("unknown color_by '" + output.render.color_by + "'" +
                detail::suggestion(output.render.color_by, kColorBy));
    }
    if (auto e = render.optional("camera")) output.render.camera = read_camera(*e);
  }
  if (auto f = map.optional("movie")) {
    const MapFields movie(*f, {"fps"});
    output.movie.enabled = true;
    if (auto e = movie.optional("fps")) {
      output.movie.fps = e->positive();
      if (!(output.movie.fps >= 0.01 && output.movie.fps <= 1000))
        e->fail("must be within [0.01, 1000] frames per second, got " + e->node().Scalar());
    }
    if (!output.render.enabled) f->fail("needs output.render: the movie is made of the rendered frames");
    // H.264 in yuv420p, the format every player reads, needs even frame sizes.
    if (output.render.width % 2) {
      if (width) width->fail("must be even for a movie, got " + width->node().Scalar());
    }
    if (output.render.height % 2) {
      if (height) height->fail("must be even for a movie, got " + height->node().Scalar());
    }
  }
  return output;
}

std::string read_file(const std::string& path) {
  if (const char* what = not_a_plain_file(path))
    throw InputError(SourceLocation{path, 0, 0}, "", std::string("is ") + what + ", not a scene file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(SourceLocation{path, 0, 0}, "", std::string("cannot open the scene file: ") + std::strerror(errno));
  // Read in chunks up to the limit: /dev/zero or a runaway pipe is refused
  // instead of filling the memory.
  std::string text;
  char chunk[1 << 16];
  while (in.read(chunk, sizeof chunk) || in.gcount() > 0) {
    text.append(chunk, static_cast<std::size_t>(in.gcount()));
    if (static_cast<double>(text.size()) > limits().scene_mib * 1048576.0)
      throw InputError(SourceLocation{path, 0, 0}, "",
                       "larger than " + shortest(limits().scene_mib) + " MiB: not a scene file (particles in "
                       "bulk belong in a csv block; --limit scene_mib=N raises it)");
  }
  return text;
}

// True when the text holds nothing but blanks and comments.
bool blank_yaml(const std::string& text) {
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const std::size_t at = line.find_first_not_of(" \t\r");
    if (at != std::string::npos && line[at] != '#') return false;
  }
  return true;
}

}  // namespace

const char* effect_name(Effect e) {
  switch (e) {
    case Effect::gravity: return "gravity";
    case Effect::collisions: return "collisions";
    case Effect::walls: return "walls";
    case Effect::restitution: return "restitution";
    case Effect::friction: return "friction";
    case Effect::rolling_resistance: return "rolling_resistance";
    case Effect::drag: return "drag";
  }
  return "unknown";
}

const char* reference_name(ReferenceSpec::Kind kind) {
  if (kind == ReferenceSpec::Kind::none) return "none";
  return kReferenceKinds[static_cast<std::size_t>(kind) - 1].c_str();
}

std::uint32_t Scene::material_index(const std::string& name, const SourceLocation& where, const std::string& key) const {
  if (name.empty()) return 0;
  std::vector<std::string> names;
  for (std::size_t i = 0; i < materials.size(); ++i) {
    if (materials[i].name == name) return static_cast<std::uint32_t>(i);
    names.push_back(materials[i].name);
  }
  throw InputError(where, key, "unknown material '" + name + "'" + detail::suggestion(name, names));
}

namespace {

// YAML merge keys (`<<: *anchor`, `<<: [*a, *b]`), which yaml-cpp leaves as
// ordinary keys: each map takes the keys of the merged maps it does not give
// itself (of a list, the earlier map wins), then loses its `<<`. Merged
// values are the anchor's nodes, so an error in one names the anchor's line.
// Visits are counted: an alias bomb is refused, not expanded. A node that
// holds itself through an alias (`a: &x {<<: *x}`, `a: &x {b: *x}` in a file
// with merge keys) is refused too, not followed until the stack runs out.
// (Without merge keys this pass does not run; the readers then meet such a
// node as a key they do not know.)
class MergeKeys {
 public:
  explicit MergeKeys(std::string path) : m_path(std::move(path)) {}

  void resolve(YAML::Node node, const std::string& key) {
    if (++m_visits > kMaxVisits)
      throw InputError(SourceLocation{m_path, 0, 0}, "", "aliases expand to more than 20,000,000 nodes");
    if (m_chain.size() >= kMaxDepth)
      throw InputError(detail::location_of(m_path, node.Mark()), key.size() > 120 ? key.substr(0, 120) + "..." : key,
                       "nested more than 1,000 levels deep (an alias inside the node it names?)");
    m_chain.push_back(node);
    struct Pop {
      std::vector<YAML::Node>& chain;
      ~Pop() { chain.pop_back(); }
    } pop{m_chain};
    if (node.IsSequence()) {
      for (std::size_t i = 0; i < node.size(); ++i) resolve(node[i], key + "[" + std::to_string(i) + "]");
      return;
    }
    if (!node.IsMap()) return;
    std::vector<YAML::Node> sources;
    bool merges = false;
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (!it->first.IsScalar() || it->first.Scalar() != "<<") continue;
      merges = true;
      const YAML::Node value = it->second;
      const std::string merge_key = (key.empty() ? "" : key + ".") + "<<";
      const auto fail = [&] {
        throw InputError(detail::location_of(m_path, value.Mark()), merge_key, "a merge key takes a map or a list of maps");
      };
      const auto take = [&](const YAML::Node& source) {
        for (const YAML::Node& around : m_chain)
          if (around.is(source))
            throw InputError(detail::location_of(m_path, it->first.Mark()), merge_key,
                             "a merge key names a map that holds it (its own anchor, or one around it)");
        sources.push_back(source);
      };
      if (value.IsMap()) {
        take(value);
      } else if (value.IsSequence()) {
        for (const YAML::Node& item : value) {
          if (!item.IsMap()) fail();
          take(item);
        }
      } else {
        fail();
      }
    }
    if (merges) {
      for (YAML::Node& source : sources) resolve(source, key);  // merged maps may merge too
      std::vector<std::string> present;
      for (auto it = node.begin(); it != node.end(); ++it)
        if (it->first.IsScalar()) present.push_back(it->first.Scalar());
      node.remove("<<");
      for (const YAML::Node& source : sources)
        for (auto it = source.begin(); it != source.end(); ++it) {
          if (!it->first.IsScalar() || it->first.Scalar() == "<<") continue;
          const std::string& name = it->first.Scalar();
          if (std::find(present.begin(), present.end(), name) != present.end()) continue;
          node.force_insert(it->first, it->second);
          present.push_back(name);
        }
    }
    for (auto it = node.begin(); it != node.end(); ++it)
      resolve(it->second, (key.empty() ? "" : key + ".") + (it->first.IsScalar() ? it->first.Scalar() : "?"));
  }

 private:
  static constexpr std::size_t kMaxVisits = 20'000'000;
  static constexpr std::size_t kMaxDepth = 1'000;
  std::string m_path;
  std::size_t m_visits = 0;
  std::vector<YAML::Node> m_chain;  // the maps and lists being resolved, outermost first
};

// Whether the text, its comments and document markers aside, is YAML's null
// alone (yaml-cpp reads it as it reads a document it could not read).
bool null_yaml(const std::string& text) {
  std::string rest;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (const std::size_t hash = line.find(" #"); hash != std::string::npos) line.erase(hash);
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    line = line.substr(first, line.find_last_not_of(" \t\r") - first + 1);
    if (line == "---" || line == "...") continue;
    rest += line;
  }
  return rest == "~" || rest == "null" || rest == "Null" || rest == "NULL";
}

// A scene's tree is a map of keys.
void expect_scene_map(const YAML::Node& document, const std::string& source) {
  const Field root(document, "", source);
  if (!root.is_map())
    root.fail("a scene is a map of keys (time, materials, particles, ...), got " + root.description());
}

// The file's one YAML document, which must be a map.
YAML::Node read_document(const std::string& path) {
  const std::string text = read_file(path);
  // YAML is Unicode: UTF-8, or UTF-16/32 with its byte order mark (which the
  // reader decodes). Bytes that are no UTF-8 it would keep in names, or
  // read as a mark ("\xff\xfe"), so they are refused where they stand.
  const bool utf16_or_32 = text.starts_with("\xfe\xff") || text.starts_with("\xff\xfe") ||
                           text.starts_with(std::string_view("\0\0\xfe\xff", 4));
  // The line and column of the byte at `at`.
  const auto place_of = [&](std::size_t at) {
    const std::size_t line_start = text.rfind('\n', at);
    const auto line = 1 + std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(at), '\n');
    const std::size_t column = at - (line_start == std::string::npos ? 0 : line_start + 1) + 1;
    return SourceLocation{path, static_cast<int>(line), static_cast<int>(column)};
  };
  if (const std::size_t at = first_non_utf8(text); at != std::string::npos && !utf16_or_32)
    throw InputError(place_of(at), "", not_utf8_text(text, at) + " (save the file as UTF-8)");
  // A NUL byte is no text (yaml-cpp read one as a bad escape): where it
  // stands. Not in UTF-16/32 without a mark, which YAML tells by the NUL
  // bytes around the first character (as the reader does).
  const bool unmarked_wide = text.size() >= 2 && (text[0] == '\0' || text[1] == '\0');
  if (const std::size_t at = text.find('\0'); at != std::string::npos && !utf16_or_32 && !unmarked_wide)
    throw InputError(place_of(at), "", "a NUL byte: not text (a binary file?)");
  YAML::Node document;
  detail::YamlScan scan;
  try {
    document = YAML::Load(text);
    scan = detail::scan_yaml(text, 2, !utf16_or_32 && !unmarked_wide);
  } catch (const YAML::DeepRecursion& e) {  // yaml-cpp's own message for it is "bad file"
    throw InputError(detail::location_of(path, e.mark), "",
                     "nested deeper than the YAML reader follows (" + std::to_string(e.depth()) + " levels)");
  } catch (const YAML::Exception& e) {  // its message quotes the offending byte, which may be any
    throw InputError(detail::location_of(path, e.mark), "", "not valid YAML: " + printable(e.msg));
  }
  if (document.IsNull() && blank_yaml(text)) throw InputError(SourceLocation{path, 0, 0}, "", "the scene file is empty");
  if (document.IsNull() && null_yaml(text))  // `~` or `null`: a document, but no map
    throw InputError(SourceLocation{path, 1, 1}, "",
                     "a scene is a map of keys (time, materials, particles, ...), got nothing (null)");
  if (document.IsNull())
    throw InputError(SourceLocation{path, 1, 1}, "", "not valid YAML: no document could be read (does it begin with "
                                                     "a stray ',', '-' or ':'?)");
  if (scan.documents > 1)
    throw InputError(detail::location_of(path, scan.second), "", "a scene is one YAML document, this file holds more");
  if (scan.problem)
    throw InputError(detail::location_of(path, scan.problem->mark), scan.problem->key, scan.problem->what);
  expect_scene_map(document, path);
  if (text.find("<<") != std::string::npos) MergeKeys(path).resolve(document, "");
  return document;
}

namespace {

// The overrides applied to a scene's tree, as `--set` applies them: each
// value put in, then merge keys in their values resolved as in a file (the
// file's own were resolved as it was read; resolving again finds none).
void apply_overrides_whole(YAML::Node document, const std::vector<std::string>& overrides,
                           detail::Origins& origins) {
  detail::apply_overrides(document, overrides, origins);
  for (const std::string& o : overrides)
    if (o.find("<<") != std::string::npos) {
      MergeKeys("--set " + o).resolve(document, "");
      break;
    }
}

// The fingerprint's first bytes: no scene's equals a fingerprint of the
// texts (text_fingerprint, sim/checkpoint.hpp) by the way it starts.
constexpr char kFingerprintTag[] = "marbles scene 1";

// Folds `node` (at `key`, a Field's key) into the fingerprint `h`
// (Scene::fingerprint): each scalar as the reader took it, else its text;
// a map's keys sorted where the reader did not take them in order. Each
// part is a tag and a counted text, so no two trees fold alike. (Nodes are
// sorted by index: assigning a YAML::Node would rewrite the tree.)
void fold_tree(const YAML::Node& node, const std::string& key, const detail::Origins& origins, std::uint64_t& h) {
  const auto put = [&h](char tag, const std::string& text) {
    const std::uint64_t size = text.size();
    h = fnv1a(&tag, 1, h);
    h = fnv1a(&size, sizeof size, h);
    h = fnv1a(text.data(), text.size(), h);
  };
  if (node.IsScalar()) {
    const std::uint64_t value = origins.taken(key, node.Scalar());
    put(value ? 'v' : 's', value ? std::string(reinterpret_cast<const char*>(&value), sizeof value) : node.Scalar());
  } else if (node.IsSequence()) {
    put('[', std::to_string(node.size()));
    std::size_t i = 0;
    for (const YAML::Node& item : node) fold_tree(item, key + "[" + std::to_string(i++) + "]", origins, h);
  } else if (node.IsMap()) {
    std::vector<std::string> names;
    std::vector<YAML::Node> values;
    for (const auto& entry : node) {
      names.push_back(entry.first.Scalar());
      values.push_back(entry.second);
    }
    std::vector<std::size_t> order(names.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    if (!origins.is_ordered(key))
      std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return names[a] < names[b]; });
    put('{', std::to_string(names.size()));
    for (const std::size_t i : order) {
      put('k', names[i]);
      fold_tree(values[i], key.empty() ? names[i] : key + "." + names[i], origins, h);
    }
  } else {
    put('~', "");
  }
}

}  // namespace

// `path`: where the scene came from (errors name it); `stem`: the default name
// and output folder; the `--set` overrides are applied to the tree first;
// `duration` (run --duration) replaces time.duration's value, not the tree.
Scene read_scene(YAML::Node document, const std::string& path, const std::string& stem,
                 const std::vector<std::string>& overrides, std::optional<double> duration) {
  detail::Origins origins;
  apply_overrides_whole(document, overrides, origins);
  const Field root(document, "", path, &origins);
  const MapFields top(root, {"format", "name", "time", "solver", "effects", "gravity", "drag", "materials",
                             "contact_pairs", "walls", "particles", "output", "reference"});

  if (auto f = top.optional("format")) {
    const long long version = f->integer();
    if (version != kFormatVersion)
      f->fail("unsupported scene format " + f->node().Scalar() + "; this version reads format " +
              std::to_string(kFormatVersion));
  }

  Scene scene;
  scene.path = path;
  scene.name = stem;
  if (auto f = top.optional("name")) scene.name = f->word();

  scene.time = read_time(top.required("time"), duration, scene.dt_where);
  if (auto f = top.optional("solver")) scene.solver = read_solver(*f);

  scene.effects = kDefaultEffects;
  if (auto f = top.optional("effects")) scene.effects = read_effects(*f);
  if (auto f = top.optional("gravity")) scene.gravity = f->vec3();
  // A substep's fall under gravity, g h^2, and so each sphere's travel and
  // reach in it, in the precision's range (with room for a few sums): past
  // it the first substep's contact search meets no finite bound.
  if (scene.has(Effect::gravity)) {
    const double h = scene.time.dt / scene.time.substeps;
    const double gx = scene.gravity.x, gy = scene.gravity.y, gz = scene.gravity.z;
    const double fall = std::sqrt(gx * gx + gy * gy + gz * gz) * h * h;
    if (!(fall <= kSubstepRoom)) refuse_substep_motion(scene, "lets gravity move a sphere |g| h^2 =", fall);
  }
  if (auto f = top.optional("drag")) {
    if (f->is_map()) {
      const MapFields drag(*f, {"linear", "quadratic"});
      if (drag.entries().empty()) f->fail("give linear (1/s), quadratic (1/m) or both");
      if (auto g = drag.optional("linear")) scene.drag = g->non_negative();
      if (auto g = drag.optional("quadratic")) scene.drag_quadratic = g->non_negative();
    } else {
      scene.drag = f->non_negative();
    }
  }
  if (scene.has(Effect::drag) && !top.has("drag")) {
    const Field effects = *top.optional("effects");
    for (const Field& item : effects.items())
      if (item.word() == "drag") item.fail("the drag effect needs the top-level key 'drag' (linear rate 1/s, or {linear, quadratic})");
  }

  scene.materials = read_materials(top.required("materials"));
  if (auto f = top.optional("contact_pairs")) scene.contact_pairs = read_contact_pairs(scene, *f);
  if (auto f = top.optional("walls")) scene.walls = read_walls(scene, *f);
  scene.particles = read_particles(scene, top.required("particles"));

  scene.output.dir = "out/" + stem;
  if (auto f = top.optional("output")) scene.output = read_output(*f, stem);
  if (auto f = top.optional("reference")) scene.reference = read_reference(*f);
  scene.fingerprint = fnv1a(kFingerprintTag, sizeof kFingerprintTag);
  fold_tree(document, "", origins, scene.fingerprint);
  return scene;
}

}  // namespace

void refuse_substep_motion(const Scene& scene, const std::string& moves, double amount) {
  const double h = scene.time.dt / scene.time.substeps;
  throw InputError(scene.dt_where, "time.dt",
                   "a substep of h = " + shortest(h) + " s " + moves + " " +
                       (std::isfinite(amount) ? significant(amount, 6) : "more than " + significant(kSubstepRoom, 6)) +
                       " m in it, more than " + std::string(kRealName) + " precision holds with room for its sums (" +
                       significant(kSubstepRoom, 6) + " m); lower time.dt or raise time.substeps");
}

Scene load_scene(const std::string& path) { return load_scene(path, {}); }

Scene load_scene(const std::string& path, const std::vector<std::string>& overrides, std::optional<double> duration) {
  return read_scene(read_document(path), path, std::filesystem::path(path).stem().string(), overrides, duration);
}

namespace {

// A JSON value as the YAML tree the file loader would have built; nodes made
// here carry no position, so errors name the key path alone. Nested no
// deeper than a scene file may be (the YAML reader's bound): a dict of 20 000
// levels from Python overflowed the stack here.
constexpr int kJsonDepth = 500;
YAML::Node yaml_of(const nlohmann::ordered_json& value, const std::string& label, int depth = 0) {
  // A value of kJsonDepth levels (the top the first) is refused, as the file loader refuses one.
  if ((value.is_object() || value.is_array()) && depth + 1 >= kJsonDepth)
    throw InputError(SourceLocation{label, 0, 0}, "",
                     "nested deeper than the YAML reader follows (" + std::to_string(kJsonDepth) + " levels)");
  switch (value.type()) {
    case nlohmann::ordered_json::value_t::object: {
      YAML::Node map(YAML::NodeType::Map);
      for (const auto& [key, item] : value.items()) map.force_insert(key, yaml_of(item, label, depth + 1));
      return map;
    }
    case nlohmann::ordered_json::value_t::array: {
      YAML::Node sequence(YAML::NodeType::Sequence);
      for (const auto& item : value) sequence.push_back(yaml_of(item, label, depth + 1));
      return sequence;
    }
    case nlohmann::ordered_json::value_t::string:
      return YAML::Node(value.get<std::string>());
    case nlohmann::ordered_json::value_t::boolean:
      return YAML::Node(value.get<bool>() ? "true" : "false");
    case nlohmann::ordered_json::value_t::number_integer:
      return YAML::Node(std::to_string(value.get<std::int64_t>()));
    case nlohmann::ordered_json::value_t::number_unsigned:
      return YAML::Node(std::to_string(value.get<std::uint64_t>()));
    case nlohmann::ordered_json::value_t::number_float:
      return YAML::Node(shortest(value.get<double>()));
    default:
      return YAML::Node(YAML::NodeType::Null);
  }
}

}  // namespace

Scene load_scene_json(const std::string& text, const std::string& label, const std::string& stem,
                      const std::vector<std::string>& overrides) {
  nlohmann::ordered_json json;
  try {
    json = nlohmann::ordered_json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(SourceLocation{label, 0, 0}, "", std::string("not a scene: ") + e.what());
  }
  const YAML::Node document = yaml_of(json, label);
  expect_scene_map(document, label);
  return read_scene(document, label, stem, overrides, std::nullopt);
}

namespace {

// solver.precision of a scene's tree once the overrides are applied (as
// read_scene applies them).
std::string precision_of(YAML::Node document, const std::vector<std::string>& overrides) {
  detail::Origins origins;
  apply_overrides_whole(document, overrides, origins);
  const YAML::Node& root = document;
  if (root.IsMap() && root["solver"].IsMap() && root["solver"]["precision"].IsScalar() &&
      root["solver"]["precision"].Scalar() == "double")
    return "double";
  return "float";
}

}  // namespace

std::string scene_precision(const std::string& path, const std::vector<std::string>& overrides) {
  try {
    return precision_of(read_document(path), overrides);
  } catch (const std::exception&) {
    return "float";
  }
}

std::string scene_precision_json(const std::string& text, const std::vector<std::string>& overrides) {
  try {
    return precision_of(yaml_of(nlohmann::ordered_json::parse(text), ""), overrides);
  } catch (const std::exception&) {
    return "float";
  }
}

}  // namespace marbles::scene
