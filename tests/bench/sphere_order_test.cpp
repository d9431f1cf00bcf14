// Tests of `marbles bench step --sphere-order` (bench/step_bench.hpp:
// in_sphere_order): each order is a permutation that carries every field of
// a sphere with it, made leaves the world as it is, shuffled is a fixed
// random order, and morton and cells sort by keys made here another way (the
// Z curve's bits interleaved one by one; the home grid's cells compared as
// (z, y, x)).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <tuple>
#include <vector>

#include "bench/step_bench.hpp"
#include "broadphase/grid.hpp"
#include "core/error.hpp"

namespace marbles::bench {
namespace {

World random_world(std::size_t n) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  auto vec = [&](double scale) { return Vec3(real(scale * u(rng)), real(scale * u(rng)), real(scale * u(rng))); };
  World w;
  for (std::size_t i = 0; i < n; ++i) {
    w.position.push_back(vec(1));
    w.velocity.push_back(vec(2));
    w.angular_velocity.push_back(vec(3));
    w.radius.push_back(real(0.005 + 0.01 * u(rng)));
    w.inv_mass.push_back(real(u(rng)));
    w.inv_inertia.push_back(real(u(rng)));
    w.material.push_back(static_cast<std::uint32_t>(i % 5));
  }
  return w;
}

using Sphere = std::tuple<real, real, real, real, real, real, real, real, real, real, real, real, std::uint32_t>;
std::vector<Sphere> spheres_of(const World& w) {
  std::vector<Sphere> s;
  for (std::size_t i = 0; i < w.size(); ++i) {
    const Vec3 &p = w.position[i], &v = w.velocity[i], &o = w.angular_velocity[i];
    s.emplace_back(p.x, p.y, p.z, v.x, v.y, v.z, o.x, o.y, o.z, w.radius[i], w.inv_mass[i], w.inv_inertia[i],
                   w.material[i]);
  }
  return s;
}

// The Z curve's key, one bit at a time.
std::uint64_t morton_key(std::uint64_t x, std::uint64_t y, std::uint64_t z) {
  std::uint64_t key = 0;
  for (int bit = 0; bit < 21; ++bit) {
    key |= ((x >> bit) & 1u) << (3 * bit);
    key |= ((y >> bit) & 1u) << (3 * bit + 1);
    key |= ((z >> bit) & 1u) << (3 * bit + 2);
  }
  return key;
}

TEST(SphereOrder, EachOrderPermutesWholeSpheres) {
  const World w = random_world(2000);
  auto sorted = [](std::vector<Sphere> s) {
    std::sort(s.begin(), s.end());
    return s;
  };
  const std::vector<Sphere> as_made = spheres_of(w);
  EXPECT_EQ(spheres_of(in_sphere_order(w, "made")), as_made);
  for (const char* how : {"shuffled", "morton", "cells"}) {
    SCOPED_TRACE(how);
    const World p = in_sphere_order(w, how);
    ASSERT_EQ(p.size(), w.size());
    EXPECT_NE(spheres_of(p), as_made);
    EXPECT_EQ(sorted(spheres_of(p)), sorted(as_made));
    EXPECT_EQ(spheres_of(in_sphere_order(w, how)), spheres_of(p));  // the same order every time
  }
  EXPECT_THROW(in_sphere_order(w, "spiral"), InputError);
}

TEST(SphereOrder, MortonAndCellsFollowTheirKeys) {
  const World w = random_world(3000);
  real largest = 0;
  Vec3 lo = w.position[0];
  for (std::size_t i = 0; i < w.size(); ++i) {
    largest = std::max(largest, w.radius[i]);
    lo = Vec3(std::min(lo.x, w.position[i].x), std::min(lo.y, w.position[i].y), std::min(lo.z, w.position[i].z));
  }
  const World z = in_sphere_order(w, "morton");
  const double cell = 2.0 * double(largest);
  auto at = [&](real x, real x0) { return static_cast<std::uint64_t>(std::floor((double(x) - double(x0)) / cell)); };
  for (std::size_t i = 1; i < z.size(); ++i) {
    const Vec3 &a = z.position[i - 1], &b = z.position[i];
    EXPECT_LE(morton_key(at(a.x, lo.x), at(a.y, lo.y), at(a.z, lo.z)),
              morton_key(at(b.x, lo.x), at(b.y, lo.y), at(b.z, lo.z)))
        << i;
  }
  const World c = in_sphere_order(w, "cells");
  const broadphase::HomeGrid g =
      broadphase::choose_home_grid(broadphase::bounds_of({w.position.data(), w.radius.data(), w.size()}), 0).grid;
  auto cell_of = [&](const Vec3& p) {
    auto along = [&](real x, int a) { return std::floor((double(x) - g.origin[a]) * g.inv_cell); };
    return std::tuple(along(p.z, 2), along(p.y, 1), along(p.x, 0));
  };
  for (std::size_t i = 1; i < c.size(); ++i) EXPECT_LE(cell_of(c.position[i - 1]), cell_of(c.position[i])) << i;
}

}  // namespace
}  // namespace marbles::bench
