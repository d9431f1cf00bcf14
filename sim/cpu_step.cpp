// sim/cpu_step.cpp — the substep's verbs on host arrays (StepBackend).
//
// Each verb is a loop (OpenMP where it pays) over the per-element functions
// of the stages' *_math.hpp; the solver runs colour by colour, so the result
// is the same for any thread count and the same as CudaStep's.
#include <algorithm>
#include <cmath>
#include <optional>

#include "core/bits.hpp"
#include "core/error.hpp"
#include "integrator/symplectic_euler.hpp"
#include "narrowphase/colouring.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contacts.hpp"
#include "narrowphase/solver.hpp"
#include "sim/step_backend.hpp"
#include "sim/watch_math.hpp"

namespace marbles {
namespace {

class CpuStep final : public StepBackend {
 public:
  CpuStep(const StepModel& model, World world, std::unique_ptr<broadphase::BroadPhase> broad_phase)
      : m_model(model),
        m_world(std::move(world)),
        m_walls(model.wall_shapes),
        m_broadphase(std::move(broad_phase)),
        m_solver(model.solver) {}

  void apply_body_forces(real h) override {
    // With drag, gravity's kick is taken in drag's pass (drag_update).
    const BodiesView bodies = m_world.view();
    if (m_model.drag)
      integrator::apply_drag(bodies, m_model.drag_linear, m_model.drag_quadratic, m_model.first_kick(h),
                             m_model.verlet ? integrator::DragKick::verlet_first : integrator::DragKick::whole,
                             m_model.gravity ? &m_model.g : nullptr);
    else if (m_model.gravity)
      integrator::apply_gravity(bodies, m_model.g, m_model.first_kick(h));
  }

  // Swept bounds: the broad phase sees each sphere grown by its reach (its
  // travel |v| h, at least the fastest sphere's up to half its radius:
  // contact_reach), so every pair that can meet in this substep is a
  // candidate, however fast; the narrow phase keeps those that overlap or
  // can close their gap (speculative contacts), so nothing tunnels.
  void find_contacts(real substep) override {
    const real h = m_model.lookahead(substep);  // 0 without speculative contacts: touching pairs only
    m_solver.forget_records();
    m_contact_first.clear();
    m_reach.clear();  // made again below where the search runs: integrate_positions' check reads it then only
    // The sphere search replaces the second run, reusing its elements
    // (sphere_contacts); it is emptied wherever that search does not run
    // or fails.
    if (!m_model.collisions || m_non_finite) m_contact_rest.clear();
    if (!m_model.collisions && !m_model.wall_contacts) return;
    if (m_non_finite) return;  // the step ends with "non-finite at step N, sphere i", not a broad-phase error
    const BodiesView bodies = m_world.view();
    const std::size_t n = m_world.size();
    narrowphase::contact_reaches(bodies, h, m_reach);
    try {
      if (m_model.collisions) {
        m_bound_radius.resize(n);
#pragma omp parallel for schedule(static) if (n > 20000)
        for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i)
          m_bound_radius[i] = bodies.radius[i] + m_reach[i];
        m_broadphase->find_pairs({bodies.position, m_bound_radius.data(), n}, 0, m_pairs);
        m_counters.candidate_pairs += m_pairs.size();
        m_counters.broadphase_ms += m_broadphase->last_stats().ms_total;
        narrowphase::sphere_contacts(bodies, m_pairs.data(), m_pairs.size(), m_model.pair_table(), h,
                                     m_reach.data(), m_contact_first, m_contact_rest, m_contact_scratch);
      }
      if (m_model.wall_contacts)  // after every sphere pair's: at the end of the last run
        narrowphase::wall_contacts(bodies, m_walls, m_model.pair_table(), h, m_reach.data(),
                                   m_contact_rest.empty() ? m_contact_first : m_contact_rest, &m_contact_scratch);
    } catch (const broadphase::NonFiniteInput&) {
      // A reach past the precision's range (a speed times the substep): the
      // state goes non-finite as it moves, and the step ends with that
      // ("non-finite state", the watchdog's to repair), not a broad-phase
      // error, as on the GPU.
      m_contact_first.clear();
      m_contact_rest.clear();
      m_non_finite = true;
      return;
    } catch (...) {  // no contact of the substep before left in the runs
      m_contact_first.clear();
      m_contact_rest.clear();
      throw;
    }
    m_counters.contacts += contact_count();
  }

