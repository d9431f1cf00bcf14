// render/camera.hpp — where the picture is taken from, and the default view
// that shows the whole scene.
#pragma once

#include <string_view>

#include "core/vec3.hpp"
#include "core/walls.hpp"
#include "render/snapshot.hpp"

namespace marbles::render {

/// A pinhole camera. Positions in scene units (m).
struct Camera {
  Vec3 position{0, -5, 2};
  Vec3 look_at{0, 0, 0};
  Vec3 up{0, 0, 1};  ///< need not be orthogonal to the view direction
  double fov = 40;   ///< vertical field of view, degrees, in (0, 180)
};

/// An axis-aligned box in double precision; `empty()` until something is added.
struct Bounds {
  double lo[3] = {1e300, 1e300, 1e300};
  double hi[3] = {-1e300, -1e300, -1e300};

  bool empty() const { return lo[0] > hi[0]; }
  void add(double x, double y, double z, double pad = 0);
  void add(const Bounds& o);
  double center(int axis) const { return 0.5 * (lo[axis] + hi[axis]); }
  double extent(int axis) const { return hi[axis] - lo[axis]; }
  /// Half the diagonal: the radius of a sphere enclosing the box.
  double radius() const;
};

/// Bounds of what should be in view: every sphere (centre ± radius), every box,
/// sphere obstacle and finite cylinder wall, and for each plane wall the shadow of those bounds on the plane (so a
/// floor under falling spheres is in the picture). Never empty: an empty scene
/// gives the unit box around the origin.
Bounds scene_bounds(const Snapshot& snapshot, const Walls& walls);

/// A camera that frames `bounds` tightly at the given image aspect ratio:
/// looking from the front-left and 25 degrees above (with `up` as up), with
/// some room on the right for the colour bar.
Camera default_camera(const Bounds& bounds, int width, int height, double fov = 40, Vec3 up = {0, 0, 1});

/// Parses the command-line form "x,y,z:lx,ly,lz" (position : look-at; up
/// +z, fov 40 unless given). Throws marbles::InputError with key `key`.
Camera parse_camera(std::string_view text, std::string_view key = "--camera");

}  // namespace marbles::render
