// core/parallel.hpp's collect_in_order and fill_apart, and
// core/counting_sort.hpp's CPU counting sort, against their serial
// definitions on random inputs, for several thread counts (the step's
// contacts, the broad phase's chunks and the colouring's and cache's sorts
// rest on them).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/counting_sort.hpp"
#include "core/parallel.hpp"

namespace marbles {
namespace {

// Runs f with n threads, then restores the count.
template <class F>
void with_threads(int n, F&& f) {
  const int was = thread_count();
  set_thread_count(n);
  f();
  set_thread_count(was);
}

// make(k): 0 to 3 items for k (a fixed pseudo-random count), each naming k
// and its place among k's items.
struct Items {
  void operator()(std::size_t k, std::vector<std::uint64_t>& out) const {
    const std::uint64_t many = (k * 2654435761u >> 7) % 4;
    for (std::uint64_t i = 0; i < many; ++i) out.push_back(k << 8 | i);
  }
};

TEST(CollectInOrder, AppendsWhatTheSerialLoopAppendsInItsOrder) {
  for (const std::size_t count : {std::size_t(0), std::size_t(7), std::size_t(50000), std::size_t(123457)}) {
    std::vector<std::uint64_t> want{1, 2, 3};  // what was there before stays first
    for (std::size_t k = 0; k < count; ++k) Items()(k, want);
    for (const int threads : {1, 2, 3, 5, 16}) {  // 123 457 items: past the joins' parallel copy
      with_threads(threads, [&] {
        std::vector<std::uint64_t> out{1, 2, 3};
        std::vector<std::vector<std::uint64_t>> parts(1, std::vector<std::uint64_t>(9, 99));  // stale buffers
        collect_in_order(count, 1000, out, parts, Items());
        EXPECT_EQ(out, want) << count << " items, " << threads << " threads";
      });
    }
  }
}

TEST(FillApart, KeepsTheSlotsContentsAndStorageAlsoOnAThrow) {
  std::vector<int> slot{4, 5};
  slot.reserve(100);
  const int* storage = slot.data();
  fill_apart(slot, [&](std::vector<int>& v) {
    EXPECT_NE(&v, &slot) << "a vector object of its own";
    EXPECT_EQ(v, (std::vector<int>{4, 5}));
    v.push_back(6);
  });
  EXPECT_EQ(slot, (std::vector<int>{4, 5, 6}));
  EXPECT_EQ(slot.data(), storage) << "the same storage, no copy";
  EXPECT_THROW(fill_apart(slot, [](std::vector<int>& v) {
                 v.push_back(7);
                 throw std::runtime_error("fill failed");
               }),
               std::runtime_error);
  EXPECT_EQ(slot, (std::vector<int>{4, 5, 6, 7})) << "what the fill had made before it threw";
  EXPECT_EQ(slot.data(), storage);
}

// The counting sort's places: stable by bucket, skipped items placed
// nowhere, and each bucket's first place; few buckets (as the colouring's
// colours) and many (as the cache's spheres: from 2^16 buckets on more
// than two threads sort by groups of buckets first, detail::wide_counting_sort).
TEST(CountingSort, StableByBucketForAnyThreadCount) {
  std::mt19937 rng(17);
  for (const std::uint32_t buckets : {1u, 3u, 17u, 65u, 100000u, (1u << 20) + 3u}) {  // the last two by groups
    for (const std::uint32_t n : {0u, 100u, 20000u, 250001u}) {
      std::vector<std::uint32_t> bucket_of(n);
      for (auto& b : bucket_of) b = rng() % 10 == 0 ? kSkipItem : rng() % buckets;
      std::vector<std::uint32_t> want;  // item indices, stable by bucket
      for (std::uint32_t k = 0; k < n; ++k)
        if (bucket_of[k] != kSkipItem) want.push_back(k);
      std::stable_sort(want.begin(), want.end(),
                       [&](std::uint32_t x, std::uint32_t y) { return bucket_of[x] < bucket_of[y]; });
      std::vector<std::uint32_t> want_begin(buckets + 1, 0);
      for (const std::uint32_t k : want) ++want_begin[bucket_of[k] + 1];
      for (std::uint32_t b = 0; b < buckets; ++b) want_begin[b + 1] += want_begin[b];
      for (const int threads : {1, 2, 3, 5, 16}) {  // more threads than buckets, and fewer
        with_threads(threads, [&] {
          std::vector<std::uint32_t> placed(want.size(), kSkipItem), begin, scratch(3, 7);
          std::atomic<bool> past_the_end{false};
          counting_sort(
              n, buckets, [&](std::uint32_t k) { return bucket_of[k]; },
              [&](std::uint32_t k, std::uint32_t place) {
                if (place < placed.size()) placed[place] = k;
                else past_the_end = true;
              },
              begin, scratch);
          const std::string where = std::to_string(n) + " items, " + std::to_string(buckets) + " buckets, " +
                                    std::to_string(threads) + " threads";
          EXPECT_FALSE(past_the_end) << where;
          EXPECT_EQ(placed, want) << where;
          EXPECT_EQ(begin, want_begin) << where;
        });
      }
    }
  }
}

// Each bucket's first place in a list sorted by bucket: the first item at or
// past the bucket, as a serial search finds it; buckets with no item, runs
// of one bucket, items in the last bucket (`buckets` itself) and none.
TEST(SortedBucketStarts, FirstItemAtOrPastEachBucketForAnyThreadCount) {
  std::mt19937 rng(23);
  for (const std::uint32_t buckets : {1u, 7u, 5000u, 300000u}) {
    for (const std::uint32_t n : {0u, 1u, 999u, 70001u}) {
      std::vector<std::uint32_t> bucket(n);
      for (auto& b : bucket) b = rng() % (buckets + 1);  // `buckets` itself: past every bucket
      std::sort(bucket.begin(), bucket.end());
      std::vector<std::uint32_t> want(std::size_t(buckets) + 1);
      for (std::uint32_t b = 0; b <= buckets; ++b)
        want[b] = static_cast<std::uint32_t>(std::lower_bound(bucket.begin(), bucket.end(), b) - bucket.begin());
      for (const int threads : {1, 2, 3, 16}) {
        with_threads(threads, [&] {
          std::vector<std::uint32_t> first(want.size(), 0xdeadbeefu);
          sorted_bucket_starts(n, buckets, [&](std::uint32_t k) { return bucket[k]; }, first.data(), 1000);
          EXPECT_EQ(first, want) << n << " items, " << buckets << " buckets, " << threads << " threads";
        });
      }
    }
  }
}

}  // namespace
}  // namespace marbles
