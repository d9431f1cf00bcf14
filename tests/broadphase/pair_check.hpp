// tests/broadphase/pair_check.hpp — comparing a backend's pairs with the oracle.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "broadphase/broadphase.hpp"

namespace marbles::broadphase::testing {

// Every pair has i < j, no pair twice, and the set equals `expected`
// (expected is in lexicographic order, as the oracle emits it).
inline ::testing::AssertionResult same_pair_set(std::vector<Pair> got, const std::vector<Pair>& expected) {
  for (const Pair& p : got)
    if (!(p.i < p.j)) return ::testing::AssertionFailure() << "pair (" << p.i << ", " << p.j << ") not ordered";
  std::sort(got.begin(), got.end());
  for (std::size_t k = 1; k < got.size(); ++k)
    if (got[k] == got[k - 1])
      return ::testing::AssertionFailure() << "pair (" << got[k].i << ", " << got[k].j << ") emitted twice";
  if (got == expected) return ::testing::AssertionSuccess();
  std::vector<Pair> missing, extra;
  std::set_difference(expected.begin(), expected.end(), got.begin(), got.end(), std::back_inserter(missing));
  std::set_difference(got.begin(), got.end(), expected.begin(), expected.end(), std::back_inserter(extra));
  auto out = ::testing::AssertionFailure();
  out << got.size() << " pairs, expected " << expected.size() << "; " << missing.size() << " missing, "
      << extra.size() << " extra";
  if (!missing.empty()) out << "; first missing (" << missing[0].i << ", " << missing[0].j << ")";
  if (!extra.empty()) out << "; first extra (" << extra[0].i << ", " << extra[0].j << ")";
  return out;
}

}  // namespace marbles::broadphase::testing
