// Tests of the per-element math that both backends run.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "broadphase/broadphase_math.hpp"
#include "broadphase/grid.hpp"

namespace mb = marbles::broadphase;
using marbles::real;
using marbles::Vec3;

TEST(BroadphaseMath, CellTypesOfNeighboursDiffer) {
  for (int x = -3; x <= 3; ++x)
    for (int y = -3; y <= 3; ++y)
      for (int z = -3; z <= 3; ++z) {
        const unsigned t = mb::cell_type(x, y, z);
        ASSERT_GE(t, 1u);
        ASSERT_LE(t, 8u);
        for (int dx = -1; dx <= 1; ++dx)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dz = -1; dz <= 1; ++dz) {
              if (dx || dy || dz) {
                ASSERT_NE(t, mb::cell_type(x + dx, y + dy, z + dz));
              }
            }
      }
}

TEST(BroadphaseMath, KeysAreABijectionAndTypeMajor) {
  mb::Grid g;
  const std::uint64_t half_max[3] = {37, 5, 1000};
  mb::set_key_layout(g, half_max);
  std::mt19937_64 rng(7);
  std::set<std::uint64_t> keys;
  std::set<std::tuple<long, long, long>> coords;
  for (int i = 0; i < 20000; ++i) {
    mb::CellCoord c{std::int64_t(rng() % 76), std::int64_t(rng() % 12), std::int64_t(rng() % 2002)};
    coords.insert({c.x, c.y, c.z});
    const std::uint64_t k = mb::pack_key(c, g);
    keys.insert(k);
    ASSERT_LT(k, std::uint64_t{1} << g.key_bits);
    ASSERT_EQ(mb::key_type(k, g), mb::cell_type(c));
  }
  EXPECT_EQ(keys.size(), coords.size());
}

TEST(BroadphaseMath, CellIdsHomeFirstAndMaskConsistent) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  mb::Bounds b{Vec3(-100, -100, -100), Vec3(100, 100, 100), real(2)};
  const mb::GridChoice gc = mb::choose_grid(b, real(0.5));
  const mb::Grid& g = gc.grid;
  EXPECT_GE(g.cell, 1.5 * 2 * std::sqrt(2.0) * (2 + 0.25) * (1 - 1e-12));
  for (int i = 0; i < 20000; ++i) {
    const Vec3 c(real(u(rng)), real(u(rng)), real(u(rng)));
    const real r = real(2.0 * std::uniform_real_distribution<double>(0, 1)(rng));
    const mb::SphereCellIds ids = mb::sphere_cell_ids(c, r, g);
    const mb::CellCoord home{mb::cell_coord(c.x, g.origin[0], g.inv_cell), mb::cell_coord(c.y, g.origin[1], g.inv_cell),
                             mb::cell_coord(c.z, g.origin[2], g.inv_cell)};
    ASSERT_GE(ids.count, 1u);
    ASSERT_LE(ids.count, 8u);
    ASSERT_EQ(ids.key[0], mb::pack_key(home, g));
    ASSERT_EQ(ids.home_type, mb::cell_type(home));
    unsigned mask = 0;
    for (unsigned e = 0; e < 8; ++e) {
      if (e < ids.count) {
        mask |= 1u << (mb::key_type(ids.key[e], g) - 1);
        for (unsigned f = 0; f < e; ++f) ASSERT_NE(ids.key[e], ids.key[f]);
      } else {
        ASSERT_EQ(ids.key[e], mb::kInvalidKey64);
      }
    }
    ASSERT_EQ(mask, ids.mask);
    // Every cell the (unscaled) sphere with margin/2 overlaps is occupied:
    // brute-force over the 27 neighbours with a sphere-box distance test.
    const double reach = (double(r) + 0.25) * std::sqrt(2.0);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const mb::CellCoord n{home.x + dx, home.y + dy, home.z + dz};
          const std::int64_t nc[3] = {n.x, n.y, n.z};
          double d2 = 0;
          for (int k = 0; k < 3; ++k) {
            const double lo = g.origin[k] + double(nc[k]) * g.cell, hi = lo + g.cell;
            const double p = double(c[k]);
            const double d = p < lo ? lo - p : (p > hi ? p - hi : 0.0);
            d2 += d * d;
          }
          if (d2 < reach * reach * (1 - 1e-9)) {
            const std::uint64_t k = mb::pack_key(n, g);
            bool found = false;
            for (unsigned e = 0; e < ids.count; ++e) found = found || ids.key[e] == k;
            ASSERT_TRUE(found) << "cell " << dx << "," << dy << "," << dz << " not occupied";
          }
        }
  }
}

TEST(BroadphaseMath, ValuesRoundTrip) {
  const std::uint32_t v = mb::make_value(123456, true, 7);
  EXPECT_EQ(mb::value_id(v), 123456u);
  EXPECT_TRUE(mb::value_phantom(v));
  EXPECT_EQ(mb::value_type(v), 7u);
  const std::uint32_t w = mb::make_value(mb::kMaxObjects - 1, false, 1);
  EXPECT_EQ(mb::value_id(w), mb::kMaxObjects - 1);
  EXPECT_FALSE(mb::value_phantom(w));
  EXPECT_EQ(mb::value_type(w), 1u);
}

TEST(BroadphaseMath, SkipRule) {
  // A home type 1 (mask 1,2), B home type 2 (mask 1,2): tested in pass 1 (cell of type 1), skipped in pass 2.
  const auto a = mb::make_info(1, 0b11), b = mb::make_info(2, 0b11);
  EXPECT_FALSE(mb::tested_in_earlier_pass(1, a, b));
  EXPECT_TRUE(mb::tested_in_earlier_pass(2, a, b));
  // B does not occupy a cell of A's home type: pass 2 is the only one.
  const auto b2 = mb::make_info(2, 0b10);
  EXPECT_FALSE(mb::tested_in_earlier_pass(2, a, b2));
  // Same home type: never skipped.
  EXPECT_FALSE(mb::tested_in_earlier_pass(3, mb::make_info(3, 0b100), mb::make_info(3, 0b100)));
}

TEST(BroadphaseMath, OverlapIsStrict) {
  EXPECT_TRUE(mb::spheres_overlap(Vec3(0, 0, 0), 1, Vec3(1.5, 0, 0), 1, 0));
  EXPECT_FALSE(mb::spheres_overlap(Vec3(0, 0, 0), 1, Vec3(2, 0, 0), 1, 0));
  EXPECT_TRUE(mb::spheres_overlap(Vec3(0, 0, 0), 1, Vec3(2, 0, 0), 1, real(0.01)));
  EXPECT_FALSE(mb::spheres_overlap(Vec3(0, 0, 0), 0, Vec3(0, 0, 0), 0, 0));
}
