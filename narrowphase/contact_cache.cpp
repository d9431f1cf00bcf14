#include "narrowphase/contact_cache.hpp"

#include <algorithm>

namespace marbles::narrowphase {
namespace {

inline std::uint64_t key_of(const Contact& c) { return (std::uint64_t(c.a) << 32) | c.b; }

inline Vec3 tangential(const Vec3& v, const Vec3& n) { return v - n * dot(v, n); }

}  // namespace

std::size_t ContactCache::restore(std::vector<Contact>& contacts) const {
  if (m_entries.empty()) return 0;
  std::size_t matched = 0;
  for (Contact& c : contacts) {
    const std::uint64_t key = key_of(c);
    auto it = std::lower_bound(m_entries.begin(), m_entries.end(), key,
                               [](const Entry& e, std::uint64_t k) { return e.key < k; });
    if (it == m_entries.end() || it->key != key) continue;
    c.normal_impulse = it->normal_impulse;
    c.tangent_impulse = tangential(it->tangent_impulse, c.normal);
    c.rolling_impulse = tangential(it->rolling_impulse, c.normal);
    ++matched;
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
