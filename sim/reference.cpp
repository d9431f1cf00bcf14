#include "sim/reference.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace marbles {

namespace {

using render::D3;
using render::d3;
using Kind = scene::ReferenceSpec::Kind;

bool single_ball(Kind k) {
  return k == Kind::rebound_heights || k == Kind::time_to_rest || k == Kind::incline || k == Kind::slide_to_roll ||
         k == Kind::oblique_rebound;
}

double relative(double measured, double expected) {
  return std::abs(measured - expected) / std::max(std::abs(expected), 1e-300);
}

// A rebound that never came counts as 100 %.
constexpr double kMissing = 1.0;

D3 momentum_of(const World& w) {
  double p[3];
  w.momentum(p);
  return {p[0], p[1], p[2]};
}

// Centre of mass (3), radius of gyration about it and mean radius: what the
// study compares between a setting and its finest one.
std::vector<double> shape_of(const World& w) {
  D3 c{};
  double rg = 0, rmean = 0;
  const double n = std::max<double>(1, static_cast<double>(w.size()));
  for (std::size_t i = 0; i < w.size(); ++i) c = c + (1 / n) * d3(w.position[i]);
  for (std::size_t i = 0; i < w.size(); ++i) {
    const D3 d = d3(w.position[i]) - c;
    rg += dot(d, d) / n;
    rmean += w.radius[i] / n;
  }
  return {c.x, c.y, c.z, std::sqrt(rg), rmean};
}

// The largest value of the parabola through three equally spaced samples
// (the middle one the largest).
double parabola_vertex(double before, double middle, double after) {
  const double curvature = before - 2 * middle + after;
  if (!(curvature < 0)) return middle;
  const double d = before - after;
  return middle - d * d / (8 * curvature);
}

}  // namespace

ReferenceProbe::ReferenceProbe(const scene::Scene& scene, const World& initial) : m_spec(scene.reference) {
  const scene::ReferenceSpec& s = m_spec;
  const std::string key = "reference." + std::string(scene::reference_name(s.kind));
  const bool gravity = scene.has(scene::Effect::gravity) && length(scene.gravity) > 0;
  m_g = gravity ? static_cast<double>(length(scene.gravity)) : 0.0;
  m_down = gravity ? render::normalize(d3(scene.gravity)) : D3{0, 0, -1};
  if (single_ball(s.kind)) {
    if (s.sphere >= initial.size())
      throw InputError(s.where, key + ".sphere",
                       "sphere " + std::to_string(s.sphere) + " does not exist (the scene has " +
                           std::to_string(initial.size()) + ")");
    m_x0 = d3(initial.position[s.sphere]);
    m_v0 = d3(initial.velocity[s.sphere]);
  }
  const bool needs_gravity = s.kind == Kind::rebound_heights || s.kind == Kind::time_to_rest ||
                             s.kind == Kind::incline || s.kind == Kind::slide_to_roll;
  if (needs_gravity && !gravity) throw InputError(s.where, key, "needs the gravity effect and a non-zero gravity");
  const bool needs_none = s.kind == Kind::oblique_rebound || s.kind == Kind::kinetic_energy || s.kind == Kind::momentum;
  if (needs_none && gravity) throw InputError(s.where, key, "holds only without gravity: remove the gravity effect");
  if (s.kind == Kind::momentum && scene.has(scene::Effect::walls) && !scene.walls.empty())
    throw InputError(s.where, key, "holds only without walls (they take momentum)");
  if (s.kind == Kind::oblique_rebound) {
    const auto plane = std::find_if(scene.walls.begin(), scene.walls.end(),
                                    [](const scene::WallSpec& w) { return w.kind == scene::WallSpec::Kind::plane; });
    if (plane == scene.walls.end()) throw InputError(s.where, key, "needs a plane wall (the first plane is used)");
    m_plane_normal = render::normalize(d3(plane->normal));
    if (!(dot(m_v0, m_plane_normal) < 0)) throw InputError(s.where, key, "the ball must start moving towards the plane");
  }
  if (s.kind == Kind::rebound_heights || s.kind == Kind::time_to_rest) {
    const double up = -dot(m_v0, m_down);
    m_t_up = std::max(0.0, up) / m_g;
    m_h0 = height(initial) + std::max(0.0, up) * std::max(0.0, up) / (2 * m_g);
    if (!(m_h0 > 0)) throw InputError(s.where, key, "the ball must start above the floor");
  }
  m_e0 = initial.kinetic_energy();
  m_p0 = momentum_of(initial);
  for (std::size_t i = 0; i < initial.size(); ++i)
    if (initial.inv_mass[i] > 0) m_p_scale += length(initial.velocity[i]) / initial.inv_mass[i];
  if (s.kind == Kind::kinetic_energy && !(m_e0 > 0)) throw InputError(s.where, key, "the scene starts at rest");
  if (s.kind == Kind::momentum && !(m_p_scale > 0)) throw InputError(s.where, key, "the scene starts at rest");
  m_last_up = -dot(m_v0, m_down);
}

