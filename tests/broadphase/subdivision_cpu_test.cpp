// The CPU backends (seed algorithm and home-cell variant) against the O(N^2) oracle.
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "broadphase/broadphase.hpp"
#include "core/error.hpp"
#include "pair_check.hpp"
#include "sphere_sets.hpp"

namespace mb = marbles::broadphase;
namespace mt = marbles::broadphase::testing;
using marbles::real;

namespace {

void check_against_oracle(mb::BroadPhase& bp, const mt::SphereSet& s, real margin, const std::string& what) {
  std::vector<mb::Pair> got, expected;
  bp.find_pairs(s.view(), margin, got);
  mb::brute_force_pairs(s.view(), margin, expected);
  ASSERT_TRUE(mt::same_pair_set(got, expected)) << what;
  ASSERT_EQ(bp.last_stats().pairs, got.size());
}

}  // namespace

class SubdivisionCpu : public ::testing::TestWithParam<mb::Algorithm> {};

// How gtest (and ctest's listing) shows the parameter: "home", not bytes.
namespace marbles::broadphase {
void PrintTo(Algorithm a, std::ostream* out) { *out << algorithm_name(a); }
}  // namespace marbles::broadphase

// 8 kinds x 2 margins x 14 seeds = 224 random sets.
TEST_P(SubdivisionCpu, EqualsOracleOnRandomAndAdversarialSets) {
  auto bp = mb::make_subdivision_cpu(GetParam());
  std::uint64_t seed = 42;
  std::size_t sets = 0, pairs = 0;
  for (int k = 0; k < int(mt::SetKind::count); ++k) {
    const auto kind = mt::SetKind(k);
    for (int rep = 0; rep < 14; ++rep) {
      const std::size_t n = 2 + (seed * 7919) % 2500;
      const mt::SphereSet s = mt::make_set(kind, n, ++seed);
      for (real margin : {real(0), real(0.05 + 0.1 * (rep % 3))}) {
        check_against_oracle(*bp, s, margin,
                             std::string(mt::set_name(kind)) + " n=" + std::to_string(n) + " seed=" +
                                 std::to_string(seed) + " margin=" + std::to_string(margin));
        pairs += bp->last_stats().pairs;
        ++sets;
      }
    }
  }
  EXPECT_GE(sets, 200u);
  EXPECT_GT(pairs, 10000u);  // the sets are not trivially empty
}

TEST_P(SubdivisionCpu, KeyWidthsAreExercised) {
  auto bp = mb::make_subdivision_cpu(GetParam());
  std::vector<mb::Pair> out;
  bool saw32 = false, saw64 = false, sawc = false;
  for (std::uint64_t seed = 1; seed < 40 && !(saw32 && saw64 && sawc); ++seed) {
    const mt::SphereSet s = mt::make_set(mt::SetKind::outlier, 500, seed);
    bp->find_pairs(s.view(), 0, out);
    const mb::Stats& st = bp->last_stats();
    saw64 = saw64 || (st.key_width == 64 && !st.compressed_keys);
    sawc = sawc || st.compressed_keys;
    const mt::SphereSet m = mt::make_set(mt::SetKind::mono, 500, seed);
    bp->find_pairs(m.view(), 0, out);
    saw32 = saw32 || bp->last_stats().key_width == 32;
  }
  EXPECT_TRUE(saw32);
  EXPECT_TRUE(saw64);
  EXPECT_TRUE(sawc);
}

TEST_P(SubdivisionCpu, LargerSetsEqualOracle) {
  auto bp = mb::make_subdivision_cpu(GetParam());
  std::uint64_t seed = 9000;
  for (auto kind : {mt::SetKind::mono, mt::SetKind::poly20, mt::SetKind::clustered}) {
    const mt::SphereSet s = mt::make_set(kind, 20000, ++seed);
    check_against_oracle(*bp, s, real(0.02), mt::set_name(kind));
  }
}

