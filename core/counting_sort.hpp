// core/counting_sort.hpp — a stable counting sort, in parallel.
//
// Items 0..n-1 go to buckets (bucket(k) < buckets, or kSkipItem: left out);
// move(k, place) puts item k at its place: bucket by bucket, and within a
// bucket in item order, whatever the thread count. Each thread counts its
// slice of the items per bucket; the slices' places follow bucket by bucket
// and slice by slice; then each thread moves its slice. `begin` gets the
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

template <class Bucket, class Move>
void counting_sort(std::uint32_t n, std::uint32_t buckets, Bucket&& bucket, Move&& move,
                   std::vector<std::uint32_t>& begin, std::vector<std::uint32_t>& scratch) {
  const int most = n >= 20000 ? thread_count() : 1;
  // Each thread's counts on cache lines of their own (64 bytes at least
  // between two threads' counts, wherever the scratch begins): a few
  // buckets (the colouring's colours) would otherwise put two threads'
  // counts on one line, which every count writes.
  const std::size_t stride = (std::size_t(buckets) + 16 + 15) / 16 * 16;
  // Each thread clears its own counts; the single pass writes every begin.
  scratch.resize(std::size_t(most) * stride);
  begin.resize(std::size_t(buckets) + 1);
  std::uint32_t* count = scratch.data();
#pragma omp parallel num_threads(most) if (most > 1)
  {
    // The thread's own copies: through the shared references, the loops
    // read each functor's captures again after every store.
    const std::decay_t<Bucket> bucket_of = bucket;
    std::decay_t<Move> move_to = move;
    const int t = thread_index(), threads = team_size();
    const auto lo = static_cast<std::uint32_t>(std::uint64_t(n) * t / threads);
    const auto hi = static_cast<std::uint32_t>(std::uint64_t(n) * (t + 1) / threads);
    std::uint32_t* mine = count + std::size_t(t) * stride;
    std::fill(mine, mine + buckets, 0u);
    for (std::uint32_t k = lo; k < hi; ++k) {
      const std::uint32_t b = bucket_of(k);
      if (b != kSkipItem) ++mine[b];
    }
#pragma omp barrier
#pragma omp single
    {
      std::uint32_t at = 0;
      for (std::uint32_t b = 0; b < buckets; ++b) {
        begin[b] = at;
        for (int u = 0; u < threads; ++u) {
          const std::uint32_t v = count[std::size_t(u) * stride + b];
          count[std::size_t(u) * stride + b] = at;
          at += v;
        }
      }
      begin[buckets] = at;
    }
    for (std::uint32_t k = lo; k < hi; ++k) {
      const std::uint32_t b = bucket_of(k);
      if (b != kSkipItem) move_to(k, mine[b]++);
    }
  }
}

}  // namespace marbles
