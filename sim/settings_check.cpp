// sim/settings_check.cpp — the risky-settings rules (see settings_check.hpp).
//
// Each rule is one function returning its message, or nothing when the
// scene passes it. Quantities are computed in double from the scene and the
// initial spheres; numbers in messages have three significant digits.
#include "sim/settings_check.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <limits>
#include <numbers>
#include <optional>
#include <sstream>

#include "narrowphase/solver_math.hpp"

namespace marbles {

namespace {

using scene::Effect;
using Axis = std::array<double, 3>;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPacking = 0.6;     // volume fraction of a settled random pile
constexpr double kFloatRange = 1e5;  // scene extent over the smallest radius that float still resolves well
constexpr double kCreepShare = 0.01;  // of sqrt(|g| r_min): the slowest speed float positions must still resolve
const double kSlop = narrowphase::SolverSettings{}.slop;  // overlap the solver leaves, of the smaller radius

std::string num(double v) {
  std::ostringstream s;
  s << std::setprecision(3) << v;
  return s.str();
}

// The smallest whole number >= v, for "raise X to at least N".
// A count to raise a setting to: whole where it fits an integer, else in
// the form of a double (a count past 2^53 is no advice anyone can take).
std::string at_least(double v) {
  const double whole = std::ceil(v);
  if (whole < 9.007199254740992e15) return std::to_string(static_cast<long long>(whole));
  return num(whole);
}

double along(const Vec3& p, const Axis& a) { return double(p.x) * a[0] + double(p.y) * a[1] + double(p.z) * a[2]; }

Axis cross(const Axis& a, const Axis& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// An axis-aligned box grown point by point.
struct Box {
  Axis lo{kInf, kInf, kInf}, hi{-kInf, -kInf, -kInf};

  void add(const Vec3& p, double r) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], double(p[a]) - r);
      hi[a] = std::max(hi[a], double(p[a]) + r);
    }
  }
  void add(const Box& b) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], b.lo[a]);
      hi[a] = std::max(hi[a], b.hi[a]);
    }
  }
  double largest_side() const { return std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}); }
  // The lowest corner's height along `up`.
  double bottom(const Axis& up) const {
    double h = 0;
    for (int a = 0; a < 3; ++a) h += std::min(lo[a] * up[a], hi[a] * up[a]);
    return h;
  }
};

// The box around a wall of finite size (box, sphere, cylinder of given length).
std::optional<Box> wall_box(const scene::WallSpec& w) {
  Box box;
  switch (w.kind) {
    case scene::WallSpec::Kind::box:
      box.add(w.lo, 0);
      box.add(w.hi, 0);
      return box;
    case scene::WallSpec::Kind::sphere:
      box.add(w.centre, w.radius);
      return box;
    case scene::WallSpec::Kind::cylinder:
      if (w.length <= 0) return std::nullopt;
      box.add(w.base, w.radius);
      box.add(w.base + w.axis * real(w.length), w.radius);
      return box;
    case scene::WallSpec::Kind::plane:
      break;
  }
  return std::nullopt;
}

// The lowest point of a wall along `up`, where it has one: a finite wall, or
// a plane square to gravity.
std::optional<double> wall_bottom(const scene::WallSpec& w, const Axis& up) {
  if (auto box = wall_box(w)) return box->bottom(up);
  if (w.kind == scene::WallSpec::Kind::plane && std::fabs(along(w.normal, up)) > 1 - 1e-6) return along(w.point, up);
  return std::nullopt;
}

// Two unit axes square to `up` and to each other.
std::array<Axis, 2> across(const Axis& up) {
  int least = 0;  // the world axis least aligned with up
  for (int a = 1; a < 3; ++a)
    if (std::fabs(up[a]) < std::fabs(up[least])) least = a;
  Axis e{0, 0, 0};
  e[least] = 1;
  const Axis c = cross(up, e);
  const double n = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
  const Axis e1{c[0] / n, c[1] / n, c[2] / n};
  return {e1, cross(up, e1)};
}

