// tests/narrowphase/contact_cache_test.cpp — the cache's entries under a
// new numbering of the spheres (renumbered, for solver.renumber).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <random>
#include <set>
#include <stdexcept>
#include <vector>

#include "narrowphase/colouring.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contact_cache_math.hpp"

namespace marbles::narrowphase {
namespace {

// `count` cache entries of n spheres, sorted by key: pairs a < b and, one
// in four, a sphere and one of `walls` walls; random impulses, a third of
// them idle (normal 0), some components -0 or +0; colours below 20.
CacheEntries random_entries(std::mt19937_64& rng, std::uint32_t n, std::size_t count, std::uint32_t walls) {
  std::uniform_real_distribution<float> u(-1, 1);
  std::set<std::uint64_t> keys;
  while (keys.size() < count) {
    const std::uint32_t a = rng() % n, b = rng() % 4 == 0 ? kWallFlag | static_cast<std::uint32_t>(rng() % walls) : rng() % n;
    if (is_wall(b) || a < b) keys.insert(cache_key(a, b));
  }
  CacheEntries e;
  for (std::uint64_t key : keys) {
    e.key.push_back(key);
    e.normal_impulse.push_back(rng() % 3 == 0 ? 0.0f : std::abs(u(rng)));
    e.tangent_impulse.push_back({u(rng), rng() % 5 == 0 ? -0.0f : u(rng), u(rng)});
    e.rolling_impulse.push_back({u(rng), u(rng), rng() % 5 == 0 ? 0.0f : u(rng)});
    e.colour.push_back(static_cast<std::uint8_t>(rng() % 20));
  }
  return e;
}

// A random numbering of n spheres (new_index[i]: sphere i's new index).
std::vector<std::uint32_t> random_numbering(std::mt19937_64& rng, std::uint32_t n) {
  std::vector<std::uint32_t> new_index(n);
  std::iota(new_index.begin(), new_index.end(), 0u);
  std::shuffle(new_index.begin(), new_index.end(), rng);
  return new_index;
}

// renumbered: the entries of random pairs (and walls) under a random
// numbering of the spheres are the same contacts with the new names (a
// swapped pair with its tangential and rolling impulses negated), sorted
// by key; the inverse numbering gives back every bit.
TEST(ContactCacheRenumbered, NewNamesSameImpulsesAndBackAgain) {
  std::mt19937_64 rng(21);
  const std::uint32_t n = 300;
  const CacheEntries e = random_entries(rng, n, 900, 3);
  const std::vector<std::uint32_t> new_index = random_numbering(rng, n);
  std::vector<std::uint32_t> old_index(n);
  for (std::uint32_t i = 0; i < n; ++i) old_index[new_index[i]] = i;

  const CacheEntries r = renumbered(e, new_index);
  ASSERT_EQ(r.size(), e.size());
  EXPECT_TRUE(std::is_sorted(r.key.begin(), r.key.end()));
  std::size_t swapped = 0;
  for (std::size_t k = 0; k < e.size(); ++k) {
    const auto a = static_cast<std::uint32_t>(e.key[k] >> 32), b = static_cast<std::uint32_t>(e.key[k]);
    const std::uint32_t na = new_index[a], nb = is_wall(b) ? b : new_index[b];
    const bool swap = !is_wall(b) && nb < na;
    const std::uint64_t key = swap ? cache_key(nb, na) : cache_key(na, nb);
    const auto at = std::lower_bound(r.key.begin(), r.key.end(), key);
    ASSERT_TRUE(at != r.key.end() && *at == key) << k;
    const std::size_t j = at - r.key.begin();
    const real sign = swap ? -1 : 1;
    swapped += swap;
    EXPECT_EQ(r.normal_impulse[j], e.normal_impulse[k]);
    EXPECT_EQ(r.tangent_impulse[j].x, sign * e.tangent_impulse[k].x);
    EXPECT_EQ(r.tangent_impulse[j].z, sign * e.tangent_impulse[k].z);
    EXPECT_EQ(r.rolling_impulse[j].y, sign * e.rolling_impulse[k].y);
    EXPECT_EQ(r.colour[j], e.colour[k]);
  }
  EXPECT_GT(swapped, 100u);
  const CacheEntries back = renumbered(r, old_index);
  EXPECT_EQ(back.key, e.key);
  EXPECT_EQ(back.normal_impulse, e.normal_impulse);
  EXPECT_EQ(std::memcmp(back.tangent_impulse.data(), e.tangent_impulse.data(), e.size() * sizeof(Vec3)), 0);
  EXPECT_EQ(std::memcmp(back.rolling_impulse.data(), e.rolling_impulse.data(), e.size() * sizeof(Vec3)), 0);
  EXPECT_EQ(back.colour, e.colour);
}

// A cache large enough for the parallel counting sort (more entries and
// spheres than one thread sorts): the same entries as a plain sort of the
// renamed ones gives, bit for bit; a name past the spheres is refused.
TEST(ContactCacheRenumbered, LargeCacheAgreesWithAPlainSort) {
  std::mt19937_64 rng(1127);
  const std::uint32_t n = 40000;
  const CacheEntries e = random_entries(rng, n, 150000, 5);
  const std::vector<std::uint32_t> new_index = random_numbering(rng, n);

  struct Renamed {
    std::uint64_t key;
    std::size_t from;
    bool swapped;
  };
  std::vector<Renamed> oracle;
  for (std::size_t k = 0; k < e.size(); ++k) {
    const auto a = static_cast<std::uint32_t>(e.key[k] >> 32), b = static_cast<std::uint32_t>(e.key[k]);
    const std::uint32_t na = new_index[a], nb = is_wall(b) ? b : new_index[b];
    const bool swap = !is_wall(b) && nb < na;
    oracle.push_back({swap ? cache_key(nb, na) : cache_key(na, nb), k, swap});
  }
  std::sort(oracle.begin(), oracle.end(), [](const Renamed& x, const Renamed& y) { return x.key < y.key; });

  const CacheEntries r = renumbered(e, new_index);
  ASSERT_EQ(r.size(), e.size());
  std::size_t swapped = 0;
  for (std::size_t j = 0; j < r.size(); ++j) {
    const Renamed& o = oracle[j];
    ASSERT_EQ(r.key[j], o.key) << j;
    // Turned round: negated, but a zero keeps its sign.
    const auto turn = [&o](const Vec3& v) {
      const auto one = [&o](real x) { return o.swapped && x != 0 ? -x : x; };
      return Vec3{one(v.x), one(v.y), one(v.z)};
    };
    const Vec3 t = turn(e.tangent_impulse[o.from]);
    const Vec3 w = turn(e.rolling_impulse[o.from]);
    ASSERT_EQ(std::memcmp(&r.normal_impulse[j], &e.normal_impulse[o.from], sizeof(real)), 0) << j;
    ASSERT_EQ(std::memcmp(&r.tangent_impulse[j], &t, sizeof(Vec3)), 0) << j;
    ASSERT_EQ(std::memcmp(&r.rolling_impulse[j], &w, sizeof(Vec3)), 0) << j;
    ASSERT_EQ(r.colour[j], e.colour[o.from]) << j;
    swapped += o.swapped;
  }
  EXPECT_GT(swapped, e.size() / 4);

  // A sphere with a wall entry named past the spheres: that entry's new key
  // would name it first.
  const auto wall = std::find_if(e.key.begin(), e.key.end(), [](std::uint64_t k) { return is_wall(static_cast<std::uint32_t>(k)); });
  ASSERT_NE(wall, e.key.end());
  std::vector<std::uint32_t> past = new_index;
  past[static_cast<std::uint32_t>(*wall >> 32)] = n;
  EXPECT_THROW(renumbered(e, past), std::out_of_range);
}

// A world that lost spheres: entries that name a sphere past the
// numbering (as a or as b) are dropped, the rest renamed as ever.
TEST(ContactCacheRenumbered, EntriesOfSpheresPastTheNumberingAreDropped) {
  CacheEntries e;
  const std::uint64_t keys[] = {cache_key(0, 2), cache_key(0, 7), cache_key(1, kWallFlag | 2), cache_key(2, 3),
                                cache_key(6, kWallFlag), cache_key(6, 9)};
  for (std::uint64_t key : keys) {
    e.key.push_back(key);
    e.normal_impulse.push_back(real(e.key.size()));
    e.tangent_impulse.push_back({1, 2, 3});
    e.rolling_impulse.push_back({4, 5, 6});
    e.colour.push_back(static_cast<std::uint8_t>(e.key.size()));
  }
  const std::vector<std::uint32_t> new_index{3, 0, 1, 2};  // spheres 0..3 only
  const CacheEntries r = renumbered(e, new_index);
  // (0, 2) -> (3, 1) turned: (1, 3); (1, wall 2) -> (0, wall 2); (2, 3) -> (1, 2).
  ASSERT_EQ(r.key, (std::vector<std::uint64_t>{cache_key(0, kWallFlag | 2), cache_key(1, 2), cache_key(1, 3)}));
  EXPECT_EQ(r.normal_impulse, (std::vector<real>{3, 4, 1}));
  EXPECT_EQ(r.tangent_impulse[2], Vec3(-1, -2, -3));
  EXPECT_EQ(r.rolling_impulse[0], Vec3(4, 5, 6));
  EXPECT_EQ(r.colour, (std::vector<std::uint8_t>{3, 4, 1}));
}


// keep() holds the entries as they were, with no copy, through whatever
// changes them after (set_entries, clear, store: each writes the arrays not
// kept), and back_to_kept() gives them back bit for bit, as often as asked;
// a later keep() holds the entries of then.
TEST(ContactCacheKept, TheKeptEntriesComeBackWhateverChangedThemSince) {
  std::mt19937_64 rng(17);
  auto same = [](const CacheEntries& x, const CacheEntries& y) {
    return x.key == y.key && x.colour == y.colour && x.size() == y.size() &&
           std::memcmp(x.normal_impulse.data(), y.normal_impulse.data(), x.size() * sizeof(real)) == 0 &&
           std::memcmp(x.tangent_impulse.data(), y.tangent_impulse.data(), x.size() * sizeof(Vec3)) == 0 &&
           std::memcmp(x.rolling_impulse.data(), y.rolling_impulse.data(), x.size() * sizeof(Vec3)) == 0;
  };
  const CacheEntries first = random_entries(rng, 50, 80, 3), second = random_entries(rng, 60, 90, 3),
                     third = random_entries(rng, 40, 70, 3);
  ContactCache cache;
  cache.set_entries(first);
  cache.keep();
  cache.set_entries(second);
  EXPECT_TRUE(same(cache.entries(), second));
  cache.clear();
  EXPECT_EQ(cache.size(), 0u);
  // A store from contacts (one colour each, impulses loaded): what it keeps
  // is not the kept entries.
  std::vector<Contact> contacts(3);
  for (std::uint32_t k = 0; k < 3; ++k) contacts[k].a = k, contacts[k].b = k + 5, contacts[k].normal_impulse = 1;
  ColourRanges ranges;
  ranges.colours = 3, ranges.begin = {0, 1, 2, 3, 3};
  cache.store(contacts, ranges);
  ASSERT_EQ(cache.size(), 3u);
  cache.set_entries(third);
  cache.back_to_kept();
  EXPECT_TRUE(same(cache.entries(), first));
  cache.store(contacts, ranges);  // a redone step writes elsewhere: still kept
  cache.back_to_kept();
  EXPECT_TRUE(same(cache.entries(), first));
  cache.set_entries(second);
  cache.keep();
  cache.set_entries(third);
  cache.back_to_kept();
  EXPECT_TRUE(same(cache.entries(), second));
}

}  // namespace
}  // namespace marbles::narrowphase
