#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "narrowphase/contact_cache_math.hpp"
#include "narrowphase/contacts_cuda.cuh"

namespace marbles::narrowphase::cuda {
namespace {

using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

__global__ void max_speed_kernel(BodiesView bodies, unsigned long long* max_speed) {
  real v = 0;
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x) {
    const real s = length(bodies.velocity[i]);
    v = s > v ? s : v;
  }
  ::marbles::cuda::warp_atomic_max(max_speed, bits_of_real(v));
}

// With `mixed` (not null), *mixed is set to 1 when some sphere's radius
// differs from sphere 0's in any bit (every thread of a warp reaches the
// vote together, after its loop), and *radius is sphere 0's.
__global__ void reach_kernel(BodiesView bodies, real h, const unsigned long long* max_speed, real* reach,
                             real* bound, unsigned* mixed, real* radius) {
  const real v_max = real_of_bits(*max_speed);
  const unsigned long long first = mixed ? bits_of_real(bodies.radius[0]) : 0;
  bool differs = false;
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i < bodies.count; i += gridDim.x * blockDim.x) {
    const real r = bodies.radius[i];
    reach[i] = contact_reach(length(bodies.velocity[i]), v_max, r, h);
    if (bound) bound[i] = r + reach[i];
    if (mixed) differs = differs || bits_of_real(r) != first;
  }
  if (!mixed) return;
  if (__any_sync(0xffffffffu, differs) && (threadIdx.x & 31) == 0) atomicOr(mixed, 1u);
  if (blockIdx.x == 0 && threadIdx.x == 0) *radius = bodies.radius[0];
}

// Whether contact c would enter the impact stage (is_impact_candidate on the
// approach speed its record will hold: prepare_from_world's, from the same
// bodies, which nothing moves before the solve).
__device__ __forceinline__ bool approaches(Contact& c, const BodiesView& bodies, const ImpactWatch& watch) {
  if (!watch.any) return false;
  c.approach_speed = approach_from_world(c, bodies);
  return is_impact_candidate(c, watch.rest_speed);
}

// Flag k of a flag pass: whether the contact was found; `seen` is set once
// a found contact will be an impact candidate.
__device__ __forceinline__ std::uint32_t flag_of(bool found, Contact& c, const BodiesView& bodies,
                                                 const ImpactWatch& watch, bool& seen) {
  if (found && !seen) seen = approaches(c, bodies, watch);
  return found ? 1u : 0u;
}

// Raises *watch.any when some thread of the warp saw a candidate (all of a
// warp's threads reach it together, after their loops).
__device__ __forceinline__ void raise_if_any(bool seen, const ImpactWatch& watch) {
  if (__any_sync(0xffffffffu, seen) && (threadIdx.x & 31) == 0) atomicOr(watch.any, 1u);
}

__global__ void sphere_flags_kernel(BodiesView bodies, const IndexPair* pairs, std::size_t items,
                                    const std::uint32_t* count_on_device, PairTable table, real h, const real* reach,
                                    std::uint32_t* flags, ImpactWatch watch) {
  const std::size_t count = ::marbles::cuda::count_within(items, count_on_device);
  bool seen = false;
  for (std::size_t k = blockIdx.x * blockDim.x + threadIdx.x; k <= items; k += gridDim.x * blockDim.x) {
    if (k >= count) {
      flags[k] = 0;
      continue;
    }
    Contact c;
    flags[k] = flag_of(make_sphere_contact(bodies, pairs[k].i, pairs[k].j, table, h, reach, c), c, bodies, watch, seen);
  }
  raise_if_any(seen, watch);
}

__global__ void wall_flags_kernel(BodiesView bodies, const WallShape* walls, std::uint32_t wall_count,
                                  PairTable table, real h, const real* reach, std::uint32_t* flags,
                                  ImpactWatch watch) {
  bool seen = false;
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i <= bodies.count; i += gridDim.x * blockDim.x) {
    std::uint32_t found = 0;
    const auto s = static_cast<std::uint32_t>(i);
    const WallClearance clearance = i < bodies.count ? wall_clearance(bodies, s, h, reach) : WallClearance{};
    for (std::uint32_t k = 0; i < bodies.count && k < wall_count; ++k) {
      if (wall_passable(walls[k]) && wall_passed_over(walls[k], bodies, s, clearance)) continue;
      Contact c;
      found += flag_of(make_wall_contact(bodies, s, walls[k], k, table, h, reach, c), c, bodies, watch, seen);
    }
    flags[i] = found;
  }
  raise_if_any(seen, watch);
}

