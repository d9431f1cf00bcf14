// sim/step_backend.hpp — the verbs of a substep, and where the state lives.
//
// Simulation::substep (simulation.cpp) is one text for every backend: it
// calls these verbs in the order of DESIGN.md. CpuStep (cpu_step.cpp) runs
// them on host arrays with OpenMP; CudaStep (cuda_step.cu) on device arrays
// in one stream, the world staying on the device and coming back only when
// asked for (output, tests). Both call the same per-element functions
// (the stages' *_math.hpp) in the same coloured order, so they give the
// same bits.
#pragma once

#include <cstdint>
#include <iterator>
#include <memory>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "core/device.hpp"
#include "narrowphase/contact.hpp"
#include "sim/step_model.hpp"
#include "narrowphase/contact_cache.hpp"
#include "sim/world.hpp"

namespace marbles {

// The verbs of a substep, for per-verb timing.
enum class Verb : int {
  body_forces, find_contacts, colour_contacts, warm_start, solve_velocities, integrate_positions,
  project_positions, store_impulses, close_velocities, count
};
inline constexpr const char* kVerbNames[] = {"body_forces", "find_contacts", "colour_contacts", "warm_start",
                                             "solve_velocities", "integrate_positions", "project_positions",
                                             "store_impulses", "close_velocities"};

// What a substep without waits outgrew, so that it was undone
// (StepCounters::undo_causes; the CUDA step's check on the device): a bit
// each, as several can meet in one substep.
enum UndoCause : std::uint32_t {
  kUndoPairs = 1u << 0,        // the candidate pairs outgrew their room
  kUndoContacts = 1u << 1,     // the contacts outgrew theirs
  kUndoGrid = 1u << 2,         // the broad phase's grid outgrew its plan
  kUndoImpactWords = 1u << 3,  // an impact candidate, where the records held approach speeds alone
  kUndoArms = 1u << 4,         // radii not all the one the records' left-out arms word stood for
  kUndoColours = 1u << 5,      // a plan the slots launched for it do not hold (more colours, or a new one
                               // with an overflow set: narrowphase::slots_hold)
};
inline constexpr const char* kUndoCauseNames[] = {"pairs", "contacts", "grid", "impact_words", "arms", "colours"};
// The names of the causes set in `causes`, in kUndoCauseNames' order.
inline std::vector<std::string> undo_cause_names(std::uint32_t causes) {
  std::vector<std::string> names;
  for (std::uint32_t k = 0; k < std::size(kUndoCauseNames); ++k)
    if (causes & (1u << k)) names.emplace_back(kUndoCauseNames[k]);
  return names;
}

// Figures of the last step, summed (or maximised) over its substeps.
struct StepCounters {
  std::uint64_t candidate_pairs = 0;  // summed over substeps
  std::uint64_t contacts = 0;         // summed over substeps
  std::uint32_t colours = 0;          // most colours of a substep
  std::uint64_t overflow = 0;         // contacts solved one by one (beyond the colours), summed
  double broadphase_ms = 0;           // summed over substeps (CUDA: with profiling on only)
  real max_overlap = 0;               // deepest overlap at the end of the step (overlap_ratio: of the smaller radius)
  std::uint64_t projection_sweeps = 0;  // projection sweeps run (until settled: ContactSolver), summed over substeps
  std::uint64_t bytes_copied = 0;     // host<->device traffic of the step (CUDA)
  std::uint64_t one_launch_solves = 0;  // substeps whose warm start and sweeps took one launch (CUDA)
  std::uint64_t cluster_stages = 0;   // one-launch stages (solve, position, impact) run as one cluster (CUDA, sm_90)
  std::uint64_t turn_launches = 0;    // sweep launches that visited a turn's range twice (CUDA: visit_sweeps)
  std::uint64_t range_groups = 0;     // launches that walked a run of small ranges in one block (CUDA: RangeGroup)
  std::uint64_t uniform_arms = 0;     // substeps whose records left the arms word out (UniformArms)
  std::uint64_t impact_words = 0;     // substeps whose records kept whole impact words, not approach speeds (CUDA)
  std::uint64_t pair_redos = 0;       // substeps whose pairs or contacts outgrew their room: found again (CUDA)
  std::uint64_t grid_replans = 0;     // of those, the broad phase's grid outgrew its plan: found with a wait (CUDA)
  std::uint64_t grid_shrinks = 0;     // substeps whose grid fit a plan larger than it asks: planned again (CUDA)
  std::uint64_t buffer_trims = 0;     // buffers freed at the step's start, held beyond their need (CUDA)
  std::uint64_t unwaited_substeps = 0;  // substeps that waited for nothing (CUDA: one wait a step)
  std::uint64_t undone_substeps = 0;  // of those, outgrew a room: put back and done again with waits (CUDA)
  std::uint32_t undo_causes = 0;      // what the undone substeps outgrew: UndoCause bits, or-ed (CUDA)
  // With the watch on (StepBackend::set_watch), the figures of the watchdog's
  // invariants at the end of the step (sim/watch_math.hpp):
  double kinetic_energy = 0;          // J, translational + rotational
  std::uint64_t beyond_walls = 0;     // spheres wholly past a wall's surface
  // A meeting no contact stood for (watch_math.hpp, "Motion the substep did
  // not sweep"), over the step's substeps: the most a sphere set moving past
  // its reach went deeper into a sphere or wall (of the smaller radius), and
  // where some substep had more such spheres than are checked, how many are
  // (watch::unswept_checked; else 0).
  real unswept_depth = 0;
  std::uint64_t unswept_unchecked = 0;
  double verb_ms[static_cast<int>(Verb::count)] = {};  // with profiling on: wall ms per verb, summed
};

// Device memory that one part of the step holds (StepBackend::device_buffers).
struct DeviceBytes {
  std::string name;
  std::size_t bytes = 0;
};

// What a step depends on besides the world: the warm-start cache and the
// walls as they have moved. With the world and the step count it is a
// checkpoint (sim/checkpoint.hpp): restored, the run goes on bit for bit.
struct StepState {
  narrowphase::CacheEntries cache;
  std::vector<narrowphase::WallShape> walls;
};

// An order of the spheres (new index -> old) in a backend's memory, valid
// until its next renumber (std::span's part that CUDA sources, C++17, read).
struct SphereOrder {
  const std::uint32_t* data = nullptr;
  std::size_t size = 0;
  bool empty() const { return size == 0; }
  const std::uint32_t* begin() const { return data; }
  const std::uint32_t* end() const { return data + size; }
  std::uint32_t operator[](std::size_t i) const { return data[i]; }
};

class StepBackend {
 public:
  virtual ~StepBackend() = default;

