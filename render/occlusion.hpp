// render/occlusion.hpp — which spheres can show at all, found on the CPU
// before drawing.
//
// llvmpipe shades every fragment of every impostor: a shader that writes its
// own depth gets no early depth test, so a sphere buried in a pile costs as
// much as one in front. This pass removes, conservatively, the spheres that
// are off screen or certainly hidden behind nearer spheres, with a coarse
// occlusion grid: spheres are taken near to far; a sphere is hidden when
// every grid cell its image may touch is already fully covered by a nearer
// sphere whose surface there is closer than this sphere's nearest point;
// otherwise it is kept and marks the cells that its image certainly covers.
// For a dense pile this keeps roughly the outer shell (10-20 % of the
// spheres); for a sparse gas it keeps almost everything. It never removes a
// sphere that would change a pixel.
#pragma once

#include <cstdint>
#include <vector>

namespace marbles::render {

/// A sphere as the occlusion test sees it, on a screen of pixels.
struct ProjectedSphere {
  float x = 0, y = 0;  ///< image of the centre, pixels
  float depth = 0;     ///< centre depth along the view axis, scene units
  float radius = 0;    ///< scene units
  /// Radius (pixels) of a disk around (x, y) inside the sphere's image, whose
  /// rays meet the sphere no deeper than `depth`.
  float inner = 0;
  /// Radius (pixels) of a disk around (x, y) that contains the sphere's image.
  float outer = 0;
};

/// Indices of the spheres that may be visible on a width x height pixel
/// screen, near to far. `cell` is the grid cell edge in pixels (finer culls
/// more, costs more). Spheres reaching in front of depth `near` are always
/// kept and never occlude.
std::vector<std::uint32_t> visible_spheres(const std::vector<ProjectedSphere>& spheres, int width, int height,
                                           float cell, float near);

}  // namespace marbles::render
