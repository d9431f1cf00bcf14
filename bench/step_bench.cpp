#include "bench/step_bench.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <iterator>
#include <numbers>
#include <optional>
#include <ostream>
#include <random>
#include <sstream>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <nlohmann/json.hpp>

#include "bench/api_count.hpp"
#include "broadphase/grid.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/format.hpp"
#include "core/hash.hpp"
#include "narrowphase/solver.hpp"
#include "render/atomic_file.hpp"
#include "sim/particles.hpp"
#include "sim/run.hpp"
#include "sim/scene.hpp"
#include "sim/simulation.hpp"

namespace marbles::bench {
namespace {

scene::Effect parse_effect(const std::string& name) {
  using E = scene::Effect;
  for (E e : {E::gravity, E::collisions, E::walls, E::restitution, E::friction, E::rolling_resistance, E::drag})
    if (name == scene::effect_name(e)) return e;
  throw InputError({}, "--effects", "unknown effect '" + name + "'");
}

// A jittered cubic lattice at the given volume fraction (no initial
// overlaps), random velocities of about 1 m/s, radius 1 cm, in a box container.
std::pair<scene::Scene, scene::GeneratedParticles> gas(std::size_t n, const std::vector<std::string>& effects,
                                                       double volume_fraction = 0.1) {
  scene::Scene s;
  s.path = s.name = "bench-gas";
  s.time = {1.0, 1e-3, 1};
  for (const auto& e : effects) s.effects.push_back(parse_effect(e));
  scene::Material m;
  m.name = "m";
  m.restitution = 0.9;
  m.friction = 0.4;
  m.rolling_friction = 0.01;
  s.materials.push_back(m);
  s.drag = 0.1;
  s.drag_quadratic = 0.1;
  const double r = 0.01;
  const double spacing = r * std::cbrt(4.0 / 3.0 * std::numbers::pi / volume_fraction);
  const double max_jitter = std::min(0.4 * r, 0.45 * (spacing - 2 * r));
  const auto side = static_cast<std::size_t>(std::ceil(std::cbrt(static_cast<double>(n))));
  scene::WallSpec box;
  box.kind = scene::WallSpec::Kind::box;
  box.lo = {0, 0, 0};
  box.hi = Vec3(1, 1, 1) * real(side * spacing);
  s.walls.push_back(box);
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> jitter(-max_jitter, max_jitter), vel(-1, 1);
  scene::GeneratedParticles g;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t x = i % side, y = (i / side) % side, z = i / (side * side);
    g.position.push_back({real((x + 0.5) * spacing + jitter(rng)), real((y + 0.5) * spacing + jitter(rng)),
                          real((z + 0.5) * spacing + jitter(rng))});
    g.velocity.push_back({real(vel(rng)), real(vel(rng)), real(vel(rng))});
    g.radius.push_back(real(r));
    g.material.push_back(0);
  }
  return {s, g};
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t k = v.size() / 2;
  return v.size() % 2 ? v[k] : 0.5 * (v[k - 1] + v[k]);
}

struct Timing {
  double step_ms, step_min_ms, broadphase_ms, pairs, contacts;
};

// Median of `repeats` timed steps after `warmup` untimed ones.
Timing time_steps(Simulation& sim, int warmup, int repeats) {
  for (int k = 0; k < warmup; ++k) sim.step();
  std::vector<double> step_ms, bp_ms;
  double pairs = 0, contacts = 0;
  for (int k = 0; k < repeats; ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    sim.step();
    step_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (sim.broad_phase()) bp_ms.push_back(sim.broad_phase()->last_stats().ms_total);
    pairs += sim.last_step().candidate_pairs;
    contacts += sim.last_step().contacts;
  }
  return {median(step_ms), *std::min_element(step_ms.begin(), step_ms.end()), bp_ms.empty() ? 0.0 : median(bp_ms),
          pairs / repeats, contacts / repeats};
}

}  // namespace

int run_effects_bench(const EffectsBenchOptions& options, std::ostream& out) {
  const broadphase::Backend backend = options.backend == "cuda" ? broadphase::Backend::cuda : broadphase::Backend::cpu;
  const std::vector<std::string> base{"collisions", "walls"};
  std::vector<std::pair<std::string, std::vector<std::string>>> configs{{"collisions+walls", base}};
  for (const char* extra : {"gravity", "restitution", "friction", "rolling_resistance", "drag"}) {
    auto e = base;
    e.push_back(extra);
    configs.push_back({std::string("+ ") + extra, e});
  }
  configs.push_back({"all", {"collisions", "walls", "gravity", "restitution", "friction", "rolling_resistance", "drag"}});
  std::vector<Timing> rows;
  for (const auto& [label, effects] : configs) {
    auto [s, g] = gas(options.n, effects, options.volume_fraction);
    Simulation sim(s, make_world(s, g), backend);
    rows.push_back(time_steps(sim, 5, options.repeats));
  }
  // A step's time over its contacts, where it met at least one a step on
  // average (else no per-contact cost: null in JSON, "-" in the table).
  const auto per_contact = [&](std::size_t k) -> std::optional<double> {
    if (!(rows[k].contacts >= 1)) return std::nullopt;
    return 1e3 * rows[k].step_ms / rows[k].contacts;
  };
  if (options.json) {
    nlohmann::ordered_json doc{{"benchmark", "effects"}, {"backend", options.backend}, {"n", options.n},
                               {"volume_fraction", options.volume_fraction}, {"repeats", options.repeats},
                               {"results", nlohmann::ordered_json::array()}};
    for (std::size_t k = 0; k < rows.size(); ++k)
      doc["results"].push_back({{"pipeline", configs[k].first},
                                {"step_ms_median", rows[k].step_ms},
                                {"contacts", rows[k].contacts},
                                {"us_per_contact", per_contact(k) ? nlohmann::ordered_json(*per_contact(k))
                                                                  : nlohmann::ordered_json(nullptr)}});
    out << json_text(doc);
    return 0;  // --json: JSON only
  }
  out << "effect cost (" << options.backend << ", " << kRealName << ", N = " << options.n << ", volume fraction "
      << options.volume_fraction << ", median of " << options.repeats << " steps)\n";
  out << std::setw(22) << std::left << "pipeline" << std::right << std::setw(12) << "step ms" << std::setw(10)
      << "x base" << std::setw(12) << "contacts" << std::setw(14) << "us/contact" << "\n";
  for (std::size_t k = 0; k < rows.size(); ++k) {
    out << std::setw(22) << std::left << configs[k].first << std::right << std::fixed << std::setprecision(3)
        << std::setw(12) << rows[k].step_ms << std::setw(10) << std::setprecision(2)
        << rows[k].step_ms / rows[0].step_ms << std::setw(12) << std::setprecision(0) << rows[k].contacts
        << std::setw(14) << std::setprecision(3);
    if (per_contact(k)) out << *per_contact(k);
    else out << "-";
    out << "\n" << std::defaultfloat;
  }
  out << "(effects change the motion, hence the contact count: compare us/contact for the per-contact cost)\n";
  return 0;
}

