#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "narrowphase/solver_cuda.cuh"

#include <cooperative_groups.h>

#include <algorithm>
#include <utility>

namespace marbles::narrowphase::cuda {
namespace {

namespace cg = cooperative_groups;

using ::marbles::cuda::kBlock;

// Thread t of a range: contact begin + t, or for a serial range, one thread
// visiting the whole range in order.
template <class F>
__device__ void for_range(const ContactRange& r, F&& f) {
  if (r.serial) {
    if (blockIdx.x != 0 || threadIdx.x != 0) return;
    if (r.backwards)
      for (std::uint32_t k = r.end; k > r.begin; --k) f(k - 1);
    else
      for (std::uint32_t k = r.begin; k < r.end; ++k) f(k);
    return;
  }
  const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t < r.end - r.begin) f(r.mirrored ? r.end - 1 - t : r.begin + t);
}

inline int blocks(const ContactRange& r) {
  return r.serial ? 1 : static_cast<int>((r.end - r.begin + kBlock - 1) / kBlock);
}

__global__ void gather_bodies_kernel(BodiesView world, SolverBody* bodies) {
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < world.count; i += gridDim.x * blockDim.x)
    bodies[i] = gather_solver_body(world, i);
}

__global__ void scatter_bodies_kernel(const SolverBody* bodies, BodiesView world) {
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < world.count; i += gridDim.x * blockDim.x)
    scatter_solver_body(world, i, bodies[i]);
}

// Programmatic dependent launch (sm_90): a colour's launch lets the next one
// start as its own last blocks run (launch_dependents), and the next one's
// threads wait for it to finish, its writes visible (wait), before they touch
// a body. A block lets the next launch start only after its own wait, so a
// launch starts early only once the one before the last has ended: what a
// thread reads before its wait need only be safe from the launch just
// before, a record of another range (ContactRange::early), never a body.
// Elsewhere both are no-ops.
__device__ __forceinline__ void let_next_launch_start() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  asm volatile("griddepcontrol.launch_dependents;" ::: "memory");
#endif
}
__device__ __forceinline__ void wait_for_last_launch() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  asm volatile("griddepcontrol.wait;" ::: "memory");
#endif
}

// A parallel range's thread loads what it may before its wait (load(k)),
// then does its work (work(k, loaded)); every thread waits, so the launch
// ends only after the one before it. A serial range waits first.
template <class Load, class Work>
__device__ void for_range_early(const ContactRange& r, Load&& load, Work&& work) {
  const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  const bool early = r.early && !r.serial && t < r.end - r.begin;
  const std::uint32_t k = r.mirrored ? r.end - 1 - t : r.begin + t;
  decltype(load(k)) loaded{};
  if (early) loaded = load(k);
  // Any thread past its wait means the launch before has ended.
  wait_for_last_launch();
  let_next_launch_start();
  if (early) work(k, loaded);
  else for_range(r, [&](std::uint32_t j) { work(j, load(j)); });
}

template <bool Friction, bool Rolling>
__global__ void warm_start_kernel(SweepRecords records, ContactRange r, SolverBody* bodies) {
  for_range_early(
      r, [&](std::uint32_t k) { return load_streaming(records.impulse + k); },
      [&](std::uint32_t k, const Real4& i) { warm_start_loaded<Friction, Rolling>(records, k, i, bodies); });
}

template <bool Friction, bool Rolling>
__global__ void record_sweep_kernel(SweepRecords s, ContactRange r, SolverBody* bodies, real inv_h) {
  for_range_early(
      r, [&](std::uint32_t k) { return load_sweep_contact<Friction, Rolling>(s, k); },
      [&](std::uint32_t k, const Contact& c) { solve_loaded<Friction, Rolling>(s, k, c, bodies, inv_h); });
}

