// narrowphase/contacts.hpp — exact contact generation.
//
// Sphere pairs come from the broad phase (candidate pairs whose gap is below
// the margin); walls are flattened once into half-spaces (a box container is
// its six inward faces), so one sphere–plane test serves every wall kind.
// Contacts come out in a fixed order: sphere pairs in the order given, then
// walls by sphere then wall index — the solver's order, so runs repeat exactly.
#pragma once

#include <cstddef>
#include <vector>

#include "core/pair.hpp"
#include "core/spheres.hpp"
#include "core/walls.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

// Every wall as a half-space, in contact-index order: planes, then each box's
// faces (-x, +x, -y, +y, -z, +z inner faces).
std::vector<PlaneWall> wall_half_spaces(const Walls& walls);

// Appends a contact for each pair whose gap is below `margin`.
void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real margin, std::vector<Contact>& out);

// Appends a contact for each sphere–half-space gap below `margin`.
void wall_contacts(const BodiesView& bodies, const std::vector<PlaneWall>& half_spaces,
                   const PairTable& table, real margin, std::vector<Contact>& out);

}  // namespace marbles::narrowphase
