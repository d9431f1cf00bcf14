// core/radix_sort.cpp — see radix_sort.hpp.
//
// Cost per pass: one read of the keys (count), one read of keys and values
// and one write of both (scatter). Blocks are at least kMinBlock entries so
// small sorts stay on one thread.
#include "core/radix_sort.hpp"

#include <algorithm>
#include <array>
#include <utility>

#if defined(_OPENMP)
#include <omp.h>
#endif

namespace marbles {
namespace {

constexpr std::size_t kRadix = 256;
// The fewest keys a thread takes: 8192, so the broad phase's sort of 10^5
// keys runs on 12 threads where there are (with 32768 a thread, on 3 of 16:
// 0.9-1.4 ms a step on the 16-core host).
constexpr std::size_t kMinBlock = 1 << 13;

int thread_count(std::size_t n) {
#if defined(_OPENMP)
  const std::size_t by_size = std::max<std::size_t>(1, n / kMinBlock);
  return static_cast<int>(std::min<std::size_t>(by_size, static_cast<std::size_t>(omp_get_max_threads())));
#else
  (void)n;
  return 1;
#endif
}

template <class Key>
unsigned sort_pairs(std::vector<Key>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                    std::vector<Key>& tmp_keys, std::vector<std::uint32_t>& tmp_values) {
  const std::size_t n = keys.size();
  if (values.size() != n) values.resize(n);
  if (n < 2 || key_bits == 0) return 0;
  key_bits = std::min<unsigned>(key_bits, 8 * sizeof(Key));
  tmp_keys.resize(n);
  tmp_values.resize(n);

  const int threads = thread_count(n);
  std::vector<std::array<std::size_t, kRadix>> counts(static_cast<std::size_t>(threads));
  Key* src_k = keys.data();
  std::uint32_t* src_v = values.data();
  Key* dst_k = tmp_keys.data();
  std::uint32_t* dst_v = tmp_values.data();
  unsigned passes = 0;

  for (unsigned shift = 0; shift < key_bits; shift += 8) {
    bool skip = false;
#pragma omp parallel num_threads(threads)
    {
      // Slices by the team the region was given, which may be fewer
      // threads than asked for (a nested call, a thread limit).
#if defined(_OPENMP)
      const int t = omp_get_thread_num(), team = omp_get_num_threads();
#else
      const int t = 0, team = 1;
#endif
      const std::size_t begin = n * static_cast<std::size_t>(t) / static_cast<std::size_t>(team);
      const std::size_t end = n * static_cast<std::size_t>(t + 1) / static_cast<std::size_t>(team);
      auto& c = counts[static_cast<std::size_t>(t)];
      c.fill(0);
      for (std::size_t i = begin; i < end; ++i) ++c[(src_k[i] >> shift) & 0xff];
#pragma omp barrier
#pragma omp single
      {
        // Exclusive prefix sum in (digit, block) order: stable.
        std::size_t total = 0;
        for (std::size_t d = 0; d < kRadix; ++d) {
          std::size_t in_digit = 0;
          for (int b = 0; b < team; ++b) {
            const std::size_t k = counts[static_cast<std::size_t>(b)][d];
            counts[static_cast<std::size_t>(b)][d] = total;
            total += k;
            in_digit += k;
          }
          if (in_digit == n) skip = true;  // every key has this digit
        }
      }
      if (!skip) {
        for (std::size_t i = begin; i < end; ++i) {
          const std::size_t at = c[(src_k[i] >> shift) & 0xff]++;
          dst_k[at] = src_k[i];
          dst_v[at] = src_v[i];
        }
      }
    }
    if (skip) continue;
    std::swap(src_k, dst_k);
    std::swap(src_v, dst_v);
    ++passes;
  }
  if (src_k != keys.data()) {
    keys.swap(tmp_keys);
    values.swap(tmp_values);
  }
  return passes;
}

}  // namespace

unsigned radix_sort_pairs(std::vector<std::uint32_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                          std::vector<std::uint32_t>& scratch_keys, std::vector<std::uint32_t>& scratch_values) {
  return sort_pairs(keys, values, key_bits, scratch_keys, scratch_values);
}
unsigned radix_sort_pairs(std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                          std::vector<std::uint64_t>& scratch_keys, std::vector<std::uint32_t>& scratch_values) {
  return sort_pairs(keys, values, key_bits, scratch_keys, scratch_values);
}
unsigned radix_sort_pairs(std::vector<std::uint32_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits) {
  std::vector<std::uint32_t> sk, sv;
  return sort_pairs(keys, values, key_bits, sk, sv);
}
unsigned radix_sort_pairs(std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits) {
  std::vector<std::uint64_t> sk;
  std::vector<std::uint32_t> sv;
  return sort_pairs(keys, values, key_bits, sk, sv);
}

}  // namespace marbles
