// core/counting_sort_cuda.cuh — the CUDA twin of core/counting_sort.hpp: a
// stable counting sort over a few hundred buckets at most, which places each
// item (move(k, place, bucket)) without sorting keys and indices: bucket by
// bucket, and within a bucket in item order. The items are cut into tiles of
// kSortTile, a warp each. A warp counts its tile's items per bucket; an
// exclusive scan over the counts, bucket-major, gives each tile's first place
// in each bucket; the warp then walks its tile again, 32 items at a time in
// order, and ranks each item among its equals with __match_any_sync. The
// same places as a stable sort, whatever the launch; no atomics. Its
// temporaries are a count and a place per bucket and tile (2 words per
// bucket and 1024 items) and the scan's storage. Unlike the CPU's it skips
// no item and gives each bucket's first place (or none), not the starts.
// Only .cu files include it.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"

namespace marbles::cuda {

inline constexpr std::uint32_t kSortTile = 1024;         // items a warp counts and places (32 a lane)
inline constexpr std::uint32_t kSortWarps = kBlock / 32;  // warps, so tiles, a block

// A counting sort's temporaries for n items in `buckets` buckets: sized
// once (for_items), then carved by the caller (take, which a carve runs
// twice).
struct CountingSortArrays {
  std::uint32_t buckets = 0, tiles = 0;
  std::uint32_t *count = nullptr, *place = nullptr;  // bucket-major: [b * tiles + t], one more for the total
  void* temp = nullptr;
  std::size_t temp_bytes = 0;

