// narrowphase/contacts.hpp — exact contact generation.
//
// Sphere pairs come from the broad phase (candidates from swept bounds); walls are flattened once into WallShapes (a box container is
// its six inward faces), so one gap function serves every wall kind.
// Contacts come out in a fixed order: sphere pairs in the order given, then
// walls by sphere then wall index — the solver's order, so runs repeat exactly.
#pragma once

#include <cstddef>
#include <vector>

#include "core/pair.hpp"
#include "core/spheres.hpp"
#include "core/walls.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_math.hpp"

namespace marbles::narrowphase {

// Every wall as a WallShape, in contact-index order: planes, then each box's
// six inner faces (-x, +x, -y, +y, -z, +z), then cylinders, then spheres.
std::vector<WallShape> wall_shapes(const Walls& walls);
// The scene's wall (its place in the `walls` list: PlaneWall::index, ...) of
// each of wall_shapes' shapes: what output names a wall contact by.
std::vector<std::uint32_t> wall_shape_owners(const Walls& walls);

// Moves translating walls by h times their velocity.
void advance_walls(std::vector<WallShape>& shapes, real h);

// Per-thread buffers of the contact loops, kept between substeps so that a
// step allocates (and page-faults) nothing: with 10^5 spheres the contacts
// are 65 MB, and fresh buffers cost more than the contact tests.
struct ContactScratch {
  std::vector<std::vector<Contact>> parts;
  std::vector<std::vector<FoundContact>> found_parts;  // the forms that append FoundContacts
  std::vector<std::uint8_t> near_walls;                 // the wall search's: a flag a sphere
};

// Appends a contact for each pair that overlaps or whose gap closes within
// the substep h at the current approach speed (a speculative contact):
//   separation < max(0, -v_n) h.
// Pairs drifting apart or passing at a distance make no contact, so a
// contact never holds back bodies that would not have met (which would
// swallow kinetic energy); h = 0 keeps overlaps only.
// A gap within reach[i] + reach[j] (contact_reach) makes a contact too.
void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real h, const real* reach, std::vector<Contact>& out,
                     ContactScratch* scratch = nullptr);
// The same in two runs, not joined (Runs): the first thread's contacts
// appended to `out`, the other threads' in `rest`, which they replace (out's
// new ones, then rest, in order, are what the form above appends). Where one
// thread makes them all, `rest` is left empty.
void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real h, const real* reach, std::vector<Contact>& out,
                     std::vector<Contact>& rest, ContactScratch& scratch);

// The same contacts as found (FoundContact, found_of): the CPU step's form.
void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real h, const real* reach, std::vector<FoundContact>& out,
                     std::vector<FoundContact>& rest, ContactScratch& scratch);

// The same for every sphere against every wall (approach speed relative to
// the wall's surface, a gap within reach[i]).
void wall_contacts(const BodiesView& bodies, const std::vector<WallShape>& walls, const PairTable& table, real h,
                   const real* reach, std::vector<Contact>& out, ContactScratch* scratch = nullptr);
void wall_contacts(const BodiesView& bodies, const std::vector<WallShape>& walls, const PairTable& table, real h,
                   const real* reach, std::vector<FoundContact>& out, ContactScratch* scratch = nullptr);

// reach[i] = contact_reach of sphere i for the substep h (the fastest
// sphere's speed is a reduction over all).
void contact_reaches(const BodiesView& bodies, real h, std::vector<real>& reach);

}  // namespace marbles::narrowphase
