// The CUDA backends (seed algorithm and home-cell variant, each with both
// sorts) against the oracle and the CPU backend of the same algorithm, and
// both GPU sorts against std::stable_sort. Label `gpu`; every case skips,
// saying so, where no CUDA device is present.
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "broadphase/grid.hpp"
#include "core/device.hpp"
#include "core/error.hpp"
#include "pair_check.hpp"
#include "sphere_sets.hpp"
#include "tests/require_device.hpp"
#if defined(MARBLES_BROADPHASE_CUDA)
#include <cuda_runtime.h>

#include "broadphase/broadphase_cuda.hpp"
#include "core/device_memory.hpp"
#endif

namespace mb = marbles::broadphase;
namespace mt = marbles::broadphase::testing;
using marbles::real;

#if defined(MARBLES_BROADPHASE_CUDA)

struct Variant {
  mb::Algorithm algorithm;
  mb::SortKind sort;
};

// How gtest (and ctest's listing) shows a variant: "home, cub sort", not bytes.
void PrintTo(const Variant& v, std::ostream* out) {
  *out << mb::algorithm_name(v.algorithm) << ", " << (v.sort == mb::SortKind::seed ? "seed" : "cub") << " sort";
}

class SubdivisionCuda : public ::testing::TestWithParam<Variant> {
 protected:
  mb::Algorithm algorithm() const { return GetParam().algorithm; }
  mb::SortKind sort() const { return GetParam().sort; }
};

TEST_P(SubdivisionCuda, EqualsOracleOnRandomAndAdversarialSets) {
  REQUIRE_DEVICE();
  auto gpu = mb::make_subdivision_cuda(algorithm(), sort());
  std::uint64_t seed = 4242;
  std::size_t sets = 0;
  for (int k = 0; k < int(mt::SetKind::count); ++k) {
    const auto kind = mt::SetKind(k);
    for (int rep = 0; rep < 14; ++rep) {
      const std::size_t n = 2 + (seed * 7919) % 3000;
      const mt::SphereSet s = mt::make_set(kind, n, ++seed);
      for (real margin : {real(0), real(0.05 + 0.1 * (rep % 3))}) {
        std::vector<mb::Pair> got, expected;
        gpu->find_pairs(s.view(), margin, got);
        mb::brute_force_pairs(s.view(), margin, expected);
        ASSERT_TRUE(mt::same_pair_set(got, expected))
            << mt::set_name(kind) << " n=" << n << " seed=" << seed << " margin=" << margin;
        ++sets;
      }
    }
  }
  EXPECT_GE(sets, 200u);
}

// Large sets: the GPU emits exactly the CPU backend's pairs of the same
// algorithm, in the same order; the home-cell variant's pair set also equals
// the seed algorithm's (oracle-checked above; O(N^2) is out of reach here).
TEST_P(SubdivisionCuda, LargeSetsEqualCpuBackend) {
  REQUIRE_DEVICE();
  auto gpu = mb::make_subdivision_cuda(algorithm(), sort());
  auto cpu = mb::make_subdivision_cpu(algorithm());
  auto seed_cpu = mb::make_subdivision_cpu(mb::Algorithm::seed);
  std::uint64_t seed = 777;
  for (std::size_t n : {100000ul, 1000000ul, 4000000ul}) {
    for (auto kind : {mt::SetKind::mono, mt::SetKind::poly20, mt::SetKind::clustered, mt::SetKind::far_away,
                      mt::SetKind::outlier}) {
      if (n == 4000000ul && kind != mt::SetKind::mono && kind != mt::SetKind::poly20) continue;
      const mt::SphereSet s = mt::make_set(kind, n, ++seed);
      std::vector<mb::Pair> a, b;
      gpu->find_pairs(s.view(), real(0.01), a);
      cpu->find_pairs(s.view(), real(0.01), b);
      ASSERT_EQ(a.size(), b.size()) << mt::set_name(kind) << " n=" << n;
      ASSERT_TRUE(a == b) << mt::set_name(kind) << " n=" << n << ": same pairs, different order";
      EXPECT_EQ(gpu->last_stats().cell_entries, cpu->last_stats().cell_entries);
      EXPECT_EQ(gpu->last_stats().collision_cells, cpu->last_stats().collision_cells);
      EXPECT_EQ(gpu->last_stats().tests, cpu->last_stats().tests);
      if (algorithm() == mb::Algorithm::home) {
        std::vector<mb::Pair> c;
        seed_cpu->find_pairs(s.view(), real(0.01), c);
        std::sort(c.begin(), c.end());  // same_pair_set wants the expected set in order
        ASSERT_TRUE(mt::same_pair_set(a, c)) << mt::set_name(kind) << " n=" << n << ": home vs seed";
      }
    }
  }
}

