// core/bits.hpp — a float's or double's bits as an unsigned word and back,
// the same on host and device (the device's intrinsics, the host's
// memcpy): for order-preserving keys and exact tests of signs.
#pragma once

#include <cstdint>

#include "core/config.hpp"

namespace marbles {

MARBLES_HD_INLINE std::uint32_t bits_of_float(float x) {
#if defined(__CUDA_ARCH__)
  return __float_as_uint(x);
#else
  std::uint32_t bits;
  __builtin_memcpy(&bits, &x, sizeof bits);
  return bits;
#endif
}
MARBLES_HD_INLINE float float_of_bits(std::uint32_t bits) {
#if defined(__CUDA_ARCH__)
  return __uint_as_float(bits);
#else
  float x;
  __builtin_memcpy(&x, &bits, sizeof x);
  return x;
#endif
}
MARBLES_HD_INLINE std::uint64_t bits_of_double(double x) {
#if defined(__CUDA_ARCH__)
  return static_cast<std::uint64_t>(__double_as_longlong(x));
#else
  std::uint64_t bits;
  __builtin_memcpy(&bits, &x, sizeof bits);
  return bits;
#endif
}
MARBLES_HD_INLINE double double_of_bits(std::uint64_t bits) {
#if defined(__CUDA_ARCH__)
  return __longlong_as_double(static_cast<long long>(bits));
#else
  double x;
  __builtin_memcpy(&x, &bits, sizeof x);
  return x;
#endif
}

// The sign bit of a real (set for -0 as for any negative value).
MARBLES_HD_INLINE bool sign_bit(real x) {
  if constexpr (sizeof(real) == 4) return (bits_of_float(static_cast<float>(x)) >> 31) != 0u;
  else return (bits_of_double(static_cast<double>(x)) >> 63) != 0u;
}

}  // namespace marbles
