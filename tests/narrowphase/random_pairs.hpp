// tests/narrowphase/random_pairs.hpp — random contact sets for the narrow
// phase's tests: `count` distinct body pairs, only a and b set.
#pragma once

#include <cstdint>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "narrowphase/contact.hpp"

namespace marbles::narrowphase::test {

// Spheres from [lo, hi): a sphere pair (a < b) or, with probability
// wall_share, a sphere and one of six walls (b); with probability
// hub_share the pair's first sphere is `hub`.
inline std::vector<Contact> random_pairs(std::mt19937_64& rng, std::uint32_t lo, std::uint32_t hi, std::size_t count,
                                         double wall_share = 0.1, double hub_share = 0, std::uint32_t hub = 0) {
  std::uniform_int_distribution<std::uint32_t> body(lo, hi - 1), wall(0, 5);
  std::uniform_real_distribution<double> u(0, 1);
  std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
  std::vector<Contact> out;
  while (out.size() < count) {
    Contact c;
    c.a = u(rng) < hub_share ? hub : body(rng);
    c.b = u(rng) < wall_share ? (kWallFlag | wall(rng)) : body(rng);
    if (c.b == c.a) continue;
    if (!is_wall(c.b) && c.b < c.a) std::swap(c.a, c.b);
    if (!seen.insert({c.a, c.b}).second) continue;
    out.push_back(c);
  }
  return out;
}

}  // namespace marbles::narrowphase::test
