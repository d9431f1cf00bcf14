// sim/scene.hpp — a scene file turned into a plain description.
//
// load_scene() parses and validates a YAML scene (format v1, docs/scene-format.md)
// and returns this description; nothing here knows about YAML. Every value
// that came from the file keeps its SourceLocation so later checks (e.g. a
// block naming an unknown material) can still point at the line.
// All quantities are SI: m, s, kg, kg/m^3, m/s, rad/s.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "core/vec3.hpp"

namespace marbles::scene {

struct TimeSpec {
  double duration = 0;  // s, simulated time
  double dt = 0;        // s, one step (output cadence counts steps)
  int substeps = 1;     // substeps per step, h = dt / substeps
};

struct SolverSpec {
  int iterations = 10;                        // velocity sweeps per substep
  int closing_iterations = 2;                 // velocity Verlet's closing solve's sweeps per substep
  int impact_passes = 16;                     // passes of the impact stage per substep, at most (narrowphase::kImpactPasses)
  static constexpr int kMostImpactPasses = 4096;  // the most a scene may ask for
  // The most velocity sweeps a scene may ask for: a step of one sphere at
  // 10^7 took 3.7 s on a CPU core, and the watchdog's retries sweep up to 8
  // times as often (which past 2^28 would not fit an int).
  static constexpr int kMostIterations = 100'000;
  std::string integrator = "symplectic_euler";  // symplectic_euler | velocity_verlet
  bool speculative = true;                    // speculative contacts (gaps that close within a substep)
  std::string precision = "float";            // float | double: the type the run computes in
  SourceLocation precision_where;             // the `precision:` value (line 0 when not given)
  // Every this many steps the spheres are numbered again in the broad
  // phase's order, hidden from output, checkpoints and edits (0: never;
  // docs/scene-format.md).
  int renumber = 0;
};

struct Material {
  std::string name;
  double density = 1000;        // kg/m^3, > 0
  double restitution = 0.5;     // [0, 1]
  double friction = 0.5;        // Coulomb mu, >= 0
  double rolling_friction = 0;  // dimensionless rolling resistance coefficient, >= 0
  double twisting_friction = 0; // dimensionless twisting (spin) resistance coefficient, >= 0
  SourceLocation where;
};

// An explicit coefficient set for one pair of materials, replacing the mixing rule.
struct ContactPairSpec {
  std::string first, second;  // material names (order does not matter)
  double restitution = -1, friction = -1, rolling_friction = -1, twisting_friction = -1;  // < 0: mixing rule
  SourceLocation where;
};


struct WallSpec {
  enum class Kind { plane, box, cylinder, sphere };
  Kind kind = Kind::plane;
  Vec3 point, normal{0, 0, 1};  // plane: a point on it and the normal towards free space (normalised on load)
  Vec3 lo, hi;                  // box: spheres are kept inside [lo, hi]
  Vec3 base, axis{0, 0, 1};     // cylinder: a point on the axis and the axis direction (normalised on load)
  double radius = 0;            // cylinder, sphere (m)
  double length = 0;            // cylinder: from base along axis; 0 = infinite
  bool inside = true;           // cylinder: keep spheres inside (tube, drum) or outside (post)
  double angular_velocity = 0;  // cylinder: spin about the axis, rad/s
  Vec3 centre;                  // sphere: a fixed spherical obstacle
  Vec3 velocity;                // plane, box, sphere: prescribed translation, m/s
  std::string material;         // name; empty = the first material
  SourceLocation where;
  SourceLocation material_where;  // the `material:` value (file:0:0 when not given)
};

struct RadiusSpec {
  enum class Kind { constant, uniform, log_uniform };
  Kind kind = Kind::constant;
  double value = 0;       // constant
  double min = 0, max = 0; // uniform, log_uniform
};

struct VelocitySpec {
  enum class Kind { zero, constant, random };
  Kind kind = Kind::zero;
  Vec3 value;              // constant
  double speed = 0;        // random: each component uniform in [-speed, speed]
  std::uint64_t seed = 1;  // random
};

struct ParticleBlock {
  enum class Kind { list, lattice, random, csv };
  Kind kind = Kind::list;
  std::string material;  // name; empty = the first material

  // list: explicit spheres (positions and radii; velocities optional, one per sphere)
  std::vector<Vec3> positions;
  std::vector<double> radii;
  std::vector<Vec3> velocities;

