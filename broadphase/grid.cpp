// broadphase/grid.cpp — the bounds the grids are chosen from (grid.hpp), apart
// from the broad phases themselves: the step's renumbering and the scene's
// `order: cells` order spheres by the same grid.
#include "broadphase/grid.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "broadphase/broadphase.hpp"

namespace marbles::broadphase {

Bounds bounds_of(const SpheresIn& s) {
  Bounds b;
  if (s.count == 0) return b;
  const real inf = std::numeric_limits<real>::infinity();
  real lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};
  real r_max = 0;
  bool finite = true;
  const auto n = static_cast<std::ptrdiff_t>(s.count);
#pragma omp parallel for reduction(min : lo[:3]) reduction(max : hi[:3], r_max) reduction(&& : finite) \
    schedule(static) if (n > 65536)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    const Vec3 c = s.centre[i];
    const real r = s.radius[i];
    finite = finite && is_finite(c) && std::isfinite(r) && r >= 0;
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], c[k]);
      hi[k] = std::max(hi[k], c[k]);
    }
    r_max = std::max(r_max, r);
  }
  if (!finite) throw NonFiniteInput();
  b.lo = {lo[0], lo[1], lo[2]};
  b.hi = {hi[0], hi[1], hi[2]};
  b.r_max = r_max;
  return b;
}

}  // namespace marbles::broadphase
