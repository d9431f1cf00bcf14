#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "core/environment.hpp"
#include "core/lower_bound.hpp"
#include "narrowphase/solver_cuda.cuh"

#include <cub/device/device_radix_sort.cuh>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <utility>

namespace marbles::narrowphase::cuda {
namespace {

using ::marbles::cuda::kBlock;
using ::marbles::cuda::Launch;
using ::marbles::cuda::launch;

// A range as its launch runs it: a plan's slot read from the plan (the
// colouring wrote it launches before: it may be read before the wait for the
// launch just before).
__device__ ContactRange resolved(ContactRange r) {
  if (!r.plan) return r;
  const std::uint32_t colours = r.plan->colours;
  if (r.slot > colours) {
    r.begin = r.end = 0;
    r.serial = false;
    return r;
  }
  r.begin = r.plan->begin[r.slot];
  r.end = r.plan->begin[r.slot + 1];
  r.serial = r.slot == colours;
  return r;
}

// The u-th contact of a parallel range (mirrored: from the end).
__device__ __forceinline__ std::uint32_t contact_at(const ContactRange& r, std::uint32_t u) {
  return r.mirrored ? r.end - 1 - u : r.begin + u;
}

// f(contact_at(r, u)) for u = from, from + the grid's threads, ... within
// the range.
template <class F>
__device__ __forceinline__ void stride_over(const ContactRange& r, std::uint32_t from, F&& f) {
  for (std::uint32_t u = from; u < r.end - r.begin; u += gridDim.x * blockDim.x) f(contact_at(r, u));
}

// Thread t of a range: contacts begin + t, + the grid's threads, ...
// (mirrored: from the end), or for a serial range, one thread visiting the
// whole range in order (and back, twice).
template <class F>
__device__ void for_range(const ContactRange& r, F&& f) {
  if (r.serial) {
    if (blockIdx.x != 0 || threadIdx.x != 0) return;
    for (int pass = 0; pass < (r.twice ? 2 : 1); ++pass) {
      if (r.backwards != (pass == 1)) {
        for (std::uint32_t k = r.end; k > r.begin; --k) f(k - 1);
      } else {
        for (std::uint32_t k = r.begin; k < r.end; ++k) f(k);
      }
    }
    return;
  }
  stride_over(r, blockIdx.x * blockDim.x + threadIdx.x, f);
}

inline int blocks(const ContactRange& r) {
  if (r.plan) return static_cast<int>(std::max<std::uint32_t>(1, (r.width + kBlock - 1) / kBlock));
  return r.serial ? 1 : static_cast<int>((r.end - r.begin + kBlock - 1) / kBlock);
}

__global__ void gather_bodies_kernel(BodiesView world, SolverBody* bodies) {
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < world.count; i += gridDim.x * blockDim.x)
    bodies[i] = gather_solver_body(world, i);
}

// f(k) for each of a plan's contacts, over the launch's threads (n, the
// launch's size, may be a room's: past the plan's contacts the records are
// not this substep's).
template <class F>
__device__ void for_plan_contacts(const ColourPlan& plan, F&& f) {
  const std::uint32_t contacts = plan.begin[plan.colours + 1];
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < contacts; k += gridDim.x * blockDim.x) f(k);
}

// Velocity Verlet's closing solve: each of the plan's records takes its gap
// at the substep's end (close_record), then its separation back and both
// solves' impulses (reopen_record).
template <bool Friction, bool Rolling>
__global__ void close_records_kernel(const ColourPlan* plan, SweepRecords s, const SolverBody* bodies,
                                     BodiesView world, const WallShape* walls, real rest_speed, ClosingKept kept,
                                     const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  for_plan_contacts(*plan, [&](std::uint32_t k) {
    close_record<Friction, Rolling>(s, k, bodies, world, walls, rest_speed, kept);
  });
}

template <bool Friction, bool Rolling>
__global__ void reopen_records_kernel(const ColourPlan* plan, SweepRecords s, ClosingKept kept,
                                      const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  for_plan_contacts(*plan, [&](std::uint32_t k) { reopen_record<Friction, Rolling>(s, k, kept); });
}