// Sphere i's wall contacts again, each at the next place from its offset;
// the item past the last writes the total, where asked for.
__global__ void wall_pair_write_kernel(BodiesView bodies, const WallShape* walls, std::uint32_t wall_count,
                                       PairTable table, real h, const real* reach, const std::uint32_t* offsets,
                                       const std::uint32_t* first, std::uint32_t room, BodyPair* out,
                                       std::uint32_t* total) {
  const std::uint32_t base = first ? *first : 0;
  for (std::size_t i = blockIdx.x * blockDim.x + threadIdx.x; i <= bodies.count; i += gridDim.x * blockDim.x) {
    std::uint32_t at = base + offsets[i];
    if (i == bodies.count) {
      if (total) *total = at;
      continue;
    }
    const std::uint32_t end = base + offsets[i + 1];
    const auto s = static_cast<std::uint32_t>(i);
    const WallClearance clearance = at < end ? wall_clearance(bodies, s, h, reach) : WallClearance{};
    for (std::uint32_t k = 0; k < wall_count && at < end; ++k) {
      if (wall_passable(walls[k]) && wall_passed_over(walls[k], bodies, s, clearance)) continue;
      Contact c;
      if (!make_wall_contact(bodies, s, walls[k], k, table, h, reach, c)) continue;
      if (at < room) out[at] = {s, kWallFlag | k};
      ++at;
    }
  }
}

// The sphere pair write: flagged candidate t's body pair at offsets[t]
// where that fits the room; the item past the last writes the total, where
// asked for.
__global__ void sphere_pair_write_kernel(const IndexPair* pairs, std::size_t items, const std::uint32_t* offsets,
                                         std::uint32_t room, BodyPair* out, std::uint32_t* total) {
  for (std::size_t t = blockIdx.x * blockDim.x + threadIdx.x; t <= items; t += gridDim.x * blockDim.x) {
    const std::uint32_t at = offsets[t];
    if (t == items) {
      if (total) *total = at;
    } else if (offsets[t + 1] != at && at < room) {
      out[at] = {pairs[t].i, pairs[t].j};
    }
  }
}

// make_sphere_contact / make_wall_contact as the flag pass called them (it
// found a contact, and so does this call: the same inputs).
__device__ Contact made_contact(const ContactInputs& in, const BodyPair& ab) {
  Contact c;
  if (is_wall(ab.b)) {
    const std::uint32_t k = ab.b & ~kWallFlag;
    make_wall_contact(in.bodies, ab.a, in.walls[k], k, in.table, in.h, in.reach, c);
  } else {
    make_sphere_contact(in.bodies, ab.a, ab.b, in.table, in.h, in.reach, c);
  }
  return c;
}

// Thread i makes contact i (its pair, entry and bodies read in the order
// they were found, which the broad phase keeps spatially close) and writes
// its record at position[i]: colour-major order costs scattered writes, not
// scattered reads (H100, pile of 10^6: colour verb 1.57 -> 1.38 ms).
__global__ void records_kernel(ContactInputs in, const BodyPair* pairs, const std::uint32_t* match,
                               CacheImpulses cache, const std::uint32_t* position, std::uint32_t items,
                               const std::uint32_t* count_on_device, SweepRecords records, ImpactRecords impacts) {
  const auto n = static_cast<std::uint32_t>(::marbles::cuda::count_within(items, count_on_device));
  for (std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    Contact c = made_contact(in, pairs[i]);
    const std::uint32_t e = match ? match[i] : kNoEntry;
    if (e != kNoEntry)
      restore_impulses(c, cache.normal[e], cache.tangent ? cache.tangent[e] : Vec3{},
                       cache.rolling ? cache.rolling[e] : Vec3{});
    prepare_from_world(c, in.bodies);
    const std::uint32_t k = position[i];
    pack_contact(c, records, impacts, k);
  }
}

