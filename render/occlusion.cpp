// render/occlusion.cpp — see occlusion.hpp.
#include "render/occlusion.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace marbles::render {

std::vector<std::uint32_t> visible_spheres(const std::vector<ProjectedSphere>& spheres, int width, int height,
                                           float cell, float near) {
  const int gw = std::max(1, int(std::ceil(width / cell))), gh = std::max(1, int(std::ceil(height / cell)));
  // For each cell, the depth behind which everything in the cell is hidden.
  std::vector<float> hidden_beyond(std::size_t(gw) * gh, std::numeric_limits<float>::infinity());

  std::vector<std::uint32_t> order;
  order.reserve(spheres.size());
  std::vector<float> front(spheres.size());
  for (std::size_t i = 0; i < spheres.size(); ++i) {
    const ProjectedSphere& s = spheres[i];
    front[i] = s.depth - s.radius;
    if (s.depth + s.radius <= near) continue;  // entirely behind the eye
    if (s.x + s.outer < 0 || s.y + s.outer < 0 || s.x - s.outer > width || s.y - s.outer > height) continue;
    order.push_back(std::uint32_t(i));
  }
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return front[a] < front[b]; });

  std::vector<std::uint32_t> kept;
  kept.reserve(order.size());
  const float inv = 1 / cell;
  for (std::uint32_t i : order) {
    const ProjectedSphere& s = spheres[i];
    if (front[i] <= near) {  // crosses the near plane: keep, but it proves nothing
      kept.push_back(i);
      continue;
    }
    const int x0 = std::max(0, int(std::floor((s.x - s.outer) * inv)));
    const int x1 = std::min(gw - 1, int(std::floor((s.x + s.outer) * inv)));
    const int y0 = std::max(0, int(std::floor((s.y - s.outer) * inv)));
    const int y1 = std::min(gh - 1, int(std::floor((s.y + s.outer) * inv)));
    bool hidden = true;
    for (int y = y0; y <= y1 && hidden; ++y)
      for (int x = x0; x <= x1; ++x)
        if (!(hidden_beyond[std::size_t(y) * gw + x] < front[i])) {
          hidden = false;
          break;
        }
    if (hidden) continue;
    kept.push_back(i);

    // Cells whose four corners all lie inside the inner disk are covered.
    const float r2 = s.inner * s.inner;
    const int cy0 = std::max(0, int(std::ceil((s.y - s.inner) * inv)));
    const int cy1 = std::min(gh, int(std::floor((s.y + s.inner) * inv))) - 1;
    const int cx0 = std::max(0, int(std::ceil((s.x - s.inner) * inv)));
    const int cx1 = std::min(gw, int(std::floor((s.x + s.inner) * inv))) - 1;
    for (int y = cy0; y <= cy1; ++y) {
      const float dy = std::max(std::abs(y * cell - s.y), std::abs((y + 1) * cell - s.y));
      for (int x = cx0; x <= cx1; ++x) {
        const float dx = std::max(std::abs(x * cell - s.x), std::abs((x + 1) * cell - s.x));
        if (dx * dx + dy * dy > r2) continue;
        float& h = hidden_beyond[std::size_t(y) * gw + x];
        h = std::min(h, s.depth);
      }
    }
  }
  return kept;
}

}  // namespace marbles::render
