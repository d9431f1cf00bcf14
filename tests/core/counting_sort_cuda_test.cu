// core/counting_sort_cuda.cuh against std::stable_sort on random and
// adversarial buckets: every item placed once, where a stable sort by bucket
// puts it, and each bucket's first place (or none). Label `gpu`; every case
// skips, saying so, without a CUDA device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

#include "core/counting_sort_cuda.cuh"
#include "tests/require_device.hpp"

namespace dev = ::marbles::cuda;

namespace {

constexpr std::uint32_t kNone = 0xfffffff0u;

struct BucketOf {
  const std::uint32_t* bucket;
  __device__ std::uint32_t operator()(std::uint32_t k) const { return bucket[k]; }
};
struct PlaceOf {
  std::uint32_t* place;
  const std::uint32_t* bucket;
  __device__ void operator()(std::uint32_t k, std::uint32_t p, std::uint32_t b) const {
    if (b != bucket[k]) p = 0xfffffff1u;  // not the item's own bucket: caught below
    place[k] = p;
  }
};

// The places and firsts the GPU gives; in_place: each item's place written
// over its own bucket, as the colouring writes positions over colours.
void expect_stable_places(const std::vector<std::uint32_t>& bucket, std::uint32_t buckets, bool in_place) {
  const auto n = static_cast<std::uint32_t>(bucket.size());
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) { return bucket[x] < bucket[y]; });
  std::vector<std::uint32_t> want_place(n), want_first(buckets, kNone);
  for (std::uint32_t p = 0; p < n; ++p) {
    want_place[order[p]] = p;
    if (want_first[bucket[order[p]]] == kNone) want_first[bucket[order[p]]] = p;
  }

  dev::DeviceBuffer keys_memory, places_memory, first_memory, scratch;  // freed however the test ends
  auto* keys = keys_memory.as<std::uint32_t>(n + 1);
  auto* places = in_place ? keys : places_memory.as<std::uint32_t>(n + 1);
  auto* first = first_memory.as<std::uint32_t>(buckets);
  ASSERT_EQ(cudaMemcpy(keys, bucket.data(), n * 4, cudaMemcpyHostToDevice), cudaSuccess);
  if (!in_place) ASSERT_EQ(cudaMemset(places, 0xff, (n + 1) * 4), cudaSuccess);  // poisoned
  ASSERT_EQ(cudaMemset(first, 0xab, buckets * 4), cudaSuccess);
  dev::CountingSortArrays at = dev::CountingSortArrays::for_items(n, buckets);
  dev::carve(scratch, [&](dev::Carve& c) { at.take(c); });
  ASSERT_EQ(cudaMemset(scratch.get(), 0xa5, scratch.bytes()), cudaSuccess);  // dirty, as a shared scratch is
  dev::counting_sort(at, n, BucketOf{keys}, PlaceOf{places, keys}, first, kNone, nullptr);
  ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);

  std::vector<std::uint32_t> place(n), got_first(buckets);
  if (n > 0) ASSERT_EQ(cudaMemcpy(place.data(), places, n * 4, cudaMemcpyDeviceToHost), cudaSuccess);
  ASSERT_EQ(cudaMemcpy(got_first.data(), first, buckets * 4, cudaMemcpyDeviceToHost), cudaSuccess);
  for (std::uint32_t k = 0; k < n; ++k) ASSERT_EQ(place[k], want_place[k]) << "item " << k << " of " << n;
  EXPECT_EQ(got_first, want_first);
}

}  // namespace

// Sizes around a warp, a tile (1024) and a block of tiles (8192), over
// one to 252 buckets, uniformly spread.
TEST(CountingSortCuda, StableOnRandomBucketsAroundTheTileSizes) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(41);
  for (const std::uint32_t n : {0u, 1u, 31u, 32u, 33u, 1023u, 1024u, 1025u, 8191u, 8192u, 8193u, 70001u})
    for (const std::uint32_t buckets : {1u, 2u, 66u, 252u}) {
      std::vector<std::uint32_t> bucket(n);
      for (auto& b : bucket) b = static_cast<std::uint32_t>(rng() % buckets);
      expect_stable_places(bucket, buckets, false);
      expect_stable_places(bucket, buckets, true);
    }
}

// Adversarial spreads: all in the last bucket, one item alone in a bucket
// among many of another, runs in descending order, a bucket per warp lane.
TEST(CountingSortCuda, StableOnAdversarialBuckets) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(43);
  const std::uint32_t n = 20000, buckets = 66;
  std::vector<std::uint32_t> last(n, buckets - 1), lone(n, 3), descending(n), lanes(n), skewed(n);
  lone[rng() % n] = 64;
  for (std::uint32_t k = 0; k < n; ++k) {
    descending[k] = buckets - 1 - k * buckets / n;
    lanes[k] = k % 32;
    skewed[k] = rng() % 10 < 9 ? 0 : static_cast<std::uint32_t>(rng() % buckets);
  }
  for (const auto* b : {&last, &lone, &descending, &lanes, &skewed}) {
    expect_stable_places(*b, buckets, false);
    expect_stable_places(*b, buckets, true);
  }
}
