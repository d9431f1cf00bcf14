#include "sim/simulation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <iterator>
#include <sstream>

#include "sim/scene.hpp"

namespace marbles {

Simulation::Simulation(const scene::Scene& scene, World world, broadphase::Backend backend,
                       broadphase::Algorithm algorithm)
    : m_model(std::make_unique<const StepModel>(compile_step_model(scene, algorithm))),
      m_backend(backend == broadphase::Backend::cuda ? make_cuda_step(*m_model, std::move(world))
                                                     : make_cpu_step(*m_model, std::move(world))) {}

std::string Simulation::describe_pipeline() const {
  const StepModel& m = *m_model;
  const narrowphase::SolverSettings& s = m.solver;
  std::ostringstream out;
  out << "pipeline (" << m.substeps << " substep" << (m.substeps > 1 ? "s" : "") << " of h = " << m.dt / m.substeps
      << " s per step, " << kRealName << ", " << (m_backend->name() == "cuda" ? "on the GPU" : "on the CPU") << "):\n";
  if (m.gravity) out << "  body forces    gravity (" << m.g.x << ", " << m.g.y << ", " << m.g.z << ") m/s^2\n";
  if (m.drag) out << "  body forces    air drag (linear " << m.drag_linear << " 1/s, quadratic " << m.drag_quadratic << " 1/m)\n";
  if (m.collisions) out << "  broad phase    " << m_backend->broad_phase()->name() << "\n";
  if (m.collisions) out << "  narrow phase   sphere-sphere\n";
  if (m.wall_contacts)
    out << "  narrow phase   sphere-wall (" << m.walls.planes.size() << " plane(s), " << m.walls.boxes.size()
        << " box(es), " << m.walls.cylinders.size() << " cylinder(s), " << m.walls.spheres.size() << " sphere(s))\n";
  if (m.collisions || m.wall_contacts) {
    if (!m.speculative) out << "  narrow phase   touching pairs only (speculative contacts off)\n";
    out << "  colouring      contacts into colours (no sphere twice in a colour)\n";
    out << "  contact solver " << s.iterations << " sequential-impulse sweeps, colour by colour: normal";
    if (s.friction) out << " + friction";
    if (s.rolling) out << " + rolling resistance";
    out << (s.restitution ? "; impacts with restitution" : "; plastic impacts (no restitution)")
        << (s.warm_start ? "; warm start" : "") << "\n";
  }
  out << (m.verlet ? "  integrate      velocity Verlet (gravity in half kicks around the drift)\n"
                   : "  integrate      symplectic Euler\n");
  if (m.collisions || m.wall_contacts) out << "  project        positions (overlap beyond slop)\n";
  return out.str();
}

void Simulation::step() {
  m_last_rollbacks.clear();
  const real overlap_before = m_last.max_overlap;
  if (m_watchdog) m_backend->keep_step_start();
  for (int retry = 0;; ++retry) {
    attempt(1 << retry);
    std::string broken = m_watchdog ? violation() : std::string();
    if (broken.empty() && m_watchdog && m_last.max_overlap > kWatchdogOverlap && overlap_before < kWatchdogOverlap / 2)
      broken = "overlap " + std::to_string(m_last.max_overlap) + " of a radius";
    if (broken.empty()) break;
    m_backend->undo_step();
    m_last.max_overlap = overlap_before;
    ++m_rollbacks;
    m_last_rollbacks.push_back(broken);
    if (retry == kWatchdogRetries)
      throw WatchdogFailure("watchdog: step " + std::to_string(m_steps + 1) + ": " + broken + " after " +
                            std::to_string(kWatchdogRetries) + " retries down to " +
                            std::to_string(m_model->substeps << kWatchdogRetries) + " substeps");
  }
  ++m_steps;
  m_time = m_steps * m_model->dt;
}

void Simulation::attempt(int split) {
  if ((split == 1 || m_fault_every_try) && m_fault_step == m_steps + 1)
    m_backend->edit_world().velocity.at(0).x = std::nan("");
  const real h = m_model->substep() / static_cast<real>(split);
  m_backend->begin_step();
  std::fill(std::begin(m_verb_ms), std::end(m_verb_ms), 0.0);
  for (int k = 0; k < m_model->substeps * split; ++k) substep(h);
  m_backend->end_step(m_last);
  std::copy(std::begin(m_verb_ms), std::end(m_verb_ms), m_last.verb_ms);
}

std::string Simulation::violation() {
  if (m_backend->non_finite())
    return "non-finite state (sphere " + std::to_string(m_backend->world().first_non_finite()) + ")";
  return {};
}

void Simulation::substep(real h) {
  StepBackend& b = *m_backend;
  run_verb(Verb::body_forces, [&] { b.apply_body_forces(h); });
  run_verb(Verb::find_contacts, [&] { b.find_contacts(h); });
  run_verb(Verb::colour_contacts, [&] { b.colour_contacts(); });
  run_verb(Verb::warm_start, [&] { b.warm_start(); });
  run_verb(Verb::solve_velocities, [&] { b.solve_velocities(h); });
  run_verb(Verb::integrate_positions, [&] { b.integrate_positions(h); });
  run_verb(Verb::project_positions, [&] { b.project_positions(); });
  run_verb(Verb::store_impulses, [&] { b.store_impulses(); });
}

// Runs one verb; with profiling on, waits for it and adds its wall time.
template <class F>
void Simulation::run_verb(Verb verb, F&& f) {
  if (!m_profiling) {
    f();
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  f();
  m_backend->synchronize();
  m_verb_ms[static_cast<int>(verb)] +=
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace marbles
