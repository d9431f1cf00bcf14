// narrowphase/contacts.hpp — exact contact generation.
//
// Sphere pairs come from the broad phase (candidate pairs whose gap is below
// the margin); walls are flattened once into WallShapes (a box container is
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

// Moves translating walls by h times their velocity.
void advance_walls(std::vector<WallShape>& shapes, real h);

// Appends a contact for each pair whose gap is below `margin`, or, when
// `margins` is given, below margins[i] + margins[j] (swept bounds: each
// sphere's travel within the substep).
void sphere_contacts(const BodiesView& bodies, const IndexPair* pairs, std::size_t pair_count,
                     const PairTable& table, real margin, const real* margins, std::vector<Contact>& out);

// Appends a contact for each sphere–wall gap below `margin`; `margins`, when
// given, holds one margin per sphere instead (swept bounds).
void wall_contacts(const BodiesView& bodies, const std::vector<WallShape>& walls, const PairTable& table,
                   real margin, const real* margins, std::vector<Contact>& out);

}  // namespace marbles::narrowphase
