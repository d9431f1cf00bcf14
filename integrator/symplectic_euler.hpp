// integrator/symplectic_euler.hpp — the CPU loops of the semi-implicit Euler
// integrator (see integrator_math.hpp for the scheme).
#pragma once

#include "core/spheres.hpp"
#include "integrator/integrator_math.hpp"

namespace marbles::integrator {

// Body-force stage: v += h g on every movable sphere.
void apply_gravity(const BodiesView& bodies, const Vec3& g, real h);

// Body-force stage: air drag with linear rate k1 (1/s) and quadratic
// coefficient k2 (1/m), see drag_kick.
// The kick (integrator_math.hpp drag_update), gravity's kick over h with it
// where g is given (one pass: no apply_gravity then).
void apply_drag(const BodiesView& bodies, real k1, real k2, real h, DragKick kick = DragKick::whole,
                const Vec3* g = nullptr);

// Position stage: x += h v, and the impacts' shifts where given (drift).
// Returns true when a position, velocity or angular velocity is not finite
// afterwards (the step's non_finite flag). With `reach` (m a sphere,
// contact_reach), the spheres that moved past it (moved_past_reach) are
// counted into *past.
bool integrate_positions(const BodiesView& bodies, real h, const real* reach = nullptr, std::size_t* past = nullptr,
                         const Vec3* shift = nullptr);

}  // namespace marbles::integrator
