// sim/step_model.hpp — the scene compiled once into the plain values a step
// reads: which effects run, g, drag, the material-pair table, the walls,
// the solver settings, dt and substeps.
//
// Both step backends (CpuStep, CudaStep) read only this: the step never sees
// YAML types and never throws input errors (compile_step_model does, with
// the scene's file, line and key).
#pragma once

#include <cstdint>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "core/walls.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_math.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles {

namespace scene {
struct Scene;
struct Material;
}  // namespace scene

struct StepModel {
  // The effects of the pipeline (each false costs nothing at run time).
  bool gravity = false;
  bool drag = false;
  bool collisions = false;     // sphere-sphere contacts (broad phase + narrow phase)
  bool wall_contacts = false;  // sphere-wall contacts (the scene has walls and the `walls` effect)
  bool moving_walls = false;   // with wall_contacts: some wall's surface moves (surface_at_rest false)
  bool speculative = true;     // contacts for gaps that can close within the substep (else touching only)
  // Velocity Verlet (kick-drift-kick): gravity is applied in two half kicks
  // around the drift, so free flight under gravity is exact; symplectic Euler
  // applies it in one kick before.
  bool verlet = false;

  Vec3 g;                                   // m/s^2
  real drag_linear = 0, drag_quadratic = 0; // 1/s, 1/m

  // Coefficients of every material pair, row-major over material ids.
  std::vector<narrowphase::PairCoefficients> pair_coefficients;
  std::uint32_t material_count = 0;
  // Every pair has the same friction and rolling friction, bit for bit:
  // where the spheres also share one radius, every contact has the same arms
  // word, and the GPU's records leave it out (narrowphase::UniformArms).
  bool uniform_pairs = false;

  Walls walls;                                     // as the scene gives them (output, rendering)
  std::vector<narrowphase::WallShape> wall_shapes; // flattened for the narrow phase, at t = 0

  narrowphase::SolverSettings solver;
  broadphase::Algorithm algorithm = broadphase::kDefaultCpuAlgorithm;
  double dt = 0;
  int substeps = 1;
  // Steps between numberings of the spheres in the broad phase's order (0:
  // never): Simulation's, between steps, the same on every backend.
  std::uint64_t renumber_every = 0;

  narrowphase::PairTable pair_table() const { return {pair_coefficients.data(), material_count}; }
  // With uniform_pairs, the one arms word of every contact where every
  // sphere has `radius` (both backends' records without arms).
  narrowphase::UniformArms uniform_arms(real radius) const {
    const narrowphase::PairCoefficients& c = pair_coefficients.front();
    return {radius, c.friction, c.rolling_friction};
  }
  real substep() const { return static_cast<real>(dt / substeps); }
  // The gravity kick before the contacts (h, or h/2 for velocity Verlet) and after the drift (0 or h/2).
  real first_kick(real h) const { return verlet ? h / 2 : h; }
  real second_kick(real h) const { return verlet ? h / 2 : real(0); }
  // Velocity Verlet with a second kick that changes something: the substep
  // ends with the closing solve (StepBackend::close_velocities).
  bool closing_solve() const { return verlet && (gravity || drag); }
  // The substep the contact test looks ahead (0 without speculative contacts).
  real lookahead(real h) const { return speculative ? h : real(0); }
};

StepModel compile_step_model(const scene::Scene& scene, broadphase::Algorithm algorithm);

// Mixing rule for a material pair (documented in docs/solver.md): the
// geometric mean of each coefficient, so a pair of equal materials keeps its
// values and a zero on either side gives zero.
narrowphase::PairCoefficients mix_materials(const scene::Material& a, const scene::Material& b);

}  // namespace marbles