// What the rules read from the scene and its initial spheres.
struct Setting {
  double dt = 0, h = 0;  // step, substep
  double g = 0;          // |g| when gravity is on, else 0
  Axis up{0, 0, 1};      // against gravity
  double r_min = kInf, r_max = 0, r_mean = 0;
  double volume = 0;     // of all spheres
  double speed = 0;      // the largest initial speed
};

Setting read_setting(const scene::Scene& scene, const scene::GeneratedParticles& p) {
  Setting s;
  s.dt = scene.time.dt;
  s.h = scene.time.dt / scene.time.substeps;
  const Axis g{scene.gravity.x, scene.gravity.y, scene.gravity.z};
  const double g_len = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  if (scene.has(Effect::gravity) && g_len > 0) {
    s.g = g_len;
    s.up = {-g[0] / g_len, -g[1] / g_len, -g[2] / g_len};
  }
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double r = p.radius[i];
    s.r_min = std::min(s.r_min, r);
    s.r_max = std::max(s.r_max, r);
    s.r_mean += r / double(p.size());
    s.volume += 4.0 / 3.0 * std::numbers::pi * r * r * r;
    s.speed = std::max(s.speed, double(length(p.velocity[i])));
  }
  return s;
}

// The fastest a moving wall can set a sphere going: twice a translating
// wall's speed (a sphere at rest struck elastically), a spinning cylinder's
// surface speed (friction carries a sphere up to it). 0 without walls.
double push_of(const scene::WallSpec& w) {
  const double moving = 2 * double(length(w.velocity));
  return w.kind == scene::WallSpec::Kind::cylinder ? std::max(moving, std::fabs(w.angular_velocity) * w.radius)
                                                   : moving;
}

// The largest push of the walls, `skip` (an index) left out.
double wall_push(const scene::Scene& scene, std::size_t skip = std::size_t(-1)) {
  if (!scene.has(Effect::walls)) return 0;
  double push = 0;
  for (std::size_t k = 0; k < scene.walls.size(); ++k)
    if (k != skip) push = std::max(push, push_of(scene.walls[k]));
  return push;
}

// Fastest sphere: its initial speed, or what a moving wall gives it, plus a
// fall from the highest centre to the lowest centre or wall bottom.
struct Fastest {
  double v = 0, fall = 0, pushed = 0;
};
Fastest fastest(const Setting& s, const scene::Scene& scene, const scene::GeneratedParticles& p,
                std::size_t skip_wall = std::size_t(-1)) {
  Fastest f;
  if (s.g > 0) {
    double top = -kInf, bottom = kInf;
    for (const Vec3& c : p.position) {
      top = std::max(top, along(c, s.up));
      bottom = std::min(bottom, along(c, s.up));
    }
    if (scene.has(Effect::walls))
      for (const scene::WallSpec& w : scene.walls)
        if (auto b = wall_bottom(w, s.up)) bottom = std::min(bottom, *b);
    f.fall = std::max(0.0, top - bottom);
  }
  f.pushed = wall_push(scene, skip_wall);
  f.v = std::max(s.speed, f.pushed) + std::sqrt(2 * s.g * f.fall);
  return f;
}

// The fastest sphere against the smallest radius per substep.
std::optional<std::string> fast_motion(const Setting& s, const scene::Scene& scene,
                                       const scene::GeneratedParticles& p) {
  const auto [v, fall, pushed] = fastest(s, scene, p);
  const double move = v * s.h;
  if (!(move > s.r_min)) return std::nullopt;
  const std::string start = s.speed >= pushed ? num(s.speed) + " m/s at the start"
                                              : num(pushed) + " m/s from a moving wall (twice a moving wall's speed, or "
                                                              "a spinning wall's surface speed)";
  return "dt so large that the fastest sphere moves " + num(move) + " m (" + num(move / s.r_min) +
         " radii) per substep: up to " + num(v) + " m/s (" + start + ", plus a fall of " +
         num(fall) + " m) over h = dt / substeps = " + num(s.h) + " s, more than the smallest radius " +
         num(s.r_min) + " m, so it can pass through a sphere or a wall; raise time.substeps to at least " +
         at_least(v * s.dt / s.r_min) + " (or lower time.dt)";
}

