// sim/simulation.hpp — the step pipeline, assembled once from the scene.
//
// One step advances dt in `substeps` substeps of h = dt / substeps:
//
//   for each substep:
//     apply body forces              gravity, air drag (if the scene lists them)
//     find contacts                  swept bounds -> broad phase -> sphere and wall contacts
//     colour contacts                no sphere twice in a colour; walls take none
//     warm start                     impulses of persisting contacts
//     solve velocities               impacts, then sweeps: colour by colour
//     integrate positions            x += h v; raises non_finite
//     project positions              remove overlap without adding energy
//     store impulses                 for the next substep's warm start
//   end of step: one read of counters and flags
//
// The verbs run on a StepBackend (step_backend.hpp): host arrays (CpuStep) or
// device arrays (CudaStep). Effects the scene does not name are not part of
// the pipeline at all.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "core/error.hpp"
#include "core/walls.hpp"
#include "narrowphase/contact.hpp"
#include "sim/step_backend.hpp"
#include "sim/step_model.hpp"
#include "sim/world.hpp"

namespace marbles {

// How the spheres of `world` overlap as they stand, measured as a step's
// end measures its max_overlap (narrowphase::overlap_ratio: of the smaller
// radius, a wall's of the sphere's): sphere pairs where `model` has
// collisions (two fixed spheres make no contact), sphere and `walls` (as
// they stand: moving walls move) where it has wall contacts. `deepest` is
// the step's measure, fixed spheres in a wall included (a rough floor of
// glued spheres set into it); the counts, deeper than `tolerance`, and
// deepest_free() are of what the solver moves: pairs with a movable
// sphere, movable spheres in a wall.
struct StateOverlaps {
  std::size_t pairs = 0;  // sphere pairs deeper than the tolerance
  std::size_t walls = 0;  // movable spheres deeper than it into a wall (or beyond one)
  double deepest = 0;
  double deepest_pair = 0;
  double deepest_wall = 0;  // of movable spheres in walls
  double deepest_free() const { return deepest_pair > deepest_wall ? deepest_pair : deepest_wall; }
};
// The tolerance of the warnings of spheres that start overlapping.
inline constexpr double kStartOverlapTolerance = 0.01;
StateOverlaps state_overlaps(const World& world, const StepModel& model,
                             const std::vector<narrowphase::WallShape>& walls, double tolerance);

// The watchdog gave up: the step is back at its start (a checkpoint of it is
// the last good state).
class WatchdogFailure : public RuntimeFailure {
 public:
  using RuntimeFailure::RuntimeFailure;
};

namespace scene {
struct Scene;
}

class Simulation {
 public:
  // `backend`: cpu (CpuStep) or cuda (CudaStep, the world on the device);
  // auto-selection happens in the caller.
  Simulation(const scene::Scene& scene, World world, broadphase::Backend backend,
             broadphase::Algorithm algorithm = broadphase::kDefaultCpuAlgorithm);

  // Advances one step (dt).
  void step();

  // The state, as a host copy (on the CUDA backend downloaded when stale),
  // in the scene's numbering (with solver.renumber the step numbers the
  // spheres its own way: world(), edit_world(), contacts(), save_state() and
  // restore() translate).
  const World& world() const;
  const Walls& walls() const { return m_model->walls; }
  const StepModel& model() const { return *m_model; }
  // How the state overlapped where the watchdog last measured it whole (its
  // start, set_watchdog(true), or a restart), counted past
  // kStartOverlapTolerance: the start's warnings read it.
  const StateOverlaps& watched_overlaps() const { return m_watched_overlaps; }
  double time() const { return m_time; }
  std::uint64_t steps() const { return m_steps; }
  double dt() const { return m_model->dt; }
  int substeps() const { return m_model->substeps; }
  const StepCounters& last_step() const { return m_last; }
  // True when the last step left a non-finite position or velocity.
  bool non_finite() const { return m_backend->non_finite(); }
  // Direct access to the state, for tests and tools that edit it between
  // steps (sent to the device before the next step).
  World& edit_world();
  // The state where the step keeps it (device pointers on the CUDA backend),
  // to read and write in place between steps; after writing, state_written()
  // (the watchdog then treats the next step as after an edit).
  // Not in a scene with solver.renumber (the arrays are in the step's
  // numbering, and a numbering replaces them): throws RuntimeFailure.
  BodiesView state_in_place();
  void state_written() {
    m_watch.known = false;
    m_backend->state_written();
  }
  // Every position, velocity and angular velocity finite, its square too (checked where the state lives).
  bool state_finite() { return m_backend->state_finite(); }
  // The contacts of the last substep (solver order), for diagnostics and tests.
  const std::vector<narrowphase::Contact>& contacts() const;
  const broadphase::BroadPhase* broad_phase() const { return m_backend->broad_phase(); }
  std::string backend_name() const { return m_backend->name(); }

  // Per-verb timing (StepCounters::verb_ms): the backend synchronises after
  // each verb, which costs time on the GPU; for the benchmark.
  void set_profiling(bool on) {
    m_profiling = on;
    m_backend->set_profiling(on);
  }
  std::size_t device_bytes() const { return m_backend->device_bytes(); }
  std::vector<DeviceBytes> device_buffers() const { return m_backend->device_buffers(); }

  // The state beside the world that the next step depends on (cache, walls),
  // and a restart: world, that state and the step count put back, with the
  // step's numbering (ids(): empty where it is the scene's).
  StepState save_state();
  // The walls where they stand now (save_state()'s, without the cache).
  std::vector<narrowphase::WallShape> wall_shapes() { return m_backend->wall_shapes(); }
  void restore(const World& world, const StepState& state, std::uint64_t steps,
               const std::vector<std::uint32_t>& ids = {});
  // With solver.renumber: each sphere's index in the scene's numbering, by
  // its index in the step's (empty: the same numbering). The step numbers
  // the spheres again in the broad phase's order at the start of every
  // renumber-th step (docs/architecture.md "The spheres' order").
  const std::vector<std::uint32_t>& ids() const { return m_ids; }