__global__ void contacts_of_records_kernel(SweepRecords records, ImpactRecords impacts, std::uint32_t first,
                                           std::uint32_t count, BodiesView world, PairTable table,
                                           const WallShape* walls, Contact* out) {
  for (std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x; t < count; t += gridDim.x * blockDim.x)
    out[t] = contact_of_record(records, impacts, first + t, world, table, walls);
}

__global__ void advance_walls_kernel(WallShape* walls, std::uint32_t count, real h, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  const std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k < count) walls[k].point += walls[k].velocity * h;
}

}  // namespace

void launch_contact_reaches(const BodiesView& bodies, real h, unsigned long long* max_speed, real* reach,
                            real* bound, unsigned* mixed_radii, real* radius, int sm_count,
                            cudaStream_t stream) {
  if (bodies.count == 0) return;
  max_speed_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, max_speed);
  MARBLES_CUDA_CHECK_LAUNCH();
  reach_kernel<<<grid_for(bodies.count, sm_count), kBlock, 0, stream>>>(bodies, h, max_speed, reach, bound,
                                                                      mixed_radii, radius);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_sphere_contact_flags(const BodiesView& bodies, const IndexPair* pairs, std::size_t items,
                                 const std::uint32_t* count_on_device, const PairTable& table, real h,
                                 const real* reach, std::uint32_t* flags, const ImpactWatch& watch, int sm_count,
                                 cudaStream_t stream) {
  sphere_flags_kernel<<<grid_for(items + 1, sm_count), kBlock, 0, stream>>>(bodies, pairs, items, count_on_device,
                                                                            table, h, reach, flags, watch);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_sphere_pair_write(const IndexPair* pairs, std::size_t items, const std::uint32_t* offsets,
                              std::uint32_t room, BodyPair* out, std::uint32_t* total, int sm_count,
                              cudaStream_t stream) {
  if (items == 0 && !total) return;
  sphere_pair_write_kernel<<<grid_for(items + 1, sm_count), kBlock, 0, stream>>>(pairs, items, offsets, room, out,
                                                                                 total);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_wall_contact_flags(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, const real* reach, std::uint32_t* flags,
                               const ImpactWatch& watch, int sm_count, cudaStream_t stream) {
  wall_flags_kernel<<<grid_for(bodies.count + 1, sm_count), kBlock, 0, stream>>>(bodies, walls, wall_count, table,
                                                                                  h, reach, flags, watch);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_wall_pair_write(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                            const PairTable& table, real h, const real* reach, const std::uint32_t* offsets,
                            const std::uint32_t* first, std::uint32_t room, BodyPair* out, std::uint32_t* total,
                            int sm_count, cudaStream_t stream) {
  wall_pair_write_kernel<<<grid_for(bodies.count + 1, sm_count), kBlock, 0, stream>>>(
      bodies, walls, wall_count, table, h, reach, offsets, first, room, out, total);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_sorted_records(const ContactInputs& in, const BodyPair* pairs, const std::uint32_t* match,
                           const CacheImpulses& cache, const std::uint32_t* position, std::uint32_t n,
                           const std::uint32_t* count_on_device, const SweepRecords& records,
                           const ImpactRecords& impacts, int sm_count, cudaStream_t stream) {
  if (n == 0) return;
  records_kernel<<<grid_for(n, sm_count), kBlock, 0, stream>>>(in, pairs, match, cache, position, n, count_on_device,
                                                               records, impacts);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_contacts_of_records(const SweepRecords& records, const ImpactRecords& impacts, std::uint32_t first,
                                std::uint32_t count, const BodiesView& world, const PairTable& table,
                                const WallShape* walls, Contact* out, int sm_count, cudaStream_t stream) {
  if (count == 0) return;
  contacts_of_records_kernel<<<grid_for(count, sm_count), kBlock, 0, stream>>>(records, impacts, first, count, world,
                                                                               table, walls, out);
  MARBLES_CUDA_CHECK_LAUNCH();
}

void launch_advance_walls(WallShape* walls, std::uint32_t count, real h, cudaStream_t stream,
                          const unsigned long long* skip) {
  if (count == 0) return;
  advance_walls_kernel<<<(count + kBlock - 1) / kBlock, kBlock, 0, stream>>>(walls, count, h, skip);
  MARBLES_CUDA_CHECK_LAUNCH();
}

}  // namespace marbles::narrowphase::cuda