// The set's centres and radii on the device (core's upload; done when the
// call returns), as the device entry points take them.
marbles::SpheresIn on_device(const mt::SphereSet& s, marbles::cuda::DeviceBuffer& centre,
                             marbles::cuda::DeviceBuffer& radius) {
  const marbles::Vec3* c = marbles::cuda::upload(centre, s.centre, nullptr);
  const real* r = marbles::cuda::upload(radius, s.radius, nullptr);
  EXPECT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  return {c, r, s.centre.size()};
}

// The first `count` pairs the broad phase holds on the device.
std::vector<mb::Pair> pairs_on_device(const mb::SubdivisionCuda& gpu, std::size_t count) {
  std::vector<mb::Pair> out(count);
  EXPECT_EQ(cudaMemcpy(out.data(), gpu.device_pairs(), count * sizeof(mb::Pair), cudaMemcpyDeviceToHost),
            cudaSuccess);
  return out;
}

// Also the sanitizer's case (scripts/gpu-check): a dense grid, and a sparse
// one (one sphere far out: the home-cell variant binary-searches the keys).
TEST_P(SubdivisionCuda, DeviceResidentEntryPoint) {
  REQUIRE_DEVICE();
  mb::SubdivisionCuda gpu(algorithm(), sort());
  for (bool sparse : {false, true}) {
    mt::SphereSet s = mt::make_set(mt::SetKind::mono, 20000, 99);
    if (sparse) s.centre[123] = marbles::Vec3(real(2.0e5), real(-1.0e5), real(3.0e5));
    marbles::cuda::DeviceBuffer centre, radius;  // freed, as the stream is destroyed, however the test ends
    marbles::cuda::Stream stream;
    stream.create();
    const std::size_t count = gpu.find_pairs_device(on_device(s, centre, radius), real(0), stream);
    const std::vector<mb::Pair> got = pairs_on_device(gpu, count);
    std::vector<mb::Pair> expected;
    mb::brute_force_pairs(s.view(), 0, expected);
    EXPECT_TRUE(mt::same_pair_set(got, expected)) << (sparse ? "sparse" : "dense");
    if (algorithm() == mb::Algorithm::home) {
      EXPECT_EQ(gpu.last_stats().dense_cell_starts, !sparse);
    }
  }
}

// The home-cell variant's temporaries in a scratch buffer shared with other
// stages, which leave it dirty (poisoned here, before and after each call)
// and find it larger or smaller than this call needs: the same pairs as
// brute force, whatever the memory held; the pairs are not in it.
TEST_P(SubdivisionCuda, SharedScratchLeftDirtyBetweenCalls) {
  REQUIRE_DEVICE();
  if (algorithm() != mb::Algorithm::home) GTEST_SKIP() << "the seed algorithm keeps its own buffers";
  mb::SubdivisionCuda gpu(algorithm(), sort());
  marbles::cuda::DeviceBuffer scratch, centre, radius;  // freed, as the stream is destroyed, however the test ends
  gpu.share_scratch(scratch);
  marbles::cuda::Stream stream;
  stream.create();
  std::uint64_t seed = 7;
  const std::pair<std::size_t, mt::SetKind> sets[] = {
      {20000, mt::SetKind::mono}, {500, mt::SetKind::poly20}, {30000, mt::SetKind::clustered},
      {2000, mt::SetKind::outlier}, {25000, mt::SetKind::mono}};
  for (const auto& [n, kind] : sets) {
    if (scratch.bytes() > 0) {
      ASSERT_EQ(cudaMemset(scratch.get(), 0xa5, scratch.bytes()), cudaSuccess);
    }
    mt::SphereSet s = mt::make_set(kind, n, ++seed);
    const std::size_t count = gpu.find_pairs_device(on_device(s, centre, radius), real(0), stream);
    ASSERT_GT(scratch.bytes(), 0u) << "the temporaries went to the shared scratch";
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
    ASSERT_EQ(cudaMemset(scratch.get(), 0x5a, scratch.bytes()), cudaSuccess);  // the next user's writes
    const std::vector<mb::Pair> got = pairs_on_device(gpu, count);
    std::vector<mb::Pair> expected;
    mb::brute_force_pairs(s.view(), 0, expected);
    EXPECT_TRUE(mt::same_pair_set(got, expected)) << mt::set_name(kind) << " n=" << n;
  }
}