namespace {

// --- the pile ------------------------------------------------------------------

// Bump when pile() or its scene changes: older cache files are then not used.
constexpr std::uint32_t kPileVersion = 8;  // 7: a checksum at the end; 8: settled with 16 impact passes
constexpr char kPileMagic[8] = {'M', 'B', 'L', 'P', 'I', 'L', 'E', '\0'};
constexpr double kPileRadius = 0.01;
constexpr double kPileLayers = 30;  // about this many layers deep

// A loose lattice on a floor in a box: what the pile settles from, and the
// issue's CPU settling scene.
struct Lattice {
  double layers = kPileLayers;  // about this many layers deep
  double spacing = 2.004;       // in-plane, of a radius
  bool rolling = true;          // rolling resistance (rolling friction 0.05)
  bool friction = true;         // friction (0.5)
};

scene::Scene pile_scene(bool rolling, bool friction = true) {
  using E = scene::Effect;
  scene::Scene s;
  s.path = s.name = !friction ? "bench-pile-frictionless" : rolling ? "bench-pile" : "bench-settle";
  s.time = {1.0, 1e-3, 1};
  s.solver.iterations = 10;
  s.effects = {E::gravity, E::collisions, E::walls, E::restitution};
  if (friction) s.effects.push_back(E::friction);
  if (rolling) s.effects.push_back(E::rolling_resistance);
  scene::Material m;
  m.name = "m";
  m.density = 1000;
  m.restitution = 0.3;
  m.friction = friction ? 0.5 : 0;
  m.rolling_friction = rolling ? 0.05 : 0;
  s.materials.push_back(m);
  return s;
}

// The loose lattice, and the box around it: triangular layers (in-plane
// spacing a = lattice.spacing r, 2.004 for the pile, rows alternately shifted
// by a/2), stacked A B C so that each sphere sits over a hollow of three
// below, each layer 0.003 r higher than resting (the top layer falls about
// 0.1 r); a floor about square, wide enough for lattice.layers layers; a
// horizontal jitter of 0.001 r per axis (no overlaps: that needs a layer gap
// above 0.002 r). At 2.004 r the gaps are within the contact skin, so the
// pile starts with its final contacts: 6 in the layer, 3 below, 3 above
// (about 11 a sphere with the surfaces; contacts / N about 5.5, each pair
// counted once). A looser lattice (2.02 r) first settles with about 6 a
// sphere, then, stepped on, closes its in-plane gaps within some tens of
// steps and ends at the same 11.
std::pair<scene::Scene, scene::GeneratedParticles> pile(std::size_t n, const Lattice& lattice = {}) {
  scene::Scene s = pile_scene(lattice.rolling, lattice.friction);
  const double r = kPileRadius;
  const double a = lattice.spacing * r;
  const double row = a * std::sqrt(3.0) / 2;                   // between rows of a layer
  const double dz = std::sqrt(4 * r * r - a * a / 3) + 0.003 * r;  // between layers
  const double per_layer = std::max(1.0, static_cast<double>(n) / lattice.layers);
  const auto ny = static_cast<std::size_t>(std::max(1.0, std::round(std::sqrt(per_layer * 2 / std::sqrt(3.0)))));
  const auto nx = static_cast<std::size_t>(std::max(1.0, std::ceil(per_layer / static_cast<double>(ny))));
  const std::size_t layers = (n + nx * ny - 1) / (nx * ny);
  const double gap = 0.003 * r, x0 = r + gap, y0 = r + gap, z0 = r + gap;
  const double offset_x[3] = {0, a / 2, 0}, offset_y[3] = {0, a / (2 * std::sqrt(3.0)), a / std::sqrt(3.0)};
  scene::WallSpec box;
  box.kind = scene::WallSpec::Kind::box;
  box.lo = {0, 0, 0};
  box.hi = {real(x0 + nx * a + r + gap), real(y0 + (ny - 1) * row + a / std::sqrt(3.0) + r + gap),
            real(z0 + (layers - 1) * dz + 5 * r)};
  s.walls.push_back(box);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> jitter(-0.001 * r, 0.001 * r);
  scene::GeneratedParticles g;
  g.position.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t x = i % nx, y = (i / nx) % ny, k = i / (nx * ny);
    g.position.push_back({real(x0 + x * a + (y % 2) * a / 2 + offset_x[k % 3] + jitter(rng)),
                          real(y0 + y * row + offset_y[k % 3] + jitter(rng)), real(z0 + k * dz)});
    g.velocity.push_back({});
    g.radius.push_back(real(r));
    g.material.push_back(0);
  }
  return {s, g};
}

// The settling scene: 25 layers on a loose lattice (2.02 r in the plane),
// friction 0.5 and no rolling resistance, stepped from the lattice; the
// timed steps start once the in-plane gaps have closed (the dense phase).
constexpr Lattice kSettleLattice{25, 2.02, false};
constexpr int kSettleWarmup = 40;

std::string default_cache_dir() {
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  if (xdg != nullptr && *xdg != '\0') return std::string(xdg) + "/marbles";
  const char* home = std::getenv("HOME");
  if (home != nullptr && *home != '\0') return std::string(home) + "/.cache/marbles";
  return ".marbles-cache";
}

// Steps without a quench before a pile counts as settled (settle_pile).
constexpr int kFreeSteps = 50;

// How the pile was made (from the file when it came from the cache).
struct SettleInfo {
  bool cached = false;
  std::string backend;
  std::uint64_t steps = 0;
  double seconds = 0;
  std::uint64_t quenched_until = 0;  // the step after which the velocities were last zeroed
  double bound = 0;          // J a sphere: the settle's bound (--settle-ke)
  double ke_per_sphere = 0;  // J
  double max_overlap = 0;    // of a radius, at the last settle step
  // At rest by itself below its bound (settle_pile's rule), not cut off by
  // the step budget.
  bool settled() const { return ke_per_sphere < bound && steps >= quenched_until + kFreeSteps; }
};

struct PileState {
  World world;
  SettleInfo settle;
};

template <class T>
void put(std::ostream& f, const T& v) {
  f.write(reinterpret_cast<const char*>(&v), sizeof v);
}
template <class T>
bool get(std::istream& f, T& v) {
  return static_cast<bool>(f.read(reinterpret_cast<char*>(&v), sizeof v));
}