  void colour_contacts() override {
    const std::size_t n = contact_count();
    const bool kept = m_kept_colour.size() == n && n > 0;
    const bool loads = m_loaded.size() == n && n > 0;
    // The records made from the contacts where the search left them (its
    // runs), each prepared on its way: nothing moves the bodies before the
    // solve. No colour-major copy of the contacts is made.
    const narrowphase::KeptMasks masks{m_kept_masks.data(), m_kept_colours};
    m_colouring.colour_and_place(contact_runs(), n, m_world.size(), m_colours, kept ? m_kept_colour.data() : nullptr,
                                 loads ? m_loaded.data() : nullptr, kept ? &masks : nullptr);
    const narrowphase::UniformArms* uniform = uniform_arms();
    m_solver.make_records(contact_runs(), m_colouring.places(), m_colours, m_world.view(), m_model.pair_table(),
                          m_walls, uniform);
    m_counters.uniform_arms += uniform && n > 0 ? 1 : 0;
    m_counters.colours = std::max(m_counters.colours, m_colours.colours);
    m_counters.overflow += m_colours.overflow();
  }

  // Before the colouring: the contacts that persist get their impulses and
  // the colour they had (kept by the colouring).
  void warm_start() override {
    m_kept_colour.clear();
    m_loaded.clear();
    if (contact_count() == 0) return;
    m_cache.restore(contact_runs(), contact_count(), m_world.view(),
                    m_model.gravity ? length(m_model.g) * m_model.substep() : real(0), m_kept_colour, &m_loaded);
    // The kept colours at their spheres from the matched entries (in key
    // order), so that the colouring reads no kept contact.
    m_kept_colours = m_cache.kept_masks(m_world.size(), m_kept_masks);
  }

  void solve_velocities(real h) override {
    if (has_records()) m_solver.solve_records(m_colours, m_world.view(), h);
  }

  void integrate_positions(real h) override {
    // With the watch and speculative contacts, where the reaches were made
    // for this substep: the spheres that moved past theirs, checked.
    const bool check = m_watch && m_model.speculative && m_reach.size() == m_world.size();
    std::size_t past = 0;
    const Vec3* shift = has_records() ? m_solver.impact_shift() : nullptr;
    m_non_finite = integrator::integrate_positions(m_world.view(), h, check ? m_reach.data() : nullptr, &past, shift) ||
                   m_non_finite;
    if (past > 0 && !m_non_finite) check_unswept(h, past);
    if (m_model.verlet && m_model.drag)
      integrator::apply_drag(m_world.view(), m_model.drag_linear, m_model.drag_quadratic, m_model.second_kick(h),
                             integrator::DragKick::verlet_second, m_model.gravity ? &m_model.g : nullptr);
    else if (m_model.verlet && m_model.gravity)
      integrator::apply_gravity(m_world.view(), m_model.g, m_model.second_kick(h));
    narrowphase::advance_walls(m_walls, h);
  }

  void project_positions() override {
    if (has_records()) m_counters.projection_sweeps += m_solver.project_records(m_colours, m_world.view(), m_walls);
  }

  void close_velocities(real h) override {
    if (has_records()) m_solver.close_velocities(m_colours, m_world.view(), m_walls, h);
  }

  // Also when there are no contacts: no stale impulses survive a contact-free substep.
  // The impulses from the solve's records, the contacts' only form.
  void store_impulses() override {
    if (const narrowphase::SweepRecords* records = m_solver.made_records())
      m_cache.store(*records, static_cast<std::uint32_t>(m_colours.size()), m_model.solver.rolling, m_colours,
                    static_cast<std::uint32_t>(m_world.size()));
    else
      m_cache.clear();
  }

  void begin_step() override {
    m_counters = {};
    m_non_finite = false;
  }
  void end_step(StepCounters& counters) override {
    const BodiesView bodies = m_world.view();
    // The last substep projected these contacts (project_positions runs
    // whenever there are any).
    m_counters.max_overlap = has_records() ? m_solver.deepest_overlap(bodies, m_walls) : real(0);
    if (m_watch) watch(bodies);
    // A step with an unchecked substep reports no depth (as the GPU's one
    // step word, kUnswept, holds either).
    if (m_counters.unswept_unchecked != 0) m_counters.unswept_depth = 0;
    counters = m_counters;
  }
  void set_watch(bool on) override { m_watch = on; }
  void set_iteration_factor(int factor) override {
    m_solver.set_iteration_factor(factor, m_model.solver.iterations, m_model.solver.closing_iterations);
  }
  bool non_finite() const override { return m_non_finite; }