// Settled layers: the spheres' volume at packing 0.6 spread over the area of
// their centres square to gravity, in layers one mean diameter thick.
std::optional<std::string> stack_height(const Setting& s, const scene::Scene& scene,
                                        const scene::GeneratedParticles& p) {
  if (!(s.g > 0) || !scene.has(Effect::collisions)) return std::nullopt;
  const double d = 2 * s.r_mean;
  double area = 1;
  for (const Axis& e : across(s.up)) {
    double lo = kInf, hi = -kInf;
    for (const Vec3& c : p.position) {
      lo = std::min(lo, along(c, e));
      hi = std::max(hi, along(c, e));
    }
    area *= std::max(hi - lo, d);
  }
  const double layers = s.volume / kPacking / area / d;
  if (!(scene.solver.iterations < layers / 2)) return std::nullopt;
  return "stack too tall for the solver: about " + num(layers) + " layers of spheres will settle (" +
         num(s.volume) + " m^3 of spheres at packing " + num(kPacking) + " over " + num(area) + " m^2, " + num(d) +
         " m a layer), more than twice solver.iterations = " + std::to_string(scene.solver.iterations) +
         ": its sweeps will not carry the weight down the stack, which sinks into itself; raise solver.iterations "
         "to at least " + at_least(layers / 2);
}

// A resting sphere falls g h^2 in a substep before its contact pushes back;
// beyond the solver's slop the overlap shows as sinking and jitter.
std::optional<std::string> coarse_substeps(const Setting& s, const scene::Scene& scene) {
  if (!(s.g > 0) || !(scene.has(Effect::collisions) || scene.has(Effect::walls))) return std::nullopt;
  const double sink = s.g * s.h * s.h;
  const double slop = kSlop * s.r_min;
  if (!(sink > slop)) return std::nullopt;
  return "substeps too coarse for gravity: a resting sphere falls |g| h^2 = " + num(sink) +
         " m per substep, more than the solver's slop " + num(kSlop) + " x the smallest radius = " + num(slop) +
         " m, so resting contacts sink and jitter; raise time.substeps to at least " +
         at_least(s.dt * std::sqrt(s.g / slop)) + " (or lower time.dt)";
}

// A heavy sphere that lands on a light one held by a wall or another sphere
// squeezes it: each impact pass and sweep takes only about 2 / R of the heavy
// one's speed (R the mass ratio), and more sweeps help little. Measured (a
// sphere R times denser dropped 0.19 m onto a light one on a floor, dt = 1
// ms, 10 iterations; the largest overlap): R = 20, 2.9 % at 1 substep, 0.6 %
// at 4; R = 50, 10.6 % at 1, 2.9 % at 4, 0.5 % at 16; R = 100, the watchdog
// gives up at 1, 6.3 % at 4, 1.1 % at 16; the same at 20 iterations. The
// demo pour (h R = 24.9 ms: steel on glass, twice the radius) keeps 2.9 %, a
// heavy sphere landing on several light ones shares its load. The rule
// fires past h R = 30 ms and asks for 12 ms, where every case above stays
// within 3 % (R = 100 at h R = 25 ms, 6.3 %, is below its trigger: the
// demo's h R sets it). Spheres of about one mass (R < 10: R = 10 at h R =
// 10 ms kept 0.3 %) are not its case.
constexpr double kMassRatioFires = 30e-3;    // s: h R past which it warns
constexpr double kMassRatioSubstep = 12e-3;  // s: the h R it asks for
constexpr double kLeastMassRatio = 10;       // below it spheres are of about one mass