// The file: magic, version, sizeof(real), N, how it settled (backend, steps,
// the step of the last quench, the bound, seconds, kinetic energy per
// sphere, largest overlap), then positions, velocities, angular velocities
// (x y z per sphere) and radii, all as `real`, then the FNV-1a of all before
// it (a file cut short or with flipped bytes is settled again, not used).
void save_pile(const std::string& path, const World& w, const SettleInfo& info) {
  namespace fs = std::filesystem;
  fs::create_directories(fs::path(path).parent_path());
  std::ostringstream f(std::ios::binary);
  {
    f.write(kPileMagic, sizeof kPileMagic);
    put(f, kPileVersion);
    put(f, static_cast<std::uint32_t>(sizeof(real)));
    put(f, static_cast<std::uint64_t>(w.size()));
    char backend[8] = {};
    std::snprintf(backend, sizeof backend, "%s", info.backend.c_str());
    f.write(backend, sizeof backend);
    put(f, info.steps);
    put(f, info.quenched_until);
    put(f, info.bound);
    put(f, info.seconds);
    put(f, info.ke_per_sphere);
    put(f, info.max_overlap);
    for (const auto* v : {&w.position, &w.velocity, &w.angular_velocity})
      for (const Vec3& p : *v) {
        put(f, p.x);
        put(f, p.y);
        put(f, p.z);
      }
    for (real x : w.radius) put(f, x);
  }
  std::string bytes = std::move(f).str();  // the buffer itself, not a copy
  const std::uint64_t sum = fnv1a(bytes.data(), bytes.size());
  bytes.append(reinterpret_cast<const char*>(&sum), sizeof sum);
  render::write_file_atomic(path, bytes);  // a temporary renamed: a reader sees the old file or the whole new one
}

// The cached pile, or nothing when the file is missing, of another version,
// precision or N, short, damaged (its checksum) or holding a state no settle
// writes (not finite, a radius not above zero).
std::optional<PileState> load_pile(const std::string& path, std::size_t n, const Lattice& lattice) {
  if (not_a_plain_file(path)) return std::nullopt;
  std::string bytes;
  {
    std::ifstream file(path, std::ios::binary);
    if (!file) return std::nullopt;
    bytes.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  }
  std::uint64_t sum = 0;
  if (bytes.size() < sizeof sum) return std::nullopt;
  std::memcpy(&sum, bytes.data() + bytes.size() - sizeof sum, sizeof sum);
  bytes.resize(bytes.size() - sizeof sum);
  if (sum != fnv1a(bytes.data(), bytes.size())) return std::nullopt;
  std::istringstream f(std::move(bytes), std::ios::binary);  // the bytes themselves, not a copy
  char magic[8];
  std::uint32_t version = 0, real_bytes = 0;
  std::uint64_t count = 0;
  char backend[8];
  if (!f.read(magic, sizeof magic) || std::memcmp(magic, kPileMagic, sizeof magic) != 0) return std::nullopt;
  if (!get(f, version) || version != kPileVersion || !get(f, real_bytes) || real_bytes != sizeof(real)) return std::nullopt;
  if (!get(f, count) || count != n || !f.read(backend, sizeof backend)) return std::nullopt;
  SettleInfo info;
  info.cached = true;
  info.backend.assign(backend, strnlen(backend, sizeof backend));
  if (!get(f, info.steps) || !get(f, info.quenched_until) || !get(f, info.bound) || !get(f, info.seconds) ||
      !get(f, info.ke_per_sphere) || !get(f, info.max_overlap))
    return std::nullopt;
  auto [s, g] = pile(n, lattice);  // materials, masses; positions replaced below
  std::vector<Vec3> arrays[3];
  for (auto& v : arrays) {
    v.resize(n);
    for (Vec3& p : v)
      if (!get(f, p.x) || !get(f, p.y) || !get(f, p.z)) return std::nullopt;
  }
  for (real& x : g.radius)
    if (!get(f, x) || !(x > 0) || !std::isfinite(x)) return std::nullopt;
  if (f.peek() != std::char_traits<char>::eof()) return std::nullopt;  // bytes past the fields
  g.position = arrays[0];
  g.velocity = arrays[1];
  World w = make_world(s, g);
  w.angular_velocity = arrays[2];
  if (w.first_out_of_range() < w.size()) return std::nullopt;  // not finite, or a square past the range
  return PileState{std::move(w), info};
}

// Steps the loose lattice on `backend` until it rests (SettleInfo::settled)
// or the budget is spent; progress on `log`. Until the kinetic energy per
// sphere is first below options.settle_ke (read every 10 steps, from step 50,
// when the top layer has landed), the velocities are set to zero every
// options.settle_quench steps once the energy has been read (a quench): the
// energy read is then what the pile gains from rest in that many steps, and
// no fast sphere widens every sphere's contact reach for long (the settle
// costs a fraction of the steps and of the time per step). A quenched pile
// below the bound need not be at rest (a frictionless bed still slides into
// a denser packing once let go: KE/sphere 10^-8 -> 10^-6 J in 20 steps), so
// the quenches then stop, and the pile is settled when the energy is below
// the bound again kFreeSteps steps or more after the last quench. No quench
// on the budget's last step: the file keeps the energy it reports.
PileState settle_pile(std::size_t n, const Lattice& lattice, broadphase::Backend backend,
                      const StepBenchOptions& options, std::ostream& log) {
  auto [s, g] = pile(n, lattice);
  Simulation sim(s, make_world(s, g), backend);
  const int check = 10, min_steps = 50;
  SettleInfo info;
  info.backend = sim.backend_name();
  info.bound = options.settle_ke;
  const auto t0 = std::chrono::steady_clock::now();
  double ke = 0;
  log << "pile N = " << n << ": settling on " << info.backend << " (budget " << options.settle_steps
      << " steps, until KE/sphere < " << options.settle_ke << " J";
  if (options.settle_quench > 0)
    log << ", velocities zeroed every " << options.settle_quench << " steps until then, then " << kFreeSteps
        << " steps or more without";
  log << ")\n";
  bool quenching = options.settle_quench > 0;
  int last_quench = 0;  // the step after which the velocities were last zeroed
  for (int k = 1; k <= options.settle_steps; ++k) {
    sim.step();
    if (sim.non_finite()) throw RuntimeFailure("pile N = " + std::to_string(n) + ": non-finite state while settling");
    const bool quench_step = quenching && k % options.settle_quench == 0 && k != options.settle_steps;
    if (k % check != 0 && !quench_step && k != options.settle_steps) continue;
    ke = sim.world().kinetic_energy() / static_cast<double>(n);
    info.steps = static_cast<std::uint64_t>(k);
    info.quenched_until = static_cast<std::uint64_t>(last_quench);
    info.ke_per_sphere = ke;
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (k % (5 * check) == 0)
      log << "  step " << k << ": KE/sphere " << ke << " J, max overlap " << 100 * sim.last_step().max_overlap
          << " %, " << secs << " s" << (quenching ? "" : " (no quench)") << "\n";
    if (k >= min_steps && info.settled()) break;
    const bool below = k >= min_steps && ke < options.settle_ke;
    if (below && quenching) {
      quenching = false;  // from here the pile comes to rest by itself, or is not settled
      log << "  step " << k << ": below the bound with quenches; now without\n";
    }
    if (quench_step && quenching) {
      World& w = sim.edit_world();
      std::fill(w.velocity.begin(), w.velocity.end(), Vec3{});
      std::fill(w.angular_velocity.begin(), w.angular_velocity.end(), Vec3{});
      last_quench = k;
    }
  }
  info.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  info.max_overlap = sim.last_step().max_overlap;
  log << "pile N = " << n << ": " << (info.settled() ? "settled" : "step budget spent") << " after " << info.steps
      << " steps (the last " << info.steps - info.quenched_until << " without a quench) in " << info.seconds
      << " s, KE/sphere " << ke << " J, max overlap " << 100 * info.max_overlap << " %\n";
  World w = sim.world();
  return {std::move(w), info};
}

