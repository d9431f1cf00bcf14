// The GPU colouring (Jones–Plassmann rounds, colouring_cuda.cu) against the
// CPU colouring on random and adversarial contact sets: the same colour
// ranges and the same colour-major order, contact for contact; and the
// impact levels against the CPU's by_round colouring. Label `gpu`; every case
// skips, saying so, without a CUDA device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <numeric>
#include <random>
#include <set>
#include <vector>

#include "core/device.hpp"
#include "narrowphase/colouring.hpp"
#include "narrowphase/colouring_cuda.cuh"
#include "narrowphase/solver_math.hpp"

using namespace marbles;
using namespace marbles::narrowphase;

#define REQUIRE_DEVICE()                                                                 \
  do {                                                                                   \
    if (!marbles::cuda_device().available) GTEST_SKIP() << "skipped: no CUDA device";  \
  } while (0)

namespace {

std::vector<Contact> random_contacts(std::mt19937_64& rng, std::uint32_t bodies, std::size_t count) {
  std::uniform_int_distribution<std::uint32_t> body(0, bodies - 1), wall(0, 5);
  std::uniform_real_distribution<double> u(0, 1);
  std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
  std::vector<Contact> out;
  while (out.size() < count) {
    Contact c;
    c.a = body(rng);
    c.b = u(rng) < 0.1 ? (kWallFlag | wall(rng)) : body(rng);
    if (c.b == c.a) continue;
    if (!is_wall(c.b) && c.b < c.a) std::swap(c.a, c.b);
    if (!seen.insert({c.a, c.b}).second) continue;
    c.separation = real(1e-3 * u(rng));
    c.approach_speed = real(u(rng) < 0.5 ? -2 * u(rng) : u(rng));  // about half are impacts
    c.normal_impulse = real(out.size());                          // a tag
    out.push_back(c);
  }
  return out;
}

struct DeviceContacts {
  Contact* in = nullptr;
  Contact* out = nullptr;
  explicit DeviceContacts(const std::vector<Contact>& c) {
    const std::size_t bytes = (c.size() + 1) * sizeof(Contact);
    EXPECT_EQ(cudaMalloc(&in, bytes), cudaSuccess);
    EXPECT_EQ(cudaMalloc(&out, bytes), cudaSuccess);
    EXPECT_EQ(cudaMemset(out, 0xff, bytes), cudaSuccess);  // poisoned
    EXPECT_EQ(cudaMemcpy(in, c.data(), c.size() * sizeof(Contact), cudaMemcpyHostToDevice), cudaSuccess);
  }
  ~DeviceContacts() {
    cudaFree(in);
    cudaFree(out);
  }
};

void expect_same_as_cpu(const std::vector<Contact>& input, std::uint32_t bodies) {
  std::vector<Contact> cpu = input;
  ColourRanges ranges;
  ContactColouring().colour_and_sort(cpu, bodies, ranges);

  DeviceContacts d(input);
  narrowphase::cuda::ColouringCuda gpu;
  std::vector<std::uint32_t> begin;
  std::uint32_t rounds = 0;
  const auto n = static_cast<std::uint32_t>(input.size());
  const std::uint32_t colours = gpu.colour_and_sort(d.in, n, bodies, d.out, begin, rounds, 8, nullptr);
  ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  EXPECT_EQ(colours, ranges.colours);
  EXPECT_EQ(begin, ranges.begin);
  std::vector<Contact> sorted(n);
  if (n > 0) ASSERT_EQ(cudaMemcpy(sorted.data(), d.out, n * sizeof(Contact), cudaMemcpyDeviceToHost), cudaSuccess);
  for (std::uint32_t k = 0; k < n; ++k) ASSERT_EQ(sorted[k].normal_impulse, cpu[k].normal_impulse) << "position " << k;

  // Impact levels: the candidates of each level, in index order, as the CPU's.
  const real rest = real(0.1);
  std::vector<std::uint32_t> candidates, level(n, kUncoloured);
  std::vector<std::uint64_t> rank(n);
  for (std::uint32_t k = 0; k < n; ++k)
    if (is_impact_candidate(input[k], rest)) {
      candidates.push_back(k);
      rank[k] = impact_rank(time_of_impact(input[k]), k);
    }
  std::uint32_t cpu_levels = 0;
  ContactColouring().colour(input.data(), candidates, rank.data(), bodies, ColourRule::by_round, level, &cpu_levels);
  std::uint32_t* order = nullptr;
  std::vector<std::uint32_t> level_begin;
  const std::uint32_t levels = gpu.impact_levels(d.in, n, bodies, rest, order, level_begin, 8, nullptr);
  ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  if (candidates.empty()) {
    EXPECT_EQ(levels, 0u);
    return;
  }
  ASSERT_EQ(levels, cpu_levels);
  std::vector<std::uint32_t> gpu_order(candidates.size());
  ASSERT_EQ(cudaMemcpy(gpu_order.data(), order, gpu_order.size() * 4, cudaMemcpyDeviceToHost), cudaSuccess);
  // Level by level, then the overflow (beyond kMaxColourRounds levels), each in index order.
  std::vector<std::uint32_t> expect;
  for (std::uint32_t l = 0; l <= levels; ++l)
    for (std::uint32_t k : candidates)
      if (level[k] == (l < levels ? l : kOverflowColour)) expect.push_back(k);
  ASSERT_EQ(expect.size(), candidates.size());
  EXPECT_EQ(level_begin.back(), candidates.size());
  EXPECT_EQ(gpu_order, expect);
}

}  // namespace

TEST(ColouringCuda, EqualsTheCpuColouringOnRandomSets) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(21);
  for (int trial = 0; trial < 30; ++trial) {
    const std::uint32_t bodies = 2 + static_cast<std::uint32_t>(rng() % 20000);
    const std::size_t count = std::min<std::size_t>(std::size_t(bodies) * (bodies - 1) / 2, rng() % 60000);
    expect_same_as_cpu(random_contacts(rng, bodies, count), bodies);
  }
}

TEST(ColouringCuda, LargeSetAndAStarBeyondSixtyFourColours) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(4);
  expect_same_as_cpu(random_contacts(rng, 300000, 1000000), 300000);
  std::vector<Contact> star;
  for (std::uint32_t k = 1; k <= 300; ++k) {
    Contact c;
    c.a = 0;
    c.b = k;
    c.approach_speed = -1;
    c.normal_impulse = real(star.size());
    star.push_back(c);
  }
  expect_same_as_cpu(star, 301);
  expect_same_as_cpu({}, 10);
}
