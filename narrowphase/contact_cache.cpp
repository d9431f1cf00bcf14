#include "narrowphase/contact_cache.hpp"

#include <algorithm>
#include <numeric>

#include "core/counting_sort.hpp"
#include "narrowphase/contact_cache_math.hpp"

namespace marbles::narrowphase {
namespace {

// Union-find root with path halving.
inline std::uint32_t root(std::vector<std::uint32_t>& parent, std::uint32_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

constexpr std::ptrdiff_t kParallelFrom = 20000;

}  // namespace

std::size_t cold_start_unloaded_islands(std::vector<Contact>& contacts, const std::uint64_t* keys,
                                        const real* normal_impulse, const std::uint8_t* matched,
                                        std::size_t entry_count, const BodiesView& bodies, real weight_impulse) {
  std::vector<std::uint32_t> unloaded;
  for (std::size_t k = 0; k < entry_count; ++k) {
    if (matched[k]) continue;
    const auto a = static_cast<std::uint32_t>(keys[k] >> 32);
    if (a >= bodies.count || !is_lost_load(normal_impulse[k], bodies.inv_mass[a], weight_impulse)) continue;
    unloaded.push_back(static_cast<std::uint32_t>(k));
  }
  if (unloaded.empty()) return 0;

  // Islands of touching spheres. An island starts cold when it lost a load
  // of at least a quarter of the largest impulse it still carries (the top of
  // a stack removed), not when a sphere merely leaves the surface of a deep pile.
  std::vector<std::uint32_t> parent(bodies.count);
  std::iota(parent.begin(), parent.end(), 0u);
  for (const Contact& c : contacts)
    if (!is_wall(c.b)) parent[root(parent, c.a)] = root(parent, c.b);
  std::vector<real> island_max(bodies.count, 0);
  for (const Contact& c : contacts) {
    real& m = island_max[root(parent, c.a)];
    m = std::max(m, c.normal_impulse);
  }
  std::vector<char> cold(bodies.count, 0);
  for (std::uint32_t k : unloaded) {
    const auto a = static_cast<std::uint32_t>(keys[k] >> 32);
    const auto b = static_cast<std::uint32_t>(keys[k] & 0xffffffffu);
    for (std::uint32_t body : {a, b}) {
      if (is_wall(body) || body >= bodies.count) continue;
      const std::uint32_t r = root(parent, body);
      if (island_starts_cold(normal_impulse[k], island_max[r])) cold[r] = 1;
    }
  }
  std::size_t set_cold = 0;
  for (Contact& c : contacts) {
    if (!cold[root(parent, c.a)] || c.normal_impulse <= 0) continue;
    c.normal_impulse = 0;
    c.tangent_impulse = Vec3{};
    c.rolling_impulse = Vec3{};
    ++set_cold;
  }
  return set_cold;
}

bool keep_proper_colours(CacheEntries& e) {
  const std::size_t m = e.size();
  bool proper = e.colour.size() == m;
  // Every (sphere, colour) an entry holds, at both its spheres (not at a
  // wall); sorted, a pair that stands twice is a conflict.
  std::vector<std::pair<std::uint32_t, std::uint8_t>> used;
  used.reserve(2 * m);
  for (std::size_t k = 0; proper && k < m; ++k) {
    const std::uint8_t c = e.colour[k];
    if (c == kNoKeptColour) continue;
    if (c >= kMaxColours) {
      proper = false;
      break;
    }
    const auto a = static_cast<std::uint32_t>(e.key[k] >> 32), b = static_cast<std::uint32_t>(e.key[k]);
    used.push_back({a, c});
    if (!is_wall(b)) used.push_back({b, c});
  }
  if (proper) {
    std::sort(used.begin(), used.end());
    for (std::size_t k = 1; k < used.size(); ++k)
      if (used[k] == used[k - 1]) proper = false;  // one sphere, one colour, twice
  }
  if (!proper) e.colour.assign(m, kNoKeptColour);
  return proper;
}

std::size_t ContactCache::restore(std::vector<Contact>& contacts, const BodiesView& bodies, real weight_impulse,
                                  std::vector<std::uint8_t>& kept_colour) {
  kept_colour.assign(contacts.size(), kNoKeptColour);
  const auto m = static_cast<std::uint32_t>(m_entries.size());
  if (m == 0) return 0;
  const std::uint8_t* colour = m_entries.colour.size() == m ? m_entries.colour.data() : nullptr;
  m_matched.assign(m, 0);
  const std::uint64_t* keys = m_entries.key.data();
  // The entries of sphere a are keys[first[a], first[a + 1]) (sorted by key,
  // so grouped by a): a contact scans its sphere's few entries instead of
  // searching all of them, and finds the same entry (keys are unique).
  // Entries of spheres that no longer exist (a >= count) are never matched.
  const std::size_t spheres = bodies.count;
  m_first.assign(spheres + 1, 0);
  for (std::uint32_t k = 0; k < m; ++k) {
    const std::uint64_t a = keys[k] >> 32;
    if (a < spheres) ++m_first[a + 1];
  }
  for (std::size_t i = 0; i < spheres; ++i) m_first[i + 1] += m_first[i];
  const std::uint32_t* first = m_first.data();
  const auto n = static_cast<std::ptrdiff_t>(contacts.size());
  std::size_t matched = 0;
#pragma omp parallel for schedule(static) reduction(+ : matched) if (n >= kParallelFrom)
  for (std::ptrdiff_t t = 0; t < n; ++t) {
    Contact& c = contacts[t];
    if (c.a >= spheres) continue;
    const std::uint64_t key = cache_key(c.a, c.b);
    std::uint32_t k = first[c.a];
    while (k < first[c.a + 1] && keys[k] < key) ++k;
    if (k == first[c.a + 1] || keys[k] != key) continue;
    restore_impulses(c, m_entries.normal_impulse[k], m_entries.tangent_impulse[k], m_entries.rolling_impulse[k]);
    if (colour) kept_colour[t] = colour[k];
    m_matched[k] = 1;  // keys are unique: one contact per entry
    ++matched;
  }
  return matched - cold_start_unloaded_islands(contacts, keys, m_entries.normal_impulse.data(), m_matched.data(), m,
                                                bodies, weight_impulse);
}

void ContactCache::store(const std::vector<Contact>& contacts, const ColourRanges& ranges) {
  // Only the sustained impulses of the velocity solve are carried over; an
  // impact's impulse (Contact::impact_impulse) is not a load. A contact
  // without load is kept for its colour alone, with no impulses (restored,
  // it starts as an uncached contact does).
  // Sorted by key = grouped by sphere a, then by b within a group: a
  // counting sort by a (in parallel: core/counting_sort.hpp), then each group
  // (a few entries) sorted by b in place.
  const auto n = static_cast<std::uint32_t>(contacts.size());
  m_contact_colour.assign(n, kNoKeptColour);
  if (ranges.size() == n) for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) { m_contact_colour[k] = c; });
  const Contact* cs = contacts.data();
  const std::uint8_t* colour = m_contact_colour.data();
  auto kept = [&](std::uint32_t k) { return cs[k].normal_impulse > 0 || colour[k] != kNoKeptColour; };
  std::uint32_t groups = 0;  // the largest a kept, plus one
#pragma omp parallel for schedule(static) reduction(max : groups) if (n >= kParallelFrom)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(n); ++k)
    if (kept(static_cast<std::uint32_t>(k))) groups = std::max(groups, cs[k].a + 1);
  CacheEntries& e = m_entries;  // sized for every contact, cut to the kept ones after
  e.key.resize(n);
  e.normal_impulse.resize(n);
  e.tangent_impulse.resize(n);
  e.rolling_impulse.resize(n);
  e.colour.resize(n);
  counting_sort(
      n, groups, [&](std::uint32_t k) { return kept(k) ? cs[k].a : kSkipItem; },
      [&](std::uint32_t k, std::uint32_t place) {
        const Contact& c = cs[k];
        const bool loaded = c.normal_impulse > 0;
        e.key[place] = cache_key(c.a, c.b);
        e.normal_impulse[place] = loaded ? c.normal_impulse : real(0);
        e.tangent_impulse[place] = loaded ? c.tangent_impulse : Vec3{};
        e.rolling_impulse[place] = loaded ? c.rolling_impulse : Vec3{};
        e.colour[place] = colour[k];
      },
      m_first, m_order);
  const std::size_t m = m_first[groups];
  e.key.resize(m);
  e.normal_impulse.resize(m);
  e.tangent_impulse.resize(m);
  e.rolling_impulse.resize(m);
  e.colour.resize(m);
#pragma omp parallel for schedule(static) if (groups >= kParallelFrom)
  for (std::ptrdiff_t g = 0; g < static_cast<std::ptrdiff_t>(groups); ++g) {
    const std::uint32_t a = static_cast<std::uint32_t>(g);
    for (std::uint32_t x = m_first[a] + 1; x < m_first[a + 1]; ++x)  // insertion sort by key (unique)
      for (std::uint32_t j = x; j > m_first[a] && e.key[j - 1] > e.key[j]; --j) {
        std::swap(e.key[j - 1], e.key[j]);
        std::swap(e.normal_impulse[j - 1], e.normal_impulse[j]);
        std::swap(e.tangent_impulse[j - 1], e.tangent_impulse[j]);
        std::swap(e.rolling_impulse[j - 1], e.rolling_impulse[j]);
        std::swap(e.colour[j - 1], e.colour[j]);
      }
  }
}

}  // namespace marbles::narrowphase
