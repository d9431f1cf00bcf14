// narrowphase/solver_cuda.cuh — the CUDA twin of solver.cpp over the
// per-contact functions of solver_math.hpp: a launch per colour (a thread
// per contact) walked by the host, or a whole stage in one launch (a
// cooperative grid, or one cluster) that walks the colours itself; either
// way the overflow set by one thread in order and the colours in the CPU's
// order (visit_colours), so the result is the CPU's bit for bit.
// Only .cu files include this header.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <vector>

#include "core/device.hpp"
#include "core/device_memory.hpp"
#include "core/spheres.hpp"
#include "narrowphase/colouring.hpp"
#include "narrowphase/colouring_math.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {

// The per-contact terms a scene enables: picks the kernel instance once.
struct SolverTerms {
  bool friction = false, rolling = false;
};

using ::marbles::narrowphase::ColourPlan;  // colouring_math.hpp

// A range of contacts: one colour (in parallel) or the overflow set (serial,
// forwards or backwards).
struct ContactRange {
  std::uint32_t begin = 0, end = 0;
  bool serial = false, backwards = false;
  bool mirrored = false;  // parallel: thread t takes contact end - 1 - t
  // Parallel, the warm start and the sweep: the launch before wrote none of
  // this range's records, so its threads load theirs while that launch ends
  // (programmatic dependent launch, solver_cuda.cu).
  bool early = false;
  // The sweep at a turn (visit_sweeps): the range again at once, the other
  // way (serial: back, one by one; parallel: each contact right after
  // itself), as the next sweep's first launch would.
  bool twice = false;
  // A slot of a plan in device memory instead (a step that waits once: the
  // host does not know the ranges): the launch reads its range there (slot
  // < colours: that colour, in parallel; slot == colours: the overflow set,
  // serial; past it: none), and begin, end and serial are not used. Its
  // grid is sized for `width` contacts and strides over a wider colour.
  const ColourPlan* plan = nullptr;
  std::uint32_t slot = 0, width = 0;
};

// The packed velocity state (solver_math.hpp) from the world, and back;
// the way back does nothing where `skip` (not null) is set when it runs
// (cuda::skipped: a substep that outgrew a room in a step without waits).
void launch_gather_bodies(const BodiesView& world, SolverBody* bodies, int sm_count, cudaStream_t stream);
void launch_scatter_bodies(const SolverBody* bodies, const BodiesView& world, int sm_count, cudaStream_t stream,
                           const unsigned long long* skip = nullptr);

// The stages on the sweep's records (solver_math.hpp), made in colour-major
// order by launch_sorted_records (contacts_cuda.cuh): the impacts, the warm
// start, the sweeps, the position stages and the overlap read them, and the
// whole contacts are made from them when asked for (contact_of_record). The
// same bits as on the contacts.
void launch_warm_start(const SweepRecords& records, ContactRange range, SolverBody* bodies, SolverTerms terms,
                       cudaStream_t stream);
// A sweep's range wider than sm_count SMs hold at two blocks each runs the
// sweep's form bounded to three blocks a SM (sweep_kernel_fits).
void launch_sweep(const SweepRecords& records, ContactRange range, SolverBody* bodies, real inv_h, SolverTerms terms,
                  int sm_count, cudaStream_t stream);
// A run of small ranges of the walk (narrowphase::SmallRangeGroups) as one
// launch: one block walks them in order as their launches one each would
// (for_range: the threads of a range each a contact, a serial one by its
// first thread; twice: a parallel range's contacts each solved again at
// once, a serial one walked back), a barrier between them. `plan` and
// `early` are not used. A launch's ramp and tail cost more than such a
// range's few contacts.
struct RangeGroup {
  std::uint32_t count = 0;
  ContactRange range[kMostInGroup];
};
void launch_warm_start_group(const SweepRecords& records, const RangeGroup& group, SolverBody* bodies,
                             SolverTerms terms, cudaStream_t stream);
void launch_sweep_group(const SweepRecords& records, const RangeGroup& group, SolverBody* bodies, real inv_h,
                        SolverTerms terms, cudaStream_t stream);
// The widest range a group takes: MARBLES_CUDA_GROUP contacts (one a
// thread of the block, 256, unless set: two a thread made the pile of
// 10^5's last colours slower; 0: no group), kept from its first reading; a
// value that is not a count from 0 to 4096 is refused with a RuntimeFailure.
std::uint32_t group_widest();

// A colour plan in device memory (ColouringCuda::device_plan), as the
// stages that walk every colour in one launch read it, and the widest colour
// the launch is shaped for (the host's reading of the plan, or a bound: a
// walk strides over any width, so a wider colour is walked all the same, and
// the bits do not depend on the shape).
struct DevicePlan {
  const ColourPlan* plan = nullptr;
  std::uint32_t widest = 0;
};

// The stages below walk a plan in one launch each (the solver's order,
// visit_colours, a barrier of the whole launch after each colour; the
// overflow set by one thread): the same bits as a launch per colour. The
// launch is one cluster (sm_90) where its range fits one (the solve and
// the projection: the widest colour; the impact stage: all its contacts;
// at most MARBLES_CUDA_CLUSTER contacts, 4096 unless set; 0: never), else
// a cooperative grid: the same bits again. Each says whether it took one
// cluster (false too where it launched nothing).

