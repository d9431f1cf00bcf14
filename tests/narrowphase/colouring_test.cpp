// Contact colouring: proper (no sphere twice in a colour), complete (every
// contact once, coloured or in the overflow set), deterministic (twice, any
// thread count), and equal to its oracle: the sequential greedy colouring in
// rank order, which the Jones–Plassmann rounds must reproduce exactly.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "core/parallel.hpp"
#include "narrowphase/colouring.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/solver_math.hpp"
#include "tests/narrowphase/random_pairs.hpp"

namespace marbles::narrowphase {
namespace {

// The data-parallel form the CUDA twin runs (colouring_cuda.cu), written
// plainly: Jones–Plassmann rounds over a shrinking list of uncoloured
// contacts, offers by max, the holders of both offers coloured. The library's
// colour() computes the same in one sequential pass; these tests hold the two
// (and the GPU, in colouring_cuda_test.cu) to the same answer.
// `kept`: contacts whose colour[k] is set beforehand; they mark their spheres
// and take no part in the rounds.
std::uint32_t colour_in_rounds(const Contact* contacts, const std::vector<std::uint32_t>& active,
                               const std::uint64_t* rank, std::size_t body_count, ColourRule rule,
                               std::vector<std::uint32_t>& colour, const std::vector<std::uint32_t>& kept = {}) {
  std::vector<std::uint64_t> body_word(body_count, 0), body_used(body_count, 0);
  for (const std::uint32_t k : kept) {
    body_used[contacts[k].a] |= std::uint64_t(1) << colour[k];
    if (!is_wall(contacts[k].b)) body_used[contacts[k].b] |= std::uint64_t(1) << colour[k];
  }
  std::vector<std::uint32_t> left = active, next;
  std::uint32_t round = 0;
  for (; !left.empty() && round < kMaxColourRounds; ++round) {
    for (const std::uint32_t k : left) {
      const Contact& c = contacts[k];
      const std::uint64_t word = round_word(round, rank[k]);
      body_word[c.a] = std::max(body_word[c.a], word);
      if (!is_wall(c.b)) body_word[c.b] = std::max(body_word[c.b], word);
    }
    next.clear();
    for (const std::uint32_t k : left) {
      const Contact& c = contacts[k];
      const bool wall = is_wall(c.b);
      if (!holds_both(round_word(round, rank[k]), body_word[c.a], wall ? 0 : body_word[c.b], wall)) {
        next.push_back(k);
        continue;
      }
      colour[k] = rule == ColourRule::by_round ? round
                                               : take_lowest_free(body_used[c.a], wall ? nullptr : &body_used[c.b]);
    }
    left.swap(next);
  }
  for (const std::uint32_t k : left) colour[k] = kOverflowColour;
  return round;
}

// Distinct pairs (test::random_pairs), each with its index as a tag.
std::vector<Contact> random_contacts(std::mt19937_64& rng, std::uint32_t bodies, std::size_t count, double wall_share) {
  std::vector<Contact> out = test::random_pairs(rng, 0, bodies, count, wall_share);
  for (std::size_t k = 0; k < out.size(); ++k) out[k].separation = real(k);  // a tag to find the contact after sorting
  return out;
}

// A random contact count up to 9 000, at most the distinct pairs of `bodies`.
std::size_t random_count(std::mt19937_64& rng, std::uint32_t bodies) {
  const std::size_t max_pairs = std::size_t(bodies) * (bodies - 1) / 2;
  return std::min<std::size_t>(max_pairs, rng() % 9000);
}

// The oracle: contacts with a kept colour keep it; the others in decreasing
// rank, each takes the lowest colour its spheres' kept and earlier contacts
// do not have.
std::vector<std::uint32_t> greedy_colours(const std::vector<Contact>& contacts,
                                          const std::vector<std::uint8_t>& kept = {}) {
  const auto n = static_cast<std::uint32_t>(contacts.size());
  std::vector<std::uint32_t> order;
  std::map<std::uint32_t, std::uint64_t> used;
  std::vector<std::uint32_t> colour(n);
  for (std::uint32_t k = 0; k < n; ++k) {
    if (kept.empty() || kept[k] == kNoKeptColour) {
      order.push_back(k);
      continue;
    }
    colour[k] = kept[k];
    used[contacts[k].a] |= std::uint64_t(1) << kept[k];
    if (!is_wall(contacts[k].b)) used[contacts[k].b] |= std::uint64_t(1) << kept[k];
  }
  auto rank = [&](std::uint32_t k) { return contact_rank(contacts[k].a, contacts[k].b, k); };
  std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) { return rank(x) > rank(y); });
  for (std::uint32_t k : order) {
    const Contact& c = contacts[k];
    const std::uint64_t u = used[c.a] | (is_wall(c.b) ? 0 : used[c.b]);
    colour[k] = lowest_free_colour(u);
    if (colour[k] == kOverflowColour) continue;
    used[c.a] |= std::uint64_t(1) << colour[k];
    if (!is_wall(c.b)) used[c.b] |= std::uint64_t(1) << colour[k];
  }
  return colour;
}

// `loaded`: which contacts carry a load in (empty: not told); the solver's
// records of each colour then hold its loaded contacts first, then the
// others, each part in index order, and the overflow set's are its own
// places.
void expect_matches_oracle(const std::vector<Contact>& input, std::uint32_t bodies,
                           const std::vector<std::uint8_t>& kept = {}, const std::vector<std::uint8_t>& loaded = {}) {
  std::vector<Contact> contacts = input;
  ColourRanges ranges;
  ContactColouring().colour_and_sort(contacts, bodies, ranges, kept.empty() ? nullptr : kept.data(), nullptr, 0,
                                     loaded.empty() ? nullptr : loaded.data());
  ASSERT_EQ(contacts.size(), input.size());
  EXPECT_EQ(ranges.size(), input.size());
  EXPECT_TRUE(colouring_is_proper(contacts, ranges, bodies));
  const std::vector<std::uint32_t> expect = greedy_colours(input, kept);
  std::vector<int> seen(input.size(), 0);
  for (std::uint32_t c = 0; c <= ranges.colours; ++c)
    for (std::uint32_t k = ranges.begin[c]; k < ranges.begin[c + 1]; ++k) {
      const auto tag = static_cast<std::size_t>(contacts[k].separation);
      ++seen[tag];
      const std::uint32_t want = expect[tag] == kOverflowColour ? ranges.colours : expect[tag];
      ASSERT_EQ(c, want) << "contact " << tag;
      if (k > ranges.begin[c]) {
        EXPECT_LT(contacts[k - 1].separation, contacts[k].separation) << "index order in a colour";
      }
    }
  for (std::size_t k = 0; k < seen.size(); ++k) EXPECT_EQ(seen[k], 1) << "contact " << k;
  if (loaded.empty()) {
    EXPECT_TRUE(ranges.record.empty() && ranges.unloaded.empty());
  } else {
    // The records: the oracle is a stable partition of each colour's contacts.
    ASSERT_EQ(ranges.record.size(), input.size());
    ASSERT_EQ(ranges.unloaded.size(), ranges.colours);
    std::vector<std::uint32_t> at(input.size(), 0xffffffffu);  // the contact at each record
    for (std::uint32_t c = 0; c <= ranges.colours; ++c) {
      std::vector<std::uint32_t> order(contacts.size());
      auto first = order.begin() + ranges.begin[c], last = order.begin() + ranges.begin[c + 1];
      std::iota(first, last, ranges.begin[c]);
      if (c < ranges.colours) {
        const auto split = std::stable_partition(first, last, [&](std::uint32_t k) {
          return loaded[static_cast<std::size_t>(contacts[k].separation)] != 0;
        });
        EXPECT_EQ(ranges.unloaded_from(c), static_cast<std::uint32_t>(split - order.begin())) << "colour " << c;
      }
      for (std::uint32_t r = ranges.begin[c]; r < ranges.begin[c + 1]; ++r) {
        const std::uint32_t record = ranges.record_of(order[r]);
        ASSERT_TRUE(record >= ranges.begin[c] && record < ranges.begin[c + 1]) << "contact " << order[r];
        at[record] = order[r];
      }
      for (std::uint32_t r = ranges.begin[c]; r < ranges.begin[c + 1]; ++r)
        ASSERT_EQ(at[r], order[r]) << "record " << r << " of colour " << c;
    }
  }
  // The data-parallel form (the GPU's) colours every contact alike.
  const auto n = static_cast<std::uint32_t>(input.size());
  std::vector<std::uint64_t> rank(n);
  std::vector<std::uint32_t> active, preset, colour(n, kUncoloured);
  for (std::uint32_t k = 0; k < n; ++k) {
    rank[k] = contact_rank(input[k].a, input[k].b, k);
    if (!kept.empty() && kept[k] != kNoKeptColour) colour[k] = kept[k], preset.push_back(k);
    else active.push_back(k);
  }
  colour_in_rounds(input.data(), active, rank.data(), bodies, ColourRule::lowest_free, colour, preset);
  EXPECT_EQ(colour, expect);
}