__global__ void scatter_bodies_kernel(const SolverBody* bodies, BodiesView world, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
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
__device__ void for_range_early(const ContactRange& range, Load&& load, Work&& work) {
  const ContactRange r = resolved(range);
  const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  const bool early = r.early && !r.serial && t < r.end - r.begin;
  const std::uint32_t k = contact_at(r, t);
  decltype(load(k)) loaded{};
  if (early) loaded = load(k);
  // Any thread past its wait means the launch before has ended.
  wait_for_last_launch();
  let_next_launch_start();
  if (early) {
    work(k, loaded);
    // the rest of a colour wider than the grid (a plan's slot)
    stride_over(r, t + gridDim.x * blockDim.x, [&](std::uint32_t j) { work(j, load(j)); });
  } else {
    for_range(r, [&](std::uint32_t j) { work(j, load(j)); });
  }
}

template <bool Friction, bool Rolling>
__global__ void warm_start_kernel(SweepRecords records, ContactRange r, SolverBody* bodies) {
  for_range_early(
      r, [&](std::uint32_t k) { return streamed_impulse_word<Friction>(records, k); },
      [&](std::uint32_t k, const Real4& i) { warm_start_loaded<Friction, Rolling>(records, k, i, bodies); });
}

// Twice (a parallel range at a turn): each contact solved again at once
// from what it just wrote; its bodies and record are no other thread's in
// the launch, so it reads what the next launch would. Its own instance, so
// the sweep of every other launch keeps its registers. (A serial range at a
// turn walks back in for_range: a plan's slot that turns out to be the
// overflow set is solved once a visit.)
template <bool Friction, bool Rolling, bool Twice>
__device__ __forceinline__ void sweep_range(const SweepRecords& s, const ContactRange& r, SolverBody* bodies,
                                            real inv_h) {
  const bool again = Twice && !(r.plan && r.slot == r.plan->colours);
  for_range_early(
      r, [&](std::uint32_t k) { return load_sweep_contact<Friction, Rolling>(s, k); },
      [&](std::uint32_t k, const Contact& c) {
        solve_loaded<Friction, Rolling>(s, k, c, bodies, inv_h);
        if (again) solve_record<Friction, Rolling>(s, k, bodies, inv_h);
      });
}

template <bool Friction, bool Rolling, bool Twice>
__global__ void record_sweep_kernel(SweepRecords s, ContactRange r, SolverBody* bodies, real inv_h) {
  sweep_range<Friction, Rolling, Twice>(s, r, bodies, inv_h);
}

// The sweep of a range wider than the SMs hold at two blocks each, bounded
// to three blocks a SM: left to itself the compiler gives the sweep with
// friction and rolling 94 registers, two blocks of 256 a SM (a quarter of
// the warps) waiting on their loads; bounded, 72 and nothing spilled (four
// blocks spill 68 bytes or more). Pile of 10^6 (H200, two rounds): solve
// 4.51 -> 4.32 ms. A narrow range keeps the unbounded form: with the bound
// a colour of the pile of 10^5 (about one block a SM) sweeps slower, 0.695
// -> 0.747 ms of solve (docs/architecture.md "The sweep's warps"). In
// double the bound would spill kilobytes, and any bound moves the
// registers: one form.
#if defined(MARBLES_DOUBLE)
template <bool Friction, bool Rolling, bool Twice>
constexpr auto wide_sweep_kernel = record_sweep_kernel<Friction, Rolling, Twice>;
#else
template <bool Friction, bool Rolling, bool Twice>
__global__ void __launch_bounds__(kBlock, 3)
    wide_sweep_kernel(SweepRecords s, ContactRange r, SolverBody* bodies, real inv_h) {
  sweep_range<Friction, Rolling, Twice>(s, r, bodies, inv_h);
}
#endif

// A group's ranges in order by the launch's one block (RangeGroup), each as
// for_range walks it, a barrier after each: f(k, again) for each visit,
// again where a parallel range is visited twice (a serial one for_range
// walks back itself). It waits for the launch before first: what it reads
// is mostly that launch's.
template <class F>
__device__ void walk_group(const RangeGroup& g, F&& f) {
  wait_for_last_launch();
  let_next_launch_start();
  for (std::uint32_t i = 0; i < g.count; ++i) {
    const ContactRange r = g.range[i];
    const bool again = r.twice && !r.serial;
    for_range(r, [&](std::uint32_t k) { f(k, again); });
    __syncthreads();  // the range's writes seen by the block's threads
  }
}

template <bool Friction, bool Rolling>
__global__ void group_warm_start_kernel(SweepRecords s, RangeGroup g, SolverBody* bodies) {
  walk_group(g, [&](std::uint32_t k, bool) { warm_start_record<Friction, Rolling>(s, k, bodies); });
}

template <bool Friction, bool Rolling>
__global__ void group_sweep_kernel(SweepRecords s, RangeGroup g, SolverBody* bodies, real inv_h) {
  walk_group(g, [&](std::uint32_t k, bool again) {
    solve_record<Friction, Rolling>(s, k, bodies, inv_h);
    if (again) solve_record<Friction, Rolling>(s, k, bodies, inv_h);
  });
}

// What the blocks of a one-launch stage meet at after each range
// (core/device_buffer.cuh; docs/architecture.md "One cluster for a small
// solve").
using ::marbles::cuda::ClusterSync;
using ::marbles::cuda::GridSync;

// One range [b, e) of a one-launch stage: spread over the launch's threads,
// or (serial) by one thread in order, reversed when asked; then the
// launch's barrier. Every block skips the same empty ranges. f(k) for each k.
template <class Sync, class F>
__device__ void walk_range(std::uint32_t b, std::uint32_t e, bool serial, bool reversed, const Sync& grid, F&& f) {
  if (e <= b) return;
  const std::uint32_t first = blockIdx.x * blockDim.x + threadIdx.x, stride = gridDim.x * blockDim.x;
  if (!serial)
    for (std::uint32_t k = b + first; k < e; k += stride) f(k);
  else if (first == 0 && reversed)
    for (std::uint32_t k = e; k > b; --k) f(k - 1);
  else if (first == 0)
    for (std::uint32_t k = b; k < e; ++k) f(k);
  grid.sync();
}

// A one-launch stage's plan, read from device memory into the block's
// shared memory once (the stage walks it some hundred times).
__device__ const ColourPlan& shared_plan(const ColourPlan* plan) {
  constexpr unsigned kWords = sizeof(ColourPlan) / sizeof(std::uint32_t);
  __shared__ std::uint32_t words[kWords];
  const auto* from = reinterpret_cast<const std::uint32_t*>(plan);
  for (unsigned i = threadIdx.x; i < kWords; i += blockDim.x) words[i] = from[i];
  __syncthreads();
  return *reinterpret_cast<const ColourPlan*>(words);
}

// Every contact of a colour plan in the solver's order (visit_colours), a
// range at a time (walk_range).
template <class Sync, class F>
__device__ void walk_colours(const ColourPlan& plan, bool backwards, const Sync& grid, F&& f) {
  visit_colours(plan.begin, plan.colours, backwards,
                [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
                  walk_range(b, e, serial, reversed, grid, f);
                });
}

__device__ __forceinline__ bool flag_set(const unsigned* flag) { return ::marbles::cuda::read_volatile(flag) != 0u; }

// Sets *flag the first time `happened` in this thread (one store a thread at
// most); the barrier that ends the range makes it visible to every block.
__device__ __forceinline__ void raise_once(bool happened, bool& raised, unsigned* flag) {
  if (happened && !raised) {
    raised = true;
    *flag = 1u;
  }
}

// The projection in one launch: sweeps until one moves nothing beyond
// settled_move (project_one), at most `sweeps` (projection_limit), each with
// projection_sweep_settings, as solver.cpp runs them. Sweep `it` sets
// moved[it] (zeroed before), which every block reads after the barrier that
// ends the sweep's last colour. *total += the
// sweeps run (solver.cpp ends the projection there too).
template <class Sync>
__global__ void project_kernel(const ColourPlan* plan_memory, SweepRecords records, BodiesView bodies,
                               const WallShape* walls, SolverSettings s, int sweeps, unsigned* moved,
                               unsigned long long* total, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;  // every block reads the same word: none waits at a barrier alone
  const Sync grid;
  const ColourPlan& plan = shared_plan(plan_memory);
  if (plan.empty()) return;  // a room without contacts (a step without waits): no sweep, as on the CPU
  int ran = 0;
  for (int it = 0; it < sweeps; ++it) {
    ++ran;
    bool raised = false;
    const SolverSettings sweep = projection_sweep_settings(s, it);
    walk_colours(plan, false, grid, [&](std::uint32_t k) {
      raise_once(project_one(load_position_contact(records, k), bodies, walls, sweep), raised, moved + it);
    });
    if (!flag_set(moved + it)) break;
  }
  if (blockIdx.x == 0 && threadIdx.x == 0) *total += static_cast<unsigned long long>(ran);
}

// The impact stage in one launch. Pass 0: the candidates level by level
// (their order and the firsts of the levels' keys from the colouring's
// impact_levels; a level's contacts spread over the launch, the overflow
// set by one thread), the launch's barrier after each. Pass p > 0: every
// contact colour by colour, while pass p - 1 hit something. hit[p] (zeroed
// before) records what pass p hit. Then, where pass 0 hit, every contact's
// gap takes its bodies' shifts (shifted_gap).
template <bool Friction, class Sync>
__global__ void impact_stage_kernel(const ColourPlan* plan_memory, SweepRecords records, ImpactRecords impact,
                                    const std::uint32_t* order, const std::uint32_t* first, std::uint32_t n,
                                    SolverBody* bodies, ImpactParams p, int passes, unsigned* hit) {
  const Sync grid;
  const ColourPlan& plan = shared_plan(plan_memory);
  bool raised = false;
  visit_levels(first, n, [&](std::uint32_t b, std::uint32_t e, bool serial) {
    walk_range(b, e, serial, false, grid, [&](std::uint32_t k) {
      raise_once(impact_record<Friction>(records, impact, order[k], bodies, p), raised, hit);
    });
  });
  for (int pass = 1; pass < passes && flag_set(hit + pass - 1); ++pass) {
    raised = false;
    walk_colours(plan, false, grid, [&](std::uint32_t k) {
      raise_once(impact_record<Friction>(records, impact, k, bodies, p), raised, hit + pass);
    });
  }
  if (!flag_set(hit)) return;  // every block reads the same word after the last barrier
  grid.sync();
  for_plan_contacts(plan, [&](std::uint32_t k) { shifted_gap(records, p.shift, k); });
}

// The warm start and every sweep of a substep in one launch, in the order of
// the launches per colour (forwards, then backwards every other sweep): the
// same bits. For contacts few enough a colour that the host's launches, not
// the device, would set the solve's time.
template <bool Friction, bool Rolling, class Sync>
__global__ void solve_kernel(const ColourPlan* plan_memory, SweepRecords s, SolverBody* bodies, real inv_h, bool warm,
                             int sweeps) {
  const Sync grid;
  const ColourPlan& plan = shared_plan(plan_memory);
  if (warm) walk_colours(plan, false, grid, [&](std::uint32_t k) { warm_start_record<Friction, Rolling>(s, k, bodies); });
  for (int it = 0; it < sweeps; ++it)
    walk_colours(plan, it % 2 == 1, grid, [&](std::uint32_t k) { solve_record<Friction, Rolling>(s, k, bodies, inv_h); });
}

__global__ void max_overlap_kernel(SweepRecords records, std::uint32_t items, const std::uint32_t* count_on_device,
                                   BodiesView bodies, const WallShape* walls, unsigned long long* deepest,
                                   const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  const auto n = static_cast<std::uint32_t>(::marbles::cuda::count_within(items, count_on_device));
  real d = 0;
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x) {
    const real o = overlap_ratio(load_position_contact(records, k), bodies, walls);
    d = o > d ? o : d;
  }
  ::marbles::cuda::warp_atomic_max(deepest, bits_of_real(d));
}


