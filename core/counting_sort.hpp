// core/counting_sort.hpp — a stable counting sort, in parallel.
//
// Items 0..n-1 go to buckets (bucket(k) < buckets, or kSkipItem: left out);
// move(k, place) puts item k at its place: bucket by bucket, and within a
// bucket in item order, whatever the thread count. Each thread counts its
// slice of the items per bucket; the slices' places follow bucket by bucket
// and slice by slice (each thread placing a range of buckets); then each
// thread moves its slice. With many buckets and more than two threads the
// buckets are first grouped (detail::wide_counting_sort below). `begin` gets the
// buckets' first places (buckets + 1 entries, the last one the total).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "core/parallel.hpp"

namespace marbles {

inline constexpr std::uint32_t kSkipItem = 0xffffffffu;

// The first place of each bucket in a list already sorted by bucket:
// first[b] for b <= buckets is the first k < n with bucket_of(k) >= b (n
// where none is). Each item writes the firsts of the buckets from just past
// the item before's to its own, so every first is written once, on all
// threads from `parallel_from` items (the broad phase's cell starts and the
// cache's runs by sphere; on one thread the cell starts were a part of the
// broad phase that did not shrink with more threads).
template <class BucketOf>
void sorted_bucket_starts(std::uint32_t n, std::uint64_t buckets, BucketOf&& bucket_of, std::uint32_t* first,
                          std::uint32_t parallel_from) {
  const std::uint64_t end = n == 0 ? 0 : std::uint64_t(bucket_of(n - 1)) + 1;
#pragma omp parallel if (n >= parallel_from)
  {
#pragma omp for schedule(static)
    for (std::ptrdiff_t t = 0; t < static_cast<std::ptrdiff_t>(n); ++t) {
      const auto k = static_cast<std::uint32_t>(t);
      const std::uint64_t from = k == 0 ? 0 : std::uint64_t(bucket_of(k - 1)) + 1;
      for (std::uint64_t b = from; b <= std::uint64_t(bucket_of(k)); ++b) first[b] = k;
    }
#pragma omp for schedule(static)
    for (std::ptrdiff_t b = static_cast<std::ptrdiff_t>(end); b <= static_cast<std::ptrdiff_t>(buckets); ++b)
      first[b] = n;
  }
}

namespace detail {

// Inside a parallel region, called by every thread t of the team: the
// counts of `buckets` buckets of each thread's slice (row u at count + u *
// stride) become the places of the slice's first item in each bucket,
// bucket by bucket and slice by slice, and first[b] each bucket's first
// place (first[buckets] the total). Each thread sums a range of buckets
// over every slice, then writes the places of that range from the ranges
// before it. (In one `omp single` this pass over buckets x threads counts
// was the part of the cache's store that did not shrink with more threads:
// settle scene of 10^5, 3.3 ms a step on 8 and 16 threads.)
inline void place_counts(std::uint32_t* count, std::size_t stride, std::uint32_t buckets, int t, int threads,
                         std::uint32_t* range_total, std::uint32_t* first) {
  const auto b_lo = static_cast<std::uint32_t>(std::uint64_t(buckets) * t / threads);
  const auto b_hi = static_cast<std::uint32_t>(std::uint64_t(buckets) * (t + 1) / threads);
#pragma omp barrier
  std::uint32_t sum = 0;
  for (std::uint32_t b = b_lo; b < b_hi; ++b)
    for (int u = 0; u < threads; ++u) sum += count[std::size_t(u) * stride + b];
  range_total[t] = sum;
#pragma omp barrier
  std::uint32_t at = 0;
  for (int u = 0; u < t; ++u) at += range_total[u];
  for (std::uint32_t b = b_lo; b < b_hi; ++b) {
    first[b] = at;
    for (int u = 0; u < threads; ++u) {
      const std::uint32_t v = count[std::size_t(u) * stride + b];
      count[std::size_t(u) * stride + b] = at;
      at += v;
    }
  }
  if (t == threads - 1) first[buckets] = at;
#pragma omp barrier
}

// A row of counts a thread, on cache lines of its own (64 bytes at least
// between two threads' counts, wherever the scratch begins): a few buckets
// (the colouring's colours) would otherwise put two threads' counts on one
// line, which every count writes.
inline std::size_t count_stride(std::uint32_t buckets) { return (std::size_t(buckets) + 16 + 15) / 16 * 16; }

// Inside a parallel region, called by every thread: each thread counts its
// slice of the items by slot (bucket >> shift) into its row of counts, the
// rows become places (place_counts, `first` each slot's first place), then
// give(k, bucket, place) for each item of the slice, in order.
template <class BucketOf, class Give>
void sort_slices(std::uint32_t n, std::uint32_t slots, std::uint32_t shift, const BucketOf& bucket_of, Give&& give,
                 std::uint32_t* count, std::size_t stride, std::uint32_t* range_total, std::uint32_t* first) {
  const int t = thread_index(), threads = team_size();
  const auto lo = static_cast<std::uint32_t>(std::uint64_t(n) * t / threads);
  const auto hi = static_cast<std::uint32_t>(std::uint64_t(n) * (t + 1) / threads);
  std::uint32_t* mine = count + std::size_t(t) * stride;
  std::fill(mine, mine + slots, 0u);
  for (std::uint32_t k = lo; k < hi; ++k) {
    const std::uint32_t b = bucket_of(k);
    if (b != kSkipItem) ++mine[b >> shift];
  }
  place_counts(count, stride, slots, t, threads, range_total, first);
  for (std::uint32_t k = lo; k < hi; ++k) {
    const std::uint32_t b = bucket_of(k);
    if (b != kSkipItem) give(k, b, mine[b >> shift]++);
  }
}

}  // namespace detail

// From this many buckets, with more than two threads, the sort goes by
// groups of buckets (detail::wide_counting_sort).
inline constexpr std::uint32_t kWideBuckets = 1u << 16;

namespace detail {

// The same sort in two passes, for many buckets: the items are first sorted
// stably into groups of 2^shift consecutive buckets (at most ~1024 groups),
// each item carried with its bucket, then each group's items are placed
// within the group by one thread, whose counts fit its cache. In one pass
// each thread kept a count for every bucket (16 threads x 10^6 spheres: 64
// MB of counts, cleared, incremented at random, summed and incremented
// again), and the cache's store's sort of the settle scene of 10^6 took
// 13.4 ms a step on 16 threads. The same places as the one pass. For
// counting_sort alone: 2^16 <= buckets < 2^31, n >= 1.
template <class Bucket, class Move>
void wide_counting_sort(std::uint32_t n, std::uint32_t buckets, Bucket&& bucket, Move&& move,
                        std::vector<std::uint32_t>& begin, std::vector<std::uint32_t>& scratch, int most) {
  std::uint32_t shift = 10;
  while ((std::uint64_t(buckets - 1) >> shift) >= 1024) ++shift;
  const std::uint32_t groups = ((buckets - 1) >> shift) + 1, width = 1u << shift;
  const std::size_t stride = detail::count_stride(groups);
  // The scratch: the threads' group counts, the groups' firsts, each
  // placed item's bucket and index, each thread's counts within a group,
  // then the threads' range totals (nothing allocated inside the parallel
  // region, nor anything but the scratch in a call).
  const std::size_t counts = std::size_t(most) * stride, firsts = groups + 1;
  scratch.resize(counts + firsts + 2 * std::size_t(n) + std::size_t(most) * width + std::size_t(most));
  std::uint32_t* count = scratch.data();
  std::uint32_t* group_first = count + counts;
  std::uint32_t* item_bucket = group_first + firsts;
  std::uint32_t* item = item_bucket + n;
  std::uint32_t* group_counts = item + n;
  std::uint32_t* totals = group_counts + std::size_t(most) * width;
  begin.resize(std::size_t(buckets) + 1);
  std::uint32_t* first = begin.data();
#pragma omp parallel num_threads(most)
  {
    const std::decay_t<Bucket> bucket_of = bucket;
    std::decay_t<Move> move_to = move;
    detail::sort_slices(
        n, groups, shift, bucket_of,
        [item_bucket, item](std::uint32_t k, std::uint32_t b, std::uint32_t p) {
          item_bucket[p] = b;
          item[p] = k;
        },
        count, stride, totals, group_first);
#pragma omp barrier
    std::uint32_t* local = group_counts + std::size_t(thread_index()) * width;
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t g = 0; g < static_cast<std::ptrdiff_t>(groups); ++g) {
      const std::uint32_t b_lo = static_cast<std::uint32_t>(g) << shift;
      const std::uint32_t b_hi = std::min(buckets, b_lo + width);
      const std::uint32_t p_lo = group_first[g], p_hi = group_first[g + 1];
      std::fill(local, local + (b_hi - b_lo), 0u);
      for (std::uint32_t p = p_lo; p < p_hi; ++p) ++local[item_bucket[p] - b_lo];
      std::uint32_t at = p_lo;
      for (std::uint32_t b = b_lo; b < b_hi; ++b) {
        first[b] = at;
        const std::uint32_t v = local[b - b_lo];
        local[b - b_lo] = at;
        at += v;
      }
      for (std::uint32_t p = p_lo; p < p_hi; ++p) move_to(item[p], local[item_bucket[p] - b_lo]++);
    }
  }
  first[buckets] = group_first[groups];
}

}  // namespace detail