// The contacts of a substep after `previous`: a random share of them persist
// (in a new order), new ones join. kept[k] is the colour a persisting contact
// had in the previous colouring, for a random share of them (the cache keeps
// only loaded contacts), else none.
std::vector<Contact> next_substep(std::mt19937_64& rng, const std::vector<Contact>& previous,
                                  const ColourRanges& ranges, std::uint32_t bodies, std::size_t fresh,
                                  std::vector<std::uint8_t>& kept) {
  std::vector<std::pair<Contact, std::uint8_t>> next;
  std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
  std::bernoulli_distribution persists(0.8), cached(0.9);
  for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) {
    if (!persists(rng)) return;
    next.push_back({previous[k], cached(rng) ? c : kNoKeptColour});
    seen.insert({previous[k].a, previous[k].b});
  });
  for (const Contact& c : random_contacts(rng, bodies, fresh, 0.1))
    if (seen.insert({c.a, c.b}).second) next.push_back({c, kNoKeptColour});
  std::shuffle(next.begin(), next.end(), rng);
  std::vector<Contact> out;
  kept.clear();
  for (auto& [c, colour] : next) {
    c.separation = real(out.size());
    out.push_back(c);
    kept.push_back(colour);
  }
  return out;
}

TEST(Colouring, MatchesSequentialGreedyOnRandomSets) {
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 40; ++trial) {
    const std::uint32_t bodies = 2 + static_cast<std::uint32_t>(rng() % 3000);
    const std::size_t count = random_count(rng, bodies);
    expect_matches_oracle(random_contacts(rng, bodies, count, trial % 3 == 0 ? 0.3 : 0.05), bodies);
  }
}

// With loads carried in (a random share of the contacts, kept colours or
// not): the same colours and the same colour-major contacts, and the
// solver's records each colour's loaded contacts first, then the others,
// each part in index order; none loaded and all loaded as well.
TEST(Colouring, LoadedContactsFirstInTheirColoursRecords) {
  std::mt19937_64 rng(31);
  for (int trial = 0; trial < 30; ++trial) {
    const std::uint32_t bodies = 2 + static_cast<std::uint32_t>(rng() % 3000);
    const std::size_t count = random_count(rng, bodies);
    const std::vector<Contact> contacts = random_contacts(rng, bodies, count, 0.1);
    std::vector<std::uint8_t> kept(contacts.size(), kNoKeptColour), loaded(contacts.size());
    const int share = trial % 3 == 0 ? 0 : trial % 3 == 1 ? 50 : 100;
    for (std::size_t k = 0; k < contacts.size(); ++k) loaded[k] = static_cast<int>(rng() % 100) < share ? 1 : 0;
    expect_matches_oracle(contacts, bodies, {}, loaded);
    ColourRanges ranges;  // kept colours from a first colouring, then loads
    std::vector<Contact> first = contacts;
    ContactColouring().colour_and_sort(first, bodies, ranges);
    for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) {
      if (rng() % 2 == 0) kept[static_cast<std::size_t>(first[k].separation)] = c;
    });
    expect_matches_oracle(contacts, bodies, kept, loaded);
  }
}

// Substep after substep: persisting contacts keep their colours, the new ones
// take the oracle's colours around them, in both forms; colours may be left
// empty (their contacts gone) and the ranges stay right.
TEST(Colouring, KeptColoursStayAndTheRestMatchTheOracle) {
  std::mt19937_64 rng(23);
  for (int trial = 0; trial < 12; ++trial) {
    const std::uint32_t bodies = 20 + static_cast<std::uint32_t>(rng() % 2000);
    std::vector<Contact> contacts = random_contacts(rng, bodies, std::min<std::size_t>(4 * bodies, 6000), 0.1);
    ColourRanges ranges;
    ContactColouring().colour_and_sort(contacts, bodies, ranges);
    for (int substep = 0; substep < 4; ++substep) {
      std::vector<std::uint8_t> kept;
      const std::vector<Contact> next = next_substep(rng, contacts, ranges, bodies, bodies / 2, kept);
      expect_matches_oracle(next, bodies, kept);
      contacts = next;
      ContactColouring().colour_and_sort(contacts, bodies, ranges, kept.data());
      // Every kept colour is where it was kept.
      for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) {
        const std::uint8_t want = kept[static_cast<std::size_t>(contacts[k].separation)];
        if (want != kNoKeptColour) {
          EXPECT_EQ(c, want);
        }
      });
    }
  }
  // A colour left empty: two contacts on sphere 0 kept at colours 0 and 5.
  std::vector<Contact> two(2);
  two[0].a = 0, two[0].b = 1, two[1].a = 0, two[1].b = 2, two[1].separation = 1;
  ColourRanges r;
  ContactColouring().colour_and_sort(two, 3, r, std::vector<std::uint8_t>{0, 5}.data());
  EXPECT_EQ(r.colours, 6u);
  EXPECT_EQ(r.begin, (std::vector<std::uint32_t>{0, 1, 1, 1, 1, 1, 2, 2}));
  expect_matches_oracle(two, 3, {0, 5});
}

