// narrowphase/contacts_cuda.cuh — the CUDA twin of contacts.cpp: kernels over
// make_sphere_contact / make_wall_contact (contact_math.hpp), in two passes
// (flag, then write at the scanned offset) so the contacts come out in the
// CPU's order: sphere pairs in the broad phase's order, then walls by sphere
// then wall index. What is written is each contact's body pair (8 bytes);
// the contact itself is made again, with the same function and inputs, when
// it is written in colour-major order as the sweep's records
// (launch_sorted_records), so the device never holds a 112-byte Contact.
// Only .cu files include this header.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "core/pair.hpp"
#include "core/spheres.hpp"
#include "narrowphase/contact_cache_cuda.cuh"
#include "narrowphase/contact_math.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {

// The fastest sphere's speed into *max_speed (its bits as an unsigned word;
// zero it first), then reach[i] = contact_reach and bound[i] = radius +
// reach[i] (the swept bound the broad phase sees; bound may be null). With
// mixed_radii (not null; zero it first), sets *mixed_radii to 1 when the
// spheres' radii are not all the same, bit for bit, and *radius to sphere
// 0's (UniformArms).
void launch_contact_reaches(const BodiesView& bodies, real h, unsigned long long* max_speed, real* reach,
                            real* bound, unsigned* mixed_radii, real* radius, int sm_count, cudaStream_t stream);

// Whether any contact found will be an impact candidate of the impact stage
// (its prepared approach speed below -rest_speed, is_impact_candidate): *any
// (device) is set to 1 if so, left as it was if not. any null: not watched.
// Read with the contact count, it spares the impact stage its own read in a
// substep without candidates (a pile at rest).
struct ImpactWatch {
  unsigned* any = nullptr;
  real rest_speed = 0;
};

// flags[k] = 1 when candidate pair k makes a contact, for k < items
// (flags[items] = 0). With `count_on_device` (not null: the broad phase's
// count, left on the device), only the first *count_on_device pairs are
// tested and the rest of the items flagged 0; none when the count exceeds
// `items` (the pairs did not fit and were not written).
void launch_sphere_contact_flags(const BodiesView& bodies, const IndexPair* pairs, std::size_t items,
                                 const std::uint32_t* count_on_device, const PairTable& table, real h,
                                 const real* reach, std::uint32_t* flags, const ImpactWatch& watch, int sm_count,
                                 cudaStream_t stream);
// Writes the body pair of each flagged pair k < items at out[offsets[k]],
// those that fit `room` (out's length; the rest are dropped, and the caller
// reads the total and runs again with room for it). With `total` (not
// null), *total = offsets[items], the contacts found: the count the later
// stages read on the device (count_within) before the host does.
void launch_sphere_pair_write(const IndexPair* pairs, std::size_t items, const std::uint32_t* offsets,
                              std::uint32_t room, BodyPair* out, std::uint32_t* total, int sm_count,
                              cudaStream_t stream);

// The same for the walls, a count a sphere: flags[i] = how many of the
// walls sphere i touches (flags[count] = 0), so the flags and their offsets
// take 8 bytes a sphere whatever the walls (not 8 a sphere and wall).
void launch_wall_contact_flags(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, const real* reach, std::uint32_t* flags,
                               const ImpactWatch& watch, int sm_count, cudaStream_t stream);
// Its write: sphere i's wall contacts, in the walls' order (each found again
// by the same test, on the same inputs), from out[*first + offsets[i]]
// (first: the sphere contacts' total on the device; null: from out[0]),
// those that fit `room`; *total = *first + offsets[count].
void launch_wall_pair_write(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                            const PairTable& table, real h, const real* reach, const std::uint32_t* offsets,
                            const std::uint32_t* first, std::uint32_t room, BodyPair* out, std::uint32_t* total,
                            int sm_count, cudaStream_t stream);

// What the contacts are made from once more, unchanged since they were found:
// the bodies (not moved before the solve), the walls, the pair table, the
// lookahead and the reaches.
struct ContactInputs {
  BodiesView bodies;
  const WallShape* walls = nullptr;
  PairTable table;
  real h = 0;
  const real* reach = nullptr;
};

// The sweep's records (and impact words or approach speeds: ImpactRecords,
// solver_math.hpp) of the contacts of pairs[0, n), contact i at position[i]
// (the colouring's colour-major order): each contact made as it was found,
// restored from its cache entry (match[i]: an entry of `cache`, or kNoEntry;
// match null: none), prepared from the world, packed. With count_on_device
// (not null), pairs[0, n) is a room and the contacts its first
// *count_on_device (count_within).
void launch_sorted_records(const ContactInputs& in, const BodyPair* pairs, const std::uint32_t* match,
                           const CacheImpulses& cache, const std::uint32_t* position, std::uint32_t n,
                           const std::uint32_t* count_on_device, const SweepRecords& records,
                           const ImpactRecords& impacts, int sm_count, cudaStream_t stream);

// Whole contacts of records [first, first + count) into out (device), as the
// CPU holds them after the step (contact_of_record: the table and walls give
// the restitution where the substep kept approach speeds only).
void launch_contacts_of_records(const SweepRecords& records, const ImpactRecords& impacts, std::uint32_t first,
                                std::uint32_t count, const BodiesView& world, const PairTable& table,
                                const WallShape* walls, Contact* out, int sm_count, cudaStream_t stream);

// Moves translating walls by h times their velocity; nothing where `skip`
// is set (cuda::skipped).
void launch_advance_walls(WallShape* walls, std::uint32_t count, real h, cudaStream_t stream,
                          const unsigned long long* skip = nullptr);

}  // namespace marbles::narrowphase::cuda