// --- the spheres' order ---------------------------------------------------------

// Bits of v spread to every third bit (v < 2^21).
std::uint64_t spread_bits(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

}  // namespace

World in_sphere_order(World w, const std::string& how) {
  if (how == "made" || w.size() == 0) return w;
  std::vector<std::uint32_t> order(w.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<std::uint32_t>(i);
  if (how == "shuffled") {
    std::mt19937_64 rng(1);
    std::shuffle(order.begin(), order.end(), rng);
  } else if (how == "morton") {
    const broadphase::Bounds b = broadphase::bounds_of({w.position.data(), w.radius.data(), w.size()});
    const Vec3 lo = b.lo;
    const double cell = 2.0 * std::max<double>(b.r_max, 1e-30);
    std::vector<std::uint64_t> key(w.size());
    for (std::size_t i = 0; i < w.size(); ++i) {
      auto at = [&](real x, real x0) {
        return static_cast<std::uint64_t>(std::min(2097151.0, std::floor((double(x) - double(x0)) / cell)));
      };
      key[i] = spread_bits(at(w.position[i].x, lo.x)) | spread_bits(at(w.position[i].y, lo.y)) << 1 |
               spread_bits(at(w.position[i].z, lo.z)) << 2;
    }
    std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return key[a] < key[b]; });
  } else if (how == "cells") {
    order = cell_order(w);
  } else {
    throw InputError({}, "--sphere-order", "unknown order '" + how + "' (made, shuffled, morton or cells)");
  }
  return permuted(w, order);
}