// The cache remembers each loaded contact's colour and hands it back to the
// same pair in the next substep, wherever that contact stands in the list; a
// colouring from outside is kept only if it is proper.
TEST(ContactCache, KeepsThePersistingContactsColours) {
  std::mt19937_64 rng(31);
  const std::uint32_t bodies = 3000;
  std::vector<Contact> contacts = random_contacts(rng, bodies, 9000, 0.1);
  for (std::size_t k = 0; k < contacts.size(); ++k) contacts[k].normal_impulse = k % 5 == 0 ? real(0) : real(1e-3);
  ColourRanges ranges;
  ContactColouring().colour_and_sort(contacts, bodies, ranges);
  ContactCache cache;
  cache.store(contacts, ranges);
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint8_t> had;
  for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) {
    if (c != kNoKeptColour) had[{contacts[k].a, contacts[k].b}] = c;  // loaded or not
  });
  std::vector<std::uint8_t> unused;
  std::vector<Contact> next = next_substep(rng, contacts, ranges, bodies, 1000, unused);
  for (Contact& c : next) c.normal_impulse = real(-1), c.tangent_impulse = Vec3(1, 1, 1);  // poisoned
  std::vector<real> inv_mass(bodies, real(1));
  BodiesView view;
  view.inv_mass = inv_mass.data();
  view.count = bodies;
  std::vector<std::uint8_t> kept;
  cache.restore(next, view, real(1), kept);  // a large weight: no lost load here
  ASSERT_EQ(kept.size(), next.size());
  std::size_t found = 0;
  for (std::size_t k = 0; k < next.size(); ++k) {
    const auto it = had.find({next[k].a, next[k].b});
    EXPECT_EQ(kept[k], it == had.end() ? kNoKeptColour : it->second) << k;
    found += it != had.end();
    if (it == had.end()) continue;
    // A loaded contact gets its impulse back, one kept for its colour alone none.
    const bool loaded = std::any_of(contacts.begin(), contacts.end(), [&](const Contact& c) {
      return c.a == next[k].a && c.b == next[k].b && c.normal_impulse > 0;
    });
    EXPECT_EQ(next[k].normal_impulse, loaded ? real(1e-3) : real(0)) << k;
    if (!loaded) {
      EXPECT_EQ(next[k].tangent_impulse.x, real(0)) << k;
    }
  }
  EXPECT_GT(found, next.size() / 2);

  CacheEntries entries = cache.entries();
  EXPECT_TRUE(keep_proper_colours(entries));
  EXPECT_EQ(entries.colour, cache.entries().colour);
  // Two entries of one sphere with one colour: every colour is dropped.
  std::size_t first = 0;
  while (entries.colour[first] == kNoKeptColour) ++first;
  const auto a = static_cast<std::uint32_t>(entries.key[first] >> 32);
  std::size_t second = first + 1;
  while (second < entries.size() && static_cast<std::uint32_t>(entries.key[second] >> 32) != a) ++second;
  if (second == entries.size()) second = first;  // (not met with these contacts)
  ASSERT_NE(second, first);
  entries.colour[second] = entries.colour[first];
  EXPECT_FALSE(keep_proper_colours(entries));
  EXPECT_EQ(entries.colour, std::vector<std::uint8_t>(entries.size(), kNoKeptColour));
  entries.colour = {1};  // one colour for many entries: dropped
  EXPECT_FALSE(keep_proper_colours(entries));
  EXPECT_EQ(entries.colour.size(), entries.size());
}

// Prepared on the way: the colour-major contacts carry the masses and
// approach speed that the solver's prepare stage gives them, bit for bit,
// for any thread count.
TEST(Colouring, PreparesOnTheWayAsTheSolverWould) {
  std::mt19937_64 rng(37);
  const std::uint32_t bodies = 30000;
  std::vector<Contact> input = random_contacts(rng, bodies, 90000, 0.1);
  std::uniform_real_distribution<double> u(-1, 1), pos(0.2, 2);
  std::vector<Vec3> v(bodies), w(bodies);
  std::vector<real> inv_mass(bodies), inv_inertia(bodies);
  for (std::uint32_t i = 0; i < bodies; ++i) {
    v[i] = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
    w[i] = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
    inv_mass[i] = i % 97 == 0 ? real(0) : real(pos(rng));  // some immovable
    inv_inertia[i] = i % 97 == 0 ? real(0) : real(pos(rng));
  }
  for (Contact& c : input) {
    const Vec3 d = Vec3(real(u(rng)), real(u(rng)), real(u(rng))) + Vec3(0, 0, 2);
    c.normal = d / length(d);
    c.ra = real(pos(rng)), c.rb = is_wall(c.b) ? real(0) : real(pos(rng));
    c.wall_velocity = Vec3(real(u(rng)), 0, real(u(rng)));
  }
  BodiesView view;
  view.velocity = v.data(), view.angular_velocity = w.data();
  view.inv_mass = inv_mass.data(), view.inv_inertia = inv_inertia.data();
  view.count = bodies;
  std::vector<SolverBody> solver_bodies(bodies);
  for (std::uint32_t i = 0; i < bodies; ++i) solver_bodies[i] = gather_solver_body(view, i);
  std::vector<Contact> plain = input;
  ColourRanges plain_ranges;
  ContactColouring().colour_and_sort(plain, bodies, plain_ranges);
  for (Contact& c : plain) prepare_one(c, solver_bodies.data());
  const int was = thread_count();
  for (int threads : {1, 2}) {
    set_thread_count(threads);
    std::vector<Contact> prepared = input;
    ColourRanges ranges;
    ContactColouring().colour_and_sort(prepared, bodies, ranges, nullptr, &view);
    set_thread_count(was);
    ASSERT_EQ(ranges.begin, plain_ranges.begin);
    for (std::size_t k = 0; k < plain.size(); ++k) {
      ASSERT_EQ(prepared[k].separation, plain[k].separation) << k;  // the same contact in the same place
      EXPECT_EQ(prepared[k].normal_mass, plain[k].normal_mass) << k;
      EXPECT_EQ(prepared[k].tangent_mass, plain[k].tangent_mass) << k;
      EXPECT_EQ(prepared[k].rolling_mass, plain[k].rolling_mass) << k;
      EXPECT_EQ(prepared[k].approach_speed, plain[k].approach_speed) << k;
    }
    EXPECT_NE(plain[0].normal_mass, real(0)) << "the comparison must see prepared values";

    // fast_approach against a scan of the prepared contacts, at rest speeds
    // just below, at and above the fastest approach.
    real fastest = 0;
    for (const Contact& c : plain) fastest = std::min(fastest, c.approach_speed);
    ASSERT_LT(fastest, real(0));
    int seen = 0;
    for (real rest : {real(0), -fastest * real(0.999), -fastest, -fastest * real(2)}) {
      set_thread_count(threads);
      std::vector<Contact> again = input;
      ColourRanges r;
      ContactColouring().colour_and_sort(again, bodies, r, nullptr, &view, rest);
      set_thread_count(was);
      const bool any = std::any_of(plain.begin(), plain.end(),
                                   [&](const Contact& c) { return is_impact_candidate(c, rest); });
      EXPECT_EQ(r.fast_approach, any) << "rest speed " << rest << ", " << threads << " thread(s)";
      seen += any ? 1 : 2;
    }
    EXPECT_EQ(seen, 6);  // two rest speeds with candidates, two without
  }
  EXPECT_TRUE(plain_ranges.fast_approach);  // not prepared: unknown
}

