#include "narrowphase/contact_cache.hpp"

#include <algorithm>
#include <numeric>

namespace marbles::narrowphase {
namespace {

inline std::uint64_t key_of(const Contact& c) { return (std::uint64_t(c.a) << 32) | c.b; }

inline Vec3 tangential(const Vec3& v, const Vec3& n) { return v - n * dot(v, n); }

// Union-find root with path halving.
inline std::uint32_t root(std::vector<std::uint32_t>& parent, std::uint32_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace

std::size_t ContactCache::restore(std::vector<Contact>& contacts, const BodiesView& bodies, real weight_impulse) {
  if (m_entries.empty()) return 0;
  m_matched.assign(m_entries.size(), 0);
  std::size_t matched = 0;
  for (Contact& c : contacts) {
    const std::uint64_t key = key_of(c);
    auto it = std::lower_bound(m_entries.begin(), m_entries.end(), key,
                               [](const Entry& e, std::uint64_t k) { return e.key < k; });
    if (it == m_entries.end() || it->key != key) continue;
    c.normal_impulse = it->normal_impulse;
    c.tangent_impulse = tangential(it->tangent_impulse, c.normal);
    c.rolling_impulse = it->rolling_impulse;  // rolling (tangential) and twisting (normal) parts
    m_matched[it - m_entries.begin()] = 1;
    ++matched;
  }

  // Loads that went away: lost contacts that carried more than 4 times the
  // weight impulse of their sphere.
  m_unloaded.clear();
  for (std::size_t k = 0; k < m_entries.size(); ++k) {
    if (m_matched[k]) continue;
    const auto a = static_cast<std::uint32_t>(m_entries[k].key >> 32);
    if (a >= bodies.count || bodies.inv_mass[a] <= 0) continue;
    if (m_entries[k].normal_impulse <= 4 * weight_impulse / bodies.inv_mass[a]) continue;
    m_unloaded.push_back(static_cast<std::uint32_t>(k));
  }
  if (m_unloaded.empty()) return matched;

  // Islands of touching spheres. An island starts cold when it lost a load
  // of at least a quarter of the largest impulse it still carries (the top of
  // a stack removed), not when a sphere merely leaves the surface of a deep pile.
  m_parent.resize(bodies.count);
  std::iota(m_parent.begin(), m_parent.end(), 0u);
  for (const Contact& c : contacts)
    if (!is_wall(c.b)) m_parent[root(m_parent, c.a)] = root(m_parent, c.b);
  m_island_max.assign(bodies.count, 0);
  for (const Contact& c : contacts) {
    real& m = m_island_max[root(m_parent, c.a)];
    m = std::max(m, c.normal_impulse);
  }
  std::vector<char>& cold = m_matched;  // reused as a per-root flag
  cold.assign(bodies.count, 0);
  for (std::uint32_t k : m_unloaded) {
    const Entry& lost = m_entries[k];
    const auto a = static_cast<std::uint32_t>(lost.key >> 32);
    const auto b = static_cast<std::uint32_t>(lost.key & 0xffffffffu);
    for (std::uint32_t body : {a, b}) {
      if (is_wall(body) || body >= bodies.count) continue;
      const std::uint32_t r = root(m_parent, body);
      if (lost.normal_impulse >= real(0.25) * m_island_max[r]) cold[r] = 1;
    }
  }
  for (Contact& c : contacts) {
    if (!cold[root(m_parent, c.a)] || c.normal_impulse <= 0) continue;
    c.normal_impulse = 0;
    c.tangent_impulse = Vec3{};
    c.rolling_impulse = Vec3{};
    --matched;
  }
  return matched;
}

void ContactCache::store(const std::vector<Contact>& contacts) {
  m_entries.clear();
  m_entries.reserve(contacts.size());
  // Only the sustained impulses of the velocity solve are carried over; an
  // impact's impulse (Contact::impact_impulse) is not a load.
  for (const Contact& c : contacts)
    if (c.normal_impulse > 0) m_entries.push_back({key_of(c), c.normal_impulse, c.tangent_impulse, c.rolling_impulse});
  std::sort(m_entries.begin(), m_entries.end(), [](const Entry& x, const Entry& y) { return x.key < y.key; });
}

}  // namespace marbles::narrowphase