// --- the local order (LocalSweepsCuda) -----------------------------------------
// A contact between cubes sorts after every cube's own (a cube is 63 bits).
constexpr std::uint64_t kBetweenCubes = ~std::uint64_t(0);

// *largest = the largest radius's bits (zeroed before; radii are >= 0, so
// their bits order as they do: the exact largest, as the CPU's scan finds).
__global__ void largest_radius_kernel(const real* radius, std::size_t n, unsigned long long* largest) {
  unsigned long long top = 0;
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < n; i += std::size_t(gridDim.x) * blockDim.x) {
    const unsigned long long b = bits_of_real(radius[i]);
    top = b > top ? b : top;
  }
  ::marbles::cuda::warp_atomic_max(largest, top);
}

// Record k's cube where it is that cube's own (both spheres in it, or b a
// wall), else kBetweenCubes; order[k] = k, so the stable sort keeps k
// ascending within a cube, as split_by_cube does. The cubes' edge is
// `diameters` of the largest diameter.
__global__ void cube_keys_kernel(const BodyPair* pairs, std::uint32_t n, const Vec3* position, double diameters,
                                 const unsigned long long* largest, std::uint64_t* keys, std::uint32_t* order) {
  const double edge = local_cube_edge(diameters, real_of_bits(*largest));
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x) {
    const BodyPair ab = pairs[k];
    const std::uint64_t t = local_cube(position[ab.a], edge);
    keys[k] = is_wall(ab.b) || local_cube(position[ab.b], edge) == t ? t : kBetweenCubes;
    order[k] = k;
  }
}

