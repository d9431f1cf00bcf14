#include "integrator/symplectic_euler.hpp"

#include "integrator/integrator_math.hpp"

namespace marbles::integrator {

void apply_gravity(const BodiesView& bodies, const Vec3& g, real h) {
  const auto n = static_cast<std::ptrdiff_t>(bodies.count);
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t i = 0; i < n; ++i)
    bodies.velocity[i] = gravity_kick(bodies.velocity[i], g, bodies.inv_mass[i], h);
}

void apply_drag(const BodiesView& bodies, real k1, real k2, real h, DragKick kick, const Vec3* g) {
  const auto n = static_cast<std::ptrdiff_t>(bodies.count);
  const Vec3 gh = g ? *g * h : Vec3{};
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t i = 0; i < n; ++i)
    if (bodies.inv_mass[i] > 0)
      bodies.velocity[i] = drag_update(kick, bodies.velocity[i], g != nullptr, gh, k1, k2, h);
}

bool integrate_positions(const BodiesView& bodies, real h, const real* reach, std::size_t* past, const Vec3* shift) {
  const auto n = static_cast<std::ptrdiff_t>(bodies.count);
  bool bad = false;
  std::size_t moved_past = 0;
#pragma omp parallel for schedule(static) reduction(|| : bad) reduction(+ : moved_past) if (n > 20000)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    bodies.position[i] = drift(bodies.position[i], bodies.velocity[i], h, shift, static_cast<std::size_t>(i));
    bad = bad || !body_is_finite(bodies.position[i], bodies.velocity[i], bodies.angular_velocity[i]);
    if (reach != nullptr && moved_past_reach(bodies.velocity[i], bodies.radius[i], reach[i], h)) ++moved_past;
  }
  if (past != nullptr) *past = moved_past;
  return bad;
}

}  // namespace marbles::integrator