// The pair count left on the device: with room for every pair, the same
// pairs in the same order as find_pairs_device (and brute force's set);
// with one pair too few, none written (the memory poisoned before is
// untouched) and the whole count told, so the caller can ask again. Where
// the call waits for the count anyway (the seed algorithm, a grid too wide
// for the device's keys) it returns the count and writes every pair.
TEST_P(SubdivisionCuda, PairsWithinARoom) {
  REQUIRE_DEVICE();
  mb::SubdivisionCuda gpu(algorithm(), sort());
  marbles::cuda::DeviceBuffer centre, radius;  // freed, as the stream is destroyed, however the test ends
  marbles::cuda::Stream stream;
  stream.create();
  auto device_count = [&] {
    std::uint32_t count = 0;
    EXPECT_EQ(cudaMemcpy(&count, gpu.device_pair_count(), sizeof count, cudaMemcpyDeviceToHost), cudaSuccess);
    return std::size_t{count};
  };
  std::size_t counts_left = 0;  // calls that left the count on the device
  std::uint64_t seed = 11;
  const std::pair<std::size_t, mt::SetKind> sets[] = {{20000, mt::SetKind::mono},     {30000, mt::SetKind::clustered},
                                                      {3000, mt::SetKind::coincident}, {2000, mt::SetKind::outlier},
                                                      {3000, mt::SetKind::far_away},   {1, mt::SetKind::mono}};
  for (const auto& [n, kind] : sets) {
    const std::string name = std::string(mt::set_name(kind)) + " n=" + std::to_string(n);
    mt::SphereSet s = mt::make_set(kind, n, ++seed);
    const marbles::SpheresIn in = on_device(s, centre, radius);
    const std::size_t count = gpu.find_pairs_device(in, real(0), stream);
    const std::vector<mb::Pair> exact = pairs_on_device(gpu, count);
    std::vector<mb::Pair> expected;
    mb::brute_force_pairs(s.view(), 0, expected);
    ASSERT_TRUE(mt::same_pair_set(exact, expected)) << name;
    auto poison = [&] {
      if (count == 0) return;
      ASSERT_EQ(cudaMemset(const_cast<mb::Pair*>(gpu.device_pairs()), 0xa5, count * sizeof(mb::Pair)), cudaSuccess);
    };

    poison();  // what find_pairs_device left there must not pass for this call's pairs
    std::size_t told = gpu.find_pairs_device_within(in, real(0), count, stream);
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
    if (told == mb::SubdivisionCuda::kCountOnDevice) {
      ++counts_left;
      told = device_count();
    }
    ASSERT_EQ(told, count) << name << ": room for all";
    EXPECT_EQ(pairs_on_device(gpu, count), exact) << name << ": room for all";
    if (count == 0) continue;

    poison();
    told = gpu.find_pairs_device_within(in, real(0), count - 1, stream);
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
    if (told == mb::SubdivisionCuda::kCountOnDevice) {
      EXPECT_EQ(device_count(), count) << name << ": one short";
      const std::vector<mb::Pair> left = pairs_on_device(gpu, count);
      const auto* bytes = reinterpret_cast<const unsigned char*>(left.data());
      EXPECT_TRUE(std::all_of(bytes, bytes + count * sizeof(mb::Pair), [](unsigned char b) { return b == 0xa5; }))
          << name << ": one short, yet pairs were written";
    } else {
      EXPECT_EQ(told, count) << name << ": one short, waited";
      EXPECT_EQ(pairs_on_device(gpu, count), exact) << name << ": one short, waited";
    }
  }
  if (algorithm() == mb::Algorithm::home) {
    EXPECT_GE(counts_left, 3u) << "the home-cell variant leaves the count on the device";
  } else {
    EXPECT_EQ(counts_left, 0u) << "the seed algorithm waits for its counts";
  }
}