// Adversarial: one sphere touching 200 others (more than 64 colours: the rest
// overflow), a long chain, contacts on walls only, nothing at all.
TEST(Colouring, StarChainWallsAndEmpty) {
  std::vector<Contact> star;
  for (std::uint32_t k = 1; k <= 200; ++k) {
    Contact c;
    c.a = 0;
    c.b = k;
    c.separation = real(star.size());
    star.push_back(c);
  }
  expect_matches_oracle(star, 201);
  std::vector<Contact> s = star;
  ColourRanges r;
  ContactColouring().colour_and_sort(s, 201, r);
  EXPECT_EQ(r.colours, kMaxColours);
  EXPECT_EQ(r.overflow(), 200 - kMaxColours);

  std::vector<Contact> chain, walls;
  for (std::uint32_t k = 0; k + 1 < 5000; ++k) {
    Contact c;
    c.a = k;
    c.b = k + 1;
    c.separation = real(chain.size());
    chain.push_back(c);
    c.b = kWallFlag | (k % 6);
    c.separation = real(walls.size());
    walls.push_back(c);
  }
  expect_matches_oracle(chain, 5000);
  expect_matches_oracle(walls, 5000);
  std::vector<Contact> w = walls;
  ContactColouring().colour_and_sort(w, 5000, r);
  EXPECT_EQ(r.colours, 1u) << "walls take no colour: one sphere, one wall contact each";
  expect_matches_oracle({}, 10);
}

TEST(Colouring, SameColouringTwiceAndForAnyThreadCount) {
  std::mt19937_64 rng(9);
  const std::vector<Contact> input = random_contacts(rng, 20000, 120000, 0.1);
  auto run = [&] {
    std::vector<Contact> c = input;
    ColourRanges r;
    ContactColouring().colour_and_sort(c, 20000, r);
    std::vector<float> tags;
    for (const Contact& x : c) tags.push_back(x.separation);
    return std::make_pair(tags, r.begin);
  };
  const auto first = run();
  EXPECT_EQ(run(), first);
#if defined(_OPENMP)
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  EXPECT_EQ(run(), first);
  omp_set_num_threads(std::max(2, threads));
  EXPECT_EQ(run(), first);
  omp_set_num_threads(threads);
#endif
}

// Many kept colours (past the 16 384 kept contacts from which their spheres'
// masks are made in parallel): with masks of each thread's own, joined after
// (2 to 4 threads), and by atomics into one set (more), the oracle's colours
// around them, for each thread count.
TEST(Colouring, ManyKeptColoursGiveTheOracleForAnyThreadCount) {
  std::mt19937_64 rng(31);
  const std::uint32_t bodies = 20000;
  std::vector<Contact> contacts = random_contacts(rng, bodies, 80000, 0.1);
  ColourRanges ranges;
  ContactColouring().colour_and_sort(contacts, bodies, ranges);
  std::vector<std::uint8_t> kept;
  const std::vector<Contact> next = next_substep(rng, contacts, ranges, bodies, 4000, kept);
  ASSERT_GT(std::count_if(kept.begin(), kept.end(), [](std::uint8_t c) { return c != kNoKeptColour; }), 16384);
  const int was = thread_count();
  for (const int t : {1, 2, 3, 4, 6}) {  // one thread alone without OpenMP
    set_thread_count(t);
    SCOPED_TRACE(t);
    expect_matches_oracle(next, bodies, kept);
  }
  set_thread_count(was);
}

// colour() sorts only the ranks' top 24 bits when the active list's index
// order already orders their low words, and all 56 bits otherwise (here: the
// active list shuffled, or ranks whose low words are not the index). Both
// paths must give the colouring of the rounds oracle.
TEST(Colouring, EitherRankSortGivesTheOracle) {
  std::mt19937_64 rng(17);
  for (int trial = 0; trial < 20; ++trial) {
    const std::uint32_t bodies = 50 + static_cast<std::uint32_t>(rng() % 500);
    const std::vector<Contact> contacts = random_contacts(rng, bodies, 4 * bodies, 0.1);
    const auto n = static_cast<std::uint32_t>(contacts.size());
    std::vector<std::uint64_t> rank(n);
    // Four top values only, so that the low words decide most orders: the
    // index form of contact_rank and impact_rank, or any low words.
    for (std::uint32_t k = 0; k < n; ++k)
      rank[k] = ((rng() % 4) << 32) | (trial % 2 == 0 ? 0xffffffffu - k : rng() & 0xffffffffu);
    std::vector<std::uint32_t> active(n);
    std::iota(active.begin(), active.end(), 0u);
    if (trial % 4 < 2) std::shuffle(active.begin(), active.end(), rng);
    std::vector<std::uint32_t> colour(n, kUncoloured), oracle(n, kUncoloured);
    ContactColouring().colour(contacts.data(), active, rank.data(), bodies, ColourRule::lowest_free, colour);
    colour_in_rounds(contacts.data(), active, rank.data(), bodies, ColourRule::lowest_free, oracle);
    EXPECT_EQ(colour, oracle) << "trial " << trial;
  }
}

// The impact stage's levels: of two contacts sharing a sphere, the one with
// the higher rank (earlier impact) is in the lower level.
TEST(Colouring, ByRoundOrdersNeighboursByRank) {
  std::mt19937_64 rng(13);
  for (int trial = 0; trial < 20; ++trial) {
    const std::uint32_t bodies = 50 + static_cast<std::uint32_t>(rng() % 500);
    const std::vector<Contact> contacts = random_contacts(rng, bodies, 4 * bodies, 0.1);
    const auto n = static_cast<std::uint32_t>(contacts.size());
    std::vector<std::uint64_t> rank(n);
    std::uniform_real_distribution<double> toi(0, 1e-3);
    for (std::uint32_t k = 0; k < n; ++k) rank[k] = impact_rank(real(toi(rng)), k);
    std::vector<std::uint32_t> active(n), level(n, kUncoloured);
    std::iota(active.begin(), active.end(), 0u);
    ContactColouring().colour(contacts.data(), active, rank.data(), bodies, ColourRule::by_round, level);
    std::vector<std::uint32_t> level_rounds(n, kUncoloured);
    colour_in_rounds(contacts.data(), active, rank.data(), bodies, ColourRule::by_round, level_rounds);
    EXPECT_EQ(level_rounds, level);
    for (std::uint32_t x = 0; x < n; ++x)
      for (std::uint32_t y = x + 1; y < n; ++y) {
        const Contact &cx = contacts[x], &cy = contacts[y];
        const bool share = cx.a == cy.a || (!is_wall(cy.b) && cx.a == cy.b) ||
                           (!is_wall(cx.b) && (cx.b == cy.a || cx.b == cy.b));
        if (!share) continue;
        ASSERT_NE(level[x], kUncoloured);
        EXPECT_EQ(rank[x] > rank[y], level[x] < level[y]) << x << " " << y;
      }
  }
}

