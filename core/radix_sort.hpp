// core/radix_sort.hpp — the CPU radix sort of (key, value) pairs (the broad
// phase's cell keys, the colouring's ranks, the warm-start cache's keys).
//
// LSD radix sort, 8-bit digits, stable, with only the passes that the keys'
// `key_bits` low bits need (a pass whose digit is equal for every key is
// skipped). Each pass: per-thread digit counts over contiguous blocks, an
// exclusive prefix sum in (digit, block) order, a scatter in input order —
// so the result does not depend on the number of threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace marbles {

// Bits needed to write v (0 for 0): a sort's key_bits for keys up to v.
// std::bit_width without C++20, so that .cu files compiled as C++17 can
// include this header.
inline unsigned bits_needed(std::uint64_t v) {
  unsigned b = 0;
  while (v) {
    ++b;
    v >>= 1;
  }
  return b;
}

// Sorts keys[0, n) and moves values with them. `scratch_*` are resized as
// needed and may be reused between calls. Returns the passes made.
unsigned radix_sort_pairs(std::vector<std::uint32_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                          std::vector<std::uint32_t>& scratch_keys, std::vector<std::uint32_t>& scratch_values);
unsigned radix_sort_pairs(std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                          std::vector<std::uint64_t>& scratch_keys, std::vector<std::uint32_t>& scratch_values);

// Convenience overloads with their own scratch.
unsigned radix_sort_pairs(std::vector<std::uint32_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits);
unsigned radix_sort_pairs(std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits);

}  // namespace marbles

namespace marbles::broadphase {
using marbles::radix_sort_pairs;
}  // namespace marbles::broadphase
