// core/hash.hpp — FNV-1a, 64 bit: the checksum of the files the program
// reads back (checkpoints, the step benchmark's pile cache) and the scene's
// fingerprint. Not a defence against a forger, a test that bytes were not
// cut short or flipped.
#pragma once

#include <cstddef>
#include <cstdint>

namespace marbles {

inline std::uint64_t fnv1a(const void* data, std::size_t size, std::uint64_t h = 14695981039346656037ull) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

}  // namespace marbles