// A launch of a colour kernel that may start before the last one ends
// (programmatic stream serialization; its threads wait as above).
template <class... Params, class... Args>
void launch_colour(void (*kernel)(Params...), int grid, cudaStream_t s, Args&&... args) {
  cudaLaunchConfig_t config{};
  config.gridDim = dim3(static_cast<unsigned>(grid));
  config.blockDim = dim3(kBlock);
  config.stream = s;
  cudaLaunchAttribute attribute[1];
  attribute[0].id = cudaLaunchAttributeProgrammaticStreamSerialization;
  attribute[0].val.programmaticStreamSerializationAllowed = 1;
  config.attrs = attribute;
  config.numAttrs = 1;
  MARBLES_CUDA_CHECK(cudaLaunchKernelEx(&config, kernel, std::forward<Args>(args)...));
  MARBLES_CUDA_CHECK_LAUNCH();  // with MARBLES_CUDA_SYNC=1: a wait, the kernel's error here
}

template <bool Friction>
__global__ void impact_kernel(SweepRecords records, Real4* impact, const std::uint32_t* order, ContactRange r,
                              SolverBody* bodies, ImpactParams p, unsigned* hit) {
  bool any = false;
  for_range(r, [&](std::uint32_t k) {
    any = impact_record<Friction>(records, impact, order ? order[k] : k, bodies, p) || any;
  });
  if (any) *hit = 1u;
}

__global__ void rebound_kernel(SweepRecords records, ContactRange r, BodiesView bodies, const WallShape* walls) {
  for_range(r, [&](std::uint32_t k) { rebound_one(load_position_contact<true>(records, k), bodies, walls); });
}

// One projection sweep: the colours in order, a grid-wide barrier after
// each (a cooperative launch), then the overflow set by one thread. A sweep
// after one that moved nothing beyond settled_move (*go == 0) returns at
// once, every block alike (solver.cpp ends the projection there): one
// launch, where a launch per colour cost ~4 us each of the sweeps not run.
__global__ void project_sweep_kernel(SweepRecords records, ColourPlan plan, BodiesView bodies,
                                     const WallShape* walls, SolverSettings s, const unsigned* go, unsigned* moved) {
  if (go != nullptr && *go == 0u) return;
  const cg::grid_group grid = cg::this_grid();
  const std::uint32_t first = blockIdx.x * blockDim.x + threadIdx.x, stride = gridDim.x * blockDim.x;
  bool any = false;
  for (std::uint32_t c = 0; c < plan.colours; ++c) {
    for (std::uint32_t k = plan.begin[c] + first; k < plan.begin[c + 1]; k += stride)
      any = project_one(load_position_contact<false>(records, k), bodies, walls, s) || any;
    grid.sync();
  }
  if (first == 0)
    for (std::uint32_t k = plan.begin[plan.colours]; k < plan.begin[plan.colours + 1]; ++k)
      any = project_one(load_position_contact<false>(records, k), bodies, walls, s) || any;
  if (any) *moved = 1u;
}

// Sweep 0 always runs, sweep it > 0 when sweep it - 1 set moved[it - 1].
__global__ void count_sweeps_kernel(const unsigned* moved, int sweeps, unsigned long long* total) {
  unsigned long long ran = 1;
  for (int it = 1; it < sweeps; ++it) ran += moved[it - 1] != 0u ? 1u : 0u;
  *total += ran;
}

__global__ void max_overlap_kernel(SweepRecords records, std::uint32_t n, BodiesView bodies, const WallShape* walls,
                                   unsigned long long* deepest) {
  real d = 0;
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x) {
    const real o = overlap_ratio(load_position_contact<false>(records, k), bodies, walls);
    d = o > d ? o : d;
  }
  if constexpr (sizeof(real) == 4)
    ::marbles::cuda::warp_atomic_max(deepest, static_cast<unsigned long long>(__float_as_uint(d)));
  else
    ::marbles::cuda::warp_atomic_max(deepest, static_cast<unsigned long long>(__double_as_longlong(d)));
}

}  // namespace

