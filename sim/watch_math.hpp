// sim/watch_math.hpp — the per-sphere figures of the watchdog's cheap
// invariants (Simulation::step), host and device: one pass over the spheres
// at the end of a step, summed by the backend (CpuStep, CudaStep).
//
//   kinetic energy   translational + rotational, J (immovable spheres: 0)
//   beyond a wall    the whole sphere lies past a wall's surface (its centre
//                    deeper than one radius into the wall): it went through
#pragma once

#include "core/vec3.hpp"
#include "narrowphase/contact_math.hpp"

namespace marbles::watch {

MARBLES_HD_INLINE double kinetic_energy(const Vec3& v, const Vec3& w, real inv_mass, real inv_inertia) {
  if (!(inv_mass > 0)) return 0;
  const double t = static_cast<double>(length_squared(v)) / static_cast<double>(inv_mass);
  const double r = inv_inertia > 0 ? static_cast<double>(length_squared(w)) / static_cast<double>(inv_inertia) : 0.0;
  return 0.5 * (t + r);
}

MARBLES_HD_INLINE bool beyond_walls(const Vec3& p, real r, const narrowphase::WallShape* walls, std::uint32_t n) {
  for (std::uint32_t k = 0; k < n; ++k) {
    Vec3 normal;
    real separation = 0;
    if (narrowphase::wall_gap(walls[k], p, r, normal, separation) && separation < real(-2) * r) return true;
  }
  return false;
}

}  // namespace marbles::watch