  // lattice: cubic lattice of spheres filling [lo, hi] with the given spacing,
  // each centre moved by a uniform jitter in [-jitter, jitter] per axis
  // random: `count` non-overlapping spheres with centres in [lo, hi] (whole sphere inside)
  Vec3 lo, hi;
  // lattice: min and max as written, in double: a float run counts the
  // lattice's sites as a double run does (0.7 in float is 0.69999999, and
  // floor(0.6999999 / 0.1) would drop a row).
  std::array<double, 3> lo_written{}, hi_written{};
  double spacing = 0;
  double jitter = 0;
  std::size_t count = 0;
  RadiusSpec radius;
  std::uint64_t seed = 1;

  // csv: rows x,y,z,r[,vx,vy,vz]; path resolved relative to the scene file
  std::string csv_path;

  VelocitySpec velocity;  // initial velocities (lists and CSV may give their own)
  Vec3 angular_velocity;  // rad/s, every sphere of the block (CSV may give its own: wx,wy,wz)
  bool angular_velocity_given = false;  // the key was given (in the file or by an override)
  bool fixed = false;     // the spheres collide but never move (pegs, rough floors)
  // The spheres' numbering (their ids). false (`order: given`, the
  // default): as the source gives them (a list's or file's rows, a
  // lattice's rows, a random block's placing); true (`order: cells`): the
  // order in which the broad phase finds their pairs (cell_order,
  // sim/world.hpp; docs/scene-format.md: large blocks step faster).
  bool order_cells = false;
  SourceLocation where;

  // Where single keys were written, for problems found only while generating
  // (a line of 0 means the key was not given).
  SourceLocation material_where;  // `material:`
  SourceLocation count_where;     // random: `count:`
  SourceLocation csv_path_where;  // csv: `path:`
  SourceLocation velocity_where;  // `velocity:`
  SourceLocation angular_velocity_where;  // `angular_velocity:`
  SourceLocation fixed_where;     // `fixed:`
};

struct CameraSpec {
  bool given = false;  // false: frame the whole scene
  Vec3 position, look_at, up{0, 0, 1};
  double fov = 40;     // vertical field of view, degrees
};

struct RenderSpec {
  bool enabled = false;
  int every = 1;       // steps
  int width = 1280, height = 720;
  CameraSpec camera;
  std::string color_by = "speed";  // speed | id | radius | material
};

struct MovieSpec {
  bool enabled = false;
  double fps = 30;
};

struct OutputSpec {
  std::string dir = "out";          // resolved relative to the current directory
  SourceLocation dir_where;         // the `dir:` value (no file where not given)
  int vtk_every = 0;                // steps; 0 = no VTK frames
  int contacts_every = 0;           // steps; 0 = no contact frames (OUTDIR/contacts/, contacts.pvd)
  std::vector<std::string> fields{"radius", "velocity", "angular_velocity", "id", "material"};
  RenderSpec render;
  MovieSpec movie;
  int checkpoint_every = 0;         // steps; 0 = no checkpoints (OUTDIR/checkpoints/step_NNNNNN.mck)
  int checkpoint_keep = 3;          // the newest this many are kept
};

// A known answer the run is measured against (`reference:`, docs/accuracy.md).
// Each kind states the physics it expects; the run measures the same
// quantity from its own trajectory (sim/reference.hpp).
struct ReferenceSpec {
  enum class Kind {
    none,
    rebound_heights,  // a dropped ball: apex k above the contact height = H0 e^(2k)
    time_to_rest,     // a dropped ball: T = sqrt(2 H0 / g) (1 + e) / (1 - e)
    incline,          // from rest on an incline: a = 5/7 g sin(angle) rolling, g (sin - mu cos) sliding
    slide_to_roll,    // launched sliding without spin on a floor: ends rolling at 5/7 v0
    oblique_rebound,  // an oblique impact on a plane: v_n' = e v_n; v_t' = 5/7 v_t (stick) or v_t - mu (1+e) v_n
    kinetic_energy,   // conserved (elastic, frictionless, no gravity)
    momentum,         // conserved (no walls, no gravity)
    finest            // no analytic answer: the study's finest setting is the reference
  };
  Kind kind = Kind::none;
  std::uint32_t sphere = 0;  // the ball of the single-ball kinds
  double restitution = 0;    // rebound_heights, time_to_rest, oblique_rebound
  double friction = 0;       // incline, oblique_rebound
  double angle = 0;          // incline, degrees
  double floor = 0;          // rebound_heights, time_to_rest: height of the floor along -g (m)
  int bounces = 3;           // rebound_heights
  SourceLocation where;
};
const char* reference_name(ReferenceSpec::Kind kind);

enum class Effect { gravity, collisions, walls, restitution, friction, rolling_resistance, drag };
const char* effect_name(Effect e);

struct Scene {
  std::string path;  // the file it came from
  std::string name;  // optional `name:`; defaults to the file stem
  TimeSpec time;
  SourceLocation dt_where;  // time.dt's value (the rules of a substep's motion name it)
  SolverSpec solver;
  std::vector<Effect> effects;
  Vec3 gravity{0, 0, -9.81};
  double drag = 0;            // 1/s, linear drag rate (effect drag): dv/dt = -(drag + drag_quadratic |v|) v
  double drag_quadratic = 0;  // 1/m, quadratic drag coefficient (effect drag)
  std::vector<Material> materials;  // at least one
  std::vector<ContactPairSpec> contact_pairs;
  std::vector<WallSpec> walls;
  std::vector<ParticleBlock> particles;
  OutputSpec output;
  ReferenceSpec reference;
  // What a checkpoint must match (sim/checkpoint.hpp): FNV-1a of the scene's
  // tree once the overrides are applied, each value as the reader took it
  // (5e-4 and 0.0005 alike, True and true, quoted or not; a name as
  // written), each map's keys sorted but where their order counts. Set by
  // the loaders; run --duration and --out are not part of it.
  std::uint64_t fingerprint = 0;