// heads[k] = 1 where sorted key k starts a cube; heads[n] = 0.
__global__ void cube_heads_kernel(const std::uint64_t* keys, std::uint32_t n, std::uint32_t* heads) {
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k <= n; k += gridDim.x * blockDim.x)
    heads[k] = k < n && keys[k] != kBetweenCubes && (k == 0 || keys[k - 1] != keys[k]) ? 1u : 0u;
}

// starts[slot[k]] = k at each head; starts[cubes] = the own contacts' count
// (cubes = slot[n]).
__global__ void cube_starts_kernel(const std::uint64_t* keys, std::uint32_t n, const std::uint32_t* heads,
                                   const std::uint32_t* slot, std::uint32_t* starts) {
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k <= n; k += gridDim.x * blockDim.x) {
    if (k < n && heads[k]) starts[slot[k]] = k;
    const bool own_before = k > 0 && keys[k - 1] != kBetweenCubes;
    const bool own_here = k < n && keys[k] != kBetweenCubes;
    if ((k == 0 && !own_here) || (own_before && !own_here)) starts[slot[n]] = k;
  }
}

// First i in [b, e) with order[i] >= v (order ascending there).
__device__ std::uint32_t first_at_or_past(const std::uint32_t* order, std::uint32_t b, std::uint32_t e,
                                          std::uint32_t v) {
  return b + lower_bound_key(order + b, e - b, v);
}

