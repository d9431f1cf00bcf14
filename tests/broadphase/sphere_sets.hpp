// tests/broadphase/sphere_sets.hpp — random and adversarial sphere sets for
// the broad-phase tests (CPU and GPU). Every set is drawn fresh from a seed.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "core/spheres.hpp"

namespace marbles::broadphase::testing {

enum class SetKind { mono, poly20, clustered, on_boundaries, far_away, negative, coincident, outlier, count };

inline const char* set_name(SetKind k) {
  switch (k) {
    case SetKind::mono: return "mono";
    case SetKind::poly20: return "poly20";
    case SetKind::clustered: return "clustered";
    case SetKind::on_boundaries: return "on_boundaries";
    case SetKind::far_away: return "far_away";
    case SetKind::negative: return "negative";
    case SetKind::coincident: return "coincident";
    case SetKind::outlier: return "outlier";
    default: return "?";
  }
}

struct SphereSet {
  std::vector<Vec3> centre;
  std::vector<real> radius;
  SpheresIn view() const { return {centre.data(), radius.data(), centre.size()}; }
};

// Side of a cube holding n spheres of mean volume `mean_volume` at volume fraction vf.
inline double box_side(std::size_t n, double mean_volume, double vf) {
  return std::cbrt(static_cast<double>(n) * mean_volume / vf);
}

inline SphereSet make_set(SetKind kind, std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const double pi = 3.14159265358979;
  SphereSet s;
  s.centre.resize(n);
  s.radius.resize(n);
  const double vf = 0.05 + 0.35 * u01(rng);  // dense enough for many pairs
  auto uniform_box = [&](double side, double offset, double r) {
    for (std::size_t i = 0; i < n; ++i) {
      s.centre[i] = Vec3(real(offset + side * u01(rng)), real(offset + side * u01(rng)), real(offset + side * u01(rng)));
      s.radius[i] = real(r);
    }
  };
  switch (kind) {
    case SetKind::mono:
    case SetKind::count: {
      const double r = 0.1 + u01(rng);
      uniform_box(box_side(n, 4.0 / 3.0 * pi * r * r * r, vf), 0.0, r);
      break;
    }
    case SetKind::poly20: {
      // radii log-uniform over 1:20; box from the mean volume
      double mean_v = 0;
      for (std::size_t i = 0; i < n; ++i) {
        s.radius[i] = real(0.05 * std::exp(std::log(20.0) * u01(rng)));
        mean_v += 4.0 / 3.0 * pi * std::pow(double(s.radius[i]), 3) / double(n);
      }
      const double side = box_side(n, mean_v, vf);
      for (std::size_t i = 0; i < n; ++i)
        s.centre[i] = Vec3(real(side * u01(rng)), real(side * u01(rng)), real(side * u01(rng)));
      break;
    }
    case SetKind::clustered: {
      const double r = 0.5;
      const std::size_t clusters = 1 + n / 200;
      std::vector<Vec3> at(clusters);
      const double side = box_side(n, 4.0 / 3.0 * pi * r * r * r, 0.02);
      for (auto& c : at) c = Vec3(real(side * u01(rng)), real(side * u01(rng)), real(side * u01(rng)));
      std::normal_distribution<double> g(0.0, 2.0 * r);
      for (std::size_t i = 0; i < n; ++i) {
        const Vec3 c = at[rng() % clusters];
        s.centre[i] = Vec3(real(c.x + g(rng)), real(c.y + g(rng)), real(c.z + g(rng)));
        s.radius[i] = real(r * (0.5 + 0.5 * u01(rng)));
      }
      break;
    }
    case SetKind::on_boundaries: {
      // Radius chosen so that the cell edge is ~1 (or ~1 with the margin the
      // test adds, which is small); centres on an integer or half-integer
      // lattice: exactly on, or a rounding error off, cell faces. Many pairs
      // are exactly touching (distance == r_i + r_j).
      const double r = 1.0 / (3.0 * std::sqrt(2.0));
      const double step = (rng() % 2) ? 0.5 : 1.0 / 3.0;
      const int side = std::max(2, int(std::cbrt(double(n))) + 1);
      for (std::size_t i = 0; i < n; ++i) {
        const double jitter = (rng() % 4 == 0) ? 1e-7 * (u01(rng) - 0.5) : 0.0;
        s.centre[i] = Vec3(real(step * double(rng() % side) + jitter), real(step * double(rng() % side)),
                           real(step * double(rng() % side)));
        s.radius[i] = real((rng() % 3 == 0) ? r : r * (0.25 + 0.75 * u01(rng)));
      }
      break;
    }
    case SetKind::far_away: {
      const double r = 2.0 + 4.0 * u01(rng);
      uniform_box(box_side(n, 4.0 / 3.0 * pi * r * r * r, vf), 1.0e6, r);
      break;
    }
    case SetKind::negative: {
      const double r = 0.3 + u01(rng);
      const double side = box_side(n, 4.0 / 3.0 * pi * r * r * r, vf);
      uniform_box(side, -1.0e3 - side, r);
      break;
    }
    case SetKind::coincident: {
      const double r = 0.5;
      const std::size_t distinct = std::max<std::size_t>(1, n / 8);
      std::vector<Vec3> at(distinct);
      const double side = box_side(distinct, 4.0 / 3.0 * pi * r * r * r, vf);
      for (auto& c : at) c = Vec3(real(side * u01(rng)), real(side * u01(rng)), real(side * u01(rng)));
      for (std::size_t i = 0; i < n; ++i) {
        s.centre[i] = at[rng() % distinct];
        s.radius[i] = real(r * (rng() % 2 ? 1.0 : 0.5));
      }
      break;
    }
    case SetKind::outlier: {
      const double r = 0.5 + u01(rng);
      uniform_box(box_side(n, 4.0 / 3.0 * pi * r * r * r, vf), -50.0, r);
      // one sphere far outside the rest: 1e5 (64-bit keys) or 1e9 (key
      // compression), with a partner overlapping it: a pair far out too
      const double far = (rng() % 2) ? 1.0e5 : 1.0e9;
      const std::size_t a = rng() % n, b = (a + 1) % n;
      s.centre[a] = Vec3(real(far), real(-0.3 * far), real(0.5 * far));
      if (b != a) s.centre[b] = Vec3(s.centre[a].x + real(far > 1e6 ? 64.0 : 0.5 * r), s.centre[a].y, s.centre[a].z);
      if (b != a && far > 1e6) s.radius[a] = s.radius[b] = real(40.0);
      break;
    }
  }
  return s;
}

}  // namespace marbles::broadphase::testing
