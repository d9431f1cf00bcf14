// core/pair.hpp — an unordered pair of sphere indices, stored with i < j.
// The broad phase emits these; the narrow phase consumes them.
#pragma once

#include <cstdint>

namespace marbles {

struct IndexPair {
  std::uint32_t i = 0, j = 0;  // i < j
  friend bool operator==(const IndexPair& a, const IndexPair& b) { return a.i == b.i && a.j == b.j; }
  friend bool operator<(const IndexPair& a, const IndexPair& b) { return a.i < b.i || (a.i == b.i && a.j < b.j); }
};

}  // namespace marbles
