// Contact colouring: proper (no sphere twice in a colour), complete (every
// contact once, coloured or in the overflow set), deterministic (twice, any
// thread count), and equal to its oracle: the sequential greedy colouring in
// rank order, which the Jones–Plassmann rounds must reproduce exactly.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "narrowphase/colouring.hpp"

namespace marbles::narrowphase {
namespace {

// The data-parallel form the CUDA twin runs (colouring_cuda.cu), written
// plainly: Jones–Plassmann rounds over a shrinking list of uncoloured
// contacts, offers by max, the holders of both offers coloured. The library's
// colour() computes the same in one sequential pass; these tests hold the two
// (and the GPU, in colouring_cuda_test.cu) to the same answer.
std::uint32_t colour_in_rounds(const Contact* contacts, const std::vector<std::uint32_t>& active,
                               const std::uint64_t* rank, std::size_t body_count, ColourRule rule,
                               std::vector<std::uint32_t>& colour) {
  std::vector<std::uint64_t> body_word(body_count, 0), body_used(body_count, 0);
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

std::vector<Contact> random_contacts(std::mt19937_64& rng, std::uint32_t bodies, std::size_t count, double wall_share) {
  std::uniform_int_distribution<std::uint32_t> body(0, bodies - 1), wall(0, 5);
  std::bernoulli_distribution is_wall(wall_share);
  std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
  std::vector<Contact> out;
  while (out.size() < count) {
    Contact c;
    c.a = body(rng);
    if (is_wall(rng)) {
      c.b = kWallFlag | wall(rng);
    } else {
      c.b = body(rng);
      if (c.b == c.a) continue;
      if (c.b < c.a) std::swap(c.a, c.b);
    }
    if (!seen.insert({c.a, c.b}).second) continue;
    c.separation = real(out.size());  // a tag to find the contact after sorting
    out.push_back(c);
  }
  return out;
}

// The oracle: contacts in decreasing rank, each takes the lowest colour its
// spheres' earlier contacts do not have.
std::vector<std::uint32_t> greedy_colours(const std::vector<Contact>& contacts) {
  const auto n = static_cast<std::uint32_t>(contacts.size());
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  auto rank = [&](std::uint32_t k) { return contact_rank(contacts[k].a, contacts[k].b, k); };
  std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) { return rank(x) > rank(y); });
  std::map<std::uint32_t, std::uint64_t> used;
  std::vector<std::uint32_t> colour(n);
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

void expect_matches_oracle(const std::vector<Contact>& input, std::uint32_t bodies) {
  std::vector<Contact> contacts = input;
  ColourRanges ranges;
  ContactColouring().colour_and_sort(contacts, bodies, ranges);
  ASSERT_EQ(contacts.size(), input.size());
  EXPECT_EQ(ranges.size(), input.size());
  EXPECT_TRUE(colouring_is_proper(contacts, ranges, bodies));
  const std::vector<std::uint32_t> expect = greedy_colours(input);
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

  // The data-parallel form (the GPU's) colours every contact alike.
  const auto n = static_cast<std::uint32_t>(input.size());
  std::vector<std::uint64_t> rank(n);
  std::vector<std::uint32_t> active(n), colour(n, kUncoloured);
  for (std::uint32_t k = 0; k < n; ++k) rank[k] = contact_rank(input[k].a, input[k].b, k), active[k] = k;
  colour_in_rounds(input.data(), active, rank.data(), bodies, ColourRule::lowest_free, colour);
  EXPECT_EQ(colour, expect);
}

TEST(Colouring, MatchesSequentialGreedyOnRandomSets) {
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 40; ++trial) {
    const std::uint32_t bodies = 2 + static_cast<std::uint32_t>(rng() % 3000);
    const std::size_t max_pairs = std::size_t(bodies) * (bodies - 1) / 2;
    const std::size_t count = std::min<std::size_t>(max_pairs, rng() % 9000);
    expect_matches_oracle(random_contacts(rng, bodies, count, trial % 3 == 0 ? 0.3 : 0.05), bodies);
  }
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

}  // namespace
}  // namespace marbles::narrowphase