// Within a room of a shared scratch (a GPU step's), the home-cell variant
// writes its pairs at the scratch's front, where the step's next carve takes
// them first, and gives its own pair buffer back: the same pairs in the same
// order as with a buffer of its own; one short, nothing written there (the
// front poisoned before is untouched). Where the call waits for its count
// anyway (the seed algorithm, a grid too wide for the device's keys) the
// pairs are its own, as before. The scratch is reserved ahead, as the step
// does, so no call moves it.
TEST_P(SubdivisionCuda, PairsWithinARoomAtTheSharedScratchsFront) {
  REQUIRE_DEVICE();
  mb::SubdivisionCuda gpu(algorithm(), sort());
  marbles::cuda::DeviceBuffer scratch, centre, radius;  // freed, as the stream is destroyed, however the test ends
  gpu.share_scratch(scratch);
  scratch.reserve(std::size_t{64} << 20);
  marbles::cuda::Stream stream;
  stream.create();
  std::size_t fronts = 0;
  std::uint64_t seed = 23;
  const std::pair<std::size_t, mt::SetKind> sets[] = {{20000, mt::SetKind::mono},
                                                      {30000, mt::SetKind::clustered},
                                                      {3000, mt::SetKind::far_away},
                                                      {2000, mt::SetKind::outlier}};
  for (const auto& [n, kind] : sets) {
    const std::string name = std::string(mt::set_name(kind)) + " n=" + std::to_string(n);
    mt::SphereSet s = mt::make_set(kind, n, ++seed);
    const marbles::SpheresIn in = on_device(s, centre, radius);
    const std::size_t count = gpu.find_pairs_device(in, real(0), stream);
    ASSERT_GT(count, 1u) << name;
    const std::vector<mb::Pair> exact = pairs_on_device(gpu, count);
    EXPECT_FALSE(gpu.pairs_in_scratch()) << name << ": a call that waits keeps its own";
    const std::size_t own_bytes = gpu.device_bytes();
    void* const at = scratch.get();
    auto poison = [&](std::size_t pairs) {
      ASSERT_EQ(cudaMemset(scratch.get(), 0xa5, pairs * sizeof(mb::Pair)), cudaSuccess);
    };

    poison(count);
    const std::size_t told = gpu.find_pairs_device_within(in, real(0), count, stream);
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
    ASSERT_EQ(scratch.get(), at) << name << ": the scratch did not move";
    EXPECT_EQ(gpu.pairs_in_scratch(), told == mb::SubdivisionCuda::kCountOnDevice) << name;
    EXPECT_EQ(pairs_on_device(gpu, count), exact) << name << ": room for all";
    if (!gpu.pairs_in_scratch()) continue;
    ++fronts;
    EXPECT_EQ(static_cast<const void*>(gpu.device_pairs()), at) << name << ": at the front";
    EXPECT_LE(gpu.device_bytes() + count * sizeof(mb::Pair), own_bytes) << name << ": its own pairs given back";

    poison(count - 1);
    EXPECT_EQ(gpu.find_pairs_device_within(in, real(0), count - 1, stream), mb::SubdivisionCuda::kCountOnDevice);
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
    std::uint32_t left_count = 0;
    ASSERT_EQ(cudaMemcpy(&left_count, gpu.device_pair_count(), sizeof left_count, cudaMemcpyDeviceToHost),
              cudaSuccess);
    EXPECT_EQ(left_count, count) << name << ": one short";
    const std::vector<mb::Pair> left = pairs_on_device(gpu, count - 1);
    const auto* bytes = reinterpret_cast<const unsigned char*>(left.data());
    EXPECT_TRUE(std::all_of(bytes, bytes + (count - 1) * sizeof(mb::Pair), [](unsigned char b) { return b == 0xa5; }))
        << name << ": one short, yet pairs were written";
  }
  if (algorithm() == mb::Algorithm::home) {
    EXPECT_GE(fronts, 2u) << "the home-cell variant's pairs at the front";
  } else {
    EXPECT_EQ(fronts, 0u) << "the seed algorithm keeps its own";
  }
}

