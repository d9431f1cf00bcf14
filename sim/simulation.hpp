// sim/simulation.hpp — the step pipeline, assembled once from the scene.
//
// One step advances dt in `substeps` substeps of h = dt / substeps:
//
//   for each substep:
//     apply body forces              gravity, air drag (if the scene lists them)
//     broad phase → candidate pairs  spatial subdivision (if `collisions`)
//     narrow phase → contacts        sphere–sphere (`collisions`), sphere–wall (`walls`)
//     warm start from last substep   impulses of persisting contacts
//     solve contacts with impulses   friction / rolling / restitution as enabled
//     integrate positions            x += h v
//     project positions              remove overlap without adding energy
//
// Effects the scene does not name are not part of the pipeline at all.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "core/walls.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contact_math.hpp"
#include "narrowphase/solver.hpp"
#include "sim/world.hpp"

namespace marbles {

namespace scene {
struct Scene;
struct Material;
}

struct StepCounters {
  std::uint64_t candidate_pairs = 0;  // summed over substeps
  std::uint64_t contacts = 0;         // summed over substeps
};

class Simulation {
 public:
  // `backend` picks the broad phase; auto-selection happens in the caller.
  Simulation(const scene::Scene& scene, World world, broadphase::Backend backend,
             broadphase::Algorithm algorithm = broadphase::kDefaultCpuAlgorithm);

  // Advances one step (dt).
  void step();

  const World& world() const { return m_world; }
  const Walls& walls() const { return m_walls; }
  double time() const { return m_time; }
  std::uint64_t steps() const { return m_steps; }
  double dt() const { return m_dt; }
  int substeps() const { return m_substeps; }
  const StepCounters& last_step() const { return m_last; }
  // Direct access to the state, for tests and tools that edit it between steps.
  World& edit_world() { return m_world; }
  // The contacts of the last substep (solver order), for diagnostics and tests.
  const std::vector<narrowphase::Contact>& contacts() const { return m_contacts; }
  const broadphase::BroadPhase* broad_phase() const { return m_broadphase.get(); }

  // The stages this scene's pipeline runs, one per line.
  std::string describe_pipeline() const;

 private:
  void substep(real h);
  void find_contacts(real h);

  World m_world;
  Walls m_walls;
  std::vector<narrowphase::WallShape> m_wall_shapes;
  std::vector<narrowphase::PairCoefficients> m_pair_coefficients;
  narrowphase::PairTable m_pair_table;
  std::unique_ptr<broadphase::BroadPhase> m_broadphase;
  narrowphase::ContactSolver m_solver;

  // The pipeline (fixed at construction).
  bool m_gravity = false;
  bool m_drag = false;
  real m_drag_linear = 0, m_drag_quadratic = 0;
  bool m_collisions = false;
  bool m_wall_contacts = false;
  Vec3 m_g;

  // Per-substep buffers, reused.
  std::vector<real> m_bound_radius;  // m, radius + travel: what the broad phase sees
  std::vector<broadphase::Pair> m_pairs;
  std::vector<narrowphase::Contact> m_contacts;
  narrowphase::ContactCache m_cache;

  double m_dt = 0;
  int m_substeps = 1;
  double m_time = 0;
  std::uint64_t m_steps = 0;
  StepCounters m_last;
};

// Mixing rule for a material pair (documented in docs/solver.md): the
// geometric mean of each coefficient, so a pair of equal materials keeps its
// values and a zero on either side gives zero.
narrowphase::PairCoefficients mix_materials(const scene::Material& a, const scene::Material& b);

}  // namespace marbles
