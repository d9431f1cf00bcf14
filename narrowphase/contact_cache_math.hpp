// narrowphase/contact_cache_math.hpp — per-contact steps of the warm-start
// cache, host and device: the loop bodies of contact_cache.cpp and of its
// CUDA twin. The cache is a list of entries sorted by key (a << 32 | b),
// so grouped by sphere a into runs; a contact finds its entry in its
// sphere's run (a few entries), so lookups are independent.
#pragma once

#include <cstdint>

#include "core/vec3.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

MARBLES_HD_INLINE std::uint64_t cache_key(std::uint32_t a, std::uint32_t b) { return (std::uint64_t(a) << 32) | b; }

// The entry of `key` in a run of sorted keys[begin, end) (one sphere's), or
// end where there is none. The keys are the whole cache keys (the CPU's) or
// only their b halves (the GPU's: within a run a is the run's sphere, so b
// orders the run as the whole key does).
template <class Key>
MARBLES_HD_INLINE std::uint32_t find_in_run(const Key* keys, std::uint32_t begin, std::uint32_t end, Key key) {
  while (begin < end && keys[begin] < key) ++begin;
  return begin < end && keys[begin] == key ? begin : end;
}

// One sphere's run of a store, index[begin, end), ordered by key_of(index)
// (the runs' keys are unique) by insertion: a run is a few entries. An
// index may carry its own key (key_of reads only the index itself).
template <class Index, class KeyOf>
MARBLES_HD_INLINE void sort_run(Index* index, std::uint32_t begin, std::uint32_t end, const KeyOf& key_of) {
  for (std::uint32_t x = begin + 1; x < end; ++x) {
    const Index k = index[x];
    const auto key = key_of(k);
    std::uint32_t j = x;
    for (; j > begin && key_of(index[j - 1]) > key; --j) index[j] = index[j - 1];
    index[j] = k;
  }
}

// The carried impulses of a matched contact: tangential part projected onto
// the new tangent plane; rolling (tangential) and twisting (normal) parts as
// they were.
template <class C>  // Contact or FoundContact
MARBLES_HD_INLINE void restore_impulses(C& c, real normal, const Vec3& tangent, const Vec3& rolling) {
  c.normal_impulse = normal;
  c.tangent_impulse = tangent - c.normal * dot(tangent, c.normal);
  c.rolling_impulse = rolling;
}

// Whether a contact carries a load into its substep: the normal impulse it
// was restored with (after the island rule) is not <= 0, the warm start's
// own test (warm_start_one: a contact that fails it applies nothing; a NaN
// passes it and counts as carried). The CPU solver's records hold such
// contacts first within their colour (colouring.hpp ColourRanges::record),
// and its warm start walks those alone.
MARBLES_HD_INLINE bool carries_load(real restored_normal) { return !(restored_normal <= 0); }

// A lost contact counts as a lost load when it carried more than 4 times the
// weight impulse m |g| h of its sphere (sphere a, inverse mass inv_mass_a).
MARBLES_HD_INLINE bool is_lost_load(real normal_impulse, real inv_mass_a, real weight_impulse) {
  return inv_mass_a > 0 && normal_impulse > 4 * weight_impulse / inv_mass_a;
}

// The island rule: an island starts cold when a load it lost is at least a
// quarter of the largest impulse it still carries.
MARBLES_HD_INLINE bool island_starts_cold(real lost_impulse, real island_max) {
  return lost_impulse >= real(0.25) * island_max;
}

// Entry (a, b)'s key after a renumbering (renumbered, and its CUDA twin),
// every sphere i named new_index[i] of `spheres` (a wall keeps its b). A
// pair of spheres is keyed with its lower index first, so `swapped` says
// it turned round: its tangential and rolling impulses then change sign
// (turned). An entry that names a sphere past the spheres is dropped (a
// world that lost spheres: no lookup would find it); one that new_index
// would name past them is not_a_numbering (the host throws, the device
// drops it; the step's numberings are permutations).
enum class Renamed : std::uint8_t { kept, dropped, not_a_numbering };
struct RenamedKey {
  std::uint64_t key;
  bool swapped;
  Renamed outcome;
};
MARBLES_HD_INLINE bool sphere_past(std::uint32_t b, std::uint32_t spheres) { return !is_wall(b) && b >= spheres; }
MARBLES_HD_INLINE RenamedKey renamed_key(std::uint32_t a, std::uint32_t b, const std::uint32_t* new_index,
                                         std::uint32_t spheres) {
  if (a >= spheres || sphere_past(b, spheres)) return {0, false, Renamed::dropped};
  const std::uint32_t new_a = new_index[a], new_b = is_wall(b) ? b : new_index[b];
  const bool swapped = !is_wall(new_b) && new_b < new_a;
  const std::uint32_t low = swapped ? new_b : new_a, high = swapped ? new_a : new_b;
  if (low >= spheres || sphere_past(high, spheres)) return {0, false, Renamed::not_a_numbering};
  return {cache_key(low, high), swapped, Renamed::kept};
}
// Turned round: each component negated but a zero, which keeps its sign
// (+0 stays +0: an idle contact's impulses stay clear). Turning twice gives
// back every bit, -0 included (0 - x would give -0 back as +0).
MARBLES_HD_INLINE real turned(real x, bool swapped) { return swapped && x != 0 ? -x : x; }
MARBLES_HD_INLINE Vec3 turned(const Vec3& v, bool swapped) {
  return {turned(v.x, swapped), turned(v.y, swapped), turned(v.z, swapped)};
}

}  // namespace marbles::narrowphase
