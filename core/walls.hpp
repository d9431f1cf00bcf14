// core/walls.hpp — boundary geometry shared by the narrow phase (contacts)
// and the renderer (drawing the container). Walls are immovable (infinite
// mass) but may move with a prescribed velocity.
#pragma once

#include <cstdint>
#include <vector>

#include "core/vec3.hpp"

namespace marbles {

// A half-space: points x with dot(x - point, normal) >= 0 are free space.
// `normal` is unit length. `velocity` (m/s) moves the plane (its normal
// part) and drags what touches it (its tangential part, a conveyor).
struct PlaneWall {
  Vec3 point;
  Vec3 normal{0, 0, 1};
  std::uint32_t material = 0;
  Vec3 velocity;
  std::uint32_t index = 0;  // its place in the scene's `walls` list (output names it so)
};

// The inside of an axis-aligned box: spheres are kept within [lo, hi].
struct BoxWall {
  Vec3 lo, hi;
  std::uint32_t material = 0;
  Vec3 velocity;  // m/s, the whole box translates
  std::uint32_t index = 0;  // its place in the scene's `walls` list (output names it so)
};

// A circular cylinder around the axis through `base` along unit `axis`,
// from base to base + length·axis (length 0: infinite). `inside` keeps
// spheres within radius (a tube or drum, its ends open); otherwise outside
// (a post, a solid with flat ends where it is finite). It may
// spin about its axis at `angular_velocity` rad/s (right-handed about axis),
// which drags touching spheres (a rotating drum).
struct CylinderWall {
  Vec3 base;
  Vec3 axis{0, 0, 1};
  real radius = 1;
  real length = 0;
  bool inside = true;
  real angular_velocity = 0;
  std::uint32_t material = 0;
  std::uint32_t index = 0;  // its place in the scene's `walls` list (output names it so)
};

// A fixed sphere (an obstacle): spheres stay outside it.
struct SphereWall {
  Vec3 centre;
  real radius = 1;
  std::uint32_t material = 0;
  Vec3 velocity;
  std::uint32_t index = 0;  // its place in the scene's `walls` list (output names it so)
};

struct Walls {
  std::vector<PlaneWall> planes;
  std::vector<BoxWall> boxes;
  std::vector<CylinderWall> cylinders;
  std::vector<SphereWall> spheres;
  bool empty() const { return planes.empty() && boxes.empty() && cylinders.empty() && spheres.empty(); }
};

}  // namespace marbles