template <class Bucket, class Move>
void counting_sort(std::uint32_t n, std::uint32_t buckets, Bucket&& bucket, Move&& move,
                   std::vector<std::uint32_t>& begin, std::vector<std::uint32_t>& scratch) {
  const int most = n >= 20000 ? thread_count() : 1;
  if (most > 2 && buckets >= kWideBuckets) {
    detail::wide_counting_sort(n, buckets, bucket, move, begin, scratch, most);
    return;
  }
  const std::size_t stride = detail::count_stride(buckets);
  // Each thread clears its own counts; the threads write every begin. The
  // threads' range totals after the counts.
  scratch.resize(std::size_t(most) * stride + std::size_t(most));
  begin.resize(std::size_t(buckets) + 1);
  std::uint32_t* count = scratch.data();
  std::uint32_t* totals = count + std::size_t(most) * stride;
  std::uint32_t* first = begin.data();
#pragma omp parallel num_threads(most) if (most > 1)
  {
    // The thread's own copies: through the shared references, the loops
    // read each functor's captures again after every store.
    const std::decay_t<Bucket> bucket_of = bucket;
    std::decay_t<Move> move_to = move;
    detail::sort_slices(
        n, buckets, 0, bucket_of, [&move_to](std::uint32_t k, std::uint32_t, std::uint32_t p) { move_to(k, p); },
        count, stride, totals, first);
  }
}

}  // namespace marbles
