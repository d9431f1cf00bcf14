// bench/bench_scenes.hpp — the benchmark's sphere sets.
//   gas:  equal radii (1), random centres, volume fraction 0.1
//   pile: equal radii (1), jittered simple-cubic lattice at volume fraction ~0.5
//   poly: radii log-uniform over [0.1, 1] (1:10), random centres, volume fraction 0.1
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/vec3.hpp"

namespace marbles::bench {

struct BenchSpheres {
  std::vector<Vec3> centre;
  std::vector<real> radius;
};

inline BenchSpheres make_bench_scene(const std::string& scene, std::size_t n, std::uint64_t seed) {
  const double pi = 3.14159265358979323846;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  BenchSpheres s;
  s.centre.resize(n);
  s.radius.resize(n);
  if (scene == "gas" || scene == "poly") {
    double volume = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double r = scene == "gas" ? 1.0 : 0.1 * std::exp(std::log(10.0) * u01(rng));
      s.radius[i] = real(r);
      volume += 4.0 / 3.0 * pi * r * r * r;
    }
    const double side = std::cbrt(volume / 0.1);
    for (auto& c : s.centre) c = Vec3(real(side * u01(rng)), real(side * u01(rng)), real(side * u01(rng)));
  } else if (scene == "pile") {
    // Lattice spacing a with (4/3) pi r^3 / a^3 = 0.5, jitter +-0.05 r.
    const double r = 1.0, a = r * std::cbrt(4.0 / 3.0 * pi / 0.5);
    const auto side = static_cast<std::size_t>(std::ceil(std::cbrt(double(n))));
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t x = i % side, y = (i / side) % side, z = i / (side * side);
      s.centre[i] = Vec3(real(a * (double(x) + 0.05 * (u01(rng) - 0.5))), real(a * (double(y) + 0.05 * (u01(rng) - 0.5))),
                         real(a * (double(z) + 0.05 * (u01(rng) - 0.5))));
      s.radius[i] = real(r);
    }
  } else {
    throw std::invalid_argument("unknown scene '" + scene + "' (gas, pile, poly)");
  }
  return s;
}

}  // namespace marbles::bench