  const World& world() override { return m_world; }
  World& edit_world() override {
    m_uniform_known = false;  // the radii may change
    return m_world;
  }
  BodiesView state_in_place() override { return m_world.view(); }
  void state_written() override {}
  bool state_finite() override { return m_world.first_out_of_range() == m_world.size(); }
  // Made whole from the records (contact_of_record), in colour-major order.
  const std::vector<narrowphase::Contact>& contacts() override {
    m_solver.contacts_of_records(m_colours, m_world.view(), m_model.pair_table(), m_walls, m_contacts);
    return m_contacts;
  }
  const broadphase::BroadPhase* broad_phase() const override { return m_broadphase.get(); }
  std::string name() const override { return "cpu"; }
  StepState save_state() override { return {m_cache.entries(), m_walls}; }
  std::vector<narrowphase::WallShape> wall_shapes() override { return m_walls; }
  void keep_step_start() override {
    m_kept.position = m_world.position;
    m_kept.velocity = m_world.velocity;
    m_kept.angular_velocity = m_world.angular_velocity;
    m_cache.keep();  // no copy: the step's stores write the cache's other arrays
    m_kept_walls = m_walls;
  }
  void undo_step() override {
    m_world.position = m_kept.position;
    m_world.velocity = m_kept.velocity;
    m_world.angular_velocity = m_kept.angular_velocity;
    m_cache.back_to_kept();
    m_walls = m_kept_walls;
    m_non_finite = false;
  }
  void load_state(const StepState& state) override {
    m_cache.set_entries(state.cache);
    m_walls = state.walls;
  }
  SphereOrder renumber() override {
    std::vector<std::uint32_t> order = cell_order(m_world);
    if (is_identity(order)) return {};
    narrowphase::CacheEntries cache = narrowphase::renumbered(m_cache.entries(), inverse_of(order));
    m_world = permuted(m_world, order);  // after anything that may throw: all or nothing
    m_cache.set_entries(std::move(cache));
    m_order = std::move(order);
    return {m_order.data(), m_order.size()};
  }

 private:
  // Where every material pair has the same friction and rolling friction
  // (StepModel::uniform_pairs) and every sphere the same radius, bit for
  // bit, every contact's arms word is the same (UniformArms: the radius,
  // and +0 for a wall's arm), and the records leave it out, as the GPU's
  // do: 16 bytes a contact fewer to write and to read in every sweep. The
  // radii are scanned once, and again only after edit_world (nothing else
  // changes them; a renumbering permutes them).
  const narrowphase::UniformArms* uniform_arms() {
    if (!m_uniform_known) {
      m_uniform_known = true;
      m_uniform.reset();
      const BodiesView b = m_world.view();
      if (!m_model.uniform_pairs || m_model.pair_coefficients.empty() || b.count == 0) return nullptr;
      const auto n = static_cast<std::ptrdiff_t>(b.count);
      const std::uint64_t first = bits_of_real(b.radius[0]);
      bool mixed = false;
#pragma omp parallel for schedule(static) reduction(|| : mixed) if (n > 20000)
      for (std::ptrdiff_t i = 0; i < n; ++i) mixed = bits_of_real(b.radius[i]) != first || mixed;
      if (!mixed) m_uniform = m_model.uniform_arms(b.radius[0]);
    }
    return m_uniform ? &*m_uniform : nullptr;
  }

  // The `past` spheres that moved past their reach this substep (found
  // again here: a rare substep's one scan), against every sphere and wall
  // (watch_math.hpp: swept_deepening) in one pass over the spheres, as the
  // GPU's unswept_kernel; more than watch::unswept_checked are not checked,
  // and count as such.
  void check_unswept(real h, std::size_t past) {
    const BodiesView b = m_world.view();
    if (const std::uint32_t checked = watch::unswept_checked(b.count); past > checked) {
      m_counters.unswept_unchecked = checked;
      return;
    }
    m_past.clear();
    for (std::size_t i = 0; i < b.count && m_past.size() < past; ++i)
      if (integrator::moved_past_reach(b.velocity[i], b.radius[i], m_reach[i], h))
        m_past.push_back(static_cast<std::uint32_t>(i));
    const std::uint32_t* listed = m_past.data();
    const std::size_t count = m_past.size();
    const auto spheres = static_cast<std::ptrdiff_t>(m_model.collisions ? b.count : 0);  // without collisions
                                                                                       // spheres pass through
    real deepest = m_counters.unswept_depth;
#pragma omp parallel for schedule(static) reduction(max : deepest) if (spheres > 20000)
    for (std::ptrdiff_t j = 0; j < spheres; ++j)
      for (std::size_t k = 0; k < count; ++k)
        deepest = std::max(deepest, watch::unswept_pair(b, listed[k], static_cast<std::size_t>(j), h));
    if (m_model.wall_contacts)
      for (const std::uint32_t i : m_past)
        for (const narrowphase::WallShape& w : m_walls)
          deepest = std::max(deepest, watch::wall_swept_deepening(w, b.position[i], b.velocity[i], b.radius[i], h));
    m_counters.unswept_depth = deepest;
  }

