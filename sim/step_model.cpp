#include "sim/step_model.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "narrowphase/contacts.hpp"
#include "sim/scene.hpp"

namespace marbles {

narrowphase::PairCoefficients mix_materials(const scene::Material& a, const scene::Material& b) {
  auto mean = [](double x, double y) { return static_cast<real>(std::sqrt(x * y)); };
  return {mean(a.restitution, b.restitution), mean(a.friction, b.friction),
          mean(a.rolling_friction, b.rolling_friction), mean(a.twisting_friction, b.twisting_friction)};
}

namespace {

Walls make_walls(const scene::Scene& scene) {
  Walls walls;
  for (std::size_t k = 0; k < scene.walls.size(); ++k) {
    const scene::WallSpec& w = scene.walls[k];
    const std::uint32_t material = scene.material_index(w.material, w.where, "walls.material");
    const auto index = static_cast<std::uint32_t>(k);
    switch (w.kind) {
      case scene::WallSpec::Kind::plane:
        walls.planes.push_back({w.point, w.normal, material, w.velocity, index});
        break;
      case scene::WallSpec::Kind::box:
        walls.boxes.push_back({w.lo, w.hi, material, w.velocity, index});
        break;
      case scene::WallSpec::Kind::cylinder:
        walls.cylinders.push_back({w.base, w.axis, static_cast<real>(w.radius), static_cast<real>(w.length), w.inside,
                                   static_cast<real>(w.angular_velocity), material, index});
        break;
      case scene::WallSpec::Kind::sphere:
        walls.spheres.push_back({w.centre, static_cast<real>(w.radius), material, w.velocity, index});
        break;
    }
  }
  return walls;
}

// Coefficients of every material pair: the mixing rule, then the scene's
// explicit contact_pairs (each coefficient it gives replaces the mixed one).
std::vector<narrowphase::PairCoefficients> pair_coefficients(const scene::Scene& scene) {
  const std::size_t nm = scene.materials.size();
  std::vector<narrowphase::PairCoefficients> table(nm * nm);
  for (std::size_t a = 0; a < nm; ++a)
    for (std::size_t b = 0; b < nm; ++b) table[a * nm + b] = mix_materials(scene.materials[a], scene.materials[b]);
  for (const scene::ContactPairSpec& p : scene.contact_pairs) {
    const std::uint32_t a = scene.material_index(p.first, p.where, "contact_pairs");
    const std::uint32_t b = scene.material_index(p.second, p.where, "contact_pairs");
    for (narrowphase::PairCoefficients* c : {&table[a * nm + b], &table[b * nm + a]}) {
      if (p.restitution >= 0) c->restitution = static_cast<real>(p.restitution);
      if (p.friction >= 0) c->friction = static_cast<real>(p.friction);
      if (p.rolling_friction >= 0) c->rolling_friction = static_cast<real>(p.rolling_friction);
      if (p.twisting_friction >= 0) c->twisting_friction = static_cast<real>(p.twisting_friction);
    }
  }
  return table;
}

narrowphase::SolverSettings solver_settings(const scene::Scene& scene) {
  narrowphase::SolverSettings s;
  s.iterations = scene.solver.iterations;
  s.closing_iterations = scene.solver.closing_iterations;
  s.impact_passes = scene.solver.impact_passes;
  s.restitution = scene.has(scene::Effect::restitution);
  s.friction = scene.has(scene::Effect::friction);
  s.rolling = scene.has(scene::Effect::rolling_resistance);
  // Approaches slower than what gravity adds in a few substeps do not bounce,
  // so a ball comes to rest instead of hopping forever.
  const double h = scene.time.dt / scene.time.substeps;
  const double g = scene.has(scene::Effect::gravity) ? length(scene.gravity) : 0.0;
  s.rest_speed = static_cast<real>(std::max(1e-3, 4.0 * g * h));
  if (scene.solver.integrator == "velocity_verlet" && scene.has(scene::Effect::gravity)) s.wall_accel = scene.gravity;
  return s;
}

}  // namespace

StepModel compile_step_model(const scene::Scene& scene, broadphase::Algorithm algorithm) {
  StepModel m;
  m.walls = make_walls(scene);
  m.wall_shapes = narrowphase::wall_shapes(m.walls);
  m.pair_coefficients = pair_coefficients(scene);
  m.material_count = static_cast<std::uint32_t>(scene.materials.size());
  m.uniform_pairs = std::all_of(m.pair_coefficients.begin(), m.pair_coefficients.end(),
                                [&](const narrowphase::PairCoefficients& c) {
                                  const narrowphase::PairCoefficients& first = m.pair_coefficients.front();
                                  return std::memcmp(&c.friction, &first.friction, sizeof(real)) == 0 &&
                                         std::memcmp(&c.rolling_friction, &first.rolling_friction, sizeof(real)) == 0;
                                });
  m.solver = solver_settings(scene);
  m.gravity = scene.has(scene::Effect::gravity);
  m.drag = scene.has(scene::Effect::drag);
  m.drag_linear = static_cast<real>(scene.drag);
  m.drag_quadratic = static_cast<real>(scene.drag_quadratic);
  m.collisions = scene.has(scene::Effect::collisions);
  m.wall_contacts = scene.has(scene::Effect::walls) && !m.walls.empty();
  m.moving_walls = m.wall_contacts && !std::all_of(m.wall_shapes.begin(), m.wall_shapes.end(),
                                                  narrowphase::surface_at_rest);
  m.speculative = scene.solver.speculative;
  m.renumber_every = static_cast<std::uint64_t>(scene.solver.renumber);
  m.verlet = scene.solver.integrator == "velocity_verlet";
  m.g = scene.gravity;
  m.dt = scene.time.dt;
  m.substeps = scene.time.substeps;
  m.algorithm = algorithm;
  return m;
}

}  // namespace marbles