  static CountingSortArrays for_items(std::uint32_t n, std::uint32_t buckets) {
    CountingSortArrays at;
    at.buckets = buckets;
    at.tiles = static_cast<std::uint32_t>((std::uint64_t(n) + kSortTile - 1) / kSortTile);
    at.temp_bytes = exclusive_sum_bytes<std::uint32_t>(at.entries());
    return at;
  }
  std::size_t entries() const { return std::size_t(buckets) * tiles + 1; }
  void take(Carve& c) {
    count = c.take<std::uint32_t>(entries());
    place = c.take<std::uint32_t>(entries());
    temp = c.take<char>(temp_bytes);
  }
};

#if defined(__CUDACC__)
namespace counting_detail {

// The 32 items of a warp's tile from `base` (those below `end`): each
// lane's bucket, its equals among the lanes (a mask), and its rank among
// the equals of lower lanes. A lane past the end takes no bucket's value.
struct LaneItem {
  bool in;
  std::uint32_t bucket;
  unsigned equals, rank;
};
template <class Bucket>
__device__ __forceinline__ LaneItem lane_item(const Bucket& bucket, std::uint32_t k, std::uint32_t end,
                                              unsigned lane) {
  LaneItem it;
  it.in = k < end;
  it.bucket = it.in ? bucket(k) : 0xffffffffu;
  it.equals = __match_any_sync(0xffffffffu, it.bucket);
  it.rank = __popc(it.equals & ((1u << lane) - 1u));
  return it;
}

// This warp's tile: its index, its items [begin, end) and its lane; its
// words of the block's shared memory (buckets a warp).
struct WarpTile {
  std::uint32_t tile, begin, end;
  unsigned lane;
  std::uint32_t* words;
  bool valid;
};
__device__ __forceinline__ WarpTile warp_tile(std::uint32_t n, const CountingSortArrays& at, std::uint32_t* shared) {
  WarpTile w;
  w.lane = threadIdx.x & 31u;
  const unsigned warp = threadIdx.x >> 5;
  w.tile = blockIdx.x * kSortWarps + warp;
  w.valid = w.tile < at.tiles;  // the same for the whole warp
  w.begin = w.tile * kSortTile;
  w.end = n - w.begin < kSortTile ? n : w.begin + kSortTile;  // read only where valid (begin < n)
  w.words = shared + std::size_t(warp) * at.buckets;
  return w;
}

// Count[b * tiles + t]: the items of tile t in bucket b. Shared memory:
// kSortWarps * buckets words.
template <class Bucket>
__global__ void tile_count_kernel(Bucket bucket, std::uint32_t n, CountingSortArrays at) {
  extern __shared__ std::uint32_t shared_count[];
  const WarpTile w = warp_tile(n, at, shared_count);
  if (!w.valid) return;
  const unsigned lane = w.lane;
  std::uint32_t* mine = w.words;
  for (std::uint32_t b = lane; b < at.buckets; b += 32) mine[b] = 0;
  __syncwarp();
  const std::uint32_t tile = w.tile, end = w.end;
  for (std::uint32_t base = w.begin; base < end; base += 32) {
    const LaneItem it = lane_item(bucket, base + lane, end, lane);
    if (it.in && it.rank == 0) mine[it.bucket] += __popc(it.equals);  // one lane of each bucket
    __syncwarp();
  }
  for (std::uint32_t b = lane; b < at.buckets; b += 32) at.count[std::size_t(b) * at.tiles + tile] = mine[b];
  if (tile == 0 && lane == 0) at.count[std::size_t(at.buckets) * at.tiles] = 0;
}

// move(k, place, bucket) for every item of each tile, from the tile's first
// place in each bucket (the scanned counts).
template <class Bucket, class Move>
__global__ void tile_move_kernel(Bucket bucket, Move move, std::uint32_t n, CountingSortArrays at) {
  extern __shared__ std::uint32_t shared_next[];
  const WarpTile w = warp_tile(n, at, shared_next);
  if (!w.valid) return;
  const unsigned lane = w.lane;
  std::uint32_t* next = w.words;
  for (std::uint32_t b = lane; b < at.buckets; b += 32) next[b] = at.place[std::size_t(b) * at.tiles + w.tile];
  __syncwarp();
  const std::uint32_t end = w.end;
  for (std::uint32_t base = w.begin; base < end; base += 32) {
    const LaneItem it = lane_item(bucket, base + lane, end, lane);
    const std::uint32_t place = it.in ? next[it.bucket] + it.rank : 0;
    __syncwarp();
    if (it.in && it.rank == 0) next[it.bucket] += __popc(it.equals);
    __syncwarp();
    if (it.in) move(base + lane, place, it.bucket);
  }
}

// first[b]: the first place of bucket b, `none` where the bucket is empty
// (every bucket, without items: no tiles, nothing counted).
static __global__ void bucket_first_kernel(CountingSortArrays at, std::uint32_t none, std::uint32_t* first) {
  for (std::uint32_t b = blockIdx.x * blockDim.x + threadIdx.x; b < at.buckets; b += gridDim.x * blockDim.x) {
    if (at.tiles == 0) {
      first[b] = none;
      continue;
    }
    const std::uint32_t here = at.place[std::size_t(b) * at.tiles], after = at.place[std::size_t(b + 1) * at.tiles];
    first[b] = after > here ? here : none;
  }
}

}  // namespace counting_detail

// Items [0, n) by bucket(k) < at.buckets (a __device__ functor): move(k,
// place, bucket(k)) puts item k at its place (each k once, in no particular
// order of calls); first[b] gets bucket b's first place, `none` for an
// empty bucket. bucket(k) is read again after move(k', ...) of other items,
// never after move(k, ...): an item's move may overwrite what its own bucket
// is read from. `at` from CountingSortArrays::for_items(n, buckets), taken.
template <class Bucket, class Move>
void counting_sort(const CountingSortArrays& at, std::uint32_t n, const Bucket& bucket, const Move& move,
                   std::uint32_t* first, std::uint32_t none, cudaStream_t s) {
  if (at.buckets == 0) return;
  if (n > 0) {
    const int grid = static_cast<int>((at.tiles + kSortWarps - 1) / kSortWarps);
    const std::size_t shared = std::size_t(kSortWarps) * at.buckets * sizeof(std::uint32_t);
    counting_detail::tile_count_kernel<<<grid, kBlock, shared, s>>>(bucket, n, at);
    MARBLES_CUDA_CHECK_LAUNCH();
    device_exclusive_sum(at.count, at.place, at.entries(), at.temp, at.temp_bytes, s);
    counting_detail::tile_move_kernel<<<grid, kBlock, shared, s>>>(bucket, move, n, at);
    MARBLES_CUDA_CHECK_LAUNCH();
  }
  counting_detail::bucket_first_kernel<<<(at.buckets + kBlock - 1) / kBlock, kBlock, 0, s>>>(at, none, first);
  MARBLES_CUDA_CHECK_LAUNCH();
}
#endif

}  // namespace marbles::cuda
