// core/lower_bound.hpp — a binary search over sorted keys, the same on host
// and device (the broad phase's cell lookup, the local order's colour
// bounds).
#pragma once

#include <cstdint>

#include "core/config.hpp"

namespace marbles {

// First index in keys[0, n) whose key is >= k (keys ascending).
template <class Key>
MARBLES_HD_INLINE std::uint32_t lower_bound_key(const Key* keys, std::uint32_t n, Key k) {
  std::uint32_t lo = 0, hi = n;
  while (lo < hi) {
    const std::uint32_t mid = lo + (hi - lo) / 2;
    if (keys[mid] < k)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

}  // namespace marbles