std::uint64_t ReferenceProbe::every(std::uint64_t total_steps) const {
  if (single_ball(m_spec.kind)) return 1;
  return std::max<std::uint64_t>(1, total_steps / 200);
}

double ReferenceProbe::height(const World& w) const {
  const std::uint32_t i = m_spec.sphere;
  return -dot(d3(w.position[i]), m_down) - m_spec.floor - w.radius[i];
}

double ReferenceProbe::up_speed(const World& w) const { return -dot(d3(w.velocity[m_spec.sphere]), m_down); }

void ReferenceProbe::sample(double time, const World& w) {
  switch (m_spec.kind) {
    case Kind::rebound_heights: {
      // After a bounce, the first sample lower than the one before ends the
      // rise: the apex is the vertex of the parabola through the last three
      // samples (exact for a sampled ballistic flight of either integrator).
      const double up = up_speed(w), z = height(w);
      if (m_last_up < 0 && up > 0) {
        m_rising = true;
        m_recent.clear();
      }
      if (m_rising) {
        m_recent.push_back(z);
        const std::size_t n = m_recent.size();
        if (n >= 2 && m_recent[n - 1] < m_recent[n - 2]) {
          m_apexes.push_back(n >= 3 ? parabola_vertex(m_recent[n - 3], m_recent[n - 2], m_recent[n - 1])
                                    : m_recent[n - 2]);
          m_rising = false;
        }
      }
      m_last_up = up;
      break;
    }
    case Kind::time_to_rest:
      if (height(w) > 1e-4 * m_h0) m_last_off_floor = time;
      break;
    case Kind::kinetic_energy: m_max_error = std::max(m_max_error, relative(w.kinetic_energy(), m_e0)); break;
    case Kind::momentum: m_max_error = std::max(m_max_error, norm(momentum_of(w) - m_p0) / m_p_scale); break;
    default: break;
  }
}

std::vector<double> ReferenceProbe::progress() const {
  std::vector<double> p{m_last_up, m_rising ? 1.0 : 0.0, m_last_off_floor, m_max_error,
                        static_cast<double>(m_apexes.size()), static_cast<double>(m_recent.size())};
  p.insert(p.end(), m_apexes.begin(), m_apexes.end());
  p.insert(p.end(), m_recent.begin(), m_recent.end());
  return p;
}

void ReferenceProbe::resume(const std::vector<double>& p) {
  if (p.size() < 6) return;  // a scene without a reference wrote none
  m_last_up = p[0];
  m_rising = p[1] != 0;
  m_last_off_floor = p[2];
  m_max_error = p[3];
  const auto apexes = static_cast<std::size_t>(p[4]), recent = static_cast<std::size_t>(p[5]);
  if (p.size() != 6 + apexes + recent) return;
  m_apexes.assign(p.begin() + 6, p.begin() + 6 + static_cast<std::ptrdiff_t>(apexes));
  m_recent.assign(p.begin() + 6 + static_cast<std::ptrdiff_t>(apexes), p.end());
}