  // --- the verbs of one substep, in order ----------------------------------
  virtual void apply_body_forces(real h) = 0;    // gravity, drag: what the model enables
  virtual void find_contacts(real h) = 0;        // swept bounds -> broad phase -> sphere and wall contacts
  virtual void warm_start() = 0;                 // impulses and colours of persisting contacts
  virtual void colour_contacts() = 0;            // no sphere twice in a colour; walls take none; kept colours kept
  virtual void solve_velocities(real h) = 0;     // impacts, warm start, sweeps: colour by colour
  virtual void integrate_positions(real h) = 0;  // x += h v, walls move; raises non_finite
  virtual void project_positions() = 0;          // colour by colour; positions only
  virtual void store_impulses() = 0;             // for the next substep's warm start
  // Velocity Verlet's closing solve after its second kick and the store, where
  // the model asks for it (StepModel::closing_solve; narrowphase::close_record).
  virtual void close_velocities(real h) = 0;

  // --- around a step --------------------------------------------------------
  virtual void begin_step() = 0;
  // The one read of counters and flags per step.
  virtual void end_step(StepCounters& counters) = 0;
  // True when the last step left a non-finite position or velocity.
  virtual bool non_finite() const = 0;
  // After end_step: the substep to do again from (its start is the state
  // now), or -1. A backend that found, at the step's one read, that a
  // substep outgrew a room it was given without a wait (CUDA: one wait a
  // step) has undone that substep and grown the rooms; the caller runs the
  // substeps from there to the step's last and calls end_step again. Asked
  // once: the answer is cleared.
  virtual int substep_to_redo() { return -1; }
  // Waits until the verbs issued so far are done (profiling only).
  virtual void synchronize() {}
  // Profiling on: stage timings that cost syncs (the CUDA broad phase's events).
  virtual void set_profiling(bool on) {}
  // Device memory the step holds (bytes; 0 on the CPU).
  virtual std::size_t device_bytes() const { return 0; }
  // The device memory the step's own buffers hold, by part (empty on the
  // CPU), the last part "runtime": what device_bytes() has beyond their sum
  // (the runtime's modules and local memory, allocation granularity).
  virtual std::vector<DeviceBytes> device_buffers() const { return {}; }

