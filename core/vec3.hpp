// core/vec3.hpp — a plain 3-vector of `real`, usable on host and device.
//
// Kept deliberately small (no expression templates): every operation is a
// handful of flops that the compiler inlines in both the CPU loops and the
// CUDA kernels.
#pragma once

#include <cmath>
#include <limits>

#include "core/config.hpp"

namespace marbles {

struct Vec3 {
  real x = 0, y = 0, z = 0;

  MARBLES_HD_INLINE constexpr Vec3() = default;
  MARBLES_HD_INLINE constexpr Vec3(real x_, real y_, real z_) : x(x_), y(y_), z(z_) {}

  MARBLES_HD_INLINE Vec3& operator+=(const Vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
  MARBLES_HD_INLINE Vec3& operator-=(const Vec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
  MARBLES_HD_INLINE Vec3& operator*=(real s) { x *= s; y *= s; z *= s; return *this; }
  MARBLES_HD_INLINE real operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};

MARBLES_HD_INLINE Vec3 operator+(Vec3 a, const Vec3& b) { return a += b; }
MARBLES_HD_INLINE Vec3 operator-(Vec3 a, const Vec3& b) { return a -= b; }
MARBLES_HD_INLINE Vec3 operator-(const Vec3& a) { return {-a.x, -a.y, -a.z}; }
MARBLES_HD_INLINE Vec3 operator*(Vec3 a, real s) { return a *= s; }
MARBLES_HD_INLINE Vec3 operator*(real s, Vec3 a) { return a *= s; }
MARBLES_HD_INLINE Vec3 operator/(const Vec3& a, real s) { return {a.x / s, a.y / s, a.z / s}; }
MARBLES_HD_INLINE bool operator==(const Vec3& a, const Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

MARBLES_HD_INLINE real dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
MARBLES_HD_INLINE Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
MARBLES_HD_INLINE real length_squared(const Vec3& a) { return dot(a, a); }
MARBLES_HD_INLINE real length(const Vec3& a) { return std::sqrt(dot(a, a)); }
MARBLES_HD_INLINE bool is_finite(const Vec3& a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}
// Whether a vector's squared length, which the step forms (speeds into
// energies, gaps into distances), overflows the precision: such a vector is
// refused where it comes in (a scene, a CSV row, an array from Python).
MARBLES_HD_INLINE bool square_overflows(const Vec3& a) { return !std::isfinite(length_squared(a)); }
// Whether a radius above zero is too small for the overlap test, which
// compares squared distances with squared sums of radii: its square is
// below the precision's smallest normal number (below about 1.1e-19 m in
// float), and two such spheres on one spot would be found apart. Refused
// where radii come in without a mass (a CSV row, `marbles pairs`, Python's
// pairs(); a scene's spheres that small have no mass in range either).
inline bool radius_squares_below_normal(real r) { return r > 0 && !(r * r >= std::numeric_limits<real>::min()); }
// The smallest radius that is not (for messages).
inline real smallest_squarable_radius() {
  real r = std::sqrt(std::numeric_limits<real>::min());
  while (radius_squares_below_normal(r)) r = std::nextafter(r, std::numeric_limits<real>::max());
  return r;
}

}  // namespace marbles
