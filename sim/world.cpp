#include "sim/world.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "broadphase/grid.hpp"
#include "broadphase/home_cell_math.hpp"
#include "integrator/integrator_math.hpp"
#include "core/error.hpp"
#include "core/format.hpp"
#include "core/radix_sort.hpp"

#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/settings_check.hpp"

namespace marbles {

World permuted(const World& w, const std::vector<std::uint32_t>& order) {
  World p;
  p.position = gathered(w.position.data(), order);
  p.velocity = gathered(w.velocity.data(), order);
  p.angular_velocity = gathered(w.angular_velocity.data(), order);
  p.radius = gathered(w.radius.data(), order);
  p.inv_mass = gathered(w.inv_mass.data(), order);
  p.inv_inertia = gathered(w.inv_inertia.data(), order);
  p.material = gathered(w.material.data(), order);
  return p;
}

bool is_identity(const std::vector<std::uint32_t>& order) {
  for (std::size_t i = 0; i < order.size(); ++i)
    if (order[i] != i) return false;
  return true;
}

std::vector<std::uint32_t> inverse_of(const std::vector<std::uint32_t>& order) {
  std::vector<std::uint32_t> inverse;
  inverse_into(order, inverse);
  return inverse;
}

void inverse_into(const std::vector<std::uint32_t>& order, std::vector<std::uint32_t>& inverse) {
  const auto n = static_cast<std::ptrdiff_t>(order.size());
  std::uint32_t largest = 0;
#pragma omp parallel for schedule(static) reduction(max : largest) if (n > 65536)
  for (std::ptrdiff_t i = 0; i < n; ++i) largest = std::max(largest, order[i]);
  if (n > 0 && largest >= order.size()) throw std::out_of_range("inverse_of: an index past the order's length");
  inverse.assign(order.size(), 0);
  std::uint32_t* out = inverse.data();
#pragma omp parallel for schedule(static) if (n > 65536)
  for (std::ptrdiff_t i = 0; i < n; ++i) out[order[i]] = static_cast<std::uint32_t>(i);
}

std::vector<std::uint32_t> cell_order(const Vec3* position, const real* radius, std::size_t n) {
  std::vector<std::uint32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::uint32_t>(i);
  if (n == 0) return order;
  const broadphase::HomeGridChoice choice = broadphase::choose_home_grid(broadphase::bounds_of({position, radius, n}), 0);
  if (choice.width == broadphase::KeyWidth::too_wide) return order;
  std::vector<std::uint64_t> key(n), scratch_keys;
  for (std::size_t i = 0; i < n; ++i)
    key[i] = broadphase::home_key(broadphase::home_cell(position[i], choice.grid), choice.grid);
  std::vector<std::uint32_t> scratch_order;
  radix_sort_pairs(key, order, choice.grid.key_bits, scratch_keys, scratch_order);  // stable: a cell's spheres in order
  return order;
}

double World::kinetic_energy() const {
  double e = 0;
  for (std::size_t i = 0; i < size(); ++i) {
    if (inv_mass[i] <= 0) continue;
    e += 0.5 * length_squared(velocity[i]) / inv_mass[i];
    e += 0.5 * length_squared(angular_velocity[i]) / inv_inertia[i];
  }
  return e;
}

World::Motion World::motion() const {
  Motion e;
  for (std::size_t i = 0; i < size(); ++i) {
    if (!(inv_mass[i] > 0)) continue;
    e.translational += 0.5 * (1.0 / inv_mass[i]) * length_squared(velocity[i]);
    if (inv_inertia[i] > 0) e.rotational += 0.5 * length_squared(angular_velocity[i]) / inv_inertia[i];
  }
  e.max_speed = max_speed();
  return e;
}

void World::momentum(double out[3]) const {
  out[0] = out[1] = out[2] = 0;
  for (std::size_t i = 0; i < size(); ++i) {
    if (inv_mass[i] <= 0) continue;
    const double m = 1.0 / inv_mass[i];
    out[0] += m * velocity[i].x;
    out[1] += m * velocity[i].y;
    out[2] += m * velocity[i].z;
  }
}

real World::max_speed() const {
  real v2 = 0;
  for (const Vec3& v : velocity) v2 = std::max(v2, length_squared(v));
  return std::sqrt(v2);
}

std::size_t World::first_out_of_range() const {
  for (std::size_t i = 0; i < size(); ++i)
    if (!integrator::body_in_range(position[i], velocity[i], angular_velocity[i])) return i;
  return size();
}

std::size_t World::first_non_finite() const {
  for (std::size_t i = 0; i < size(); ++i)
    if (!is_finite(position[i]) || !is_finite(velocity[i]) || !is_finite(angular_velocity[i])) return i;
  return size();
}

namespace {

// A sphere's mass and moment of inertia, and the contact impulses they make
// at the scene's speeds, within the run's precision:
// - Inverse mass and inertia from the smallest normal number up to 1/8 of
//   the largest: an effective mass sums two of each (1/m_a + 1/m_b + r_a^2/I_a
//   + r_b^2/I_b = 3.5 (1/m_a + 1/m_b): narrowphase/contact_math.hpp), which
//   past the range is inf, and the pair's friction or rolling resistance 0.
// - An impulse (1 + e) m_n |v_n| is at most 4 u M, u the fastest speed
//   (fastest_speed, and the fastest spin's surface speed), M the movable
//   spheres' mass (a column that lands rests on one contact), and its moment
//   about a centre r times that (apply_impulse); 16 u M max(1 m, r) within
//   the range leaves a factor 4 for speeds the run reaches past the
//   estimate. Past it an impulse is inf, and inf times a normal's zero
//   component NaN: the run ended "non-finite state" (exit 1).
// - The clamps to the friction cone square an impulse and its limit
//   (clamp_length): with friction, 16 u M max(1, mu) squared within the
//   range; with rolling resistance, 16 u M max(1 m, r) max(1, mu_r). Past it
//   friction went through unbounded (spheres of 1e30 kg with mu = 0.05 slid
//   as with 0.5). The twist's clamp squares nothing.
// - The kinetic energy, at most M u^2 / 2, is summed in double (World::motion,
//   the watchdog's figures), in float runs too; past double's range it was
//   inf (null in summary.json). Held to the same factor 16.
constexpr double kHeadroom = 16;

// An inverse mass or inertia the step's arithmetic takes: normal, and with
// room for the sums and products of a few of them.
bool usable_inverse(real v) {
  return v >= std::numeric_limits<real>::min() && v <= std::numeric_limits<real>::max() / 8;
}

}  // namespace

bool masses_as_made(real radius, real inv_mass, real inv_inertia) {
  if (inv_mass == 0 && inv_inertia == 0) return true;
  if (!usable_inverse(inv_mass) || !usable_inverse(inv_inertia)) return false;
  const double r = radius;
  const double expected = double(inv_mass) / (0.4 * r * r);  // 1 / (2/5 m r^2)
  return std::isfinite(expected) && std::abs(double(inv_inertia) - expected) <= 1e-4 * expected;
}

World make_world(const scene::Scene& scene, const scene::GeneratedParticles& particles) {
  World w;
  const std::size_t n = particles.size();
  w.position = particles.position;
  w.velocity = particles.velocity;
  w.velocity.resize(n);
  w.angular_velocity = particles.angular_velocity;
  w.angular_velocity.resize(n);
  w.radius = particles.radius;
  w.material = particles.material;
  w.inv_mass.resize(n);
  w.inv_inertia.resize(n);
  // Sphere i refused, named by the block it came from, where the particles say (else the scene's particles).
  const auto refuse = [&](std::size_t i, const std::string& why) {
    const auto& ends = particles.block_end;
    const auto b = static_cast<std::size_t>(std::upper_bound(ends.begin(), ends.end(), i) - ends.begin());
    const bool known = b < ends.size() && b < scene.particles.size();
    const std::size_t first = known && b > 0 ? ends[b - 1] : 0;
    throw InputError(known ? scene.particles[b].where : SourceLocation{scene.path, 0, 0},
                     known ? "particles[" + std::to_string(b) + "]" : "particles",
                     "sphere " + std::to_string(known ? i - first : i) + (known ? " of the block" : "") + " (radius " +
                         significant(w.radius[i], 6) + " m, density " +
                         significant(scene.materials.at(w.material[i]).density, 6) + " kg/m^3): " + why);
  };
  const double most = std::numeric_limits<real>::max();
  double total = 0, reach = 1, spin = 0;  // movable mass, max(1 m, largest radius), fastest surface speed of a spin
  std::size_t heaviest = n;
  double heaviest_mass = 0;
  for (std::size_t i = 0; i < n; ++i) {
    reach = std::max(reach, double(w.radius[i]));  // a fixed sphere's too: its spin takes 0 x the moment
    if (i < particles.fixed.size() && particles.fixed[i]) {  // collides, never moves
      w.inv_mass[i] = 0;
      w.inv_inertia[i] = 0;
      continue;
    }
    const double r = w.radius[i];
    const double mass = scene.materials.at(w.material[i]).density * 4.0 / 3.0 * std::numbers::pi * r * r * r;
    w.inv_mass[i] = static_cast<real>(1.0 / mass);
    w.inv_inertia[i] = static_cast<real>(1.0 / (0.4 * mass * r * r));
    if (!usable_inverse(w.inv_mass[i]) || !usable_inverse(w.inv_inertia[i]))
      refuse(i, "its mass " + significant(mass, 6) + " kg or moment of inertia is out of range for " + kRealName +
                    " precision");
    total += mass;
    spin = std::max(spin, double(length(w.angular_velocity[i])) * r);
    if (mass > heaviest_mass) heaviest = i, heaviest_mass = mass;
  }
  const bool contacts = scene.has(scene::Effect::collisions) || scene.has(scene::Effect::walls);
  // The friction and rolling clamps square an impulse and its limit (clamp_length): the sliding one
  // 4 M u max(1, mu) at most, the rolling one (an angular impulse) 4 M u max(1 m, r) max(1, mu_r).
  double mu = 0, mu_rolling = 0;
  for (const scene::Material& m : scene.materials)
    mu = std::max(mu, m.friction), mu_rolling = std::max(mu_rolling, m.rolling_friction);
  for (const scene::ContactPairSpec& p : scene.contact_pairs)
    mu = std::max(mu, p.friction), mu_rolling = std::max(mu_rolling, p.rolling_friction);
  // What speeds up to `speed` would take out of range; nothing where nothing moves.
  const auto past_at = [&](double speed) -> std::string {
    const double impulse = kHeadroom * total * reach * speed;       // N s, and N m s about a centre
    const double energy = kHeadroom * 0.5 * total * speed * speed;  // J, summed in double in either precision
    const double squared = std::max(scene.has(scene::Effect::friction) ? impulse / reach * std::max(1.0, mu) : 0.0,
                                    scene.has(scene::Effect::rolling_resistance)
                                        ? impulse * std::max(1.0, mu_rolling) : 0.0);
    if (speed > 0 && contacts && !(impulse <= most))
      return "contact impulses out of range for " + std::string(kRealName) + " precision (16 x mass x max(1 m, "
             "largest radius) x speed = " + significant(impulse, 3) + ", more than " + significant(most, 3) + ")";
    if (speed > 0 && contacts && !(squared <= std::sqrt(most)))
      return "friction impulses whose squares are out of range for " + std::string(kRealName) +
             " precision (the clamp to the friction cone squares them: 16 x mass x speed x max(1, the largest "
             "coefficient), times max(1 m, largest radius) for rolling resistance, = " + significant(squared, 3) +
             ", more than " + significant(std::sqrt(most), 3) + ")";
    if (speed > 0 && !(energy <= std::numeric_limits<double>::max()))
      return "a kinetic energy out of range of its sums in double (16 x mass x speed^2 / 2 is more than " +
             significant(std::numeric_limits<double>::max(), 3) + " J)";
    return {};
  };
  const double speed = fastest_speed(scene, particles) + spin;
  // The fastest sphere's travel in a substep is its reach in the contact
  // search: past the precision's range (with room for its sums) the first
  // substep meets no finite bound.
  const double travel = speed * (scene.time.dt / scene.time.substeps);
  if (!(travel <= scene::kSubstepRoom))
    scene::refuse_substep_motion(scene,
                          "moves the fastest sphere, at up to " + significant(speed, 6) +
                              " m/s (the fast-motion warning's estimate, and the fastest spin's surface speed),",
                          travel);
  const std::string past = past_at(speed);
  // Where a wall's motion sets the speed, and the scene would pass without
  // it, the wall's speed is what to change.
  const auto wall = past.empty() ? std::nullopt : speeding_wall(scene, particles);
  if (wall && past_at(fastest_speed(scene, particles, wall->index) + spin).empty())
    throw InputError(scene.walls[wall->index].where, wall->key,
                     "too fast for the spheres' mass: it gives spheres up to " + significant(wall->push, 6) +
                         " m/s (twice a moving wall's speed, or a spinning wall's surface speed), and the movable "
                         "spheres' mass, " + significant(total, 6) + " kg in all, at " + significant(speed, 6) +
                         " m/s makes " + past +
                         (sizeof(real) == 4 ? "; lower the wall's speed, or set solver.precision: double" : "; lower "
                                                                                                             "the wall's speed"));
  if (heaviest < n && !past.empty())
    refuse(heaviest, "too heavy for the scene's speeds: the movable spheres' mass, " + significant(total, 6) +
                         " kg in all (this sphere the heaviest), at up to " + significant(speed, 6) +
                         " m/s (the fast-motion warning's estimate of the fastest sphere, and the fastest spin's "
                         "surface speed) makes " + past +
                         (sizeof(real) == 4 ? "; set solver.precision: double (or --precision double), or lower the "
                                              "density" : "; lower the density"));
  return w;
}

}  // namespace marbles