// The contacts between cubes, order[own, n): each colour's first among them
// (ContactSolver::local_sweeps' m_between_begin), as positions in order.
__global__ void between_begin_kernel(const std::uint32_t* order, std::uint32_t n, const std::uint32_t* starts,
                                     const std::uint32_t* cubes, ColourPlan plan, std::uint32_t* between_begin) {
  const std::uint32_t own = starts[*cubes];
  for (std::uint32_t c = threadIdx.x; c <= plan.colours + 1; c += blockDim.x)
    between_begin[c] = c <= plan.colours ? first_at_or_past(order, own, n, plan.begin[c]) : n;
}

// One pass over the cubes: each cube's own contacts swept `local` times,
// forwards where (l + pass) is even (colour by colour, the overflow last, one
// thread in order), else backwards (the overflow first, in reverse, then the
// colours from the last); a barrier after each. Within a colour no two
// contacts share a sphere and no two cubes share one, so the threads' order
// changes no bit: the CPU's walk, one by one in record order.
template <bool Friction, bool Rolling>
__global__ void local_pass_kernel(SweepRecords s, const std::uint32_t* order, const std::uint32_t* starts,
                                  const std::uint32_t* cubes, ColourPlan plan, SolverBody* bodies, real inv_h,
                                  int pass, int local) {
  __shared__ std::uint32_t bound[kMaxColours + 2];
  const std::uint32_t count = *cubes, colours = plan.colours;
  for (std::uint32_t t = blockIdx.x; t < count; t += gridDim.x) {
    const std::uint32_t b = starts[t], e = starts[t + 1];
    for (std::uint32_t c = threadIdx.x; c <= colours + 1; c += blockDim.x)
      bound[c] = c <= colours ? first_at_or_past(order, b, e, plan.begin[c]) : e;
    __syncthreads();
    auto colour = [&](std::uint32_t c) {
      const std::uint32_t from = bound[c], to = bound[c + 1];
      if (from == to) return;
      for (std::uint32_t i = from + threadIdx.x; i < to; i += blockDim.x)
        solve_record<Friction, Rolling>(s, order[i], bodies, inv_h);
      __syncthreads();
    };
    auto overflow = [&](bool backwards) {
      const std::uint32_t from = bound[colours], to = bound[colours + 1];
      if (from == to) return;
      if (threadIdx.x == 0) {
        if (backwards)
          for (std::uint32_t i = to; i-- > from;) solve_record<Friction, Rolling>(s, order[i], bodies, inv_h);
        else
          for (std::uint32_t i = from; i < to; ++i) solve_record<Friction, Rolling>(s, order[i], bodies, inv_h);
      }
      __syncthreads();
    };
    for (int l = 0; l < local; ++l) {
      if ((l + pass) % 2 == 0) {
        for (std::uint32_t c = 0; c < colours; ++c) colour(c);
        overflow(false);
      } else {
        overflow(true);
        for (std::uint32_t c = colours; c-- > 0;) colour(c);
      }
    }
    __syncthreads();  // every thread done with bound[] before the next cube's
  }
}

