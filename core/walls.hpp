// core/walls.hpp — static boundary geometry shared by the narrow phase (contacts)
// and the renderer (drawing the container).
#pragma once

#include <cstdint>
#include <vector>

#include "core/vec3.hpp"

namespace marbles {

// A half-space: points x with dot(x - point, normal) >= 0 are free space.
// `normal` is unit length.
struct PlaneWall {
  Vec3 point;
  Vec3 normal{0, 0, 1};
  std::uint32_t material = 0;
};

// The inside of an axis-aligned box: spheres are kept within [lo, hi].
struct BoxWall {
  Vec3 lo, hi;
  std::uint32_t material = 0;
};

struct Walls {
  std::vector<PlaneWall> planes;
  std::vector<BoxWall> boxes;
  bool empty() const { return planes.empty() && boxes.empty(); }
};

}  // namespace marbles