// The home-cell variant within a room chooses its grid on the device from
// bounds it does not read, for the buffers and sort of the plan made at the
// last read. Moved sets whose grids fit that plan (shifted, jittered, shrunk;
// each grid differs from the planned one in origin or cells) give exactly
// the CPU twin's pairs in its order, so the device chose the host's grid.
// Sets whose grid does not fit (spread out: more cells than the dense lower
// bounds hold, its key bits within the plan's, 20 against 24 on the host's
// grid; far apart: 64-bit keys) and a non-finite centre give
// kNoPairCount and write nothing; after replan() the call reads its bounds
// (and throws on the non-finite one). Back to the first set under the
// larger plan: its pairs, and the word after the count says the plan is
// outsized (plan_outsized), until replan() plans from the smaller grid. A
// call within the plan reads nothing back. A sparse plan is outgrown by its
// key bits alone.
TEST_P(SubdivisionCuda, GridChosenOnTheDevice) {
  REQUIRE_DEVICE();
  if (algorithm() != mb::Algorithm::home) GTEST_SKIP() << "the seed algorithm always reads its bounds";
  mb::SubdivisionCuda gpu(algorithm(), sort());
  auto cpu = mb::make_home_cell_cpu();
  marbles::cuda::DeviceBuffer centre, radius;  // freed, as the stream is destroyed, however the test ends
  marbles::cuda::Stream stream;
  stream.create();
  const real margin = real(0.01);
  std::uint32_t outsized = 2;  // the word after the count, as the last call left it
  auto device_count = [&] {
    std::uint32_t words[mb::SubdivisionCuda::kPairCountWords] = {};
    EXPECT_EQ(cudaMemcpy(words, gpu.device_pair_count(), sizeof words, cudaMemcpyDeviceToHost), cudaSuccess);
    outsized = words[1];
    return words[0];
  };
  constexpr std::size_t kRoom = 400000;
  auto poison = [&] {
    ASSERT_EQ(cudaMemset(const_cast<mb::Pair*>(gpu.device_pairs()), 0xa5, kRoom * sizeof(mb::Pair)), cudaSuccess);
  };
  // One call within the room; the count it left (the pairs where it fits).
  auto within = [&](const mt::SphereSet& s) {
    const std::size_t told = gpu.find_pairs_device_within(on_device(s, centre, radius), margin, kRoom, stream);
    EXPECT_EQ(told, mb::SubdivisionCuda::kCountOnDevice);
    EXPECT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
    return device_count();
  };
  auto expect_cpu_pairs = [&](const mt::SphereSet& s, std::uint32_t count, const std::string& name) {
    std::vector<mb::Pair> expected;
    cpu->find_pairs(s.view(), margin, expected);
    ASSERT_EQ(count, expected.size()) << name;
    EXPECT_TRUE(pairs_on_device(gpu, count) == expected) << name << ": the CPU twin's pairs in its order";
  };
  auto expect_nothing_written = [&](const std::string& name) {
    const std::vector<mb::Pair> left = pairs_on_device(gpu, kRoom);
    const auto* bytes = reinterpret_cast<const unsigned char*>(left.data());
    EXPECT_TRUE(std::all_of(bytes, bytes + kRoom * sizeof(mb::Pair), [](unsigned char b) { return b == 0xa5; }))
        << name << ": pairs written without a grid";
  };

  auto grid_of = [&](const mt::SphereSet& s) { return mb::choose_home_grid(mb::bounds_of(s.view()), margin); };
  const mt::SphereSet base = mt::make_set(mt::SetKind::mono, 30000, 5);
  (void)within(base);  // no plan yet: reads its bounds and plans
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> unit(-1, 1);
  int moved = 0;
  for (int k = 0; k < 8; ++k) {
    mt::SphereSet s = base;
    const double shift = 0.37 * k, jitter = 0.02 * (k % 3), shrink = 1.0 - 0.03 * k;
    for (auto& c : s.centre)
      c = marbles::Vec3(real(shrink * c.x + shift + jitter * unit(rng)), real(shrink * c.y - 0.5 * shift),
                        real(shrink * c.z + jitter * unit(rng)));
    poison();
    const std::uint64_t copied = gpu.bytes_copied();
    const std::uint32_t count = within(s);
    EXPECT_EQ(gpu.bytes_copied(), copied) << "moved " << k << ": nothing read back within the plan";
    ASSERT_NE(count, mb::SubdivisionCuda::kNoPairCount) << "moved " << k << ": within the plan";
    expect_cpu_pairs(s, count, "moved " + std::to_string(k));
    const std::size_t n = base.centre.size();
    const mb::HomeGridChoice planned = grid_of(base), now = grid_of(s);
    EXPECT_EQ(outsized, mb::plan_outsized(mb::plan_of(planned.grid, planned.width, n), now.grid, n) ? 1u : 0u)
        << "moved " << k << ": the word says what the host's rule says of the base's plan";
    ++moved;
  }
  EXPECT_EQ(moved, 8);

  struct Outgrown {
    const char* name;
    mt::SphereSet set;
  };
  std::vector<Outgrown> outgrown;
  {
    mt::SphereSet spread = base;
    for (auto& c : spread.centre) c = c * real(2.5);
    outgrown.push_back({"spread out", spread});
    mt::SphereSet far = base;
    far.centre[77] = marbles::Vec3(real(3.0e5), real(-2.0e5), real(1.0e5));  // more than 2^31 cells, not 2^62
    outgrown.push_back({"far apart", far});
  }
  for (const Outgrown& o : outgrown) {
    poison();
    EXPECT_EQ(within(o.set), mb::SubdivisionCuda::kNoPairCount) << o.name;
    expect_nothing_written(o.name);
    gpu.replan();
    poison();
    const std::uint32_t count = within(o.set);  // reads its bounds, plans, fits
    ASSERT_NE(count, mb::SubdivisionCuda::kNoPairCount) << o.name << ", planned again";
    expect_cpu_pairs(o.set, count, std::string(o.name) + ", planned again");
    EXPECT_EQ(outsized, 0u) << o.name << ": planned from its own grid";
    // Back to the base under the larger plan: its pairs, and the plan found
    // outsized (the premise from the host's grids); planned again, not.
    const std::size_t n = base.centre.size();
    const mb::HomeGridChoice big = grid_of(o.set), small = grid_of(base);
    ASSERT_TRUE(mb::plan_outsized(mb::plan_of(big.grid, big.width, n), small.grid, n)) << o.name << ": premise";
    poison();
    const std::uint32_t back = within(base);
    ASSERT_NE(back, mb::SubdivisionCuda::kNoPairCount) << o.name << ": the base fits under the larger plan";
    expect_cpu_pairs(base, back, std::string(o.name) + ", then the base under its plan");
    EXPECT_EQ(outsized, 1u) << o.name << ": the base's grid finds the larger plan outsized";
    gpu.replan();
    (void)within(base);
    EXPECT_EQ(outsized, 0u) << o.name << ": the base planned again";
    const mb::HomePlan own = mb::plan_of(small.grid, small.width, n);
    EXPECT_EQ(gpu.last_stats().key_width, own.bits32 ? 32u : 64u) << o.name << ": the base's plan";
    EXPECT_EQ(gpu.last_stats().sort_passes, mb::sort_digits(own.key_bits)) << o.name << ": the base's plan";
  }

  // A sparse plan (binary-searched keys, no lower bounds to outgrow): one
  // sphere far out along x. The host's grid finds the cases: with the
  // sphere nearer, the CPU twin's pairs; moved out until the grid's key bits
  // pass the plan's (rounded up to the sort's 8-bit digits), with 32-bit
  // keys still, kNoPairCount: the key bits alone decide.
  auto with_outlier = [&](double x) {
    mt::SphereSet s = base;
    s.centre[77].x = real(x);
    return s;
  };
  double x = 1e3;
  while (mb::use_dense_cell_starts(grid_of(with_outlier(x)).grid, base.centre.size())) x *= 2;
  const mb::HomeGridChoice sparse = grid_of(with_outlier(x));
  ASSERT_EQ(sparse.width, mb::KeyWidth::bits32) << "premise: a sparse grid of 32-bit keys";
  const std::uint32_t rounded = (sparse.grid.key_bits + 7) / 8 * 8;
  ASSERT_LT(rounded, 32u) << "premise: room above the plan's bits";
  double past = x;
  while (grid_of(with_outlier(past)).grid.key_bits <= rounded) past *= 2;
  ASSERT_EQ(grid_of(with_outlier(past)).width, mb::KeyWidth::bits32) << "premise: 32-bit keys past the plan's bits";
  gpu.replan();
  (void)within(with_outlier(x));  // reads its bounds: the sparse plan
  const mt::SphereSet nearer = with_outlier(0.75 * x);
  poison();
  const std::uint32_t nearer_count = within(nearer);
  ASSERT_NE(nearer_count, mb::SubdivisionCuda::kNoPairCount) << "sparse, nearer: within the plan";
  expect_cpu_pairs(nearer, nearer_count, "sparse, nearer");
  poison();
  EXPECT_EQ(within(with_outlier(past)), mb::SubdivisionCuda::kNoPairCount) << "sparse, past the plan's key bits";
  expect_nothing_written("sparse, past the plan's key bits");

  mt::SphereSet bad = base;
  bad.centre[4321].y = std::numeric_limits<real>::quiet_NaN();
  poison();
  EXPECT_EQ(within(bad), mb::SubdivisionCuda::kNoPairCount) << "a non-finite centre";
  expect_nothing_written("a non-finite centre");
  gpu.replan();
  EXPECT_THROW(gpu.find_pairs_device_within(on_device(bad, centre, radius), margin, kRoom, stream),
               mb::NonFiniteInput);
}

