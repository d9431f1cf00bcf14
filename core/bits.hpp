// core/bits.hpp — a float's or double's bits as an unsigned word and back,
// the same on host and device: for order-preserving keys and exact tests of
// signs.
#pragma once

#include <cstdint>
#include <cstring>

#include "core/config.hpp"

namespace marbles {

// x's bytes as a To of the same size (std::bit_cast, on host and device:
// a copy between locals, which both compilers make a register move).
template <class To, class From>
MARBLES_HD_INLINE To bit_cast_hd(const From& x) {
  static_assert(sizeof(To) == sizeof(From), "bit_cast_hd: sizes differ");
  To y;
  memcpy(&y, &x, sizeof y);
  return y;
}
MARBLES_HD_INLINE std::uint32_t bits_of_float(float x) { return bit_cast_hd<std::uint32_t>(x); }
MARBLES_HD_INLINE float float_of_bits(std::uint32_t bits) { return bit_cast_hd<float>(bits); }
MARBLES_HD_INLINE std::uint64_t bits_of_double(double x) { return bit_cast_hd<std::uint64_t>(x); }
MARBLES_HD_INLINE double double_of_bits(std::uint64_t bits) { return bit_cast_hd<double>(bits); }

// A real's bits as an unsigned word (a float's in the low 32 bits), and
// back. Non-negative reals order as their words do, so an atomic max over
// the words gives the exact largest real whatever the order.
MARBLES_HD_INLINE std::uint64_t bits_of_real(real x) {
  if constexpr (sizeof(real) == 4) return bits_of_float(static_cast<float>(x));
  else return bits_of_double(static_cast<double>(x));
}
MARBLES_HD_INLINE real real_of_bits(std::uint64_t w) {
  if constexpr (sizeof(real) == 4) return float_of_bits(static_cast<std::uint32_t>(w));
  else return double_of_bits(w);
}

// The sign bit of a real (set for -0 as for any negative value).
MARBLES_HD_INLINE bool sign_bit(real x) { return (bits_of_real(x) >> (8 * sizeof(real) - 1)) != 0u; }

}  // namespace marbles