ReferenceResult ReferenceProbe::finish(double time, const World& w) {
  sample(time, w);
  const scene::ReferenceSpec& s = m_spec;
  ReferenceResult r;
  r.kind = scene::reference_name(s.kind);
  switch (s.kind) {
    case Kind::none: break;
    case Kind::rebound_heights: {
      double e2k = 1;
      for (int k = 0; k < s.bounces; ++k) {
        e2k *= s.restitution * s.restitution;
        const double expected = m_h0 * e2k;
        r.expected.push_back(expected);
        const bool seen = k < static_cast<int>(m_apexes.size());
        if (seen) r.measured.push_back(m_apexes[k]);
        r.error = std::max(r.error, seen ? relative(m_apexes[k], expected) : kMissing);
      }
      r.note = "apex heights (m) of the first " + std::to_string(s.bounces) + " rebounds above the contact height";
      if (static_cast<int>(m_apexes.size()) < s.bounces)
        r.note += "; only " + std::to_string(m_apexes.size()) + " in the run (a missing one counts 100 %)";
      break;
    }
    case Kind::time_to_rest: {
      const double e = s.restitution;
      const double expected = m_t_up + std::sqrt(2 * m_h0 / m_g) * (1 + e) / (1 - e);
      r.expected = {expected};
      r.measured = {m_last_off_floor};
      r.error = relative(m_last_off_floor, expected);
      r.note = "time (s) until the ball stays within 1e-4 of its drop height of the floor";
      if (height(w) > 1e-4 * m_h0) {
        r.error = std::max(r.error, kMissing);
        r.note += "; still bouncing at the end of the run";
      }
      break;
    }
    case Kind::incline: {
      const double theta = s.angle * std::numbers::pi / 180;
      const bool rolls = s.friction >= 2.0 / 7.0 * std::tan(theta);
      const double expected =
          rolls ? 5.0 / 7.0 * m_g * std::sin(theta) : m_g * (std::sin(theta) - s.friction * std::cos(theta));
      const double travel = norm(d3(w.position[s.sphere]) - m_x0);
      const double measured = time > 0 ? 2 * travel / (time * time) : 0;
      r.expected = {expected};
      r.measured = {measured};
      r.error = relative(measured, expected);
      r.note = std::string("acceleration (m/s^2) down the slope from the distance travelled, ") +
               (rolls ? "rolling (mu >= 2/7 tan angle)" : "sliding (mu < 2/7 tan angle)");
      break;
    }
    case Kind::slide_to_roll: {
      const D3 v0 = m_v0 - dot(m_v0, m_down) * m_down;
      const double expected = 5.0 / 7.0 * norm(v0);
      const D3 v = d3(w.velocity[s.sphere]);
      const double measured = norm(v - dot(v, m_down) * m_down);
      r.expected = {expected};
      r.measured = {measured};
      r.error = relative(measured, expected);
      r.note = "final horizontal speed (m/s): 5/7 of the launch speed once rolling";
      break;
    }
    case Kind::oblique_rebound: {
      const D3 n = m_plane_normal;
      const double vn = -dot(m_v0, n);
      const double vt = norm(m_v0 + vn * n);
      const double e = s.restitution;
      const double slid = vt - s.friction * (1 + e) * vn;
      const double vt_expected = slid > 5.0 / 7.0 * vt ? slid : 5.0 / 7.0 * vt;
      const D3 v = d3(w.velocity[s.sphere]);
      const double vn_after = dot(v, n);
      const double vt_after = norm(v - vn_after * n);
      r.expected = {e * vn, vt_expected};
      r.measured = {vn_after, vt_after};
      r.error = std::max(std::abs(vn_after - e * vn) / vn, vt > 0 ? std::abs(vt_after - vt_expected) / vt : 0.0);
      r.note = "normal and tangential speed (m/s) after the impact, errors relative to the approach's";
      break;
    }
    case Kind::kinetic_energy:
      r.expected = {m_e0};
      r.measured = {w.kinetic_energy()};
      r.error = m_max_error;
      r.note = "kinetic energy (J); the error is the largest relative drift over the run";
      break;
    case Kind::momentum: {
      const D3 p = momentum_of(w);
      r.expected = {m_p0.x, m_p0.y, m_p0.z};
      r.measured = {p.x, p.y, p.z};
      r.error = m_max_error;
      r.note = "total momentum (kg m/s); the error is its largest change over the run relative to sum m|v| at the start";
      break;
    }
    case Kind::finest:
      r.measured = shape_of(w);
      r.error = std::numeric_limits<double>::quiet_NaN();
      r.note = "centre of mass (m), radius of gyration (m) and mean radius at the end; the study compares them "
               "with its finest setting";
      break;
  }
  return r;
}

}  // namespace marbles
