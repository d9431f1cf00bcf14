#include "bench/step_bench.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <numbers>
#include <ostream>
#include <random>
#include <sstream>

#include "core/error.hpp"
#include "sim/particles.hpp"
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
  if (options.json) {
    out << "{\"benchmark\": \"effects\", \"backend\": \"" << options.backend << "\", \"n\": " << options.n
        << ", \"volume_fraction\": " << options.volume_fraction << ", \"repeats\": " << options.repeats
        << ", \"results\": [\n";
    for (std::size_t k = 0; k < rows.size(); ++k)
      out << "  {\"pipeline\": \"" << configs[k].first << "\", \"step_ms_median\": " << rows[k].step_ms
          << ", \"contacts\": " << rows[k].contacts << ", \"us_per_contact\": "
          << 1e3 * rows[k].step_ms / std::max(1.0, rows[k].contacts) << "}" << (k + 1 < rows.size() ? "," : "") << "\n";
    out << "]}\n";
  }
  out << "effect cost (" << options.backend << ", " << kRealName << ", N = " << options.n << ", volume fraction "
      << options.volume_fraction << ", median of " << options.repeats << " steps)\n";
  out << std::setw(22) << std::left << "pipeline" << std::right << std::setw(12) << "step ms" << std::setw(10)
      << "x base" << std::setw(12) << "contacts" << std::setw(14) << "us/contact" << "\n";
  for (std::size_t k = 0; k < rows.size(); ++k)
    out << std::setw(22) << std::left << configs[k].first << std::right << std::fixed << std::setprecision(3)
        << std::setw(12) << rows[k].step_ms << std::setw(10) << std::setprecision(2)
        << rows[k].step_ms / rows[0].step_ms << std::setw(12) << std::setprecision(0) << rows[k].contacts
        << std::setw(14) << std::setprecision(3) << 1e3 * rows[k].step_ms / std::max(1.0, rows[k].contacts) << "\n"
        << std::defaultfloat;
  out << "(effects change the motion, hence the contact count: compare us/contact for the per-contact cost)\n";
  return 0;
}

int run_step_bench(const StepBenchOptions& options, std::ostream& out) {
  const broadphase::Backend backend = options.backend == "cuda" ? broadphase::Backend::cuda : broadphase::Backend::cpu;
  struct Row {
    std::size_t n;
    double step_ms, step_min_ms, broadphase_ms, pairs, contacts;
  };
  std::vector<Row> rows;
  for (std::size_t n : options.n) {
    auto [s, g] = gas(n, options.effects);
    Simulation sim(s, make_world(s, g), backend);
    const Timing t = time_steps(sim, 2, options.repeats);
    rows.push_back({n, t.step_ms, t.step_min_ms, t.broadphase_ms, t.pairs, t.contacts});
  }
  if (options.json) {
    out << "{\"benchmark\": \"step\", \"backend\": \"" << options.backend << "\", \"precision\": \"" << kRealName
        << "\", \"repeats\": " << options.repeats << ", \"results\": [\n";
    for (std::size_t k = 0; k < rows.size(); ++k) {
      const Row& r = rows[k];
      out << "  {\"n\": " << r.n << ", \"step_ms_median\": " << r.step_ms << ", \"step_ms_min\": " << r.step_min_ms
          << ", \"broadphase_ms_median\": " << r.broadphase_ms << ", \"candidate_pairs\": " << r.pairs
          << ", \"contacts\": " << r.contacts << "}" << (k + 1 < rows.size() ? "," : "") << "\n";
    }
    out << "]}\n";
  }
  out << "step benchmark (" << options.backend << ", " << kRealName << ", gas at volume fraction 0.1, median of "
      << options.repeats << " steps)\n";
  out << std::setw(10) << "N" << std::setw(14) << "step ms" << std::setw(14) << "min ms" << std::setw(16)
      << "broad phase ms" << std::setw(12) << "pairs" << std::setw(12) << "contacts" << "\n";
  for (const Row& r : rows)
    out << std::setw(10) << r.n << std::setw(14) << std::fixed << std::setprecision(2) << r.step_ms << std::setw(14)
        << r.step_min_ms << std::setw(16) << r.broadphase_ms << std::setw(12) << std::setprecision(0) << r.pairs
        << std::setw(12) << r.contacts << "\n"
        << std::defaultfloat;
  return 0;
}

}  // namespace marbles::bench