  bool has(Effect e) const {
    for (Effect x : effects) if (x == e) return true;
    return false;
  }
  // Index of a material by name (empty = 0); throws InputError at `where` if unknown.
  std::uint32_t material_index(const std::string& name, const SourceLocation& where, const std::string& key) const;
};

// How far a substep may move a sphere, by its fall under gravity or its
// travel at its speed: the precision's largest number with room for a few
// sums. Past it the first substep's contact search meets no finite bound.
inline constexpr double kSubstepRoom = double(std::numeric_limits<real>::max()) / 16;

// Refuses `scene`'s time.dt: a substep of it `moves` (the motion and its
// cause, e.g. "lets gravity move a sphere |g| h^2 =") `amount` m, past
// kSubstepRoom (an amount past double's range is said as "more than").
[[noreturn]] void refuse_substep_motion(const Scene& scene, const std::string& moves, double amount);

// Parses and validates; throws InputError (file:line:column: key: message).
Scene load_scene(const std::string& path);

// The same with `--set` overrides ("time.dt=5e-4", "particles[0].random.count=500",
// "gravity=[0, 0, -1]": a dotted key path, then a YAML value) applied in order to
// the file's tree before validation. A problem in an overridden value is
// reported at the override ("--set time.dt=-1: time.dt: must be > 0, got -1").
// `duration` (run --duration) takes time.duration's place, held to its
// rules against the time block as overridden (errors name --duration); it
// is not part of the fingerprint, so a restart may run on further.
Scene load_scene(const std::string& path, const std::vector<std::string>& overrides,
                 std::optional<double> duration = std::nullopt);

// A scene given as JSON text (the Python module's dicts): the same keys, the
// same checks and messages; errors name `label` and the key path (there are
// no lines). `stem` is the default name and output folder (out/<stem>);
// relative paths in it (CSV blocks) are taken from the current directory.
Scene load_scene_json(const std::string& text, const std::string& label, const std::string& stem,
                      const std::vector<std::string>& overrides = {});
// The scene's `solver.precision` ("float" or "double") once the `--set`
// overrides are applied to its tree, as the loader applies them (so a
// nested `solver={precision: double}` or a quoted "double" counts), read
// without validating anything else; "float" when the file or an override
// cannot be read (loading the scene then says why).
std::string scene_precision(const std::string& path, const std::vector<std::string>& overrides = {});
// The same of a scene given as JSON text (load_scene_json's).
std::string scene_precision_json(const std::string& text, const std::vector<std::string>& overrides = {});

}  // namespace marbles::scene