// Colour c of the contacts between cubes: in parallel, or (serial) by one
// thread in order, reversed when asked.
template <bool Friction, bool Rolling>
__global__ void between_kernel(SweepRecords s, const std::uint32_t* order, const std::uint32_t* between_begin,
                               std::uint32_t c, bool serial, bool reversed, SolverBody* bodies, real inv_h) {
  const std::uint32_t b = between_begin[c], e = between_begin[c + 1];
  if (serial) {
    if (blockIdx.x != 0 || threadIdx.x != 0) return;
    if (reversed)
      for (std::uint32_t i = e; i-- > b;) solve_record<Friction, Rolling>(s, order[i], bodies, inv_h);
    else
      for (std::uint32_t i = b; i < e; ++i) solve_record<Friction, Rolling>(s, order[i], bodies, inv_h);
    return;
  }
  for (std::uint32_t i = b + blockIdx.x * blockDim.x + threadIdx.x; i < e; i += gridDim.x * blockDim.x)
    solve_record<Friction, Rolling>(s, order[i], bodies, inv_h);
}

}  // namespace

void launch_max_overlap(const SweepRecords& records, std::uint32_t n, const BodiesView& bodies, const WallShape* walls,
                        unsigned long long* deepest, int sm_count, cudaStream_t s, const std::uint32_t* count_on_device,
                        const unsigned long long* skip) {
  if (n == 0) return;
  max_overlap_kernel<<<::marbles::cuda::grid_for(n, sm_count), kBlock, 0, s>>>(records, n, count_on_device, bodies,
                                                                               walls, deepest, skip);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_gather_bodies(const BodiesView& world, SolverBody* bodies, int sm_count, cudaStream_t s) {
  if (world.count == 0) return;
  gather_bodies_kernel<<<::marbles::cuda::grid_for(world.count, sm_count), kBlock, 0, s>>>(world, bodies);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_scatter_bodies(const SolverBody* bodies, const BodiesView& world, int sm_count, cudaStream_t s,
                           const unsigned long long* skip) {
  if (world.count == 0) return;
  scatter_bodies_kernel<<<::marbles::cuda::grid_for(world.count, sm_count), kBlock, 0, s>>>(bodies, world, skip);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_close_records(const SweepRecords& records, const ColourPlan* plan, std::uint32_t n,
                          const SolverBody* bodies, const BodiesView& world, const WallShape* walls, real rest_speed,
                          const ClosingKept& kept, SolverTerms t, int sm_count, cudaStream_t s,
                          const unsigned long long* skip) {
  if (n == 0) return;
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    close_records_kernel<friction, rolling><<<::marbles::cuda::grid_for(n, sm_count), kBlock, 0, s>>>(
        plan, records, bodies, world, walls, rest_speed, kept, skip);
    MARBLES_CUDA_CHECK_LAUNCH();
  });
}

void launch_reopen_records(const SweepRecords& records, const ColourPlan* plan, std::uint32_t n,
                           const ClosingKept& kept, SolverTerms t, int sm_count, cudaStream_t s,
                           const unsigned long long* skip) {
  if (n == 0) return;
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    reopen_records_kernel<friction, rolling><<<::marbles::cuda::grid_for(n, sm_count), kBlock, 0, s>>>(
        plan, records, kept, skip);
    MARBLES_CUDA_CHECK_LAUNCH();
  });
}

void launch_warm_start(const SweepRecords& records, ContactRange r, SolverBody* bodies, SolverTerms t, cudaStream_t s) {
  if (!r.plan && r.end <= r.begin) return;
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    launch(Launch::dependent, warm_start_kernel<friction, rolling>, blocks(r), s, records, r, bodies);
  });
}

void launch_sweep(const SweepRecords& records, ContactRange r, SolverBody* bodies, real inv_h, SolverTerms t,
                  int sm_count, cudaStream_t s) {
  if (!r.plan && r.end <= r.begin) return;
  const int grid = blocks(r);
  const bool wide = grid > 2 * sm_count;
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    if (r.twice && !r.serial)
      launch(Launch::dependent,
             wide ? wide_sweep_kernel<friction, rolling, true> : record_sweep_kernel<friction, rolling, true>, grid, s,
             records, r, bodies, inv_h);
    else
      launch(Launch::dependent,
             wide ? wide_sweep_kernel<friction, rolling, false> : record_sweep_kernel<friction, rolling, false>, grid,
             s, records, r, bodies, inv_h);
  });
}

void launch_warm_start_group(const SweepRecords& records, const RangeGroup& g, SolverBody* bodies, SolverTerms t,
                             cudaStream_t s) {
  if (g.count == 0) return;
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    launch(Launch::dependent, group_warm_start_kernel<friction, rolling>, 1, s, records, g, bodies);
  });
}

void launch_sweep_group(const SweepRecords& records, const RangeGroup& g, SolverBody* bodies, real inv_h,
                        SolverTerms t, cudaStream_t s) {
  if (g.count == 0) return;
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    launch(Launch::dependent, group_sweep_kernel<friction, rolling>, 1, s, records, g, bodies, inv_h);
  });
}