// The kept colours at the spheres from the cache's matched entries
// (ContactCache::kept_masks) are what the kept contacts hold, and the
// colouring given them colours and places every contact as it does reading
// the kept contacts: small and large lists (the threaded paths), on 1, 2, 5
// and 16 threads (each thread's entries split at changes of a; the random
// pairs put many a b past the next thread's spheres).
TEST(ContactCache, KeptMasksColourAsTheKeptContactsDo) {
  std::mt19937_64 rng(43);
  for (const int threads : {1, 2, 5, 16})
    for (const std::uint32_t bodies : {300u, 20000u}) {
      std::vector<Contact> contacts = random_contacts(rng, bodies, 3 * bodies, 0.1);
      for (std::size_t k = 0; k < contacts.size(); ++k) contacts[k].normal_impulse = k % 4 == 0 ? real(0) : real(1e-3);
      ColourRanges ranges;
      ContactColouring().colour_and_sort(contacts, bodies, ranges);
      ContactCache cache;
      cache.store(contacts, ranges);
      std::vector<std::uint8_t> unused, kept;
      std::vector<Contact> next = next_substep(rng, contacts, ranges, bodies, bodies / 3, unused);
      std::vector<real> inv_mass(bodies, real(1));
      BodiesView view;
      view.inv_mass = inv_mass.data();
      view.count = bodies;
      const int was = thread_count();
      set_thread_count(threads);
      cache.restore(next, view, real(1), kept);
      std::vector<std::uint64_t> used;
      const std::uint32_t colours = cache.kept_masks(bodies, used);
      // The oracle: the kept contacts' colours, or'd one by one.
      std::vector<std::uint64_t> want(bodies, 0);
      std::uint32_t want_colours = 0;
      for (std::size_t k = 0; k < next.size(); ++k) {
        if (kept[k] == kNoKeptColour) continue;
        want[next[k].a] |= std::uint64_t(1) << kept[k];
        if (!is_wall(next[k].b)) want[next[k].b] |= std::uint64_t(1) << kept[k];
        want_colours = std::max<std::uint32_t>(want_colours, kept[k] + 1u);
      }
      const std::string where = "threads " + std::to_string(threads) + ", " + std::to_string(bodies) + " bodies";
      EXPECT_GT(want_colours, 1u) << where;
      EXPECT_EQ(colours, want_colours) << where;
      EXPECT_EQ(used, want) << where;
      ContactColouring by_contacts, by_masks;
      ColourRanges from_contacts, from_masks;
      const KeptMasks masks{used.data(), colours};
      by_contacts.colour_and_place(ContactRuns(next.data()), next.size(), bodies, from_contacts, kept.data());
      by_masks.colour_and_place(ContactRuns(next.data()), next.size(), bodies, from_masks, kept.data(), nullptr, &masks);
      set_thread_count(was);
      EXPECT_EQ(from_masks.colours, from_contacts.colours) << where;
      EXPECT_EQ(from_masks.rounds, from_contacts.rounds) << where;
      EXPECT_EQ(from_masks.begin, from_contacts.begin) << where;
      EXPECT_TRUE(std::equal(by_masks.places(), by_masks.places() + next.size(), by_contacts.places())) << where;
    }
}

// A sphere's entries come out ordered by b however many it has: runs of
// 2 to 16 (ordered by counting) and past 16 (by insertion), each given in
// shuffled order, on one thread and two.
TEST(ContactCache, StoreOrdersRunsOfEveryLength) {
  std::mt19937_64 rng(47);
  for (const int threads : {1, 2}) {
    std::vector<Contact> contacts;
    const std::uint32_t hubs = 40;
    for (std::uint32_t a = 0; a < hubs; ++a)
      for (std::uint32_t j = 0; j <= a; ++j) {  // sphere a: a + 1 partners above the hubs, one a wall
        Contact c;
        c.a = a;
        c.b = j == 0 ? kWallFlag | (a % 3) : hubs + 3 * j + a % 3;
        c.normal_impulse = real(1 + j);
        contacts.push_back(c);
      }
    std::shuffle(contacts.begin(), contacts.end(), rng);
    const int was = thread_count();
    set_thread_count(threads);
    ContactCache cache;
    cache.store(contacts, ColourRanges{});  // no colours known: every loaded contact kept
    set_thread_count(was);
    const CacheEntries& e = cache.entries();
    ASSERT_EQ(e.size(), contacts.size()) << threads;
    EXPECT_TRUE(std::is_sorted(e.key.begin(), e.key.end())) << threads;
    EXPECT_EQ(std::adjacent_find(e.key.begin(), e.key.end()), e.key.end()) << threads;
    for (std::size_t k = 0; k < e.size(); ++k) {
      const auto it = std::find_if(contacts.begin(), contacts.end(), [&](const Contact& c) {
        return (std::uint64_t(c.a) << 32 | c.b) == e.key[k];
      });
      ASSERT_NE(it, contacts.end());
      EXPECT_EQ(e.normal_impulse[k], it->normal_impulse) << threads << ", entry " << k;
    }
  }
}

// The cache's entries against a plain oracle: every contact with a load or
// a colour (not the overflow set's), sorted by key, impulses only where
// loaded. Large lists (the threaded paths), small ones, every contact
// dropped, colours unknown (ranges that do not describe the list), on one
// and two threads.
TEST(ContactCache, StoreEqualsASortOfTheKeptContacts) {
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> u(0, 1);
  for (const int threads : {1, 2})
    for (const std::size_t count : {std::size_t(0), std::size_t(1), std::size_t(700), std::size_t(45000)})
      for (const double loaded_share : {0.0, 0.5, 1.0})
        for (const bool coloured : {true, false}) {
          const std::uint32_t bodies = 64 + static_cast<std::uint32_t>(count / 3);
          std::vector<Contact> contacts = random_contacts(rng, bodies, count, 0.1);
          for (Contact& c : contacts) {
            c.normal_impulse = u(rng) < loaded_share ? real(0.5 + u(rng)) : real(u(rng) < 0.5 ? 0 : -1);
            c.tangent_impulse = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
            c.rolling_impulse = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
          }
          ColourRanges ranges;
          if (coloured) ContactColouring().colour_and_sort(contacts, bodies, ranges);
          struct Entry {
            std::uint64_t key;
            real normal;
            Vec3 tangent, rolling;
            std::uint8_t colour;
          };
          std::vector<Entry> expect;
          std::vector<std::uint8_t> colour(contacts.size(), kNoKeptColour);
          if (coloured) for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) { colour[k] = c; });
          for (std::size_t k = 0; k < contacts.size(); ++k) {
            const Contact& c = contacts[k];
            const bool loaded = c.normal_impulse > 0;
            if (!loaded && colour[k] == kNoKeptColour) continue;
            expect.push_back({(std::uint64_t(c.a) << 32) | c.b, loaded ? c.normal_impulse : real(0),
                              loaded ? c.tangent_impulse : Vec3{}, loaded ? c.rolling_impulse : Vec3{}, colour[k]});
          }
          std::sort(expect.begin(), expect.end(), [](const Entry& x, const Entry& y) { return x.key < y.key; });
          const int was = thread_count();
          set_thread_count(threads);
          ContactCache cache;
          cache.store(contacts, ranges);
          set_thread_count(was);
          const CacheEntries& e = cache.entries();
          const std::string where = "threads " + std::to_string(threads) + ", " + std::to_string(count) +
                                    " contacts, loaded " + std::to_string(loaded_share) + (coloured ? "" : ", uncoloured");
          ASSERT_EQ(e.size(), expect.size()) << where;
          ASSERT_EQ(e.colour.size(), expect.size()) << where;
          for (std::size_t k = 0; k < expect.size(); ++k) {
            ASSERT_EQ(e.key[k], expect[k].key) << where << ", entry " << k;
            ASSERT_EQ(e.normal_impulse[k], expect[k].normal) << where << ", entry " << k;
            ASSERT_EQ(e.tangent_impulse[k], expect[k].tangent) << where << ", entry " << k;
            ASSERT_EQ(e.rolling_impulse[k], expect[k].rolling) << where << ", entry " << k;
            ASSERT_EQ(e.colour[k], expect[k].colour) << where << ", entry " << k;
          }
        }
}

}  // namespace
}  // namespace marbles::narrowphase

