// narrowphase/solver_cuda.cuh — the CUDA twin of solver.cpp: one launch per
// colour (a thread per contact) over the per-contact functions of
// solver_math.hpp; the overflow set by one thread in order. The host walks
// the colours in the CPU's order, so the result is the CPU's bit for bit.
// Only .cu files include this header.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "core/spheres.hpp"
#include "narrowphase/colouring_math.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {

// The per-contact terms a scene enables: picks the kernel instance once.
struct SolverTerms {
  bool friction = false, rolling = false;
};

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
};

// The packed velocity state (solver_math.hpp) from the world, and back.
void launch_gather_bodies(const BodiesView& world, SolverBody* bodies, int sm_count, cudaStream_t stream);
void launch_scatter_bodies(const SolverBody* bodies, const BodiesView& world, int sm_count, cudaStream_t stream);

// The stages on the sweep's records (solver_math.hpp), made in colour-major
// order by launch_sorted_records (contacts_cuda.cuh): the impacts, the warm
// start, the sweeps, the position stages and the overlap read them, and the
// whole contacts are made from them when asked for (contact_of_record). The
// same bits as on the contacts.
void launch_warm_start(const SweepRecords& records, ContactRange range, SolverBody* bodies, SolverTerms terms,
                       cudaStream_t stream);
void launch_sweep(const SweepRecords& records, ContactRange range, SolverBody* bodies, real inv_h, SolverTerms terms,
                  cudaStream_t stream);
// Impacts of record order[k] for k in range (order null: k itself), with
// its impact word (impact_record); sets *hit = 1 when any hit.
void launch_impacts(const SweepRecords& records, Real4* impact, const std::uint32_t* order, ContactRange range,
                    SolverBody* bodies, const ImpactParams& p, bool friction, unsigned* hit, cudaStream_t stream);
void launch_rebound(const SweepRecords& records, ContactRange range, const BodiesView& bodies, const WallShape* walls,
                    cudaStream_t stream);
// The colour ranges of colour-major contacts as one launch takes them:
// colour c is [begin[c], begin[c + 1]), the overflow set [begin[colours],
// begin[colours + 1]).
struct ColourPlan {
  std::uint32_t begin[kMaxColours + 2] = {};
  std::uint32_t colours = 0;
};

// One projection sweep over every colour in one launch, forwards, the
// overflow set last: does nothing when `go` (the last sweep's flag; null in
// the first sweep) is 0, else sets *moved = 1 when a contact moved beyond
// settled_move (project_one).
void launch_project_sweep(const SweepRecords& records, const ColourPlan& plan, const BodiesView& bodies,
                          const WallShape* walls, const SolverSettings& settings, const unsigned* go, unsigned* moved,
                          int sm_count, cudaStream_t stream);

// *total += the sweeps of a projection that ran, from the flags moved[0,
// sweeps) its launch_project_sweep calls set.
void launch_count_sweeps(const unsigned* moved, int sweeps, unsigned long long* total, cudaStream_t stream);

// *deepest = max(*deepest, overlap_ratio) over the records' contacts [0, n) (as the bits
// of a non-negative real: an atomic max, the same whatever the order).
void launch_max_overlap(const SweepRecords& records, std::uint32_t n, const BodiesView& bodies, const WallShape* walls,
                        unsigned long long* deepest, int sm_count, cudaStream_t stream);

}  // namespace marbles::narrowphase::cuda