std::uint32_t group_widest() {
  static const auto widest = static_cast<std::uint32_t>(whole_from_environment(
      "MARBLES_CUDA_GROUP", kBlock, 4096, "expected the widest range a group takes, 0 (none) to 4096"));
  return widest;
}

// The widest range a one-launch stage takes as one cluster (sm_90) unless
// MARBLES_CUDA_CLUSTER says (cluster_widest).
constexpr std::uint32_t kClusterWidest = 4096;

// A one-launch stage over ranges of at most `items` contacts: as one
// cluster of as many blocks as they ask for where that many fit one
// (`InCluster`: the kernel with ClusterSync), else on a cooperative grid
// (`OnGrid`: with GridSync). A barrier a range either way, the same bits;
// the cluster's costs a fraction of the grid's, which a small scene's
// solve meets some two hundred times a substep. True: as one cluster.
template <auto OnGrid, auto InCluster, class... Args>
bool launch_one(std::size_t items, int sm_count, cudaStream_t s, Args&&... args) {
  namespace dev = ::marbles::cuda;
  const std::size_t blocks = items > kBlock ? (items + kBlock - 1) / kBlock : 1;
  const std::uint32_t widest = cluster_widest();  // 0: never
  if (widest > 0 && items <= widest && blocks <= static_cast<std::size_t>(dev::largest_cluster<InCluster>())) {
    launch(Launch::cluster, InCluster, static_cast<int>(blocks), s, std::forward<Args>(args)...);
    return true;
  }
  dev::launch_cooperative<OnGrid>(items, sm_count, s, std::forward<Args>(args)...);
  return false;
}

bool launch_projection(const SweepRecords& records, DevicePlan plan, const BodiesView& bodies, const WallShape* walls,
                       const SolverSettings& settings, int sweeps, unsigned* moved, unsigned long long* total,
                       int sm_count, cudaStream_t s, const unsigned long long* skip) {
  if (sweeps <= 0) return false;
  return launch_one<project_kernel<GridSync>, project_kernel<ClusterSync>>(
      plan.widest, sm_count, s, plan.plan, records, bodies, walls, settings, sweeps, moved, total, skip);
}

bool launch_impact_stage(const SweepRecords& records, const ImpactRecords& impact, const std::uint32_t* order,
                         const std::uint32_t* first, std::uint32_t n, const ColourPlan* plan, SolverBody* bodies,
                         const ImpactParams& p, bool friction, int passes, unsigned* hit, int sm_count,
                         cudaStream_t s) {
  if (n == 0) return false;
  // Sized for all n contacts (its levels and colours are ranges of them).
  if (friction)
    return launch_one<impact_stage_kernel<true, GridSync>, impact_stage_kernel<true, ClusterSync>>(
        n, sm_count, s, plan, records, impact, order, first, n, bodies, p, passes, hit);
  return launch_one<impact_stage_kernel<false, GridSync>, impact_stage_kernel<false, ClusterSync>>(
      n, sm_count, s, plan, records, impact, order, first, n, bodies, p, passes, hit);
}

std::uint32_t cluster_widest() {
  static const auto widest = static_cast<std::uint32_t>(
      whole_from_environment("MARBLES_CUDA_CLUSTER", kClusterWidest, 1l << 30,
                             "expected the widest colour to solve as one cluster, 0 (never) to 1073741824"));
  return widest;
}
int cluster_blocks() { return ::marbles::cuda::largest_cluster<project_kernel<ClusterSync>>(); }

std::vector<KernelFit> sweep_kernel_fits() {
  using ::marbles::cuda::kernel_fit;
  return {kernel_fit<record_sweep_kernel<false, false, false>>(), kernel_fit<record_sweep_kernel<false, false, true>>(),
          kernel_fit<record_sweep_kernel<false, true, false>>(),  kernel_fit<record_sweep_kernel<false, true, true>>(),
          kernel_fit<record_sweep_kernel<true, false, false>>(),  kernel_fit<record_sweep_kernel<true, false, true>>(),
          kernel_fit<record_sweep_kernel<true, true, false>>(),   kernel_fit<record_sweep_kernel<true, true, true>>(),
          kernel_fit<wide_sweep_kernel<false, false, false>>(),   kernel_fit<wide_sweep_kernel<false, false, true>>(),
          kernel_fit<wide_sweep_kernel<false, true, false>>(),    kernel_fit<wide_sweep_kernel<false, true, true>>(),
          kernel_fit<wide_sweep_kernel<true, false, false>>(),    kernel_fit<wide_sweep_kernel<true, false, true>>(),
          kernel_fit<wide_sweep_kernel<true, true, false>>(),     kernel_fit<wide_sweep_kernel<true, true, true>>()};
}

