// integrator/symplectic_euler.hpp — the CPU loops of the semi-implicit Euler
// integrator (see integrator_math.hpp for the scheme).
#pragma once

#include "core/spheres.hpp"

namespace marbles::integrator {

// Body-force stage: v += h g on every movable sphere.
void apply_gravity(const BodiesView& bodies, const Vec3& g, real h);

// Position stage: x += h v.
void integrate_positions(const BodiesView& bodies, real h);

}  // namespace marbles::integrator
