#include "sim/simulation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <iterator>
#include <sstream>

#include "core/format.hpp"
#include "core/parallel.hpp"
#include "sim/scene.hpp"
#include "narrowphase/solver_math.hpp"
#include "sim/watch_math.hpp"

namespace marbles {

Simulation::Simulation(const scene::Scene& scene, World world, broadphase::Backend backend,
                       broadphase::Algorithm algorithm)
    : m_model(std::make_unique<const StepModel>(compile_step_model(scene, algorithm))),
      m_backend(backend == broadphase::Backend::cuda ? make_cuda_step(*m_model, std::move(world))
                                                     : make_cpu_step(*m_model, std::move(world))) {}

std::string Simulation::describe_pipeline(int threads) const {
  const StepModel& m = *m_model;
  if (threads <= 0) threads = thread_count();
  const narrowphase::SolverSettings& s = m.solver;
  std::ostringstream out;
  out << "pipeline (" << m.substeps << " substep" << (m.substeps > 1 ? "s" : "") << " of h = " << m.dt / m.substeps
      << " s per step, " << kRealName << ", " << (m_backend->name() == "cuda" ? std::string("on the GPU")
                                         : "on the CPU, " + std::to_string(threads) + " thread" +
                                               (threads > 1 ? "s" : ""))
      << "):\n";
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
    out << (s.restitution ? "; impacts with restitution (" + std::to_string(s.impact_passes) + " passes at most)"
                          : std::string("; plastic impacts (no restitution)"))
        << (s.warm_start ? "; warm start" : "") << "\n";
  }
  out << (m.verlet ? "  integrate      velocity Verlet (gravity in half kicks around the drift)\n"
                   : "  integrate      symplectic Euler\n");
  if (m.collisions || m.wall_contacts) out << "  project        positions (overlap beyond slop)\n";
  if (m.closing_solve() && (m.collisions || m.wall_contacts))
    out << "  closing solve  " << s.closing_iterations
        << " sweeps after the second half kick (resting contacts end at rest)\n";
  return out.str();
}

void Simulation::set_watchdog(bool on) {
  m_watchdog = on;
  m_backend->set_watch(on);
  if (on) watch_from_host(m_backend->wall_shapes());
}

StateOverlaps state_overlaps(const World& world, const StepModel& model,
                             const std::vector<narrowphase::WallShape>& walls, double tolerance) {
  StateOverlaps o;
  const BodiesView b = const_cast<World&>(world).view();
  if (model.collisions) {
    std::vector<broadphase::Pair> pairs;
    broadphase::make_subdivision_cpu()->find_pairs({world.position.data(), world.radius.data(), world.size()}, 0,
                                                   pairs);
    for (const broadphase::Pair& p : pairs) {
      if (narrowphase::both_fixed(world.inv_mass[p.i], world.inv_mass[p.j])) continue;  // glued: no contact
      narrowphase::Contact c;
      c.a = p.i, c.b = p.j;
      const double r = narrowphase::overlap_ratio(c, b, nullptr);
      o.deepest = std::max(o.deepest, r);
      o.deepest_pair = std::max(o.deepest_pair, r);
      o.pairs += r > tolerance ? 1 : 0;
    }
  }
  if (model.wall_contacts)
    for (std::uint32_t i = 0; i < world.size(); ++i) {
      double deepest = 0;
      for (std::uint32_t k = 0; k < walls.size(); ++k) {
        narrowphase::Contact c;
        c.a = i, c.b = k | narrowphase::kWallFlag;
        deepest = std::max(deepest, static_cast<double>(narrowphase::overlap_ratio(c, b, walls.data())));
      }
      o.deepest = std::max(o.deepest, deepest);
      if (!(world.inv_mass[i] > 0)) continue;  // glued where it stands: the solver never moves it
      o.deepest_wall = std::max(o.deepest_wall, deepest);
      o.walls += deepest > tolerance ? 1 : 0;
    }
  return o;
}