bool launch_solve(const SweepRecords& records, DevicePlan plan, SolverBody* bodies, real inv_h, SolverTerms t,
                  bool warm, int sweeps, int sm_count, cudaStream_t s) {
  bool cluster = false;
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    cluster = launch_one<solve_kernel<friction, rolling, GridSync>, solve_kernel<friction, rolling, ClusterSync>>(
        plan.widest, sm_count, s, plan.plan, records, bodies, inv_h, warm, sweeps);
  });
  return cluster;
}


void LocalSweepsCuda::run(const SweepRecords& records, std::uint32_t count, const ColourPlan& plan,
                          const BodiesView& world, double diameters, int passes, int local, int threads,
                          SolverBody* bodies, real inv_h, SolverTerms t, int sm_count, cudaStream_t s) {
  if (count == 0) return;
  namespace dev = ::marbles::cuda;
  using dev::Launch;
  const std::size_t n = count;
  auto* keys = m_keys.as<std::uint64_t>(2 * n);
  auto* order = m_order.as<std::uint32_t>(2 * n);
  auto* heads = m_heads.as<std::uint32_t>(2 * (n + 1));
  std::uint32_t* slot = heads + (n + 1);
  auto* starts = m_starts.as<std::uint32_t>(n + 2 + kMaxColours + 2);
  std::uint32_t* between_begin = starts + (n + 2);
  cub::DoubleBuffer<std::uint64_t> sorted_keys(keys, keys + n);
  cub::DoubleBuffer<std::uint32_t> sorted(order, order + n);
  std::size_t sort_bytes = 0;
  MARBLES_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, sort_bytes, sorted_keys, sorted, static_cast<int>(n)));
  const std::size_t scan_bytes = dev::exclusive_sum_bytes<std::uint32_t>(n + 1);
  void* temp = m_temp.reserve(std::max(sort_bytes, scan_bytes));
  const int grid = dev::grid_for(n + 1, sm_count);
  auto* largest = m_largest.as<unsigned long long>(1);
  MARBLES_CUDA_CHECK(cudaMemsetAsync(largest, 0, sizeof(unsigned long long), s));
  dev::launch(Launch::plain, largest_radius_kernel, dev::grid_for(world.count, sm_count), s, world.radius,
              world.count, largest);
  dev::launch(Launch::plain, cube_keys_kernel, grid, s, records.bodies, count, static_cast<const Vec3*>(world.position),
              diameters, static_cast<const unsigned long long*>(largest), keys, order);
  MARBLES_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp, sort_bytes, sorted_keys, sorted, static_cast<int>(n), 0,
                                                     64, s));
  const std::uint64_t* k = sorted_keys.Current();
  const std::uint32_t* o = sorted.Current();
  dev::launch(Launch::plain, cube_heads_kernel, grid, s, k, count, heads);
  dev::device_exclusive_sum(heads, slot, n + 1, temp, scan_bytes, s);
  dev::launch(Launch::plain, cube_starts_kernel, grid, s, k, count, static_cast<const std::uint32_t*>(heads),
              static_cast<const std::uint32_t*>(slot), starts);
  const std::uint32_t* cubes = slot + n;
  dev::launch(Launch::plain, between_begin_kernel, 1, s, o, count, static_cast<const std::uint32_t*>(starts), cubes,
              plan, between_begin);

  std::uint32_t index[kMaxColours + 2];
  for (std::uint32_t c = 0; c < kMaxColours + 2; ++c) index[c] = c;
  const int between_grid = dev::grid_for(plan.widest(), sm_count);
  with_terms(t.friction, t.rolling, [&](auto friction, auto rolling) {
    for (int p = 0; p < passes; ++p) {
      local_pass_kernel<friction, rolling><<<sm_count * (8 * dev::kBlock / threads), threads, 0, s>>>(
          records, o, starts, cubes, plan, bodies, inv_h, p, local);
      MARBLES_CUDA_CHECK_LAUNCH();
      visit_colours(index, plan.colours, p % 2 == 1, [&](std::uint32_t c, std::uint32_t, bool serial, bool reversed) {
        dev::launch(Launch::plain, between_kernel<friction, rolling>, serial ? 1 : between_grid, s, records, o,
                    static_cast<const std::uint32_t*>(between_begin), c, serial, reversed, bodies, inv_h);
      });
    }
  });
}

}  // namespace marbles::narrowphase::cuda
