// render/d3.hpp — small double-precision 3-D vectors for the camera and the
// light (view matrices are built in double so that scenes far from the
// origin still project without jitter) and for the reference probe's
// measurements (sim/reference.cpp).
#pragma once

#include <cmath>

#include "core/vec3.hpp"

namespace marbles::render {

struct D3 {
  double x = 0, y = 0, z = 0;
};
inline D3 d3(const Vec3& v) { return {double(v.x), double(v.y), double(v.z)}; }
inline D3 operator+(D3 a, D3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline D3 operator-(D3 a, D3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline D3 operator*(double s, D3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline D3 cross(D3 a, D3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
inline double norm(D3 a) { return std::sqrt(dot(a, a)); }
// Unit vector along a; +z for the zero vector.
inline D3 normalize(D3 a) {
  const double l = norm(a);
  return l > 0 ? (1 / l) * a : D3{0, 0, 1};
}

}  // namespace marbles::render