// `walls`: where they stand (after a restart, moved).
void Simulation::watch_from_host(const std::vector<narrowphase::WallShape>& walls) {
  const World& w = world();
  const auto wall_count = m_model->wall_contacts ? static_cast<std::uint32_t>(walls.size()) : 0u;
  // The figures of the state as it stands, as the step's end would give them:
  // the overlap rule then judges the first step from the overlaps it starts
  // with (spheres placed overlapping are pushed apart, not a blow-up).
  m_watched_overlaps = state_overlaps(w, *m_model, walls, kStartOverlapTolerance);
  m_last.max_overlap = static_cast<real>(m_watched_overlaps.deepest);
  m_last.kinetic_energy = 0;
  m_last.beyond_walls = 0;
  Watch& s = m_watch;
  s.mass = 0;
  double radius_sum = 0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    m_last.kinetic_energy +=
        watch::kinetic_energy(w.velocity[i], w.angular_velocity[i], w.inv_mass[i], w.inv_inertia[i]);
    m_last.beyond_walls += watch::beyond_walls(w.position[i], w.radius[i], walls.data(), wall_count) ? 1 : 0;
    if (w.inv_mass[i] > 0) s.mass += 1.0 / w.inv_mass[i];
    radius_sum += w.radius[i];
  }
  s.radius = w.size() > 0 ? radius_sum / static_cast<double>(w.size()) : 0.0;
  s.wall_speed = 0;
  for (const narrowphase::WallShape& shape : walls)
    s.wall_speed = std::max(s.wall_speed, static_cast<double>(length(shape.velocity)) +
                                              std::fabs(static_cast<double>(shape.angular_velocity)) * shape.radius);
  s.known = true;
}

// The largest kinetic energy a step from `e0` may reach. With M the movable
// mass, |v| summed over spheres is at most sqrt(2 M e0) (Cauchy–Schwarz), so
//   gravity over dt adds at most |g| dt sqrt(2 M e0) + M (|g| dt)^2 / 2,
//   a wall hit at surface speed u adds at most 2 u (|v| + u) m per sphere,
//   once per substep;
// contacts, drag and the projection add none. The bound doubles those, lets
// the energy grow by half, and never falls below every sphere moving 1 % of
// the mean radius per step, so only a jump (an explosion) trips it.
double Simulation::watch_bound(double e0) const {
  const Watch& s = m_watch;
  const double dt = m_model->dt;
  const double sum_speed = std::sqrt(2 * s.mass * std::max(e0, 0.0));
  double gain = 0;
  if (m_model->gravity) {
    const Vec3 g = m_model->g;  // its length in double: a huge g's square overflows float
    const double gdt = std::sqrt(double(g.x) * g.x + double(g.y) * g.y + double(g.z) * g.z) * dt;
    gain += gdt * sum_speed + 0.5 * s.mass * gdt * gdt;
  }
  if (m_model->wall_contacts && s.wall_speed > 0)
    gain += m_model->substeps * m_split * 2 * s.wall_speed * (sum_speed + 2 * s.mass * s.wall_speed);
  const double floor = 0.5 * s.mass * std::pow(0.01 * s.radius / dt, 2);
  return std::max(1.5 * e0 + 2 * gain, floor);
}

const World& Simulation::world() const {
  if (m_ids.empty()) return m_backend->world();
  if (m_given_stale) {
    m_given = permuted(m_backend->world(), m_index);
    m_given_stale = false;
  }
  return m_given;
}

World& Simulation::edit_world() {
  m_watch.known = false;
  if (m_ids.empty()) return m_backend->edit_world();
  world();
  m_given_edited = true;
  return m_given;
}

void Simulation::send_edits() {
  if (!m_given_edited) return;
  m_backend->edit_world() = permuted(m_given, m_ids);
  m_given_edited = false;
}

BodiesView Simulation::state_in_place() {
  // Refused for the whole run, not only while the numbering differs: a
  // numbering replaces the arrays, and a view of them would outlive them.
  if (m_model->renumber_every > 0)
    throw RuntimeFailure("the arrays in place are in the step's numbering, which solver.renumber changes: "
                         "use world() and edit_world(), or renumber: 0");
  return m_backend->state_in_place();
}

const std::vector<narrowphase::Contact>& Simulation::contacts() const {
  if (m_ids.empty()) return m_backend->contacts();
  m_given_contacts = m_backend->contacts();
  for (narrowphase::Contact& c : m_given_contacts) {
    c.a = m_ids[c.a];
    if (!narrowphase::is_wall(c.b)) c.b = m_ids[c.b];
  }
  return m_given_contacts;
}

StepState Simulation::save_state() {
  send_edits();
  StepState state = m_backend->save_state();
  if (!m_ids.empty()) state.cache = narrowphase::renumbered(state.cache, m_ids);
  return state;
}

void Simulation::set_numbering(std::vector<std::uint32_t> ids) {
  m_ids = std::move(ids);
  adopt_numbering();
}

// m_ids as the numbering: dropped where it is the identity (back in the
// scene's order), else inverted into m_index, whose memory is kept.
void Simulation::adopt_numbering() {
  if (is_identity(m_ids)) {
    m_ids.clear();
    m_index.clear();
  } else {
    inverse_into(m_ids, m_index);
  }
  m_given_edited = false;
  m_given_stale = true;
}