namespace {

// --- the measurements ----------------------------------------------------------

struct Row {
  std::size_t n = 0;
  double step_ms = 0, step_min_ms = 0, pairs = 0, contacts = 0;
  double broadphase_ms = 0;        // median of the profiled steps
  double contacts_per_sphere = 0;  // contacts / substeps / N, mean over the timed steps
  double coordination = 0;         // contacts a sphere takes part in (2 per sphere pair, 1 per wall), last substep
  std::uint32_t colours = 0;       // most of a timed step
  double overflow = 0;             // median over the timed steps
  double max_overlap_pct = 0;      // largest of the timed steps, % of a radius
  double projection_sweeps = 0;    // per substep, mean over the timed steps (the projection sweeps until settled)
  std::uint64_t pair_redos = 0;    // substeps of the timed steps whose contacts were found again (CUDA: rooms)
  std::uint64_t grid_replans = 0;  // of those, the broad phase's grid outgrew its plan (CUDA)
  std::uint64_t grid_shrinks = 0;  // substeps whose grid fit a plan larger than it asks: planned smaller (CUDA)
  std::uint64_t buffer_trims = 0;  // buffers freed at a step's start, held beyond their need (CUDA)
  std::uint64_t unwaited_substeps = 0;  // substeps of the timed steps that waited for nothing (CUDA: one wait a step)
  std::uint64_t undone_substeps = 0;    // of those, outgrew a room: put back and done again with waits (CUDA)
  std::uint32_t undo_causes = 0;        // what they outgrew: UndoCause bits, or-ed (CUDA)
  // Substeps of the warm-up and timed steps whose records kept whole impact
  // words (CUDA: a contact was an impact candidate; the records' memory is
  // then sized for them until a trim finds them gone: buffer_trims).
  std::uint64_t impact_substeps = 0;
  // One-launch stages (solve, projection, impact stage) of the timed steps
  // that ran as one cluster (CUDA on sm_90: their widest colour small).
  std::uint64_t cluster_stages = 0;
  // Launches of the timed steps that walked a run of small ranges of the
  // solve in one block (CUDA, a launch per colour: RangeGroup).
  std::uint64_t range_groups = 0;
  double ke_per_sphere = 0;        // J, after the timed and profiled steps (a settled pile stays still)
  std::uint64_t rollbacks = 0;     // steps the watchdog undid and redid (--watchdog on), of all the steps run here
  std::optional<double> watch_ke_per_sphere;  // J, the watch's own figure at the last step's end (--watchdog on)
  double bytes_per_step = 0;       // median host<->device bytes
  double device_bytes_per_sphere = 0;  // held after the last timed step
  // The most held after any warm-up or timed step: a substep's transients
  // (impact words and levels while some contact is an impact candidate)
  // stay until a trim frees them, so the figure after the last step may
  // miss them, or keep them after they are gone.
  double device_peak_bytes_per_sphere = 0;
  std::vector<DeviceBytes> device_buffers;  // by part (StepBackend::device_buffers)
  std::optional<double> launches, waits;  // per step, medians of the counted steps (none where nothing counts)
  // The host's time within each CUDA runtime function, per step (means of
  // the counted steps, most time first), and those steps' wall time.
  struct HostCall {
    std::string function;
    double calls = 0, us = 0;
  };
  std::vector<HostCall> host_calls;
  std::optional<double> counted_ms;
  std::optional<double> busy_ms;          // per step, the device at work: median of the traced steps
  std::optional<double> traced_ms;        // per step, the traced steps' wall time (tracing slows the host)
  // The traced steps' device time by kernel (sets and copies each as one),
  // per step (means of those steps, most time first).
  struct KernelRow {
    std::string kernel;
    double launches = 0, us = 0;
  };
  std::vector<KernelRow> kernels;
  std::optional<double> idle_ms() const { return busy_ms ? std::optional(std::max(0.0, step_ms - *busy_ms)) : std::nullopt; }
  double verb_ms[static_cast<int>(Verb::count)] = {};  // medians of the profiled steps
  std::optional<SettleInfo> settle;
};

Row measure(Simulation& sim, std::size_t n, int warmup, int repeats) {
  Row row;
  row.n = n;
  // Device bytes held after a step (read outside the timed interval): the
  // last step's and the most.
  std::size_t last = 0, peak = 0;
  auto held = [&] {
    last = sim.device_bytes();
    peak = std::max(peak, last);
  };
  for (int k = 0; k < warmup; ++k) {
    sim.step();
    row.impact_substeps += sim.last_step().impact_words;
    held();
  }
  std::vector<double> step_ms, overflow, bytes;
  double max_overlap = 0;
  const bool on_device = sim.backend_name() == "cuda";  // the CPU backend touches no device
  if (on_device) profiled_steps(true);  // a profiler started with its collection off sees the timed steps only
  for (int k = 0; k < repeats; ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    sim.step();
    step_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    held();
    const StepCounters& c = sim.last_step();
    row.pairs += static_cast<double>(c.candidate_pairs) / repeats;
    row.contacts += static_cast<double>(c.contacts) / repeats;
    row.colours = std::max(row.colours, c.colours);
    overflow.push_back(static_cast<double>(c.overflow));
    bytes.push_back(static_cast<double>(c.bytes_copied));
    max_overlap = std::max(max_overlap, static_cast<double>(c.max_overlap));
    row.projection_sweeps += static_cast<double>(c.projection_sweeps) / sim.substeps() / repeats;
    row.pair_redos += c.pair_redos;
    row.grid_replans += c.grid_replans;
    row.grid_shrinks += c.grid_shrinks;
    row.buffer_trims += c.buffer_trims;
    row.unwaited_substeps += c.unwaited_substeps;
    row.undone_substeps += c.undone_substeps;
    row.undo_causes |= c.undo_causes;
    row.impact_substeps += c.impact_words;
    row.cluster_stages += c.cluster_stages;
    row.range_groups += c.range_groups;
  }
  if (on_device) profiled_steps(false);  // each step ends with a wait for its flags: nothing of it is still running
  if (sim.non_finite()) throw RuntimeFailure("N = " + std::to_string(n) + ": non-finite state in the timed steps");
  row.step_ms = median(step_ms);
  row.step_min_ms = *std::min_element(step_ms.begin(), step_ms.end());
  row.contacts_per_sphere = row.contacts / sim.substeps() / static_cast<double>(n);
  row.overflow = median(overflow);
  row.max_overlap_pct = 100 * max_overlap;
  row.bytes_per_step = median(bytes);
  row.device_bytes_per_sphere = static_cast<double>(last) / static_cast<double>(n);
  row.device_peak_bytes_per_sphere = static_cast<double>(peak) / static_cast<double>(n);
  row.device_buffers = sim.device_buffers();

  // Kernel launches and host waits (CUDA backend): a few more steps, counted apart, since
  // counting slows every CUDA call.
  if (on_device) {
    ApiCounter counter;
    if (counter.counting()) {
      std::vector<double> launches, waits;
      ApiCounts before = counter.counts();
      const int counted = std::min(repeats, 5);
      const auto t0 = std::chrono::steady_clock::now();
      for (int k = 0; k < counted; ++k) {
        sim.step();
        const ApiCounts after = counter.counts();
        launches.push_back(static_cast<double>(after.launches - before.launches));
        waits.push_back(static_cast<double>(after.waits - before.waits));
        before = after;
      }
      row.counted_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() / counted;
      row.launches = median(launches);
      row.waits = median(waits);
      // The counter began just before these steps: its times are theirs (most first).
      for (const ApiTime& t : counter.host_times())
        row.host_calls.push_back({t.function, static_cast<double>(t.calls) / counted, 1e-3 * t.ns / counted});
    }
  }
  // The device's busy time a step (CUDA backend): the union of a step's
  // kernels, copies and sets, in a few more steps traced apart. Tracing adds
  // to each launch on the host, not to the work on the device, so the idle
  // time is the untraced steps' median less the busy time.
  if (on_device) {
    DeviceTimeline timeline;
    if (timeline.tracing()) {
      std::vector<double> busy, wall;
      const int traced = std::min(repeats, 5);
      const std::uint64_t first = timeline.now();
      for (int k = 0; k < traced; ++k) {
        const std::uint64_t t0 = timeline.now();
        sim.step();  // ends with its wait for the flags: its work is done
        const std::uint64_t t1 = timeline.now();
        busy.push_back(static_cast<double>(timeline.busy_ns(t0, t1)) * 1e-6);
        wall.push_back(static_cast<double>(t1 - t0) * 1e-6);
      }
      const std::uint64_t last = timeline.now();
      if (timeline.complete()) {  // else a record was dropped: no figure rather than a short one
        row.busy_ms = median(busy);
        row.traced_ms = median(wall);
        for (const KernelTime& k : timeline.kernels(first, last))
          row.kernels.push_back({k.kernel, static_cast<double>(k.launches) / traced, 1e-3 * k.ns / traced});
      }
    }
  }

  // Per verb and the broad phase: a separate run, since profiling waits for
  // each verb (and the CUDA broad phase times its stages only then).
  sim.set_profiling(true);
  std::vector<double> verb[static_cast<int>(Verb::count)], bp_ms;
  for (int k = 0; k < repeats; ++k) {
    sim.step();
    for (int v = 0; v < static_cast<int>(Verb::count); ++v) verb[v].push_back(sim.last_step().verb_ms[v]);
    bp_ms.push_back(sim.last_step().broadphase_ms);
  }
  sim.set_profiling(false);
  for (int v = 0; v < static_cast<int>(Verb::count); ++v) row.verb_ms[v] = median(verb[v]);
  row.broadphase_ms = median(bp_ms);

  std::size_t touches = 0;
  for (const narrowphase::Contact& c : sim.contacts()) touches += narrowphase::is_wall(c.b) ? 1 : 2;
  row.coordination = static_cast<double>(touches) / static_cast<double>(n);
  row.ke_per_sphere = sim.world().kinetic_energy() / static_cast<double>(n);
  row.rollbacks = sim.rollbacks();
  if (sim.watchdog()) row.watch_ke_per_sphere = sim.last_step().kinetic_energy / static_cast<double>(n);
  return row;
}


// The settled pile of N spheres the options name and its scene (the box):
// loaded from the cache, or settled on the options' backend and saved there
// where it is missing, was asked for again (--rebuild) or ran out of a
// smaller budget.
std::pair<scene::Scene, PileState> pile_start(const StepBenchOptions& options, std::size_t n, std::ostream& log) {
  const broadphase::Backend backend = options.backend == "cuda" ? broadphase::Backend::cuda : broadphase::Backend::cpu;
  Lattice lattice;
  lattice.rolling = options.rolling;
  lattice.friction = options.friction;
  // The box (the lattice is cheap next to the steps).
  scene::Scene box = pile(n, lattice).first;
  const std::string path = pile_cache_path(options.cache_dir, n, options.rolling, options.friction);
  std::optional<PileState> state = options.rebuild ? std::nullopt : load_pile(path, n, lattice);
  // A pile whose budget ran out is settled again where this run allows more steps.
  if (state && !state->settle.settled() && state->settle.steps < static_cast<std::uint64_t>(options.settle_steps)) {
    log << "pile N = " << n << ": " << path << " did not settle in " << state->settle.steps
        << " steps; settling again with a budget of " << options.settle_steps << "\n";
    state.reset();
  }
  // A settled pile whose energy is not below this run's bound (one settled
  // to a looser --settle-ke) is settled again, to this run's bound.
  bool keep_cached = false;  // a settled pile, not to be replaced by one that runs out of budget
  if (state && state->settle.settled() && !(state->settle.ke_per_sphere < options.settle_ke)) {
    log << "pile N = " << n << ": " << path << " rests at KE/sphere " << state->settle.ke_per_sphere
        << " J, not below this run's bound " << options.settle_ke << " J; settling again\n";
    state.reset();
    keep_cached = true;
  }
  if (state) {
    const SettleInfo& settle = state->settle;
    log << "pile N = " << n << ": loaded " << path << " (" << (settle.settled() ? "settled" : "NOT settled")
        << " on " << settle.backend << " in " << settle.steps << " steps, " << settle.seconds << " s, KE/sphere "
        << settle.ke_per_sphere << " J)\n";
    return {std::move(box), std::move(*state)};
  }
  // A cache that cannot be written is found before the settle, not after
  // it: the pile is settled for this run alone (a warning), and a save that
  // fails all the same is a warning too.
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path folder = fs::path(path).parent_path();
  fs::create_directories(folder, ec);
  if (!ec) {  // a file made there and removed: access(W_OK) says yes to root where nothing can be made (/proc)
    const fs::path probe = render::temp_path_beside(folder / "probe");
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0600);
    if (fd < 0) ec = std::error_code(errno, std::generic_category());
    else ::close(fd), ::unlink(probe.c_str());
  }
  if (ec)
    log << "warning: cannot cache the settled pile in " << folder.string() << " (" << ec.message()
        << "): settling it for this run alone\n";
  PileState settled = settle_pile(n, lattice, backend, options, log);
  if (!ec && keep_cached && !settled.settle.settled()) {
    log << "pile N = " << n << ": this settle ran out of its budget; the settled pile in " << path << " is kept\n";
  } else if (!ec) {
    try {
      save_pile(path, settled.world, settled.settle);
      log << "pile N = " << n << ": saved " << path << "\n";
    } catch (const std::exception& e) {
      log << "warning: the settled pile was not cached: " << e.what() << "\n";
    }
  }
  return {std::move(box), std::move(settled)};
}