template <class Key>
void check_sort(mb::SortKind sort, int pattern, std::size_t n, unsigned bits, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const Key mask = bits >= 8 * sizeof(Key) ? ~Key{0} : ((Key{1} << bits) - 1);
  std::vector<Key> keys(n);
  for (auto& k : keys) k = static_cast<Key>(rng()) & mask;
  if (pattern == 1) std::fill(keys.begin(), keys.end(), keys.empty() ? Key{0} : keys[0]);
  if (pattern == 2) std::sort(keys.begin(), keys.end());
  if (pattern == 3) std::sort(keys.begin(), keys.end(), std::greater<Key>());
  if (pattern == 4)
    for (auto& k : keys) k = static_cast<Key>((rng() % 7) << (bits - 3)) & mask;
  std::vector<std::uint32_t> values(n);
  std::iota(values.begin(), values.end(), 0u);
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return keys[a] < keys[b]; });
  std::vector<Key> k2 = keys;
  std::vector<std::uint32_t> v2 = values;
  mb::sort_pairs_cuda(k2, v2, bits, sort);
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(k2[i], keys[order[i]]) << "pattern " << pattern << " n " << n << " bits " << bits << " at " << i;
    ASSERT_EQ(v2[i], values[order[i]]) << "pattern " << pattern << " n " << n << " bits " << bits << " at " << i;
  }
}