  // The watchdog's figures (watch_math.hpp); walls count only where they act.
  void watch(const BodiesView& b) {
    const auto n = static_cast<std::ptrdiff_t>(b.count);
    const narrowphase::WallShape* walls = m_walls.data();
    const auto wall_count = m_model.wall_contacts ? static_cast<std::uint32_t>(m_walls.size()) : 0u;
    double energy = 0;
    std::uint64_t beyond = 0;
#pragma omp parallel for schedule(static) reduction(+ : energy, beyond) if (n > 20000)
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      energy += watch::kinetic_energy(b.velocity[i], b.angular_velocity[i], b.inv_mass[i], b.inv_inertia[i]);
      beyond += watch::beyond_walls(b.position[i], b.radius[i], walls, wall_count) ? 1 : 0;
    }
    m_counters.kinetic_energy = energy;
    m_counters.beyond_walls = beyond;
  }

  const StepModel& m_model;
  World m_world;
  std::vector<narrowphase::WallShape> m_walls;  // moving walls move
  World m_kept;             // the moving state at the start of the step (watchdog)
  std::optional<narrowphase::UniformArms> m_uniform;  // uniform_arms()' answer, once known
  bool m_uniform_known = false;
  std::vector<std::uint32_t> m_order;  // the last renumber's (its return)
  std::vector<narrowphase::WallShape> m_kept_walls;  // at the start of the step (the cache keeps its own)
  std::unique_ptr<broadphase::BroadPhase> m_broadphase;
  narrowphase::ContactColouring m_colouring;
  narrowphase::ContactSolver m_solver;
  narrowphase::ContactCache m_cache;

  // Per-substep buffers, reused.
  std::vector<real> m_reach;         // m, contact_reach per sphere
  std::vector<std::uint32_t> m_past;  // check_unswept's spheres
  std::vector<real> m_bound_radius;  // m, radius + reach: what the broad phase sees
  std::vector<broadphase::Pair> m_pairs;
  // The contacts as found, in two runs (narrowphase::Runs): the first
  // thread's, then the other threads' (not joined into one list, which
  // would copy half of them again). The colouring places them and the
  // solver makes its records from them where they are; m_contacts holds
  // them whole only when asked (contacts()).
  std::vector<narrowphase::Contact> m_contacts;
  std::vector<narrowphase::FoundContact> m_contact_first, m_contact_rest;
  narrowphase::ContactScratch m_contact_scratch;
  std::size_t contact_count() const { return m_contact_first.size() + m_contact_rest.size(); }
  // The solver holds records of this substep's contacts, and there are some.
  bool has_records() const { return m_solver.made_records() && m_colours.size() > 0; }
  narrowphase::FoundRuns contact_runs() {
    return {m_contact_first.data(), m_contact_first.size(), m_contact_rest.data()};
  }
  narrowphase::ColourRanges m_colours;
  std::vector<std::uint8_t> m_kept_colour;  // per contact: its colour of the last substep, or none
  std::vector<std::uint8_t> m_loaded;       // per contact: whether it carries a load in (the colouring orders by it)
  std::vector<std::uint64_t> m_kept_masks;  // per sphere: the kept colours its contacts hold (KeptMasks)
  std::uint32_t m_kept_colours = 0;
  StepCounters m_counters;
  bool m_non_finite = false;
  bool m_watch = false;
};

}  // namespace

std::unique_ptr<StepBackend> make_cpu_step(const StepModel& model, World world) {
  return std::make_unique<CpuStep>(model, std::move(world),
                                   model.collisions ? broadphase::make_subdivision_cpu(model.algorithm) : nullptr);
}

#if !defined(MARBLES_HAVE_CUDA)
std::unique_ptr<StepBackend> make_cuda_step(const StepModel&, World) {
  throw RuntimeFailure("the CUDA step: this build has no CUDA backend");
}
int cuda_cluster_blocks() { return 0; }
std::vector<KernelFit> cuda_sweep_kernel_fits() { return {}; }
#endif

}  // namespace marbles
