#include "narrowphase/contact_cache.hpp"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <type_traits>

#include "core/counting_sort.hpp"
#include "core/parallel.hpp"
#include "narrowphase/contact_cache_math.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase {
namespace {

// Union-find root with path halving.
inline std::uint32_t root(std::vector<std::uint32_t>& parent, std::uint32_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

constexpr std::ptrdiff_t kParallelFrom = 20000;

// How many places ahead the store's fill asks for a contact's impulse words
// (read from random places of the records): settle scene of 10^5, 2
// threads, the fill 2.87-2.89 ms asking 8 ahead, 2.40-2.45 asking 24 or 32.
constexpr std::uint32_t kStoreAhead = 32;

// A sphere's few places (each b << 32 | contact, unique) in ascending order,
// without a branch on the values: each goes to the count of those below it.
// Insertion's compares went wrong about every other time (the store at 10^5
// spent 0.9 ms of its 4.5 in them). Runs past 16 (rare) by insertion.
inline void order_run(std::uint64_t* v, std::uint32_t n) {
  constexpr std::uint32_t kMost = 16;
  if (n < 2) return;
  if (n > kMost) {
    sort_run(v, 0, n, [](std::uint64_t x) { return x; });
    return;
  }
  std::uint64_t in[kMost];
  for (std::uint32_t i = 0; i < n; ++i) in[i] = v[i];
  for (std::uint32_t i = 0; i < n; ++i) {
    std::uint32_t below = 0;
    for (std::uint32_t j = 0; j < n; ++j) below += in[j] < in[i] ? 1u : 0u;
    v[below] = in[i];
  }
}

}  // namespace

template <class C>
std::size_t cold_start_unloaded_islands(Runs<C> contacts, std::size_t count, const std::uint64_t* keys,
                                        const real* normal_impulse, const std::uint8_t* matched,
                                        std::size_t entry_count, const BodiesView& bodies, real weight_impulse,
                                        std::uint8_t* loaded, IslandScratch* scratch) {
  // The lost loads, on all threads in entry order (a pile at rest loses
  // none, and this scan of every entry was the rule's whole cost).
  IslandScratch local;
  IslandScratch& lists = scratch ? *scratch : local;
  std::vector<std::uint32_t>& unloaded = lists.unloaded;
  unloaded.clear();  // collect_in_order appends
  collect_in_order(entry_count, 20000, unloaded, lists.parts, [&](std::size_t k, std::vector<std::uint32_t>& to) {
    if (matched[k]) return;
    const auto a = static_cast<std::uint32_t>(keys[k] >> 32);
    if (a >= bodies.count || !is_lost_load(normal_impulse[k], bodies.inv_mass[a], weight_impulse)) return;
    to.push_back(static_cast<std::uint32_t>(k));
  });
  if (unloaded.empty()) return 0;

  // Islands of touching spheres. An island starts cold when it lost a load
  // of at least a quarter of the largest impulse it still carries (the top of
  // a stack removed), not when a sphere merely leaves the surface of a deep pile.
  std::vector<std::uint32_t> parent(bodies.count);
  std::iota(parent.begin(), parent.end(), 0u);
  for (std::size_t t = 0; t < count; ++t) {
    const auto& c = contacts[t];
    if (!is_wall(c.b)) parent[root(parent, c.a)] = root(parent, c.b);
  }
  std::vector<real> island_max(bodies.count, 0);
  for (std::size_t t = 0; t < count; ++t) {
    const auto& c = contacts[t];
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
  for (std::size_t t = 0; t < count; ++t) {
    auto& c = contacts[t];
    if (!cold[root(parent, c.a)] || c.normal_impulse <= 0) continue;
    c.normal_impulse = 0;
    c.tangent_impulse = Vec3{};
    c.rolling_impulse = Vec3{};
    if (loaded) loaded[t] = 0;
    ++set_cold;
  }
  return set_cold;
}

template std::size_t cold_start_unloaded_islands(ContactRuns, std::size_t, const std::uint64_t*, const real*,
                                                 const std::uint8_t*, std::size_t, const BodiesView&, real,
                                                 std::uint8_t*, IslandScratch*);
template std::size_t cold_start_unloaded_islands(FoundRuns, std::size_t, const std::uint64_t*, const real*,
                                                 const std::uint8_t*, std::size_t, const BodiesView&, real,
                                                 std::uint8_t*, IslandScratch*);

void key_runs(const std::uint64_t* keys, std::uint32_t m, std::size_t spheres, std::vector<std::uint32_t>& first) {
  // The entries' spheres a (spheres for those past them) are sorted.
  first.resize(spheres + 1);
  sorted_bucket_starts(
      m, spheres, [keys, spheres](std::uint32_t k) { return std::min<std::uint64_t>(keys[k] >> 32, spheres); },
      first.data(), static_cast<std::uint32_t>(kParallelFrom));
}

CacheEntries renumbered(const CacheEntries& e, const std::vector<std::uint32_t>& new_index) {
  // Each entry's new key, then a counting sort by the new a (in parallel:
  // core/counting_sort.hpp) and each sphere's few entries ordered by b, as
  // the store orders them: the keys are unique, so the sorted order. An
  // entry of a sphere past new_index (a world that lost spheres) is
  // dropped, as the CUDA twin drops it: no lookup would find it.
  const auto m = static_cast<std::uint32_t>(e.size());
  const auto spheres = static_cast<std::uint32_t>(new_index.size());
  constexpr std::uint64_t dropped = ~std::uint64_t(0);
  std::vector<std::uint64_t> key(m);
  std::vector<std::uint8_t> swapped(m, 0);
  for (std::uint32_t k = 0; k < m; ++k) {
    const RenamedKey r = renamed_key(static_cast<std::uint32_t>(e.key[k] >> 32), static_cast<std::uint32_t>(e.key[k]),
                                     new_index.data(), spheres);
    if (r.outcome == Renamed::not_a_numbering)
      throw std::out_of_range("renumbered: a new index past the spheres (not a numbering of them)");
    key[k] = r.outcome == Renamed::kept ? r.key : dropped;
    swapped[k] = r.swapped;
  }
  std::vector<std::uint32_t> order(m), first, scratch;
  counting_sort(
      m, spheres, [&](std::uint32_t k) { return key[k] == dropped ? kSkipItem : static_cast<std::uint32_t>(key[k] >> 32); },
      [&](std::uint32_t k, std::uint32_t place) { order[place] = k; }, first, scratch);
  const std::uint32_t kept = first[spheres];
#pragma omp parallel for schedule(static) if (spheres >= kParallelFrom)
  for (std::ptrdiff_t g = 0; g < static_cast<std::ptrdiff_t>(spheres); ++g) {
    const auto a = static_cast<std::uint32_t>(g);
    sort_run(order.data(), first[a], first[a + 1], [&key](std::uint32_t k) { return key[k]; });
  }
  CacheEntries out;
  out.resize(kept);
  const bool colours = e.colour.size() == m;
  if (!colours) out.colour.clear();
#pragma omp parallel for schedule(static) if (kept >= kParallelFrom)
  for (std::ptrdiff_t t = 0; t < static_cast<std::ptrdiff_t>(kept); ++t) {
    const auto i = static_cast<std::size_t>(t);
    const std::uint32_t k = order[i];
    out.key[i] = key[k];
    out.normal_impulse[i] = e.normal_impulse[k];
    out.tangent_impulse[i] = turned(e.tangent_impulse[k], swapped[k]);
    out.rolling_impulse[i] = turned(e.rolling_impulse[k], swapped[k]);
    if (colours) out.colour[i] = e.colour[k];
  }
  return out;
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
                                  std::vector<std::uint8_t>& kept_colour, std::vector<std::uint8_t>* loaded) {
  return restore(ContactRuns(contacts.data()), contacts.size(), bodies, weight_impulse, kept_colour, loaded);
}

std::size_t ContactCache::restore(ContactRuns contacts, std::size_t count, const BodiesView& bodies,
                                  real weight_impulse, std::vector<std::uint8_t>& kept_colour,
                                  std::vector<std::uint8_t>* loaded) {
  return restore_runs(contacts, count, bodies, weight_impulse, kept_colour, loaded);
}
std::size_t ContactCache::restore(FoundRuns contacts, std::size_t count, const BodiesView& bodies,
                                  real weight_impulse, std::vector<std::uint8_t>& kept_colour,
                                  std::vector<std::uint8_t>* loaded) {
  return restore_runs(contacts, count, bodies, weight_impulse, kept_colour, loaded);
}

template <class C>
std::size_t ContactCache::restore_runs(Runs<C> contacts, std::size_t count, const BodiesView& bodies,
                                       real weight_impulse, std::vector<std::uint8_t>& kept_colour,
                                       std::vector<std::uint8_t>* loaded) {
  const CacheEntries& e = entries();
  const auto m = static_cast<std::uint32_t>(e.size());
  if (m == 0) {
    kept_colour.assign(count, kNoKeptColour);
    if (loaded) loaded->assign(count, 0);
    return 0;
  }
  // Each contact's kept colour and load written once in the loop below.
  kept_colour.resize(count);
  if (loaded) loaded->resize(count);
  std::uint8_t* carried = loaded ? loaded->data() : nullptr;
  const std::uint8_t* colour = e.colour.size() == m ? e.colour.data() : nullptr;
  m_matched.resize(m);
  std::uint8_t* matched_entry = m_matched.data();
#pragma omp parallel for schedule(static) if (m >= kParallelFrom)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(m); ++k) matched_entry[k] = 0;
  const std::uint64_t* keys = e.key.data();
  // The entries of sphere a are keys[first[a], first[a + 1]) (sorted by key,
  // so grouped by a): a contact scans its sphere's few entries instead of
  // searching all of them, and finds the same entry (keys are unique).
  // Entries of spheres that no longer exist (a >= count) are never matched.
  const std::size_t spheres = bodies.count;
  if (m_runs_spheres != spheres) {
    key_runs(keys, m, spheres, m_first);
    m_runs_spheres = spheres;
  }
  const std::uint32_t* first = m_first.data();
  const auto n = static_cast<std::ptrdiff_t>(count);
  std::size_t matched = 0;
  // The arrays as pointers, and each thread's own copy of the runs: the
  // flags' byte stores may alias anything as far as the compiler knows,
  // and every pointer reached through a reference was read again after
  // each of them.
  const real* normal = e.normal_impulse.data();
  const Vec3* tangent = e.tangent_impulse.data();
  const Vec3* rolling = e.rolling_zero ? nullptr : e.rolling_impulse.data();
  std::uint8_t* kept_out = kept_colour.data();
#pragma omp parallel reduction(+ : matched) if (n >= kParallelFrom)
  {
    const Runs<C> runs = contacts;
#pragma omp for schedule(static)
    for (std::ptrdiff_t t = 0; t < n; ++t) {
      C& c = runs[t];
      const std::uint32_t k = c.a < spheres ? find_in_run(keys, first[c.a], first[c.a + 1], cache_key(c.a, c.b)) : m;
      if (k == m || k == first[c.a + 1]) {
        kept_out[t] = kNoKeptColour;
        if (carried) carried[t] = 0;
        continue;
      }
      restore_impulses(c, normal[k], tangent[k], rolling ? rolling[k] : Vec3{});
      if (carried) carried[t] = carries_load(normal[k]) ? 1 : 0;
      kept_out[t] = colour ? colour[k] : kNoKeptColour;
      matched_entry[k] = 1;  // keys are unique: one contact per entry
      ++matched;
    }
  }
  return matched - cold_start_unloaded_islands(contacts, count, keys, e.normal_impulse.data(),
                                                m_matched.data(), m, bodies, weight_impulse, carried, &m_islands);
}

std::uint32_t ContactCache::kept_masks(std::size_t body_count, std::vector<std::uint64_t>& used) {
  used.resize(body_count);
  std::uint64_t* u = used.data();
#pragma omp parallel for schedule(static) if (body_count >= kParallelFrom)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(body_count); ++i) u[i] = 0;
  const CacheEntries& e = entries();
  const std::size_t m = e.size();
  if (m == 0 || e.colour.size() != m || m_matched.size() != m) return 0;
  const std::uint64_t* keys = e.key.data();
  const std::uint8_t* colour = e.colour.data();
  const std::uint8_t* matched = m_matched.data();
  // In key order: sorted by a, and a sphere pair's b above its a.
  return or_kept_colours_by_a(
      m,
      [=](std::uint32_t k) {
        return KeptItem{static_cast<std::uint32_t>(keys[k] >> 32), static_cast<std::uint32_t>(keys[k]),
                        matched[k] ? colour[k] : kNoKeptColour};
      },
      used.data());
}

void ContactCache::store(const std::vector<Contact>& contacts, const ColourRanges& ranges) {
  const Contact* cs = contacts.data();
  std::uint32_t groups = 0;  // the largest a, plus one
  for (const Contact& c : contacts) groups = std::max(groups, c.a + 1);
  store_from(
      static_cast<std::uint32_t>(contacts.size()), groups, ranges, true,
      [cs](std::uint32_t t) { return BodyPair{cs[t].a, cs[t].b}; },
      [cs](std::uint32_t t) { return cs[t].normal_impulse; },
      [cs](std::uint32_t t) {
        const Contact& c = cs[t];
        return Stored{c.normal_impulse, c.tangent_impulse, c.rolling_impulse};
      },
      [cs](std::uint32_t t) { __builtin_prefetch(cs + t); });
}

void ContactCache::store(const SweepRecords& records, std::uint32_t count, bool rolling, const ColourRanges& ranges,
                         std::uint32_t spheres) {
  const BodyPair* bodies = records.bodies;
  const Real4* impulse = records.impulse;
  const Real4* rolling_word = records.rolling;
  auto impulses = [records, rolling](std::uint32_t t) {
    Contact c;  // the impulses as the unpacking reads them (zero rolling without its words)
    if (rolling) unpack_sweep_impulses<true>(records, t, c);
    else unpack_sweep_impulses<false>(records, t, c);
    return Stored{c.normal_impulse, c.tangent_impulse, c.rolling_impulse};
  };
  store_from(
      count, spheres, ranges, rolling, [bodies](std::uint32_t t) { return bodies[t]; },
      [records](std::uint32_t t) { return impulse_word(records, t).x; }, impulses,
      [impulse, rolling_word, rolling](std::uint32_t t) {
        __builtin_prefetch(impulse + t);
        if (rolling) __builtin_prefetch(rolling_word + t);
      });
}

template <class PairOf, class NormalOf, class Load, class Hint>
void ContactCache::store_from(std::uint32_t n, std::uint32_t groups, const ColourRanges& ranges, bool rolling,
                              PairOf&& pair_of, NormalOf&& normal_of, Load&& load, Hint&& hint) {
  // Only the sustained impulses of the velocity solve are carried over; an
  // impact's impulse (Contact::impact_impulse) is not a load. A contact
  // without load is kept for its colour alone, with no impulses (restored,
  // it starts as an uncached contact does); a contact without colour (the
  // overflow set, or every contact where no colours are known) and without
  // load is not kept.
  // Sorted by key = grouped by sphere a, then by b within a group. A
  // counting sort by a (in parallel: core/counting_sort.hpp) over the body
  // pairs read in contact order places each kept contact with its b above
  // its index; each group (a few entries) is ordered by b from the places
  // alone; then the entries are filled group by group, each contact's
  // impulses read where they are (one word, or two with rolling, asked for
  // kStoreAhead places ahead) and its colour from a byte a contact (in L2).
  const bool coloured = ranges.size() == n;
  const std::uint32_t coloured_end = coloured ? ranges.begin[ranges.colours] : 0;
  m_colour_of.resize(n);
  std::uint8_t* colour_of = m_colour_of.data();
  for (std::uint32_t c = 0; c < (coloured ? ranges.colours : 0); ++c)
    std::fill(colour_of + ranges.begin[c], colour_of + ranges.begin[c + 1], static_cast<std::uint8_t>(c));
  std::fill(colour_of + coloured_end, colour_of + n, kNoKeptColour);
  m_source.resize(n);
  std::uint64_t* source = m_source.data();
  // Captured by value (copies of the small accessors, the bounds and the
  // pointer): taken by reference, the sort's loops read each through two
  // or three pointers again after every store.
  auto bucket = [pair_of, normal_of, coloured_end, groups](std::uint32_t k) {
    const std::uint32_t a = pair_of(k).a;
    return (k < coloured_end || normal_of(k) > 0) && a < groups ? a : kSkipItem;
  };
  auto place = [pair_of, source](std::uint32_t k, std::uint32_t at) {
    source[at] = (std::uint64_t(pair_of(k).b) << 32) | k;
  };
  counting_sort(n, groups, bucket, place, m_first, m_order);
  const std::uint32_t m = m_first[groups];
  CacheEntries& e = writable();
  e.resize(m);  // entries past the last size made +0
  m_runs_spheres = groups;  // m_first: the runs key_runs would find in the keys written below
  // The entries' arrays as pointers, and each thread's own copies of the
  // accessors: the colour's byte store may alias anything as far as the
  // compiler knows, and every pointer reached through `e` or a reference
  // was read again after it. Without rolling impulses, the rolling ones are
  // written only where the entries may hold others (not known all +0).
  Vec3* rolling_out = rolling || !e.rolling_zero ? e.rolling_impulse.data() : nullptr;
  std::uint64_t* key_out = e.key.data();
  real* normal_out = e.normal_impulse.data();
  Vec3* tangent_out = e.tangent_impulse.data();
  std::uint8_t* colour_out = e.colour.data();
  const std::uint32_t* first_of = m_first.data();
#pragma omp parallel if (groups >= kParallelFrom)
  {
    const std::decay_t<Load> load_here = load;
    const std::decay_t<Hint> hint_here = hint;
#pragma omp for schedule(static)
    for (std::ptrdiff_t g = 0; g < static_cast<std::ptrdiff_t>(groups); ++g) {
      const auto a = static_cast<std::uint32_t>(g);
      const std::uint32_t first = first_of[a], last = first_of[a + 1];
      order_run(source + first, last - first);
      for (std::uint32_t t = first; t < last; ++t) {
        hint_here(static_cast<std::uint32_t>(source[std::min(t + kStoreAhead, m - 1)]));
        const auto k = static_cast<std::uint32_t>(source[t]);
        const Stored c = load_here(k);
        const bool loaded = c.normal_impulse > 0;
        key_out[t] = cache_key(a, static_cast<std::uint32_t>(source[t] >> 32));
        normal_out[t] = loaded ? c.normal_impulse : real(0);
        tangent_out[t] = loaded ? c.tangent_impulse : Vec3{};
        if (rolling_out) rolling_out[t] = loaded ? c.rolling_impulse : Vec3{};
        colour_out[t] = colour_of[k];
      }
    }
  }
  e.rolling_zero = !rolling;
}

}  // namespace marbles::narrowphase