// The pile's name for its terms, in its cache file's and scene file's names:
// "" (friction and rolling resistance), "-friction" (friction alone) or
// "-frictionless".
const char* pile_terms(bool rolling, bool friction) {
  return !friction ? "-frictionless" : rolling ? "" : "-friction";
}

// Untimed steps before the timed ones: --warmup, or 5 for the pile (its
// warm starts rebuilt), 40 for the settle (into the dense phase), 2 for the gas.
int warmup_steps(const StepBenchOptions& options) {
  if (options.warmup >= 0) return options.warmup;
  return options.scene == "pile" ? 5 : options.scene == "settle" ? kSettleWarmup : 2;
}

int threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

// bench_start, and the pile's settle (loaded or made) in `settle`.
std::pair<scene::Scene, World> bench_start(const StepBenchOptions& options, std::size_t n, std::ostream& log,
                                           std::optional<SettleInfo>& settle) {
  std::pair<scene::Scene, World> start;
  if (options.scene == "pile") {
    auto [box, state] = pile_start(options, n, log);
    settle = state.settle;
    start = {std::move(box), std::move(state.world)};
  } else {
    auto made = [](std::pair<scene::Scene, scene::GeneratedParticles> sg) {
      World w = make_world(sg.first, sg.second);
      return std::pair<scene::Scene, World>{std::move(sg.first), std::move(w)};
    };
    if (options.scene == "settle") start = made(pile(n, kSettleLattice));
    else if (options.scene == "gas") start = made(gas(n, options.effects));
    else throw InputError({}, "--scene", "unknown scene '" + options.scene + "'");
  }
  start.first.solver.integrator = options.integrator;  // the timed steps' (the pile settled as cached)
  return start;
}

}  // namespace

std::pair<scene::Scene, World> bench_start(const StepBenchOptions& options, std::size_t n, std::ostream& log) {
  std::optional<SettleInfo> settle;
  return bench_start(options, n, log, settle);
}

std::string write_bench_scene(const StepBenchOptions& options, std::size_t n, const std::string& dir,
                              std::ostream& log) {
  namespace fs = std::filesystem;
  const char* terms = options.scene != "pile" ? "" : pile_terms(options.rolling, options.friction);
  const std::string stem = "bench-" + options.scene + terms + "-n" + std::to_string(n);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InputError({}, "--write-scene", "cannot make the folder '" + dir + "': " + ec.message());
  const auto [s, w] = bench_start(options, n, log);
  auto vec = [](const Vec3& v) { return "[" + shortest(v.x) + ", " + shortest(v.y) + ", " + shortest(v.z) + "]"; };
  auto number = [](double v) { return shortest(v); };

  const bool spins = std::any_of(w.angular_velocity.begin(), w.angular_velocity.end(),
                                 [](const Vec3& v) { return v.x != 0 || v.y != 0 || v.z != 0; });
  std::ostringstream csv;
  csv << "# the spheres of " << stem << ".yaml: x, y, z, r in m, vx, vy, vz in m/s"
      << (spins ? ", wx, wy, wz in rad/s" : "") << "\nx,y,z,r,vx,vy,vz" << (spins ? ",wx,wy,wz" : "") << "\n";
  for (std::size_t i = 0; i < w.size(); ++i) {
    if (w.inv_mass[i] == 0) throw std::logic_error("write_bench_scene: a bench scene has no fixed spheres");
    csv << shortest(w.position[i].x) << ',' << shortest(w.position[i].y) << ',' << shortest(w.position[i].z) << ','
        << shortest(w.radius[i]) << ',' << shortest(w.velocity[i].x) << ',' << shortest(w.velocity[i].y) << ','
        << shortest(w.velocity[i].z);
    if (spins)
      csv << ',' << shortest(w.angular_velocity[i].x) << ',' << shortest(w.angular_velocity[i].y) << ','
          << shortest(w.angular_velocity[i].z);
    csv << '\n';
  }

  const scene::Material& m = s.materials.at(0);
  const int steps = warmup_steps(options) + options.repeats;
  std::ostringstream yaml;
  const std::string flags = options.scene != "pile" ? "" : !options.friction ? " --friction off --rolling off"
                                                       : !options.rolling    ? " --rolling off"
                                                                             : "";
  yaml << "# The scene `marbles bench step --scene " << options.scene << flags << " --n " << n
       << "` starts from; run for its warm-up and timed steps.\n"
       << "format: 1\nname: " << stem << "\n"
       << "time: {duration: " << number(steps * s.time.dt) << ", dt: " << number(s.time.dt)
       << ", substeps: " << s.time.substeps << "}\n"
       << "solver: {iterations: " << s.solver.iterations
       << (s.solver.integrator != "symplectic_euler" ? ", integrator: " + s.solver.integrator : std::string())
       << "}\n"
       << "effects: [";
  for (std::size_t k = 0; k < s.effects.size(); ++k) yaml << (k ? ", " : "") << scene::effect_name(s.effects[k]);
  yaml << "]\ngravity: " << vec(s.gravity) << "\n";
  if (s.has(scene::Effect::drag))
    yaml << "drag: {linear: " << number(s.drag) << ", quadratic: " << number(s.drag_quadratic) << "}\n";
  yaml << "materials:\n  " << m.name << ": {density: " << number(m.density) << ", restitution: "
       << number(m.restitution) << ", friction: " << number(m.friction) << ", rolling_friction: "
       << number(m.rolling_friction) << ", twisting_friction: " << number(m.twisting_friction) << "}\n"
       << "walls:\n";
  for (const scene::WallSpec& w : s.walls) {
    if (w.kind != scene::WallSpec::Kind::box) throw std::logic_error("write_bench_scene: a bench scene's wall is a box");
    yaml << "  - box: {min: " << vec(w.lo) << ", max: " << vec(w.hi) << "}\n    material: " << m.name << "\n";
  }
  yaml << "particles:\n  - csv: {path: " << stem << ".csv}\n    material: " << m.name << "\n";

  const fs::path base = fs::path(dir) / stem;
  render::write_file_atomic(base.string() + ".csv", csv.str());
  render::write_file_atomic(base.string() + ".yaml", yaml.str());
  return base.string() + ".yaml";
}

