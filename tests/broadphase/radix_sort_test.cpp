// The CPU radix sort against std::stable_sort.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <numeric>
#include <random>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "core/radix_sort.hpp"

namespace mb = marbles::broadphase;

namespace {

enum class Pattern { random, all_equal, sorted, reversed, high_bits };

template <class Key>
std::vector<Key> make_keys(Pattern p, std::size_t n, unsigned bits, std::mt19937_64& rng) {
  std::vector<Key> k(n);
  const Key mask = bits >= 8 * sizeof(Key) ? ~Key{0} : ((Key{1} << bits) - 1);
  for (auto& x : k) x = static_cast<Key>(rng()) & mask;
  switch (p) {
    case Pattern::random: break;
    case Pattern::all_equal: std::fill(k.begin(), k.end(), static_cast<Key>(rng()) & mask); break;
    case Pattern::sorted: std::sort(k.begin(), k.end()); break;
    case Pattern::reversed: std::sort(k.begin(), k.end(), std::greater<Key>()); break;
    case Pattern::high_bits:
      for (auto& x : k) x = static_cast<Key>((rng() % 7) << (bits - 3)) & mask;  // only the top 3 bits vary
      break;
  }
  return k;
}

template <class Key>
void check(Pattern p, std::size_t n, unsigned bits, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Key> keys = make_keys<Key>(p, n, bits, rng);
  std::vector<std::uint32_t> values(n);
  std::iota(values.begin(), values.end(), 0u);
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return keys[a] < keys[b]; });
  std::vector<Key> k2 = keys;
  std::vector<std::uint32_t> v2 = values;
  mb::radix_sort_pairs(k2, v2, bits);
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(k2[i], keys[order[i]]) << "at " << i;
    ASSERT_EQ(v2[i], values[order[i]]) << "at " << i;  // stability: ties keep input order
  }
}

}  // namespace

TEST(RadixSortCpu, EqualsStableSort32) {
  std::uint64_t seed = 1000;
  for (Pattern p : {Pattern::random, Pattern::all_equal, Pattern::sorted, Pattern::reversed, Pattern::high_bits})
    for (std::size_t n : {0ul, 1ul, 2ul, 255ul, 1000ul, 70000ul, 300000ul})
      for (unsigned bits : {4u, 8u, 13u, 24u, 31u, 32u}) check<std::uint32_t>(p, n, bits, ++seed);
}

TEST(RadixSortCpu, EqualsStableSort64) {
  std::uint64_t seed = 2000;
  for (Pattern p : {Pattern::random, Pattern::all_equal, Pattern::sorted, Pattern::reversed, Pattern::high_bits})
    for (std::size_t n : {0ul, 3ul, 999ul, 100000ul})
      for (unsigned bits : {9u, 33u, 47u, 63u, 64u}) check<std::uint64_t>(p, n, bits, ++seed);
}

TEST(RadixSortCpu, OnlyNeededPasses) {
  std::vector<std::uint32_t> k = {5, 3, 9, 1}, v = {0, 1, 2, 3};
  EXPECT_EQ(mb::radix_sort_pairs(k, v, 4), 1u);
  EXPECT_EQ(k, (std::vector<std::uint32_t>{1, 3, 5, 9}));
  EXPECT_EQ(v, (std::vector<std::uint32_t>{3, 1, 0, 2}));
}

// Blocks of 8192 keys and up a thread: 70 000 keys take eight, 300 000 all
// sixteen; the order is the stable sort's for every thread count.
TEST(RadixSortCpu, EqualsStableSortOnAnyThreadCount) {
#if defined(_OPENMP)
  const int before = omp_get_max_threads();
  std::uint64_t seed = 3000;
  for (const int threads : {1, 3, 7, 16}) {
    omp_set_num_threads(threads);
    for (Pattern p : {Pattern::random, Pattern::high_bits})
      for (std::size_t n : {16384ul, 70000ul, 300000ul}) {
        check<std::uint32_t>(p, n, 24, ++seed);
        check<std::uint64_t>(p, n, 40, ++seed);
      }
  }
  omp_set_num_threads(before);
#else
  GTEST_SKIP() << "skipped: built without OpenMP";
#endif
}