std::optional<std::string> mass_ratio(const Setting& s, const scene::Scene& scene,
                                      const scene::GeneratedParticles& p) {
  if (!scene.has(Effect::collisions)) return std::nullopt;
  double lightest = kInf, heaviest = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (i < p.fixed.size() && p.fixed[i]) continue;  // a fixed sphere is a wall: nothing squeezes it
    const double r = p.radius[i];
    const std::size_t k = i < p.material.size() ? p.material[i] : 0;
    const double density = k < scene.materials.size() ? scene.materials[k].density : 1;
    const double m = density * r * r * r;  // the 4 pi / 3 cancels
    lightest = std::min(lightest, m);
    heaviest = std::max(heaviest, m);
  }
  if (!(heaviest > 0 && lightest > 0)) return std::nullopt;
  const double ratio = heaviest / lightest;
  if (!(ratio >= kLeastMassRatio) || !(s.h * ratio > kMassRatioFires)) return std::nullopt;
  return "spheres up to " + num(ratio) +
         " times heavier than the lightest: a heavy sphere that lands on a light one held by a wall or another "
         "sphere is slowed by only about 2 / " + num(ratio) +
         " of its speed a sweep and squeezes it (overlaps of several % of a radius, more as h x mass ratio grows; "
         "more iterations help little); "
         "raise time.substeps to at least " + at_least(s.dt * ratio / kMassRatioSubstep) + " (h x mass ratio = " +
         num(s.h * ratio) + " s, more than " + num(kMassRatioFires) + "; at most " + num(kMassRatioSubstep) +
         " s keeps such overlaps within 3 %)";
}

// The broad phase's cells are sized by the largest sphere (an edge of 2
// r_max): where radii spread widely a cell holds many of the smallest, and
// each is tested against all in its neighbouring cells. Measured (27 000
// spheres of 1 cm on a loose lattice, one larger sphere, 1 thread): a step
// 7.5 times slower with the larger 3 times the radius, 28 times at 5, 80 at
// 8. The rule fires where a cell can hold more than 64 of the smallest
// (about 1.15 (r_max / r_min)^3 at a packing of 0.6: a ratio past 3.8) and
// there are enough spheres for it to matter.
constexpr double kCellCrowd = 64;
constexpr std::size_t kCrowdSpheres = 1000;

std::optional<std::string> radius_spread(const Setting& s, const scene::Scene& scene,
                                         const scene::GeneratedParticles& p) {
  if (!scene.has(Effect::collisions) || p.size() < kCrowdSpheres) return std::nullopt;
  const double r_max = s.r_max;
  const double ratio = r_max / s.r_min;
  const double crowd = kPacking * 6 / std::numbers::pi * ratio * ratio * ratio;  // of the smallest in a cell
  if (!(crowd > kCellCrowd)) return std::nullopt;
  return "radii from " + num(s.r_min) + " to " + num(r_max) + " m (" + num(ratio) +
         " times): the broad phase's cells are sized by the largest sphere (an edge of " + num(2 * r_max) +
         " m), so a cell can hold about " + num(crowd) +
         " of the smallest, each tested against all in the neighbouring cells, and steps can be many times slower "
         "(a sphere 5 times the radius of the others made each step 28 times slower, 8 times 80); a large sphere that "
         "never moves is better a `sphere` wall (walls are not in the broad phase), else narrow the radius range";
}