void Simulation::restore(const World& world, const StepState& state, std::uint64_t steps,
                         const std::vector<std::uint32_t>& ids) {
  set_numbering(ids);
  StepState checked = state;
  if (m_ids.empty()) {
    m_backend->edit_world() = world;
  } else {
    m_backend->edit_world() = permuted(world, m_ids);
    checked.cache = narrowphase::renumbered(state.cache, m_index);
  }
  narrowphase::keep_proper_colours(checked.cache);  // colours from outside: only a proper colouring is kept
  m_backend->load_state(checked);
  m_steps = steps;
  m_time = static_cast<double>(steps) * m_model->dt;
  if (m_watchdog) watch_from_host(checked.walls);
}

// The step's spheres numbered again in the broad phase's order, and the
// warm-start cache with them (StepBackend::renumber): the same state, other
// indices. Both backends do it at the same steps and give the same order
// and bits (the CPU on its arrays, the GPU on the device's).
// The new ids are composed into the spare array and the index inverted in
// place: a run that numbers often allocates nothing after its first time.
void Simulation::renumber() {
  send_edits();
  const SphereOrder order = m_backend->renumber();
  if (order.empty()) return;
  const auto n = static_cast<std::ptrdiff_t>(order.size);
  const bool first = m_ids.empty();
  m_spare_ids.resize(order.size);
  std::uint32_t* ids = m_spare_ids.data();
#pragma omp parallel for schedule(static) if (n > 65536)
  for (std::ptrdiff_t i = 0; i < n; ++i) ids[i] = first ? order[i] : m_ids[order[i]];
  std::swap(m_ids, m_spare_ids);
  adopt_numbering();
}

void Simulation::step() {
  // (Not a state gone non-finite: it has no cells, and the step ends it anyway.)
  if (m_model->renumber_every > 0 && m_steps % m_model->renumber_every == 0 && !m_backend->non_finite()) renumber();
  send_edits();
  m_given_stale = true;  // nothing within the step reads the scene-numbered copy (violation reads the step's)
  m_last_rollbacks.clear();
  m_last_kept.clear();
  const StepCounters before = m_last;
  // What the rules compare with. After an edit (state written between steps)
  // the state's overlap is not known: the overlap rule waits a step rather
  // than take spheres placed in each other for a blow-up (that step is
  // checked for non-finite values; watch_from_host measures it where the
  // state comes whole, at the start and at a restart).
  StepCounters judged = before;
  if (!m_watch.known) judged.max_overlap = kWatchdogOverlap;
  if (m_watchdog) m_backend->keep_step_start();
  std::string first_unswept;  // the first try's broken rule, where the unswept rule was its only one
  const auto keep_unswept = [&](std::string why) {
    m_last_kept = std::move(why);
    ++m_unswept_kept;
  };
  for (int retry = 0;; ++retry) {
    m_backend->set_iteration_factor(1 << retry);
    attempt(1 << retry);
    std::string broken = m_watchdog ? violation(judged) : std::string();
    bool unswept_only = false;
    if (broken.empty() && m_watchdog) {
      broken = unswept_violation();
      unswept_only = !broken.empty();
    }
    if (retry == 0 && unswept_only) first_unswept = broken;
    // Still unswept at the last retry: kept (a sphere set moving faster
    // than even the finest substep sweeps), as every step was before the rule.
    if (unswept_only && retry == kWatchdogRetries) {
      keep_unswept(broken + ", still at " + std::to_string(m_model->substeps << kWatchdogRetries) + " substeps: kept");
      break;
    }
    if (broken.empty()) break;
    m_backend->undo_step();
    m_last = before;
    ++m_rollbacks;
    m_last_rollbacks.push_back(broken);
    if (retry == kWatchdogRetries && !first_unswept.empty()) {
      // The finer substeps broke a rule the first try kept: the first try
      // again (the same bits), kept as unswept, so the rule never ends a
      // run that ran before it.
      m_backend->set_iteration_factor(1);
      attempt(1);
      keep_unswept(first_unswept + ", and the finer substeps broke another rule: the first try kept");
      break;
    }
    if (retry == kWatchdogRetries) {
      m_backend->set_iteration_factor(1);
      throw WatchdogFailure("watchdog: step " + std::to_string(m_steps + 1) + ": " + broken + " after " +
                            std::to_string(kWatchdogRetries) + " retries down to " +
                            std::to_string(m_model->substeps << kWatchdogRetries) + " substeps");
    }
  }
  m_backend->set_iteration_factor(1);
  m_watch.known = m_watchdog;  // the end-of-step figures describe the next step's start
  ++m_steps;
  m_time = m_steps * m_model->dt;
}