std::string pile_cache_path(const std::string& cache_dir, std::size_t n, bool rolling, bool friction) {
  const std::string dir = cache_dir.empty() ? default_cache_dir() : cache_dir;
  const char* terms = pile_terms(rolling, friction);
  return dir + "/pile-v" + std::to_string(kPileVersion) + terms + "-n" + std::to_string(n) + "-" + kRealName + ".bin";
}

int run_step_bench(const StepBenchOptions& options, std::ostream& out) {
  const broadphase::Backend backend = options.backend == "cuda" ? broadphase::Backend::cuda : broadphase::Backend::cpu;
  const bool is_pile = options.scene == "pile", is_settle = options.scene == "settle";
  if (!is_pile && !is_settle && options.scene != "gas")
    throw InputError({}, "--scene", "unknown scene '" + options.scene + "'");
  if (!options.rolling && !is_pile) throw InputError({}, "--rolling", "'off' is for --scene pile only");
  if (!options.friction && !is_pile) throw InputError({}, "--friction", "'off' is for --scene pile only");
  if (!options.friction && options.rolling)
    throw InputError({}, "--friction", "'off' makes the pile without rolling resistance too: give --rolling off");
  if (!options.write_scene.empty()) {
    for (std::size_t n : options.n)
      out << write_bench_scene(options, n, options.write_scene, std::cerr) << " (and its .csv)\n";
    return 0;
  }
  const int warmup = warmup_steps(options);
  std::ostream& log = std::cerr;
  std::vector<Row> rows;
  // Each N's timed steps: the benchmark's scene and world (bench_start),
  // in the order and with the numbering the options ask for.
  for (std::size_t n : options.n) {
    std::optional<SettleInfo> settle;
    auto [s, w] = bench_start(options, n, log, settle);
    s.solver.renumber = options.renumber;
    Simulation sim(s, in_sphere_order(std::move(w), options.sphere_order), backend);
    sim.set_watchdog(options.watchdog);
    rows.push_back(measure(sim, n, warmup, options.repeats));
    rows.back().settle = settle;
  }
  constexpr int kVerbs = static_cast<int>(Verb::count);
  // The CPU sweep's SIMD lanes (solver.hpp: SweepLanes); none on the GPU.
  const char* lanes = options.backend == "cpu" ? narrowphase::name(narrowphase::best_lanes()) : nullptr;
  if (options.json) {
    nlohmann::ordered_json doc{{"benchmark", "step"}, {"backend", options.backend}, {"scene", options.scene},
                               {"precision", kRealName}, {"threads", threads()},
                               {"friction", is_pile ? options.friction
                                                    : is_settle || std::count(options.effects.begin(),
                                                                              options.effects.end(), "friction") > 0},
                               {"rolling_resistance", is_pile ? options.rolling
                                                              : !is_settle && std::count(options.effects.begin(),
                                                                                         options.effects.end(),
                                                                                         "rolling_resistance") > 0},
                               {"cpu_lanes", lanes ? nlohmann::ordered_json(lanes) : nlohmann::ordered_json()},
                               {"repeats", options.repeats}, {"warmup", warmup},
                               {"sphere_order", options.sphere_order}, {"renumber", options.renumber},
                               {"integrator", options.integrator},
                               {"watchdog", options.watchdog},
                               {"launches_per_step", nlohmann::ordered_json::array()},
                               {"results", nlohmann::ordered_json::array()}};
    auto count = [](const std::optional<double>& v) {
      return v ? nlohmann::ordered_json(*v) : nlohmann::ordered_json();
    };
    for (const Row& r : rows) doc["launches_per_step"].push_back(count(r.launches));  // one per N, as in results
    for (const Row& r : rows) {
      nlohmann::ordered_json row{{"n", r.n},
                                 {"step_ms_median", r.step_ms},
                                 {"step_ms_min", r.step_min_ms},
                                 {"broadphase_ms_median", r.broadphase_ms},
                                 {"candidate_pairs", r.pairs},
                                 {"contacts", r.contacts},
                                 {"contacts_per_sphere", r.contacts_per_sphere},
                                 {"coordination", r.coordination},
                                 {"colours", r.colours},
                                 {"overflow_median", r.overflow},
                                 {"max_overlap_pct", r.max_overlap_pct},
                                 {"projection_sweeps", r.projection_sweeps},
                                 {"pair_redos", r.pair_redos},
                                 {"grid_replans", r.grid_replans},
                                 {"grid_shrinks", r.grid_shrinks},
                                 {"buffer_trims", r.buffer_trims},
                                 {"unwaited_substeps", r.unwaited_substeps},
                                 {"undone_substeps", r.undone_substeps},
                                 {"undo_causes", undo_cause_names(r.undo_causes)},
                                 {"impact_word_substeps", r.impact_substeps},
                                 {"cluster_stages", r.cluster_stages},
                                 {"range_groups", r.range_groups},
                                 {"ke_per_sphere_J", r.ke_per_sphere},
                                 {"rollbacks", r.rollbacks},
                                 {"watch_ke_per_sphere_J", count(r.watch_ke_per_sphere)},
                                 {"bytes_per_step_median", r.bytes_per_step},
                                 {"device_bytes_per_sphere", r.device_bytes_per_sphere},
                                 {"device_peak_bytes_per_sphere", r.device_peak_bytes_per_sphere},
                                 {"launches_per_step", count(r.launches)},
                                 {"host_waits_per_step", count(r.waits)},
                                 {"device_busy_ms_per_step", count(r.busy_ms)},
                                 {"device_idle_ms_per_step", count(r.idle_ms())},
                                 {"traced_step_ms", count(r.traced_ms)},
                                 {"counted_step_ms", count(r.counted_ms)},
                                 {"host_calls_per_step", nlohmann::ordered_json::array()},
                                 {"kernels_per_step", nlohmann::ordered_json::array()},
                                 {"verb_ms", nlohmann::ordered_json::object()}};
      for (const Row::HostCall& c : r.host_calls)
        row["host_calls_per_step"].push_back({{"function", c.function}, {"calls", c.calls}, {"us", c.us}});
      for (const Row::KernelRow& k : r.kernels)
        row["kernels_per_step"].push_back({{"kernel", k.kernel}, {"launches", k.launches}, {"us", k.us}});
      for (int v = 0; v < kVerbs; ++v) row["verb_ms"][kVerbNames[v]] = r.verb_ms[v];
      row["device_bytes_per_sphere_by_part"] = nlohmann::ordered_json::object();
      for (const DeviceBytes& b : r.device_buffers)
        row["device_bytes_per_sphere_by_part"][b.name] = static_cast<double>(b.bytes) / static_cast<double>(r.n);
      if (r.settle)
        row["settle"] = {{"cached", r.settle->cached},          {"backend", r.settle->backend},
                         {"steps", r.settle->steps},            {"quenched_until", r.settle->quenched_until},
                         {"seconds", r.settle->seconds},
                         {"ke_per_sphere_J", r.settle->ke_per_sphere}, {"max_overlap_pct", 100 * r.settle->max_overlap},
                         {"bound_J", r.settle->bound}, {"settled", r.settle->settled()}};
      doc["results"].push_back(std::move(row));
    }
    out << json_text(doc);
    return 0;
  }
  out << "step benchmark (" << options.backend << ", " << kRealName << ", " << threads() << " thread(s), "
      << (lanes ? std::string("sweep lanes ") + lanes + ", " : "")
      << (is_pile ? std::string("settled pile (") + (options.friction ? "" : "no ") + "friction, " +
                        (options.rolling ? "" : "no ") + "rolling resistance, 10 iterations, dt 1 ms)"
          : is_settle ? "settling lattice (25 layers, friction, 10 iterations, dt 1 ms)"
                      : "gas at volume fraction 0.1")
      << (options.sphere_order != "made" ? ", spheres in " + options.sphere_order + " order" : std::string())
      << (options.renumber > 0 ? ", renumbered every " + std::to_string(options.renumber) + " steps" : std::string())
      << (options.watchdog ? ", watchdog on" : "")
      << (options.integrator != "symplectic_euler" ? ", " + options.integrator : std::string())
      << ", median of " << options.repeats << " steps after " << warmup << " warm-up)\n";
  out << std::setw(9) << "N" << std::setw(10) << "ms/step" << std::setw(9) << "min ms" << std::setw(9) << "bp ms"
      << std::setw(10) << "contacts" << std::setw(7) << "coord" << std::setw(8) << "colours" << std::setw(9)
      << "overflow" << std::setw(9) << "overlap%" << std::setw(7) << "proj" << std::setw(12) << "bytes/step"
      << std::setw(11) << "dev B/sph" << std::setw(11) << "peak B/sph" << std::setw(9) << "launches" << std::setw(7)
      << "waits" << std::setw(8) << "busy ms" << "\n";
  auto counted = [](const std::optional<double>& v) { return v ? std::to_string(std::lround(*v)) : std::string("-"); };
  auto milliseconds = [](const std::optional<double>& v) {
    char text[32] = "-";
    if (v) std::snprintf(text, sizeof text, "%.3f", *v);
    return std::string(text);
  };
  for (const Row& r : rows)
    out << std::setw(9) << r.n << std::fixed << std::setprecision(2) << std::setw(10) << r.step_ms << std::setw(9)
        << r.step_min_ms << std::setw(9) << r.broadphase_ms << std::setprecision(3) << std::setw(10)
        << r.contacts_per_sphere << std::setprecision(2) << std::setw(7) << r.coordination << std::setw(8)
        << r.colours << std::setprecision(0) << std::setw(9) << r.overflow << std::setprecision(3) << std::setw(9)
        << r.max_overlap_pct << std::setprecision(2) << std::setw(7) << r.projection_sweeps << std::setprecision(0)
        << std::setw(12) << r.bytes_per_step << std::setprecision(1)
        << std::setw(11) << r.device_bytes_per_sphere << std::setw(11) << r.device_peak_bytes_per_sphere
        << std::setw(9) << counted(r.launches) << std::setw(7)
        << counted(r.waits) << std::setw(8) << milliseconds(r.busy_ms) << "\n"
        << std::defaultfloat;
  out << "(contacts = contacts per sphere per substep; coord = contacts a sphere takes part in; overlap% = largest,\n"
         " of a radius; proj = projection sweeps per substep (until settled); bp ms: of the profiled steps;\n"
         " launches, waits = kernel launches and host waits per step, counted in separate steps;\n"
         " busy ms = the device's time a step in kernels, copies and sets, traced in separate steps\n"
         " dev B/sph = device memory held after the last timed step, peak B/sph = the most after any step\n"
         " (ms/step less busy ms: the device waiting on the host)\n"
         " (- where not counted))\n";
  if (options.watchdog)
    for (const Row& r : rows) out << "N = " << r.n << ": the watchdog rolled back " << r.rollbacks << " step(s)\n";
  for (const Row& r : rows) {
    if (r.host_calls.empty()) continue;
    double in_calls = 0;
    for (const Row::HostCall& c : r.host_calls) in_calls += c.us;
    out << "N = " << r.n << ", host time a step in CUDA runtime calls (counted steps, " << std::fixed
        << std::setprecision(3) << *r.counted_ms << " ms each): " << std::setprecision(0) << in_calls << " us;";
    for (std::size_t k = 0; k < std::min<std::size_t>(r.host_calls.size(), 6); ++k)
      out << (k ? "," : "") << " " << r.host_calls[k].function << " " << r.host_calls[k].calls << " calls "
          << r.host_calls[k].us << " us";
    out << std::defaultfloat << "\n";
  }
  out << "per verb, median ms of " << options.repeats << " profiled steps (profiling waits for each verb)\n";
  out << std::setw(20) << std::left << "verb" << std::right;
  for (const Row& r : rows) out << std::setw(11) << r.n;
  out << "\n";
  for (int v = 0; v < kVerbs; ++v) {
    out << std::setw(20) << std::left << kVerbNames[v] << std::right << std::fixed << std::setprecision(3);
    for (const Row& r : rows) out << std::setw(11) << r.verb_ms[v];
    out << "\n" << std::defaultfloat;
  }
  for (const Row& r : rows) {
    if (r.device_buffers.empty()) continue;
    out << "device B/sphere by part, N = " << r.n << ":" << std::fixed << std::setprecision(1);
    for (const DeviceBytes& b : r.device_buffers)
      if (b.bytes > 0) out << " " << b.name << " " << static_cast<double>(b.bytes) / static_cast<double>(r.n) << ";";
    out << "\n" << std::defaultfloat;
  }
  for (const Row& r : rows)
    if (r.settle)
      out << "pile N = " << r.n << ": " << (r.settle->cached ? "from the cache, " : "")
          << (r.settle->settled() ? "settled on " : "NOT settled (step budget spent) on ")
          << r.settle->backend << " in " << r.settle->steps << " steps, " << std::setprecision(3)
          << r.settle->seconds << " s, KE/sphere " << r.settle->ke_per_sphere << " J\n"
          << std::defaultfloat;
  return 0;
}

}  // namespace marbles::bench