// Float keeps 24 bits: a position is rounded to about 2^-24 of its own size,
// so the scene's farthest point from the origin (the box around every sphere
// and finite wall) sets the rounding, not the scene's span: a small pile 10
// km from the origin rounds as a 10 km scene does. That reaches the solver's
// slop at 1e5 smallest radii.
std::optional<std::string> float_precision(const Setting& s, const scene::Scene& scene,
                                           const scene::GeneratedParticles& p, bool single_precision) {
  if (!single_precision) return std::nullopt;
  Box box;
  for (std::size_t i = 0; i < p.size(); ++i) box.add(p.position[i], p.radius[i]);
  for (const scene::WallSpec& w : scene.walls)
    if (auto b = wall_box(w)) box.add(*b);
  double reach = 0;  // the largest coordinate's size
  for (int a = 0; a < 3; ++a) reach = std::max({reach, std::fabs(box.lo[a]), std::fabs(box.hi[a])});
  // Float positions at `reach` are `spacing` apart; a sphere moving less than
  // half of it in a substep does not move: below `still` (m/s). Under gravity
  // grains creep at a small part of sqrt(|g| r), the speed a sphere gains
  // falling by half its radius: where `still` passes 1 % of it for the
  // smallest sphere, slow motion is lost (a sphere rolling at 3 mm/s 10^4
  // radii out stood still, with no warning before).
  const double spacing = reach > 0 ? std::ldexp(1.0, std::ilogb(reach) - 23) : 0;
  const double still = spacing / (2 * s.h), creep = kCreepShare * std::sqrt(s.g * s.r_min);
  const bool coarse = reach > kFloatRange * s.r_min, stills = s.g > 0 && still > creep;
  if (!coarse && !stills) return std::nullopt;
  const double rounding = std::ldexp(reach, -24);
  const double extent = box.largest_side();
  const std::string remedy = std::string("set solver.precision: double (or --precision double)") +
                             (reach > 2 * extent ? ", or move the scene to the origin" : ", or make the scene smaller");
  if (!coarse)
    return "float precision: the scene reaches " + num(reach) + " m from the origin (it spans " + num(extent) +
           " m), where float positions are " + num(spacing) + " m apart: a sphere slower than " + num(still) +
           " m/s (half that spacing per substep of " + num(s.h) + " s) does not move at all, more than 1 % of " +
           "sqrt(|g| r) = " + num(creep / kCreepShare) + " m/s for the smallest radius, so creeping motion is lost; " +
           remedy;
  return "float precision: the scene reaches " + num(reach) + " m from the origin (it spans " + num(extent) +
         " m), " + num(reach / s.r_min) + " times the smallest radius (more than " + num(kFloatRange) +
         "): float positions there are rounded to about " + num(rounding) + " m, " + num(100 * rounding / s.r_min) +
         " % of that radius; " + remedy;
}

}  // namespace

double fastest_speed(const scene::Scene& scene, const scene::GeneratedParticles& particles,
                     std::optional<std::size_t> without_wall) {
  if (particles.size() == 0) return 0;
  return fastest(read_setting(scene, particles), scene, particles, without_wall.value_or(std::size_t(-1))).v;
}

std::optional<SpeedingWall> speeding_wall(const scene::Scene& scene, const scene::GeneratedParticles& particles) {
  if (particles.size() == 0 || !scene.has(Effect::walls)) return std::nullopt;
  double push = read_setting(scene, particles).speed;
  std::optional<SpeedingWall> found;
  for (std::size_t k = 0; k < scene.walls.size(); ++k) {
    const scene::WallSpec& w = scene.walls[k];
    if (!(push_of(w) > push)) continue;
    push = push_of(w);
    const bool spin = w.kind == scene::WallSpec::Kind::cylinder && std::fabs(w.angular_velocity) * w.radius >= push;
    found = SpeedingWall{k, spin ? "walls[" + std::to_string(k) + "].cylinder.angular_velocity"
                                 : "walls[" + std::to_string(k) + "].velocity",
                         push};
  }
  return found;
}

std::vector<std::string> risky_settings(const scene::Scene& scene, const scene::GeneratedParticles& particles,
                                        bool single_precision) {
  if (particles.size() == 0) return {};
  const Setting s = read_setting(scene, particles);
  std::vector<std::string> warnings;
  for (std::optional<std::string> w :
       {fast_motion(s, scene, particles), stack_height(s, scene, particles), coarse_substeps(s, scene),
        mass_ratio(s, scene, particles), radius_spread(s, scene, particles),
        float_precision(s, scene, particles, single_precision)})
    if (w) warnings.push_back(std::move(*w));
  return warnings;
}

}  // namespace marbles