// MARBLES_CUDA_CLUSTER's widest range for one cluster (kept from its first
// reading; a value that is not a count from 0 to 2^30 is refused with a
// RuntimeFailure).
std::uint32_t cluster_widest();
// The most blocks of one cluster here (largest_cluster of the projection's
// kernel, which every scene with contacts runs): 0 where no one-launch
// stage runs as one.
int cluster_blocks();

// How the velocity sweep's kernels fit a multiprocessor here: the form for
// ranges the SMs hold at two blocks each, then the form for wider ones
// (launch_sweep; the same kernel in double), each friction x rolling x
// twice in that order.
std::vector<KernelFit> sweep_kernel_fits();

// The projection: sweeps until one moves nothing beyond settled_move
// (project_one), at most `sweeps`; moved[0, sweeps) zeroed before, sweep
// `it` sets moved[it]; *total += the sweeps run. Nothing where `skip` is set
// (cuda::skipped).
bool launch_projection(const SweepRecords& records, DevicePlan plan, const BodiesView& bodies, const WallShape* walls,
                       const SolverSettings& settings, int sweeps, unsigned* moved, unsigned long long* total,
                       int sm_count, cudaStream_t stream, const unsigned long long* skip = nullptr);

// The impact stage (ContactSolver::impacts): the candidates level by level
// (`order` and `first` from ColouringCuda::impact_levels, n contacts), then
// passes 1 .. passes - 1 over every contact while the pass before hit
// something; hit[p] (zeroed before) is set when pass p hits. p.shift: a
// word a sphere, zeroed before.
bool launch_impact_stage(const SweepRecords& records, const ImpactRecords& impact, const std::uint32_t* order,
                         const std::uint32_t* first, std::uint32_t n, const ColourPlan* plan, SolverBody* bodies,
                         const ImpactParams& p, bool friction, int passes, unsigned* hit, int sm_count,
                         cudaStream_t stream);

// Velocity Verlet's closing solve around its warm start and sweeps
// (ContactSolver::close_velocities): each of the plan's records its gap at
// the substep's end (close_record; `bodies` gathered after the second kick,
// `world` and `walls` at the substep's end), what
// it held kept in `kept` (a word each of n); then its separation back and
// both solves' impulses (reopen_record). n: the contacts or their room.
// Nothing where `skip` is set (cuda::skipped).
void launch_close_records(const SweepRecords& records, const ColourPlan* plan, std::uint32_t n,
                          const SolverBody* bodies, const BodiesView& world, const WallShape* walls, real rest_speed,
                          const ClosingKept& kept, SolverTerms terms, int sm_count, cudaStream_t stream,
                          const unsigned long long* skip = nullptr);
void launch_reopen_records(const SweepRecords& records, const ColourPlan* plan, std::uint32_t n,
                           const ClosingKept& kept, SolverTerms terms, int sm_count, cudaStream_t stream,
                           const unsigned long long* skip = nullptr);

// The warm start (when `warm`) and `sweeps` sweeps in one launch, where a
// launch per colour would leave the device waiting for the host's launches
// (contacts few a colour).
bool launch_solve(const SweepRecords& records, DevicePlan plan, SolverBody* bodies, real inv_h,
                  SolverTerms terms, bool warm, int sweeps, int sm_count, cudaStream_t stream);

// *deepest = max(*deepest, overlap_ratio) over the records' contacts [0, n) (as the bits
// of a non-negative real: an atomic max, the same whatever the order).
// With count_on_device, records [0, n) are a room (count_within); with
// `skip` set (cuda::skipped), nothing.
void launch_max_overlap(const SweepRecords& records, std::uint32_t n, const BodiesView& bodies, const WallShape* walls,
                        unsigned long long* deepest, int sm_count, cudaStream_t stream,
                        const std::uint32_t* count_on_device = nullptr, const unsigned long long* skip = nullptr);

// The local order's sweeps (solver.hpp LocalOrder, a study switch): the
// CPU's ContactSolver::local_sweeps on the device, the same bits. Each pass
// sweeps every cube's own contacts `local` times (a block a cube, a barrier
// between its colours, its overflow by one thread), then the contacts
// between cubes once, a launch per colour (visit_colours). The split is made
// on the device each substep (a sort of the contacts by cube); nothing is
// read on the host. Slower than the solver's order on an H100 (pile of 10^6:
// 9.6-12.4 against 8.0 ms a step; docs/architecture.md "The local order on
// the GPU, first form").
class LocalSweepsCuda {
 public:
  // count records in colour-major order as `plan` ranges them; the cubes
  // of `diameters` of the world's largest diameter (local_cube_edge, the
  // radius found on the device) over its centres (those of the solve).
  void run(const SweepRecords& records, std::uint32_t count, const ColourPlan& plan, const BodiesView& world,
           double diameters, int passes, int local, int threads, SolverBody* bodies, real inv_h, SolverTerms terms,
           int sm_count, cudaStream_t stream);
  // Device bytes it holds (none until it first runs).
  std::size_t device_bytes() const {
    return ::marbles::cuda::bytes_of(m_keys, m_order, m_heads, m_starts, m_temp, m_largest);
  }

 private:
  ::marbles::cuda::DeviceBuffer m_keys, m_order, m_heads, m_starts, m_temp, m_largest;
};

}  // namespace marbles::narrowphase::cuda