void launch_max_overlap(const SweepRecords& records, std::uint32_t n, const BodiesView& bodies, const WallShape* walls,
                        unsigned long long* deepest, int sm_count, cudaStream_t s) {
  if (n == 0) return;
  max_overlap_kernel<<<::marbles::cuda::grid_for(n, sm_count), kBlock, 0, s>>>(records, n, bodies, walls, deepest);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_gather_bodies(const BodiesView& world, SolverBody* bodies, int sm_count, cudaStream_t s) {
  if (world.count == 0) return;
  gather_bodies_kernel<<<::marbles::cuda::grid_for(world.count, sm_count), kBlock, 0, s>>>(world, bodies);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_scatter_bodies(const SolverBody* bodies, const BodiesView& world, int sm_count, cudaStream_t s) {
  if (world.count == 0) return;
  scatter_bodies_kernel<<<::marbles::cuda::grid_for(world.count, sm_count), kBlock, 0, s>>>(bodies, world);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_warm_start(const SweepRecords& records, ContactRange r, SolverBody* bodies, SolverTerms t, cudaStream_t s) {
  if (r.end <= r.begin) return;
  const int g = blocks(r);
  if (t.friction && t.rolling) launch_colour(warm_start_kernel<true, true>, g, s, records, r, bodies);
  else if (t.friction) launch_colour(warm_start_kernel<true, false>, g, s, records, r, bodies);
  else if (t.rolling) launch_colour(warm_start_kernel<false, true>, g, s, records, r, bodies);
  else launch_colour(warm_start_kernel<false, false>, g, s, records, r, bodies);
}

void launch_sweep(const SweepRecords& records, ContactRange r, SolverBody* bodies, real inv_h, SolverTerms t,
                  cudaStream_t s) {
  if (r.end <= r.begin) return;
  const int g = blocks(r);
  if (t.friction && t.rolling) launch_colour(record_sweep_kernel<true, true>, g, s, records, r, bodies, inv_h);
  else if (t.friction) launch_colour(record_sweep_kernel<true, false>, g, s, records, r, bodies, inv_h);
  else if (t.rolling) launch_colour(record_sweep_kernel<false, true>, g, s, records, r, bodies, inv_h);
  else launch_colour(record_sweep_kernel<false, false>, g, s, records, r, bodies, inv_h);
}

void launch_impacts(const SweepRecords& records, Real4* impact, const std::uint32_t* order, ContactRange r,
                    SolverBody* bodies, const ImpactParams& p, bool friction, unsigned* hit, cudaStream_t s) {
  if (r.end <= r.begin) return;
  if (friction)
    impact_kernel<true><<<blocks(r), kBlock, 0, s>>>(records, impact, order, r, bodies, p, hit);
  else
    impact_kernel<false><<<blocks(r), kBlock, 0, s>>>(records, impact, order, r, bodies, p, hit);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_rebound(const SweepRecords& records, ContactRange r, const BodiesView& bodies, const WallShape* walls,
                    cudaStream_t s) {
  if (r.end <= r.begin) return;
  rebound_kernel<<<blocks(r), kBlock, 0, s>>>(records, r, bodies, walls);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_project_sweep(const SweepRecords& records, const ColourPlan& plan, const BodiesView& bodies,
                          const WallShape* walls, const SolverSettings& settings, const unsigned* go, unsigned* moved,
                          int sm_count, cudaStream_t s) {
  std::uint32_t widest = 0;
  for (std::uint32_t c = 0; c < plan.colours; ++c) widest = std::max(widest, plan.begin[c + 1] - plan.begin[c]);
  if (widest == 0 && plan.begin[plan.colours + 1] == plan.begin[plan.colours]) return;
  static const int resident = ::marbles::cuda::resident_per_sm(project_sweep_kernel);
  const int grid = ::marbles::cuda::grid_for(widest, sm_count, resident);
  SweepRecords r = records;
  ColourPlan p = plan;
  BodiesView b = bodies;
  SolverSettings set = settings;
  void* args[] = {&r, &p, &b, &walls, &set, &go, &moved};
  MARBLES_CUDA_CHECK(cudaLaunchCooperativeKernel(reinterpret_cast<const void*>(&project_sweep_kernel), dim3(grid),
                                                 dim3(kBlock), args, 0, s));
}

void launch_count_sweeps(const unsigned* moved, int sweeps, unsigned long long* total, cudaStream_t s) {
  if (sweeps <= 0) return;
  count_sweeps_kernel<<<1, 1, 0, s>>>(moved, sweeps, total);
  MARBLES_CUDA_CHECK_LAUNCH();
}

}  // namespace marbles::narrowphase::cuda
