// narrowphase/contacts_cuda.cuh — the CUDA twin of contacts.cpp: kernels over
// make_sphere_contact / make_wall_contact (contact_math.hpp), in two passes
// (flag, then write at the scanned offset) so the contacts come out in the
// CPU's order: sphere pairs in the broad phase's order, then walls by sphere
// then wall index. Each candidate is tested twice (flag, then write): the
// test is a few flops against a 132-byte write it would otherwise stage.
// Only .cu files include this header.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "core/pair.hpp"
#include "core/spheres.hpp"
#include "narrowphase/contact_math.hpp"

namespace marbles::narrowphase::cuda {

// The fastest sphere's speed into *max_speed (its bits as an unsigned word;
// zero it first), then reach[i] = contact_reach and bound[i] = radius +
// reach[i] (the swept bound the broad phase sees; bound may be null).
void launch_contact_reaches(const BodiesView& bodies, real h, unsigned long long* max_speed, real* reach,
                            real* bound, int sm_count, cudaStream_t stream);

// flags[k] = 1 when candidate pair k makes a contact (flags[count] = 0).
void launch_sphere_contact_flags(const BodiesView& bodies, const IndexPair* pairs, std::size_t count,
                                 const PairTable& table, real h, const real* reach, std::uint32_t* flags,
                                 int sm_count, cudaStream_t stream);
// Writes the contact of each flagged pair k at out[offsets[k]].
void launch_sphere_contact_write(const BodiesView& bodies, const IndexPair* pairs, std::size_t count,
                                 const PairTable& table, real h, const real* reach, const std::uint32_t* offsets,
                                 narrowphase::Contact* out, int sm_count, cudaStream_t stream);

// The same over sphere i x wall k, item i * wall_count + k.
void launch_wall_contact_flags(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, const real* reach, std::uint32_t* flags,
                               int sm_count, cudaStream_t stream);
void launch_wall_contact_write(const BodiesView& bodies, const WallShape* walls, std::uint32_t wall_count,
                               const PairTable& table, real h, const real* reach, const std::uint32_t* offsets,
                               narrowphase::Contact* out, int sm_count, cudaStream_t stream);

// Moves translating walls by h times their velocity.
void launch_advance_walls(WallShape* walls, std::uint32_t count, real h, cudaStream_t stream);

}  // namespace marbles::narrowphase::cuda
