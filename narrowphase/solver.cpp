#include "narrowphase/solver.hpp"

#include <algorithm>

#include "narrowphase/contact_math.hpp"

namespace marbles::narrowphase {
namespace {

// Loads the velocity state of body `index` (a wall is immovable and moves
// with its surface velocity).
inline BodyState load(const BodiesView& bodies, std::uint32_t index, const Contact& c) {
  if (is_wall(index)) return {c.wall_velocity, Vec3{}, 0, 0};
  return {bodies.velocity[index], bodies.angular_velocity[index], bodies.inv_mass[index], bodies.inv_inertia[index]};
}

inline void store(const BodiesView& bodies, std::uint32_t index, const BodyState& s) {
  if (is_wall(index)) return;
  bodies.velocity[index] = s.v;
  bodies.angular_velocity[index] = s.w;
}

// One Gauss-Seidel sweep, forwards or backwards over the contacts:
// alternating the direction lets a correction cross a chain of contacts (a
// stack) in both directions within one pair of sweeps.
template <bool Friction, bool Rolling>
void sweep(std::vector<Contact>& contacts, const BodiesView& bodies, real inv_h, bool backwards) {
  const std::size_t n = contacts.size();
  for (std::size_t k = 0; k < n; ++k) {
    Contact& c = contacts[backwards ? n - 1 - k : k];
    BodyState A = load(bodies, c.a, c);
    BodyState B = load(bodies, c.b, c);
    if constexpr (Friction) solve_friction(c, A, B);
    if constexpr (Rolling) solve_rolling(c, A, B);
    solve_normal(c, A, B, inv_h);
    store(bodies, c.a, A);
    store(bodies, c.b, B);
  }
}

// Warm start: apply the impulses the contacts start with (from the cache).
template <bool Friction, bool Rolling>
void warm_start(std::vector<Contact>& contacts, const BodiesView& bodies) {
  for (Contact& c : contacts) {
    if (c.normal_impulse <= 0) continue;
    BodyState A = load(bodies, c.a, c);
    BodyState B = load(bodies, c.b, c);
    Vec3 impulse = c.normal * c.normal_impulse;
    if constexpr (Friction) impulse += c.tangent_impulse;
    apply_impulse(c, A, B, impulse);
    if constexpr (Rolling) {
      A.w += c.rolling_impulse * A.inv_inertia;
      B.w -= c.rolling_impulse * B.inv_inertia;
    }
    store(bodies, c.a, A);
    store(bodies, c.b, B);
  }
}

// Impact stage: binary impacts in time-of-impact order, repeated while
// impacts make new approaches (a chain of touching spheres), at most
// kImpactPasses times.
constexpr int kImpactPasses = 4;

template <bool Friction>
void impacts(std::vector<Contact>& contacts, const BodiesView& bodies, real rest_speed, real h,
             std::vector<std::uint32_t>& order) {
  order.clear();
  for (std::uint32_t k = 0; k < contacts.size(); ++k)
    if (contacts[k].approach_speed < -rest_speed) order.push_back(k);
  if (order.empty()) return;
  auto toi = [&](std::uint32_t k) {
    const Contact& c = contacts[k];
    return c.separation > 0 ? c.separation / -c.approach_speed : real(0);
  };
  std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) {
    const real tx = toi(x), ty = toi(y);
    return tx < ty || (tx == ty && x < y);
  });
  // Later passes look at every contact: an impact can set a touching neighbour approaching.
  for (int pass = 0; pass < kImpactPasses; ++pass) {
    bool hit = false;
    auto visit = [&](Contact& c) {
      BodyState A = load(bodies, c.a, c);
      BodyState B = load(bodies, c.b, c);
      if (!apply_impact<Friction>(c, A, B, rest_speed, h)) return;
      store(bodies, c.a, A);
      store(bodies, c.b, B);
      hit = true;
    };
    if (pass == 0)
      for (std::uint32_t k : order) visit(contacts[k]);
    else
      for (Contact& c : contacts) visit(c);
    if (!hit) break;
  }
}

}  // namespace

ContactSolver::ContactSolver(const SolverSettings& settings) : m_settings(settings) {
  if (settings.friction && settings.rolling) m_sweep = &sweep<true, true>, m_warm_start = &warm_start<true, true>;
  else if (settings.friction) m_sweep = &sweep<true, false>, m_warm_start = &warm_start<true, false>;
  else if (settings.rolling) m_sweep = &sweep<false, true>, m_warm_start = &warm_start<false, true>;
  else m_sweep = &sweep<false, false>, m_warm_start = &warm_start<false, false>;
  m_impacts = settings.friction ? &impacts<true> : &impacts<false>;
}

void ContactSolver::solve_velocities(std::vector<Contact>& contacts, const BodiesView& bodies, real h) const {
  for (Contact& c : contacts) prepare_contact(c, load(bodies, c.a, c), load(bodies, c.b, c));
  if (m_settings.restitution) m_impacts(contacts, bodies, m_settings.rest_speed, h, m_order);
  if (m_settings.warm_start) m_warm_start(contacts, bodies);

  const real inv_h = real(1) / h;
  for (int it = 0; it < m_settings.iterations; ++it) m_sweep(contacts, bodies, inv_h, it % 2 == 1);

}

void ContactSolver::project_positions(const std::vector<Contact>& contacts, const BodiesView& bodies,
                                      const std::vector<WallShape>& walls) const {
  const SolverSettings& s = m_settings;
  if (s.restitution) {
    for (const Contact& c : contacts) {
      if (c.rebound_shift <= 0) continue;
      const real inv_ma = bodies.inv_mass[c.a];
      const real inv_mb = is_wall(c.b) ? real(0) : bodies.inv_mass[c.b];
      const real k = inv_ma + inv_mb;
      if (k <= 0) continue;
      bodies.position[c.a] -= c.normal * (c.rebound_shift * inv_ma / k);
      if (!is_wall(c.b)) bodies.position[c.b] += c.normal * (c.rebound_shift * inv_mb / k);
    }
  }
  for (int it = 0; it < s.position_iterations; ++it) {
    for (const Contact& c : contacts) {
      const real inv_ma = bodies.inv_mass[c.a];
      if (is_wall(c.b)) {
        if (inv_ma <= 0) continue;
        const real r = bodies.radius[c.a];
        Vec3 normal;
        real separation;
        if (!wall_gap(walls[c.b & ~kWallFlag], bodies.position[c.a], r, normal, separation)) continue;
        const real move = projection_step(separation, s.slop * r, s.beta, s.max_correction * r);
        if (move > 0) bodies.position[c.a] += normal * move;
        continue;
      }
      const real inv_mb = bodies.inv_mass[c.b];
      const real k = inv_ma + inv_mb;
      if (k <= 0) continue;
      const real ra = bodies.radius[c.a], rb = bodies.radius[c.b];
      const Vec3 d = bodies.position[c.a] - bodies.position[c.b];
      const real dist = length(d);
      const Vec3 n = dist > real(1e-7) * (ra + rb) ? d / dist : c.normal;
      const real r_min = std::min(ra, rb);
      const real move = projection_step(dist - ra - rb, s.slop * r_min, s.beta, s.max_correction * r_min);
      if (move <= 0) continue;
      bodies.position[c.a] += n * (move * inv_ma / k);
      bodies.position[c.b] -= n * (move * inv_mb / k);
    }
  }
}

}  // namespace marbles::narrowphase
