#include "sim/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "integrator/symplectic_euler.hpp"
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
  for (const scene::WallSpec& w : scene.walls) {
    const std::uint32_t material = scene.material_index(w.material, w.where, "walls.material");
    switch (w.kind) {
      case scene::WallSpec::Kind::plane:
        walls.planes.push_back({w.point, w.normal, material, w.velocity});
        break;
      case scene::WallSpec::Kind::box:
        walls.boxes.push_back({w.lo, w.hi, material, w.velocity});
        break;
      case scene::WallSpec::Kind::cylinder:
        walls.cylinders.push_back({w.base, w.axis, static_cast<real>(w.radius), static_cast<real>(w.length), w.inside,
                                   static_cast<real>(w.angular_velocity), material});
        break;
      case scene::WallSpec::Kind::sphere:
        walls.spheres.push_back({w.centre, static_cast<real>(w.radius), material, w.velocity});
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
    for (std::size_t b = 0; b < nm; ++b) {
      table[a * nm + b] = mix_materials(scene.materials[a], scene.materials[b]);
    }
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
  s.restitution = scene.has(scene::Effect::restitution);
  s.friction = scene.has(scene::Effect::friction);
  s.rolling = scene.has(scene::Effect::rolling_resistance);
  // Approaches slower than what gravity adds in a few substeps do not bounce,
  // so a ball comes to rest instead of hopping forever.
  const double h = scene.time.dt / scene.time.substeps;
  const double g = scene.has(scene::Effect::gravity) ? length(scene.gravity) : 0.0;
  s.rest_speed = static_cast<real>(std::max(1e-3, 4.0 * g * h));
  return s;
}

}  // namespace

Simulation::Simulation(const scene::Scene& scene, World world, broadphase::Backend backend,
                       broadphase::Algorithm algorithm)
    : m_world(std::move(world)),
      m_walls(make_walls(scene)),
      m_wall_shapes(narrowphase::wall_shapes(m_walls)),
      m_pair_coefficients(pair_coefficients(scene)),
      m_solver(solver_settings(scene)),
      m_gravity(scene.has(scene::Effect::gravity)),
      m_drag(scene.has(scene::Effect::drag)),
      m_drag_linear(static_cast<real>(scene.drag)),
      m_drag_quadratic(static_cast<real>(scene.drag_quadratic)),
      m_collisions(scene.has(scene::Effect::collisions)),
      m_wall_contacts(scene.has(scene::Effect::walls) && !m_walls.empty()),
      m_g(scene.gravity),
      m_dt(scene.time.dt),
      m_substeps(scene.time.substeps) {
  m_pair_table = {m_pair_coefficients.data(), static_cast<std::uint32_t>(scene.materials.size())};
  if (m_collisions)
    m_broadphase = backend == broadphase::Backend::cuda ? broadphase::make_subdivision_cuda(algorithm)
                                                        : broadphase::make_subdivision_cpu(algorithm);
}

std::string Simulation::describe_pipeline() const {
  std::ostringstream out;
  const narrowphase::SolverSettings& s = m_solver.settings();
  out << "pipeline (" << m_substeps << " substep" << (m_substeps > 1 ? "s" : "") << " of h = " << m_dt / m_substeps
      << " s per step, " << kRealName << "):\n";
  if (m_gravity) out << "  body forces    gravity (" << m_g.x << ", " << m_g.y << ", " << m_g.z << ") m/s^2\n";
  if (m_drag) out << "  body forces    air drag (linear " << m_drag_linear << " 1/s, quadratic " << m_drag_quadratic << " 1/m)\n";
  if (m_collisions) out << "  broad phase    " << m_broadphase->name() << "\n";
  if (m_collisions) out << "  narrow phase   sphere-sphere\n";
  if (m_wall_contacts)
    out << "  narrow phase   sphere-wall (" << m_walls.planes.size() << " plane(s), " << m_walls.boxes.size()
        << " box(es), " << m_walls.cylinders.size() << " cylinder(s), " << m_walls.spheres.size() << " sphere(s))\n";
  if (m_collisions || m_wall_contacts) {
    out << "  contact solver " << s.iterations << " sequential-impulse sweeps: normal";
    if (s.friction) out << " + friction";
    if (s.rolling) out << " + rolling resistance";
    out << (s.restitution ? "; impacts with restitution" : "; plastic impacts (no restitution)")
        << (s.warm_start ? "; warm start" : "") << "\n";
  }
  out << "  integrate      symplectic Euler\n";
  if (m_collisions || m_wall_contacts) out << "  project        positions (overlap beyond slop)\n";
  return out.str();
}

void Simulation::step() {
  m_last = {};
  const real h = static_cast<real>(m_dt / m_substeps);
  for (int k = 0; k < m_substeps; ++k) substep(h);
  ++m_steps;
  m_time = m_steps * m_dt;
}

void Simulation::substep(real h) {
  const BodiesView bodies = m_world.view();

  if (m_gravity) integrator::apply_gravity(bodies, m_g, h);
  if (m_drag) integrator::apply_drag(bodies, m_drag_linear, m_drag_quadratic, h);

  m_contacts.clear();
  if (m_collisions || m_wall_contacts) find_contacts(h);
  if (!m_contacts.empty()) {
    m_cache.restore(m_contacts, bodies, m_gravity ? length(m_g) * h : real(0));
    m_solver.solve_velocities(m_contacts, bodies, h);
  }
  m_cache.store(m_contacts);  // also when empty: no stale impulses survive a contact-free substep

  integrator::integrate_positions(bodies, h);
  narrowphase::advance_walls(m_wall_shapes, h);

  if (!m_contacts.empty()) m_solver.project_positions(m_contacts, bodies, m_wall_shapes);
  m_last.contacts += m_contacts.size();
}

// Swept bounds: the broad phase sees each sphere grown by its travel |v| h
// within the substep, so every pair that can meet in this substep is a
// candidate, however fast; the narrow phase keeps those that overlap or close
// their gap at the current approach speed (speculative contacts), so nothing
// tunnels.
void Simulation::find_contacts(real h) {
  const BodiesView bodies = m_world.view();
  const std::size_t n = m_world.size();
  if (m_collisions) {
    m_bound_radius.resize(n);
    for (std::size_t i = 0; i < n; ++i) m_bound_radius[i] = bodies.radius[i] + length(bodies.velocity[i]) * h;
    m_broadphase->find_pairs({bodies.position, m_bound_radius.data(), n}, 0, m_pairs);
    m_last.candidate_pairs += m_pairs.size();
    narrowphase::sphere_contacts(bodies, m_pairs.data(), m_pairs.size(), m_pair_table, h, m_contacts);
  }
  if (m_wall_contacts) narrowphase::wall_contacts(bodies, m_wall_shapes, m_pair_table, h, m_contacts);
}

}  // namespace marbles