  // The watchdog (off unless set; `marbles run` sets it): after each step it
  // checks cheap invariants, in this order:
  //   non-finite      a position or velocity is not finite
  //   energy jump     the kinetic energy rose beyond what gravity and moving
  //                   walls can give in one step (watch_bound)
  //   escape          more spheres lie wholly beyond a wall than before
  //   overlap         an overlap deeper than kWatchdogOverlap of a radius
  //                   appeared (from below half of it)
  //   unswept         a sphere the solve set moving past the reach its
  //                   contacts were found with went more than kUnsweptDepth
  //                   of a radius deeper into a sphere or wall (watch_math.hpp)
  // A violation rolls the step back and redoes it with the substep halved and
  // the velocity sweeps doubled, up to kWatchdogRetries times; then step()
  // throws WatchdogFailure with the step back at its start, except where only
  // the unswept rule still fails: that step is kept and counted
  // (unswept_kept, last_kept); and where a retry breaks another rule that
  // the first try, broken by the unswept rule alone, kept, the first try is
  // done again and kept so. After an edit of the world (edit_world) the
  // next step checks only non-finite, overlap and unswept.
  void set_watchdog(bool on);
  bool watchdog() const { return m_watchdog; }
  static constexpr int kWatchdogRetries = 3;
  static constexpr real kWatchdogOverlap = real(1);
  static constexpr real kUnsweptDepth = real(0.01);
  // Rollbacks of the last step (each with its reason) and of the whole run.
  const std::vector<std::string>& last_rollbacks() const { return m_last_rollbacks; }
  std::uint64_t rollbacks() const { return m_rollbacks; }
  // The last step kept with the unswept rule failing (at the last retry,
  // or on the first try where a finer one broke another rule): why, and
  // what was kept (empty where it was not), and how many steps of the run were.
  const std::string& last_kept() const { return m_last_kept; }
  std::uint64_t unswept_kept() const { return m_unswept_kept; }
  // Test hooks: the first try (or every try) of step `step` starts with a
  // fault in sphere 0: a NaN velocity, a kick of 100 radii per step, or the
  // sphere put wholly beyond the first wall.
  enum class Fault { nan, kick, escape };
  // `retries_only`: the retries have it, the first try not.
  void inject_fault_at(std::uint64_t step, bool every_try = false, Fault kind = Fault::nan,
                       bool retries_only = false) {
    m_fault_step = step;
    m_fault_every_try = every_try;
    m_fault_retries_only = retries_only;
    m_fault = kind;
  }

  // The stages this scene's pipeline runs, one per line, on `threads` CPU
  // threads (the calling thread's count where 0: the count is a thread's).
  std::string describe_pipeline(int threads = 0) const;

 private:
  void substep(real h);
  void attempt(int split);  // one try of the step with `split` times the substeps
  std::string violation(const StepCounters& before);  // the broken invariant after a try, or empty
  std::string unswept_violation() const;             // the unswept rule's, checked after the others
  double watch_bound(double energy_before) const;    // the largest kinetic energy a step may reach
  StateOverlaps m_watched_overlaps;  // watch_from_host's measure of the state
  // The figures of the host world, its walls as they stand, into m_last.
  void watch_from_host(const std::vector<narrowphase::WallShape>& walls);
  void inject_fault();
  void renumber();    // the spheres numbered again in the broad phase's order
  void send_edits();  // edits of the scene-numbered copy to the step
  void set_numbering(std::vector<std::uint32_t> ids);  // m_ids (empty where the identity), m_index
  void adopt_numbering();                              // the same for m_ids as they stand
  template <class F>
  void run_verb(Verb verb, F&& f);

  std::unique_ptr<const StepModel> m_model;  // stable address: the backend keeps a reference
  std::unique_ptr<StepBackend> m_backend;
  double m_time = 0;
  std::uint64_t m_steps = 0;
  StepCounters m_last;
  bool m_profiling = false;
  bool m_watchdog = false;
  std::uint64_t m_rollbacks = 0, m_fault_step = 0;
  bool m_fault_every_try = false, m_fault_retries_only = false;
  Fault m_fault = Fault::nan;
  int m_split = 1;  // the try's substeps per model substep
  // The watchdog's view of the state before the step, and the scene's scales.
  // (Its figures of the state itself are m_last's kinetic_energy and beyond_walls.)
  struct Watch {
    bool known = false;   // m_last's figures describe the state (no edit since)
    double mass = 0;      // kg, of the movable spheres
    double radius = 0;    // m, mean
    double wall_speed = 0;  // m/s, the fastest wall surface
  } m_watch;
  std::vector<std::string> m_last_rollbacks;
  std::string m_last_kept;
  std::uint64_t m_unswept_kept = 0;
  // The step's numbering (empty: the scene's): m_ids[i] is the scene's
  // index of the step's sphere i, m_index its inverse; the world and the
  // contacts in the scene's numbering, made when asked for.
  std::vector<std::uint32_t> m_ids, m_index;
  std::vector<std::uint32_t> m_spare_ids;  // renumber's next ids, kept for their memory
  mutable World m_given;
  mutable bool m_given_stale = true;
  bool m_given_edited = false;
  mutable std::vector<narrowphase::Contact> m_given_contacts;
  double m_verb_ms[static_cast<int>(Verb::count)] = {};
};

}  // namespace marbles
