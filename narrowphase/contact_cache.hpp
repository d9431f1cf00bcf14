// narrowphase/contact_cache.hpp — warm starting.
//
// The accumulated impulses of the last substep, keyed by body pair (a, b)
// (b a sphere, or a wall with kWallFlag). A contact that persists starts the
// next solve from its old impulses, so a resting stack needs few iterations
// to hold.
//
// When a load goes away (a contact that carried more than a few times its
// sphere's weight impulse is gone, e.g. the heavy top of a stack was lifted
// off), the old impulses of everything still touching that sphere, directly
// or through other spheres, are too large: applied, they would launch the
// stack, and a few sweeps cannot take the excess back out of a long chain.
// So the whole group of touching spheres (its island) starts cold for that
// substep when the lost impulse is at least a quarter of the largest one the
// island still carries: a cold start can only under-support, never push. (A
// sphere leaving the surface of a deep pile is no such load.)
#pragma once

#include <cstdint>
#include <vector>

#include "core/spheres.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

class ContactCache {
 public:
  // Copies the impulses of matching cached contacts into `contacts`
  // (tangential and rolling parts projected onto the new tangent plane),
  // except in islands that lost a load. `weight_impulse` is |g| h (m/s): a
  // lost contact counts as a load when its impulse exceeds 4 m |g| h of its
  // sphere. Returns the number of contacts warm-started.
  std::size_t restore(std::vector<Contact>& contacts, const BodiesView& bodies, real weight_impulse);
  // Remembers the impulses of `contacts` for the next substep.
  void store(const std::vector<Contact>& contacts);
  void clear() { m_entries.clear(); }
  std::size_t size() const { return m_entries.size(); }

 private:
  struct Entry {
    std::uint64_t key;
    real normal_impulse;
    Vec3 tangent_impulse, rolling_impulse;
  };
  std::vector<Entry> m_entries;  // sorted by key
  // Scratch, reused.
  std::vector<char> m_matched;
  std::vector<std::uint32_t> m_unloaded, m_parent;
  std::vector<real> m_island_max;
};

}  // namespace marbles::narrowphase
