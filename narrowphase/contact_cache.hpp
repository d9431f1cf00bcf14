// narrowphase/contact_cache.hpp — warm starting.
//
// The accumulated impulses of the last substep, keyed by body pair (a, b)
// (b a sphere, or a wall with kWallFlag). A contact that persists starts the
// next solve from its old impulses, so a resting stack needs few iterations
// to hold. The solver's clamping of the accumulated impulse removes any excess
// (e.g. a load that has just been lifted off) within the first sweep.
#pragma once

#include <cstdint>
#include <vector>

#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

class ContactCache {
 public:
  // Copies the impulses of matching cached contacts into `contacts`
  // (tangential and rolling parts projected onto the new tangent plane).
  // Returns the number matched.
  std::size_t restore(std::vector<Contact>& contacts) const;
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
};

}  // namespace marbles::narrowphase