  // --- state ----------------------------------------------------------------
  // A host copy of the world, refreshed from the device when stale.
  virtual const World& world() = 0;
  // The host copy for editing between steps; sent back before the next step.
  virtual World& edit_world() = 0;
  // The arrays the step itself reads and writes (device pointers on the GPU),
  // for tools that change the state in place between steps (the Python
  // module's views); after such writes, state_written() before anything else.
  virtual BodiesView state_in_place() = 0;
  // The arrays of state_in_place() may have changed (the host copy is stale).
  virtual void state_written() = 0;
  // True when every position, velocity and angular velocity of the arrays
  // the step works on is finite, its square too (integrator::body_in_range;
  // on the GPU, checked there: one flag read).
  virtual bool state_finite() = 0;
  // The contacts of the last substep, in solver (colour-major) order.
  virtual const std::vector<narrowphase::Contact>& contacts() = 0;
  virtual const broadphase::BroadPhase* broad_phase() const = 0;
  virtual std::string name() const = 0;
  // The state beside the world, between steps (a host copy on the GPU).
  virtual StepState save_state() = 0;
  // save_state()'s walls alone, where they stand (on the GPU, their copy
  // without the cache's).
  virtual std::vector<narrowphase::WallShape> wall_shapes() = 0;
  virtual void load_state(const StepState& state) = 0;
  // The watchdog's undo: keep the state at the start of a step (positions,
  // velocities, cache, walls; in device memory on the GPU), and go back to it.
  virtual void keep_step_start() = 0;
  virtual void undo_step() = 0;
  // The watchdog's figures in end_step (kinetic_energy, beyond_walls): one
  // more pass over the spheres per step, folded into the step's one read.
  virtual void set_watch(bool on) = 0;
  // Numbers the spheres again in the broad phase's order (cell_order,
  // sim/world.hpp): the world's arrays and the warm-start cache's entries
  // (narrowphase::renumbered) renamed, between steps. Returns the order
  // (new index -> old), empty where it changes nothing, in the backend's
  // memory (valid until its next renumber: the GPU's is pinned, so the read
  // of 4 bytes a sphere needs no staging and no fresh pages). The GPU's does
  // it on the device, with the CPU's order and bits.
  virtual SphereOrder renumber() = 0;
  // A retry's effort: the velocity sweeps run `factor` times the model's
  // iterations until set back to 1.
  virtual void set_iteration_factor(int factor) = 0;
};

// Host arrays, OpenMP.
std::unique_ptr<StepBackend> make_cpu_step(const StepModel& model, World world);
// Device arrays, one stream. Throws RuntimeFailure without a CUDA build or device.
std::unique_ptr<StepBackend> make_cuda_step(const StepModel& model, World world);
// The most blocks the CUDA step's one-launch stages take as one cluster here
// (16 on an H100 or H200 with this build's default sm_90 code): 0 where
// they never run as one (no device, a device without cluster launches, code
// not made from sm_90 PTX, a build without CUDA).
int cuda_cluster_blocks();
// How the CUDA step's velocity sweep kernels fit a multiprocessor of the
// device (narrowphase::cuda::sweep_kernel_fits); none without a device or
// a CUDA build.
std::vector<KernelFit> cuda_sweep_kernel_fits();

}  // namespace marbles