TEST_P(SubdivisionCuda, SortEqualsStableSort) {
  REQUIRE_DEVICE();
  if (algorithm() != mb::Algorithm::seed) GTEST_SKIP() << "the sorts are the same for both algorithms: run once";
  std::uint64_t seed = 31;
  for (int pattern = 0; pattern < 5; ++pattern)
    for (std::size_t n : {0ul, 1ul, 17ul, 1000ul, 65537ul, 1000003ul, 8000000ul}) {
      for (unsigned bits : {5u, 16u, 23u, 32u}) check_sort<std::uint32_t>(sort(), pattern, n, bits, ++seed);
      if (n <= 1000003ul)
        for (unsigned bits : {37u, 64u}) check_sort<std::uint64_t>(sort(), pattern, n, bits, ++seed);
    }
}

INSTANTIATE_TEST_SUITE_P(Variants, SubdivisionCuda,
                         ::testing::Values(Variant{mb::Algorithm::seed, mb::SortKind::seed},
                                           Variant{mb::Algorithm::seed, mb::SortKind::cub},
                                           Variant{mb::Algorithm::home, mb::SortKind::seed},
                                           Variant{mb::Algorithm::home, mb::SortKind::cub}),
                         [](const auto& info) {
                           return std::string(mb::algorithm_name(info.param.algorithm)) + "_" +
                                  (info.param.sort == mb::SortKind::seed ? "seedsort" : "cubsort");
                         });

#endif

TEST(SubdivisionCudaAvailability, ThrowsWithoutDevice) {
  if (marbles::cuda_device().available) GTEST_SKIP() << "skipped: a CUDA device is present";
  EXPECT_THROW(mb::make_subdivision_cuda(mb::Algorithm::seed), marbles::RuntimeFailure);
  EXPECT_THROW(mb::make_subdivision_cuda(mb::Algorithm::home), marbles::RuntimeFailure);
}
