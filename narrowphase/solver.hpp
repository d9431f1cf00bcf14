// narrowphase/solver.hpp — sequential-impulse contact solver.
//
// Stages of one substep, in order (each in a fixed order, so a run repeats
// bit for bit):
//   prepare       effective masses; approach speed before the solve
//   impacts       (with restitution) contacts approaching faster than the
//                 rest speed collide as binary impacts, P_n = (1 + e) m |v_n|
//                 with friction limited to mu P_n, in time-of-impact order
//   warm start    apply the impulses carried over from the last substep
//                 (ContactCache, matched by body pair) when enabled
//   solve         `iterations` sweeps, alternately forwards and backwards: friction, rolling resistance (when the
//                 scene enables them), then the normal impulse (speculative:
//                 a positive gap may close within the substep, never more)
// and after the positions are integrated:
//   project       remove overlap beyond a slop by moving positions only
//                 (no velocity change, so no kinetic energy is added)
// Which stages and which per-contact terms run is fixed when the solver is
// built: a disabled effect costs no branch per contact (template dispatch).
#pragma once

#include <cstdint>
#include <vector>

#include "core/spheres.hpp"
#include "core/walls.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_math.hpp"

namespace marbles::narrowphase {

struct SolverSettings {
  int iterations = 10;            // velocity sweeps per substep
  bool restitution = true;        // impact stage (without it impacts are plastic)
  bool friction = false;          // Coulomb friction term
  bool rolling = false;           // rolling resistance term
  real rest_speed = real(0.01);   // m/s: slower approaches do not bounce
  real slop = real(0.005);        // fraction of the smaller radius left overlapping
  real beta = real(0.2);          // fraction of the remaining overlap removed per projection
  real max_correction = real(0.2);// fraction of the smaller radius moved per projection, at most
  int position_iterations = 2;    // projection sweeps per substep
  bool warm_start = true;         // start from the last substep's impulses
};

class ContactSolver {
 public:
  explicit ContactSolver(const SolverSettings& settings);

  const SolverSettings& settings() const { return m_settings; }

  // prepare + solve (+ restitution) on the velocities in `bodies`.
  void solve_velocities(std::vector<Contact>& contacts, const BodiesView& bodies, real h) const;

  // Position projection over the same contacts at the integrated positions.
  void project_positions(const std::vector<Contact>& contacts, const BodiesView& bodies,
                         const std::vector<WallShape>& walls) const;

 private:
  using SweepFn = void (*)(std::vector<Contact>&, const BodiesView&, real inv_h, bool backwards);
  using WarmStartFn = void (*)(std::vector<Contact>&, const BodiesView&);
  SolverSettings m_settings;
  SweepFn m_sweep = nullptr;
  WarmStartFn m_warm_start = nullptr;
  using ImpactFn = void (*)(std::vector<Contact>&, const BodiesView&, real rest_speed, real h,
                           std::vector<std::uint32_t>& order);
  ImpactFn m_impacts = nullptr;
  mutable std::vector<std::uint32_t> m_order;  // scratch: impact order
};

}  // namespace marbles::narrowphase