namespace marbles::narrowphase {
namespace {

// Random colour ranges: 1 to 20 colours, a quarter of them and of the
// overflow sets empty.
std::vector<std::uint32_t> random_colour_begins(std::mt19937_64& rng, std::uint32_t& colours) {
  colours = 1 + static_cast<std::uint32_t>(rng() % 20);
  std::vector<std::uint32_t> begin{0};
  for (std::uint32_t c = 0; c <= colours; ++c)
    begin.push_back(begin.back() + static_cast<std::uint32_t>(rng() % 4 == 0 ? 0 : rng() % 50));
  return begin;
}

// The solve's launches as the GPU makes them (the records made, the warm start
// forwards, then sweeps forwards and backwards in turn, an empty range
// launching nothing; visit_sweeps, with the turns' ranges merged or apart)
// over random colour ranges: a launch may load early exactly when the launch
// just before wrote none of its records, as a record-by-record account says.
TEST(LastWrites, EarlyExactlyWhenTheLaunchBeforeWroteNoneOfItsRecords) {
  int repeated[2] = {0, 0};  // launches that may not load early: turns apart, merged
  for (const bool merge : {false, true}) {
    std::mt19937_64 rng(83);
    for (int trial = 0; trial < 200; ++trial) {
      std::uint32_t colours = 0;
      const std::vector<std::uint32_t> begin = random_colour_begins(rng, colours);
      const std::uint32_t n = begin.back();
      std::vector<int> writer(n, 0);  // launch 0, the records made, wrote every record
      int launch = 0;
      LastWrites last(n);
      auto run = [&](std::uint32_t b, std::uint32_t e, bool writes) {
        if (e <= b) return;
        ++launch;
        bool untouched = true;
        for (std::uint32_t k = b; k < e; ++k) untouched = untouched && writer[k] != launch - 1;
        const bool early = last.next(b, e, writes);
        ASSERT_EQ(early, untouched) << "trial " << trial << ", launch " << launch << " over [" << b << ", " << e
                                    << ")" << (merge ? ", merged" : "");
        repeated[merge] += early ? 0 : 1;
        if (writes)
          for (std::uint32_t k = b; k < e; ++k) writer[k] = launch;
      };
      visit_colours(begin, colours, false, [&](std::uint32_t b, std::uint32_t e, bool, bool) { run(b, e, false); });
      visit_sweeps(begin, colours, 10, merge,
                   [&](std::uint32_t b, std::uint32_t e, bool, bool, bool) { run(b, e, true); });
    }
  }
  // The first warm start waits, and apart every turn of direction too;
  // merged, the turns are one launch each.
  EXPECT_GT(repeated[0], 200 * 9);
  EXPECT_LT(repeated[1], repeated[0] - 200 * 4);
}

// A range visited by a sweep: [b, e), serial or not, reversed or not.
struct Visit {
  std::uint32_t b, e;
  bool serial, reversed;
  bool operator==(const Visit&) const = default;
};

// The sweeps as launches (visit_sweeps) over random colour ranges and 0 to
// 6 sweeps: each launch's range visited once, and twice back the other way,
// walks exactly what the sweeps' visit_colours walk (empty ranges left
// out); merged, every turn is merged and no launch repeats the one before
// it: sweeps - 1 of them, or half the sweeps where one range is all (its
// launches all cover it, each twice but maybe the last).
TEST(VisitSweeps, LaunchesWalkTheSweepsAndMergeEveryTurn) {
  std::mt19937_64 rng(29);
  for (int trial = 0; trial < 300; ++trial) {
    std::uint32_t colours = 0;
    const std::vector<std::uint32_t> begin = random_colour_begins(rng, colours);
    const int sweeps = static_cast<int>(rng() % 7);
    std::vector<Visit> walk;
    for (int it = 0; it < sweeps; ++it)
      visit_colours(begin, colours, it % 2 == 1, [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
        if (e > b) walk.push_back({b, e, serial, reversed});
      });
    std::size_t ranges = 0;  // the non-empty ones
    for (std::uint32_t c = 0; c <= colours; ++c) ranges += begin[c + 1] > begin[c] ? 1 : 0;
    for (const bool merge : {false, true}) {
      std::vector<Visit> seen;
      int launches = 0, twice_launches = 0;
      std::uint32_t last_b = 0, last_e = 0;
      visit_sweeps(begin, colours, sweeps, merge,
                   [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed, bool twice) {
                     ASSERT_LT(b, e) << "trial " << trial;
                     if (merge && ranges > 1 && launches > 0) {
                       EXPECT_FALSE(b == last_b && e == last_e) << "trial " << trial;
                     }
                     ++launches;
                     last_b = b, last_e = e;
                     seen.push_back({b, e, serial, reversed});
                     if (twice) {
                       seen.push_back({b, e, serial, !reversed});
                       ++twice_launches;
                     }
                   });
      EXPECT_EQ(seen, walk) << "trial " << trial << (merge ? ", merged" : ", apart");
      const int turns = ranges == 0 || sweeps == 0 ? 0 : ranges == 1 ? sweeps / 2 : sweeps - 1;
      EXPECT_EQ(twice_launches, merge ? turns : 0) << "trial " << trial << ", " << ranges << " ranges";
    }
  }
}

// The solve's launches with runs of small ranges made one
// (SmallRangeGroups) over random colour ranges, 0 to 12 sweeps, turns
// merged or apart, and widths from none grouped to all: the groups and the
// single launches, expanded in order, are the walk's launches exactly; a
// group holds two to kMostInGroup ranges, each at most `widest` wide; and
// every run is whole: after a group that is not full, or a lone small
// range, comes a wide range or nothing.
TEST(SmallRangeGroups, RunsOfSmallRangesAreWholeAndInTheWalksOrder) {
  std::mt19937_64 rng(41);
  std::size_t grouped = 0, full = 0;
  for (int trial = 0; trial < 400; ++trial) {
    std::uint32_t colours = 0;
    const std::vector<std::uint32_t> begin = random_colour_begins(rng, colours);
    const int sweeps = static_cast<int>(rng() % 13);
    const bool merge = rng() % 2 == 0;
    const std::uint32_t widest = std::array<std::uint32_t, 5>{0, 1, 12, 30, 60}[rng() % 5];
    std::vector<WalkRange> walk;
    visit_sweeps(begin, colours, sweeps, merge, [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed,
                                                    bool twice) { walk.push_back({b, e, serial, reversed, twice}); });
    struct Item {
      std::vector<WalkRange> ranges;
      bool group;
    };
    std::vector<Item> items;
    SmallRangeGroups groups(
        widest, [&](const WalkRange& r) { items.push_back({{r}, false}); },
        [&](const WalkRange* first, std::size_t n) { items.push_back({{first, first + n}, true}); });
    for (const WalkRange& r : walk) groups.add(r);
    groups.flush();
    std::vector<WalkRange> seen;
    for (const Item& item : items) seen.insert(seen.end(), item.ranges.begin(), item.ranges.end());
    ASSERT_EQ(seen.size(), walk.size()) << "trial " << trial;
    for (std::size_t i = 0; i < walk.size(); ++i) {
      const WalkRange &a = seen[i], &b = walk[i];
      EXPECT_TRUE(a.begin == b.begin && a.end == b.end && a.serial == b.serial && a.reversed == b.reversed &&
                  a.twice == b.twice)
          << "trial " << trial << ", launch " << i;
    }
    auto small = [&](const Item& item) { return item.group || item.ranges[0].end - item.ranges[0].begin <= widest; };
    for (std::size_t i = 0; i < items.size(); ++i) {
      const Item& item = items[i];
      if (item.group) {
        EXPECT_GE(item.ranges.size(), 2u) << "trial " << trial;
        EXPECT_LE(item.ranges.size(), kMostInGroup) << "trial " << trial;
        for (const WalkRange& r : item.ranges) EXPECT_LE(r.end - r.begin, widest) << "trial " << trial;
        grouped += item.ranges.size();
        full += item.ranges.size() == kMostInGroup ? 1 : 0;
      }
      const bool whole = item.group && item.ranges.size() == kMostInGroup;
      if (small(item) && !whole && i + 1 < items.size()) {
        EXPECT_FALSE(small(items[i + 1])) << "trial " << trial << ": a run split at item " << i;
      }
    }
    if (widest == 0) {
      EXPECT_EQ(items.size(), walk.size()) << "trial " << trial;
    }
  }
  EXPECT_GT(grouped, 1000u);  // the trials group, full groups among them
  EXPECT_GT(full, 10u);
}

// The sweeps by slots of a device plan (visit_slot_sweeps) over random
// colour ranges (every tenth plan one colour with no overflow set, or the
// overflow set alone), 0 to 7 sweeps and as many slots as the plan's colours
// (where its overflow set is empty) or one more (for it) up to three more,
// so that the slots hold the plan (slots_hold); one slot where that holds
// it: each slot resolved as the device resolves it (a colour, the overflow
// set, or nothing), visited once and twice back the other way, walks exactly
// what the sweeps' visit_colours walk (empty ranges left out); merged, every
// turn is one launch: sweeps - 1 of them, each of the slot a sweep ended
// with, or with one slot half the sweeps (each launch two sweeps).
TEST(VisitSlotSweeps, SlotsWalkTheSweepsAndMergeEveryTurn) {
  std::mt19937_64 rng(37);
  int single = 0;  // trials with one slot
  for (int trial = 0; trial < 400; ++trial) {
    std::uint32_t colours = 0;
    std::vector<std::uint32_t> begin = random_colour_begins(rng, colours);
    if (trial % 10 == 0) {  // one colour and no overflow set, or the overflow set alone: one slot holds it
      colours = trial % 20 == 0 ? 0 : 1;
      begin = {0, 1 + static_cast<std::uint32_t>(rng() % 40)};
      begin.push_back(begin.back());
    }
    const int sweeps = static_cast<int>(rng() % 8);
    const bool no_overflow = begin[colours + 1] == begin[colours];
    const std::uint32_t least = colours + (no_overflow ? 0 : 1);
    const std::uint32_t slots = trial % 10 == 0 ? 1 : least + static_cast<std::uint32_t>(rng() % 4);
    single += slots == 1 ? 1 : 0;
    std::vector<Visit> walk;
    for (int it = 0; it < sweeps; ++it)
      visit_colours(begin, colours, it % 2 == 1, [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
        if (e > b) walk.push_back({b, e, serial, reversed});
      });
    for (const bool merge : {false, true}) {
      std::vector<Visit> seen;
      int launches = 0, twice_launches = 0;
      std::uint32_t last_slot = slots;
      visit_slot_sweeps(slots, sweeps, merge, [&](std::uint32_t s, bool backwards, bool twice) {
        ASSERT_LT(s, slots) << "trial " << trial;
        if (merge && slots > 1) {
          EXPECT_NE(s, last_slot) << "trial " << trial << ": a merged turn launched again";
        }
        if (twice) {
          EXPECT_EQ(s, backwards ? 0u : slots - 1) << "trial " << trial << ": a turn is a sweep's last slot";
        }
        ++launches, last_slot = s;
        twice_launches += twice ? 1 : 0;
        if (s > colours) return;  // past the plan: nothing
        const std::uint32_t b = begin[s], e = begin[s + 1];
        if (e <= b) return;
        const bool serial = s == colours;
        seen.push_back({b, e, serial, backwards});
        if (twice) seen.push_back({b, e, serial, !backwards});
      });
      EXPECT_EQ(seen, walk) << "trial " << trial << ", " << slots << " slots, " << sweeps << " sweeps"
                            << (merge ? ", merged" : ", apart");
      const int turns = !merge || sweeps == 0 ? 0 : slots == 1 ? sweeps / 2 : sweeps - 1;
      EXPECT_EQ(twice_launches, turns) << "trial " << trial << ", " << slots << " slots";
      EXPECT_EQ(launches, sweeps * static_cast<int>(slots) - turns) << "trial " << trial;
    }
  }
  EXPECT_GE(single, 40);
}

// The impact levels' ranges from the firsts of their sorted keys (the GPU's
// impact stage reads them so): on random sorted keys (levels 0 .. L - 1,
// each present, then maybe the overflow's and the others' keys), every
// level's range and the overflow's are exactly the positions of its key.
TEST(VisitLevels, RangesAreThePositionsOfEachKey) {
  std::mt19937_64 rng(41);
  for (int trial = 0; trial < 500; ++trial) {
    // The first four trials fill every level (the last level's end is then
    // the overflow's or the others' first, or n), the rest are random.
    const std::uint32_t levels =
        trial < 4 ? kMaxColourRounds : trial % 7 == 0 ? 0 : 1 + rng() % (trial % 5 == 0 ? kMaxColourRounds : 12);
    std::vector<std::uint32_t> keys;
    for (std::uint32_t l = 0; l < levels; ++l) keys.insert(keys.end(), 1 + rng() % 5, l);
    if (levels > 0 && (trial < 4 ? trial % 2 == 1 : rng() % 2 == 1))
      keys.insert(keys.end(), 1 + rng() % 4, kMaxColourRounds);  // the overflow
    if (trial < 4 ? trial >= 2 : rng() % 3 != 0)
      keys.insert(keys.end(), 1 + rng() % 6, kMaxColourRounds + 1);  // the others
    const auto n = static_cast<std::uint32_t>(keys.size());
    std::vector<std::uint32_t> first(kMaxColourRounds + 2, kNoFirst);
    for (std::uint32_t j = n; j-- > 0;) first[keys[j]] = j;
    std::vector<std::uint32_t> seen;  // the key of each position, from the ranges
    std::uint32_t visited = 0;
    visit_levels(first.data(), n, [&](std::uint32_t b, std::uint32_t e, bool serial) {
      const std::uint32_t key = serial ? kMaxColourRounds : visited++;
      ASSERT_EQ(b, seen.size()) << "trial " << trial;
      for (std::uint32_t k = b; k < e; ++k) seen.push_back(key);
    });
    EXPECT_EQ(visited, levels) << "trial " << trial;
    std::vector<std::uint32_t> expect;
    for (std::uint32_t k : keys)
      if (k <= kMaxColourRounds) expect.push_back(k);
    EXPECT_EQ(seen, expect) << "trial " << trial;
  }
}

// The colour plan from the firsts of the colouring's sorted keys (the GPU's
// colouring makes its host ranges and its device plan with it): on random
// sorted keys (colours with gaps, a kept colour whose other contacts are
// gone, then maybe the overflow's and the inactive's keys), colour c's range
// is exactly the positions of key c, empty ones where they would start, the
// overflow's those of its key, and the words past them its end; widest() the
// largest colour and empty() whether any contact is coloured or overflows.
TEST(ColourPlan, OfFirstsGivesEachKeysPositions) {
  std::mt19937_64 rng(43);
  for (int trial = 0; trial < 500; ++trial) {
    // The first trials: every colour, no contact, only the overflow, only inactive ones.
    std::vector<std::uint32_t> keys;
    const std::uint32_t top = trial == 0 ? kMaxColours : 1 + rng() % (trial % 5 == 0 ? kMaxColours : 12);
    if (trial > 3)
      for (std::uint32_t c = 0; c < top; ++c)
        if (c + 1 == top || rng() % 4 != 0) keys.insert(keys.end(), 1 + rng() % 5, c);  // gaps below the top
    if (trial == 0)
      for (std::uint32_t c = 0; c < kMaxColours; ++c) keys.push_back(c);
    if (trial == 2 || (trial > 3 && rng() % 2 == 1)) keys.insert(keys.end(), 1 + rng() % 4, kMaxColours);
    if (trial == 3 || (trial > 3 && rng() % 3 != 0)) keys.insert(keys.end(), 1 + rng() % 6, kMaxColours + 1);
    const auto n = static_cast<std::uint32_t>(keys.size());
    std::vector<std::uint32_t> first(kMaxColours + 2, kNoFirst);
    for (std::uint32_t j = n; j-- > 0;) first[keys[j]] = j;
    ColourPlan plan;
    std::fill(std::begin(plan.begin), std::end(plan.begin), 0xabababu);  // poisoned
    plan.colours = 0xabababu;
    plan_of_firsts(first.data(), n, plan);
    // The oracle: the colours up to the highest present key below kMaxColours,
    // each range starting at the count of the keys below it.
    std::uint32_t colours = 0;
    for (std::uint32_t k : keys)
      if (k < kMaxColours) colours = std::max(colours, k + 1);
    ASSERT_EQ(plan.colours, colours) << "trial " << trial;
    auto below = [&](std::uint32_t key) {
      return static_cast<std::uint32_t>(std::count_if(keys.begin(), keys.end(), [&](std::uint32_t k) {
        return k < kMaxColours ? k < key : false;
      }));
    };
    std::uint32_t widest = 0;
    for (std::uint32_t c = 0; c < colours; ++c) {
      const auto size = static_cast<std::uint32_t>(std::count(keys.begin(), keys.end(), c));
      EXPECT_EQ(plan.begin[c], below(c)) << "trial " << trial << " colour " << c;
      EXPECT_EQ(plan.begin[c + 1] - plan.begin[c], size) << "trial " << trial << " colour " << c;
      widest = std::max(widest, size);
    }
    const auto overflow = static_cast<std::uint32_t>(std::count(keys.begin(), keys.end(), kMaxColours));
    EXPECT_EQ(plan.begin[colours], below(kMaxColours)) << "trial " << trial;
    EXPECT_EQ(plan.begin[colours + 1], below(kMaxColours) + overflow) << "trial " << trial;
    for (std::uint32_t c = colours + 2; c < kMaxColours + 2; ++c)
      EXPECT_EQ(plan.begin[c], plan.begin[colours + 1]) << "trial " << trial << " word " << c;
    EXPECT_EQ(plan.widest(), widest) << "trial " << trial;
    EXPECT_EQ(plan.empty(), below(kMaxColours) + overflow == 0) << "trial " << trial;
  }
}

// Whether the slots hold a plan (slots_hold, the CUDA step's check for a
// solve without waits), against walking them: on random plans (a quarter of
// the colours and overflow sets empty) and 0 to colours + 2 slots, true
// exactly where every contact of the plan lies in a range some slot reads
// and every colour, even an empty one, has its slot (the step reads a size
// for each slot's colour, for the next step's grids).
TEST(ColourPlan, SlotsHoldExactlyWhereTheyReachEveryContact) {
  std::mt19937_64 rng(53);
  int held = 0, not_held = 0;
  for (int trial = 0; trial < 500; ++trial) {
    ColourPlan plan;
    plan.colours = static_cast<std::uint32_t>(rng() % (trial % 9 == 0 ? kMaxColours + 1 : 8));
    std::uint32_t at = static_cast<std::uint32_t>(rng() % 10);
    for (std::uint32_t c = 0; c <= plan.colours; ++c) {
      plan.begin[c] = at;
      at += rng() % 4 == 0 ? 0 : 1 + static_cast<std::uint32_t>(rng() % 9);
    }
    for (std::uint32_t c = plan.colours + 1; c < kMaxColours + 2; ++c) plan.begin[c] = at;
    for (std::uint32_t slots = 0; slots <= plan.colours + 2; ++slots) {
      std::vector<bool> reached(at, false);
      for (std::uint32_t s = 0; s < slots && s <= plan.colours; ++s)  // past the overflow set: nothing
        for (std::uint32_t k = plan.begin[s]; k < plan.begin[s + 1]; ++k) reached[k] = true;
      bool every = plan.colours <= slots;
      for (std::uint32_t k = plan.begin[0]; k < at; ++k) every = every && reached[k];
      ASSERT_EQ(slots_hold(plan, slots), every)
          << "trial " << trial << ": " << plan.colours << " colours, " << slots << " slots";
      (every ? held : not_held) += 1;
    }
  }
  EXPECT_GT(held, 500);
  EXPECT_GT(not_held, 500);
}

// Each colour's most contacts over a run of plans (what a CUDA step that
// waits once keeps for its slots' grids): on random plans of varying
// colours (gaps, empty colours, overflow sets), most[c] is the largest size
// colour c had in any plan that had it, 0 where none did; the words past the
// most colours seen are never written.
TEST(ColourPlan, KeepMostPerColourIsEachColoursLargestSize) {
  std::mt19937_64 rng(47);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<unsigned long long> most(kMaxColours + 1, 0);
    most[kMaxColours] = 0xfeedull;  // past every colour: never written
    std::vector<std::uint32_t> expect(kMaxColours, 0);
    std::uint32_t most_colours = 0;
    const int plans = 1 + static_cast<int>(rng() % 6);
    for (int p = 0; p < plans; ++p) {
      ColourPlan plan;
      plan.colours = static_cast<std::uint32_t>(rng() % (trial % 7 == 0 ? kMaxColours + 1 : 13));
      std::uint32_t at = static_cast<std::uint32_t>(rng() % 100);
      for (std::uint32_t c = 0; c <= plan.colours; ++c) {  // the colours, then the overflow set
        plan.begin[c] = at;
        const std::uint32_t size = rng() % 4 == 0 ? 0 : static_cast<std::uint32_t>(rng() % 5000);
        if (c < plan.colours) expect[c] = std::max(expect[c], size);
        at += size;
      }
      for (std::uint32_t c = plan.colours + 1; c < kMaxColours + 2; ++c) plan.begin[c] = at;
      most_colours = std::max(most_colours, plan.colours);
      keep_most_per_colour(plan, most.data());
    }
    for (std::uint32_t c = 0; c < kMaxColours; ++c)
      ASSERT_EQ(most[c], expect[c]) << "trial " << trial << " colour " << c << " (most colours " << most_colours << ")";
    EXPECT_EQ(most[kMaxColours], 0xfeedull) << "trial " << trial;
  }
}

}  // namespace
}  // namespace marbles::narrowphase