void Simulation::inject_fault() {
  World& w = m_backend->edit_world();  // within the step: the watchdog's figures of its start stay
  if (w.size() == 0) return;
  const std::size_t f = m_ids.empty() ? 0 : m_index[0];  // the scene's sphere 0, where the step has it
  switch (m_fault) {
    case Fault::nan: w.velocity[f].x = std::nan(""); break;
    case Fault::kick: {
      const Vec3 up = m_model->gravity ? -m_model->g / length(m_model->g) : Vec3(1, 0, 0);
      w.velocity[f] = w.velocity[f] + up * (100 * w.radius[f] / static_cast<real>(m_model->dt));
      break;
    }
    case Fault::escape:
      for (const narrowphase::WallShape& shape : m_model->wall_shapes) {
        Vec3 normal;
        real separation = 0;
        if (!narrowphase::wall_gap(shape, w.position[f], w.radius[f], normal, separation)) continue;
        // 20 radii beyond the face: further than the projection can bring
        // it back within a step (max_correction a sweep, deep_position_iterations
        // sweeps), a true escape.
        w.position[f] = w.position[f] - normal * (separation + 20 * w.radius[f]);
        break;
      }
      break;
  }
}

void Simulation::attempt(int split) {
  const bool faulted = m_fault_retries_only ? split > 1 : (split == 1 || m_fault_every_try);
  if (faulted && m_fault_step == m_steps + 1) inject_fault();
  const real h = m_model->substep() / static_cast<real>(split);
  m_split = split;
  m_backend->begin_step();
  std::fill(std::begin(m_verb_ms), std::end(m_verb_ms), 0.0);
  const int substeps = m_model->substeps * split;
  for (int k = 0; k < substeps; ++k) substep(h);
  m_backend->end_step(m_last);
  // A substep that outgrew a room found without a wait (CUDA): done again.
  for (int k = m_backend->substep_to_redo(); k >= 0; k = m_backend->substep_to_redo()) {
    for (; k < substeps; ++k) substep(h);
    m_backend->end_step(m_last);
  }
  std::copy(std::begin(m_verb_ms), std::end(m_verb_ms), m_last.verb_ms);
}

std::string Simulation::violation(const StepCounters& before) {
  if (m_backend->non_finite()) {
    const std::size_t i = m_backend->world().first_non_finite();
    if (i >= m_backend->world().size())  // every state finite: a reach in a substep was not
      return "non-finite state (a sphere's reach in a substep, its speed times the substep, past " +
             std::string(kRealName) + " precision's range)";
    return "non-finite state (sphere " + std::to_string(i < m_ids.size() ? m_ids[i] : i) + ")";  // the scene's numbering
  }
  if (m_watch.known) {
    const double bound = watch_bound(before.kinetic_energy);
    if (!(m_last.kinetic_energy <= bound))
      return "kinetic energy jumped from " + significant(before.kinetic_energy, 4) + " J to " +
             significant(m_last.kinetic_energy, 4) + " J (at most " + significant(bound, 4) +
             " J from gravity and walls)";
    if (m_last.beyond_walls > before.beyond_walls)
      return std::to_string(m_last.beyond_walls - before.beyond_walls) + " sphere(s) went through a wall";
  }
  if (m_last.max_overlap > kWatchdogOverlap && before.max_overlap < kWatchdogOverlap / 2)
    return "overlap " + significant(m_last.max_overlap, 4) + " of a radius";
  return {};
}

std::string Simulation::unswept_violation() const {
  if (m_last.unswept_unchecked != 0)
    return "more than " + std::to_string(m_last.unswept_unchecked) +
           " spheres moved past the reach their contacts were found with in one substep (set moving within it)";
  if (m_last.unswept_depth > kUnsweptDepth)
    return "a sphere set moving within a substep past the reach its contacts were found with went " +
           significant(m_last.unswept_depth, 3) + " of a radius deeper into a sphere or wall than at the substep's start";
  return {};
}

void Simulation::substep(real h) {
  StepBackend& b = *m_backend;
  run_verb(Verb::body_forces, [&] { b.apply_body_forces(h); });
  run_verb(Verb::find_contacts, [&] { b.find_contacts(h); });
  run_verb(Verb::warm_start, [&] { b.warm_start(); });  // impulses and kept colours of persisting contacts
  run_verb(Verb::colour_contacts, [&] { b.colour_contacts(); });
  run_verb(Verb::solve_velocities, [&] { b.solve_velocities(h); });
  run_verb(Verb::integrate_positions, [&] { b.integrate_positions(h); });
  run_verb(Verb::project_positions, [&] { b.project_positions(); });
  run_verb(Verb::store_impulses, [&] { b.store_impulses(); });
  if (m_model->closing_solve()) run_verb(Verb::close_velocities, [&] { b.close_velocities(h); });
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
