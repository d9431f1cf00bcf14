// narrowphase/contact_cache.hpp — warm starting.
//
// The accumulated impulses of the last substep, keyed by body pair (a, b)
// (b a sphere, or a wall with kWallFlag), sorted by key. A contact that
// persists starts the next solve from its old impulses (found by binary
// search on the GPU, contact_cache_math.hpp; on the CPU by a scan of its
// sphere's few entries), so a resting stack needs few iterations to hold.
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
#include <utility>
#include <vector>

#include "core/spheres.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

// The cache's entries as arrays, sorted by key.
struct CacheEntries {
  std::vector<std::uint64_t> key;
  std::vector<real> normal_impulse;
  std::vector<Vec3> tangent_impulse, rolling_impulse;
  std::size_t size() const { return key.size(); }
};

// The island rule: contacts of islands that lost a load (unmatched entries
// for which is_lost_load holds) start cold. `matched[k]` says whether entry
// k found its contact. Returns the number of contacts it set cold. Islands
// by union-find here; the CUDA twin finds the same islands by min-label
// propagation (contact_cache_cuda.cu).
std::size_t cold_start_unloaded_islands(std::vector<Contact>& contacts, const std::uint64_t* keys,
                                        const real* normal_impulse, const std::uint8_t* matched,
                                        std::size_t entry_count, const BodiesView& bodies, real weight_impulse);

class ContactCache {
 public:
  // Copies the impulses of matching cached contacts into `contacts`, except
  // in islands that lost a load. `weight_impulse` is |g| h (m/s). Returns the
  // number of contacts warm-started.
  std::size_t restore(std::vector<Contact>& contacts, const BodiesView& bodies, real weight_impulse);
  // Remembers the impulses of `contacts` for the next substep.
  void store(const std::vector<Contact>& contacts);
  void clear() { m_entries = {}; }
  // The entries themselves (a checkpoint's copy).
  const CacheEntries& entries() const { return m_entries; }
  void set_entries(CacheEntries entries) { m_entries = std::move(entries); }
  std::size_t size() const { return m_entries.size(); }

 private:
  CacheEntries m_entries;
  // Scratch, reused.
  std::vector<std::uint8_t> m_matched;
  std::vector<std::uint32_t> m_order, m_first;
};

}  // namespace marbles::narrowphase