// Sets too large for the oracle: both algorithms find the same pair set.
TEST(SubdivisionCpuAlgorithms, HomeAndSeedAgreeOnLargeSets) {
  auto home = mb::make_subdivision_cpu(mb::Algorithm::home);
  auto seed = mb::make_subdivision_cpu(mb::Algorithm::seed);
  std::uint64_t rng = 31337;
  for (auto kind : {mt::SetKind::mono, mt::SetKind::poly20, mt::SetKind::clustered, mt::SetKind::far_away,
                    mt::SetKind::outlier, mt::SetKind::on_boundaries, mt::SetKind::coincident}) {
    const mt::SphereSet s = mt::make_set(kind, 150000, ++rng);
    std::vector<mb::Pair> a, b;
    home->find_pairs(s.view(), real(0.01), a);
    seed->find_pairs(s.view(), real(0.01), b);
    std::sort(b.begin(), b.end());
    ASSERT_TRUE(mt::same_pair_set(a, b)) << mt::set_name(kind);
    EXPECT_GT(a.size(), 0u) << mt::set_name(kind);
  }
}

TEST_P(SubdivisionCpu, OrderIndependentOfThreadCount) {
#if defined(_OPENMP)
  auto bp = mb::make_subdivision_cpu(GetParam());
  const int before = omp_get_max_threads();
  for (auto kind : {mt::SetKind::mono, mt::SetKind::poly20, mt::SetKind::clustered}) {
    const mt::SphereSet s = mt::make_set(kind, 60000, 77 + int(kind));
    std::vector<mb::Pair> one;
    omp_set_num_threads(1);
    bp->find_pairs(s.view(), real(0.01), one);
    ASSERT_FALSE(one.empty());
    // Into fresh lists and into one kept from call to call (the step's):
    // its old pairs, more than a call finds, marked so that one left shows.
    std::vector<mb::Pair> kept(one.size() + 99);
    for (const int threads : {2, 3, 16, 5}) {
      omp_set_num_threads(threads);
      std::vector<mb::Pair> fresh;
      bp->find_pairs(s.view(), real(0.01), fresh);
      ASSERT_EQ(one, fresh) << mt::set_name(kind) << ", " << threads << " threads";
      for (mb::Pair& p : kept) p = {0xdeadbeefu, 0xdeadbeefu};
      bp->find_pairs(s.view(), real(0.01), kept);
      ASSERT_EQ(one, kept) << mt::set_name(kind) << ", " << threads << " threads, a kept list";
    }
    kept.resize(3);  // a kept list shorter than the pairs
    bp->find_pairs(s.view(), real(0.01), kept);
    ASSERT_EQ(one, kept) << mt::set_name(kind);
  }
  omp_set_num_threads(before);
#else
  GTEST_SKIP() << "skipped: built without OpenMP";
#endif
}

TEST_P(SubdivisionCpu, EdgeCases) {
  auto bp = mb::make_subdivision_cpu(GetParam());
  std::vector<mb::Pair> out;
  mt::SphereSet s;
  bp->find_pairs(s.view(), 0, out);
  EXPECT_TRUE(out.empty());
  s.centre = {marbles::Vec3(0, 0, 0)};
  s.radius = {1};
  bp->find_pairs(s.view(), 0, out);
  EXPECT_TRUE(out.empty());
  s.centre.push_back(marbles::Vec3(0, 0, 0));
  s.radius.push_back(0);
  bp->find_pairs(s.view(), 0, out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0], (mb::Pair{0, 1}));
  s.radius = {0, 0};  // zero radii, coincident: |d|^2 < 0 is false
  bp->find_pairs(s.view(), 0, out);
  EXPECT_TRUE(out.empty());
  bp->find_pairs(s.view(), real(0.1), out);  // with a margin they are candidates
  EXPECT_EQ(out.size(), 1u);
  s.centre[1] = marbles::Vec3(std::numeric_limits<real>::quiet_NaN(), 0, 0);
  EXPECT_THROW(bp->find_pairs(s.view(), 0, out), marbles::RuntimeFailure);
}

INSTANTIATE_TEST_SUITE_P(Algorithms, SubdivisionCpu, ::testing::Values(mb::Algorithm::seed, mb::Algorithm::home),
                         [](const auto& info) { return std::string(mb::algorithm_name(info.param)); });
