// broadphase/radix_sort_cuda.cu — the two GPU sorts of (cell key, value).
//
// The seed's radix sort (GPU Gems 3 ch. 32 as the seed report describes it):
// LSD, 8-bit digits, only the passes the keys' used bits need; per pass
//   1. count    each block takes a contiguous tile; its 256 threads form 16
//               groups of 16 that each count a contiguous sub-tile into 256
//               shared counters (counters[256][16 + 1]: the +1 pads the
//               stride against bank conflicts); counts go to global memory
//               digit-major: counts[digit][block * 16 + group];
//   2. radix summation  one block per digit: a work-efficient Blelloch scan
//               (up-sweep, down-sweep) of that digit's row, shared memory
//               padded by one word per 32 against bank conflicts; the row
//               totals are kept;
//   3. reorder  each block Blelloch-scans the 256 totals (padded) into digit
//               bases, loads its groups' counters, and walks its tiles in
//               the same order as the count: in each round the 16 threads
//               of a group take 16 consecutive entries; entries of equal
//               digit are ranked in thread order (warp match), so the sort
//               is stable; keys and values move together.
// The production sort is CUB's DeviceRadixSort::SortPairs over bits
// [0, key_bits), temporary storage grown and reused.
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include "broadphase/broadphase_cuda.cuh"
#include "broadphase/broadphase_cuda.hpp"
#include "core/device.hpp"

namespace marbles::broadphase::cuda {
namespace {

constexpr int kSortThreads = 256;
constexpr int kGroupSize = 16;
constexpr int kGroups = kSortThreads / kGroupSize;  // 16 groups of 16 threads share 256 counters
constexpr int kRadix = 256;
constexpr int kMaxSortBlocks = 512;                  // row length <= 8192
constexpr int kScanThreads = 1024;
constexpr int kLogBanks = 5;

constexpr __host__ __device__ int padded(int i) { return i + (i >> kLogBanks); }

template <class Key>
__device__ __forceinline__ unsigned digit_of(Key k, unsigned shift) {
  return static_cast<unsigned>((k >> shift) & 0xffu);
}

template <class Key>
__global__ void __launch_bounds__(kSortThreads) radix_count_kernel(const Key* __restrict__ keys, std::size_t n,
                                                                  unsigned shift, std::size_t per_group,
                                                                  std::uint32_t* __restrict__ counts) {
  __shared__ std::uint32_t counter[kRadix][kGroups + 1];
  for (int k = threadIdx.x; k < kRadix * (kGroups + 1); k += kSortThreads) (&counter[0][0])[k] = 0;
  __syncthreads();
  const int group = threadIdx.x / kGroupSize, lane = threadIdx.x % kGroupSize;
  const std::size_t g = std::size_t(blockIdx.x) * kGroups + group;
  const std::size_t begin = g * per_group;
  const std::size_t end = min(n, begin + per_group);
  for (std::size_t i = begin + lane; i < end; i += kGroupSize) atomicAdd(&counter[digit_of(keys[i], shift)][group], 1u);
  __syncthreads();
  const std::size_t row = std::size_t(gridDim.x) * kGroups;
  for (int k = threadIdx.x; k < kRadix * kGroups; k += kSortThreads) {
    const int d = k / kGroups, gg = k % kGroups;
    counts[std::size_t(d) * row + std::size_t(blockIdx.x) * kGroups + gg] = counter[d][gg];
  }
}

// Blelloch exclusive scan of s[0, 2 * blockDim.x) (padded indices) in place;
// returns the total to every thread.
__device__ std::uint32_t blelloch_scan(std::uint32_t* s, int size) {
  int offset = 1;
  for (int d = size >> 1; d > 0; d >>= 1) {  // up-sweep
    __syncthreads();
    if (int(threadIdx.x) < d) {
      const int ai = offset * (2 * threadIdx.x + 1) - 1, bi = offset * (2 * threadIdx.x + 2) - 1;
      s[padded(bi)] += s[padded(ai)];
    }
    offset <<= 1;
  }
  __syncthreads();
  const std::uint32_t total = s[padded(size - 1)];
  __syncthreads();
  if (threadIdx.x == 0) s[padded(size - 1)] = 0;
  for (int d = 1; d < size; d <<= 1) {  // down-sweep
    offset >>= 1;
    __syncthreads();
    if (int(threadIdx.x) < d) {
      const int ai = offset * (2 * threadIdx.x + 1) - 1, bi = offset * (2 * threadIdx.x + 2) - 1;
      const std::uint32_t t = s[padded(ai)];
      s[padded(ai)] = s[padded(bi)];
      s[padded(bi)] += t;
    }
  }
  __syncthreads();
  return total;
}

// Radix summation: block d scans row d of counts (length `row`) in place and
// writes its total. Each thread first sums `per` consecutive counters; the
// 2 * 1024 thread sums are Blelloch-scanned; each thread then writes its run.
__global__ void __launch_bounds__(kScanThreads) radix_scan_kernel(std::uint32_t* __restrict__ counts, int row,
                                                                 std::uint32_t* __restrict__ totals) {
  __shared__ std::uint32_t s[padded(2 * kScanThreads) + 1];
  std::uint32_t* r = counts + std::size_t(blockIdx.x) * row;
  const int per = (row + 2 * kScanThreads - 1) / (2 * kScanThreads);
  // two slots per thread, from the two halves (coalesced loads, as the seed does)
  for (int half = 0; half < 2; ++half) {
    const int slot = threadIdx.x + half * kScanThreads;
    std::uint32_t sum = 0;
    for (int k = 0; k < per; ++k) {
      const int i = slot * per + k;
      if (i < row) sum += r[i];
    }
    s[padded(slot)] = sum;
  }
  const std::uint32_t total = blelloch_scan(s, 2 * kScanThreads);
  for (int half = 0; half < 2; ++half) {
    const int slot = threadIdx.x + half * kScanThreads;
    std::uint32_t run = s[padded(slot)];
    for (int k = 0; k < per; ++k) {
      const int i = slot * per + k;
      if (i < row) {
        const std::uint32_t c = r[i];
        r[i] = run;
        run += c;
      }
    }
  }
  if (threadIdx.x == 0) totals[blockIdx.x] = total;
}

template <class Key>
__global__ void __launch_bounds__(kSortThreads) radix_reorder_kernel(
    const Key* __restrict__ keys_in, const std::uint32_t* __restrict__ values_in, Key* __restrict__ keys_out,
    std::uint32_t* __restrict__ values_out, std::size_t n, unsigned shift, std::size_t per_group,
    const std::uint32_t* __restrict__ counts, const std::uint32_t* __restrict__ totals) {
  __shared__ std::uint32_t base[padded(kRadix) + 1];
  __shared__ std::uint32_t counter[kRadix][kGroups + 1];
  // absolute digit offsets: Blelloch scan of the 256 totals (128 threads x 2)
  if (threadIdx.x < kRadix / 2) {
    base[padded(threadIdx.x)] = totals[threadIdx.x];
    base[padded(threadIdx.x + kRadix / 2)] = totals[threadIdx.x + kRadix / 2];
  }
  {
    // blelloch_scan uses threads [0, size / 2); the others only meet the barriers
    blelloch_scan(base, kRadix);
  }
  const std::size_t row = std::size_t(gridDim.x) * kGroups;
  for (int k = threadIdx.x; k < kRadix * kGroups; k += kSortThreads) {
    const int d = k / kGroups, gg = k % kGroups;
    counter[d][gg] = base[padded(d)] + counts[std::size_t(d) * row + std::size_t(blockIdx.x) * kGroups + gg];
  }
  __syncthreads();

  const int group = threadIdx.x / kGroupSize, lane = threadIdx.x % kGroupSize;
  const unsigned warp_lane = threadIdx.x % 32;
  const unsigned half_mask = (warp_lane < 16) ? 0x0000ffffu : 0xffff0000u;
  const std::size_t g = std::size_t(blockIdx.x) * kGroups + group;
  const std::size_t begin = g * per_group;
  const std::size_t end = min(n, begin + per_group);
  const std::size_t rounds = (per_group + kGroupSize - 1) / kGroupSize;  // equal for every group: warp-uniform
  for (std::size_t round = 0; round < rounds; ++round) {
    const std::size_t i = begin + round * kGroupSize + lane;
    const bool valid = i < end;
    Key key = 0;
    std::uint32_t value = 0;
    unsigned d = 0;
    if (valid) {
      key = keys_in[i];
      value = values_in[i];
      d = digit_of(key, shift);
    }
    // peers: lanes of this group with the same digit (invalid lanes match no one)
    const unsigned tag = valid ? (d | (unsigned(group & 1) << 8)) : (0x1000u + warp_lane);
    const unsigned peers = __match_any_sync(0xffffffffu, tag) & half_mask;
    const unsigned rank = __popc(peers & ((1u << warp_lane) - 1u));
    const unsigned leader = __ffs(peers) - 1;
    std::uint32_t at = 0;
    if (valid && warp_lane == leader) {
      at = counter[d][group];
      counter[d][group] = at + __popc(peers);
    }
    at = __shfl_sync(0xffffffffu, at, leader);
    if (valid) {
      keys_out[at + rank] = key;
      values_out[at + rank] = value;
    }
    __syncwarp();
  }
}

}  // namespace

template <class Key>
bool seed_radix_sort(Key* keys, std::uint32_t* values, Key* keys_alt, std::uint32_t* values_alt, std::size_t n,
                     unsigned key_bits, DeviceBuffer& scratch, int sm_count, cudaStream_t stream) {
  if (n < 2 || key_bits == 0) return false;
  // Blocks: enough that each group has ~64 entries, at most kMaxSortBlocks.
  std::size_t blocks = (n + kGroups * 64 - 1) / (kGroups * 64);
  blocks = std::max<std::size_t>(1, std::min<std::size_t>(blocks, kMaxSortBlocks));
  const std::size_t groups = blocks * kGroups;
  std::size_t per_group = (n + groups - 1) / groups;
  per_group = (per_group + kGroupSize - 1) / kGroupSize * kGroupSize;
  const int row = static_cast<int>(groups);
  std::uint32_t* counts = scratch.as<std::uint32_t>(std::size_t(kRadix) * groups + kRadix);
  std::uint32_t* totals = counts + std::size_t(kRadix) * groups;

  bool in_alt = false;
  for (unsigned shift = 0; shift < key_bits && shift < 8 * sizeof(Key); shift += 8) {
    const Key* k_in = in_alt ? keys_alt : keys;
    const std::uint32_t* v_in = in_alt ? values_alt : values;
    Key* k_out = in_alt ? keys : keys_alt;
    std::uint32_t* v_out = in_alt ? values : values_alt;
    radix_count_kernel<Key><<<unsigned(blocks), kSortThreads, 0, stream>>>(k_in, n, shift, per_group, counts);
    MARBLES_CUDA_CHECK_LAUNCH();
    radix_scan_kernel<<<kRadix, kScanThreads, 0, stream>>>(counts, row, totals);
    MARBLES_CUDA_CHECK_LAUNCH();
    radix_reorder_kernel<Key><<<unsigned(blocks), kSortThreads, 0, stream>>>(k_in, v_in, k_out, v_out, n, shift,
                                                                             per_group, counts, totals);
    MARBLES_CUDA_CHECK_LAUNCH();
    in_alt = !in_alt;
  }
  (void)sm_count;
  return in_alt;
}

template <class Key>
bool cub_radix_sort(Key* keys, std::uint32_t* values, Key* keys_alt, std::uint32_t* values_alt, std::size_t n,
                    unsigned key_bits, DeviceBuffer& temp, cudaStream_t stream) {
  if (n < 2 || key_bits == 0) return false;
  cub::DoubleBuffer<Key> k(keys, keys_alt);
  cub::DoubleBuffer<std::uint32_t> v(values, values_alt);
  const int end_bit = static_cast<int>(std::min<unsigned>(key_bits, 8 * sizeof(Key)));
  std::size_t bytes = 0;
  MARBLES_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, bytes, k, v, static_cast<std::int64_t>(n), 0, end_bit,
                                                     stream));
  void* t = temp.reserve(bytes);
  MARBLES_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(t, bytes, k, v, static_cast<std::int64_t>(n), 0, end_bit, stream));
  return k.Current() != keys;
}

void exclusive_sum(const std::uint32_t* in, std::uint32_t* out, std::size_t n, DeviceBuffer& temp,
                   cudaStream_t stream) {
  std::size_t bytes = 0;
  MARBLES_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, bytes, in, out, static_cast<std::int64_t>(n), stream));
  void* t = temp.reserve(bytes);
  MARBLES_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(t, bytes, in, out, static_cast<std::int64_t>(n), stream));
}

template bool seed_radix_sort<std::uint32_t>(std::uint32_t*, std::uint32_t*, std::uint32_t*, std::uint32_t*,
                                             std::size_t, unsigned, DeviceBuffer&, int, cudaStream_t);
template bool seed_radix_sort<std::uint64_t>(std::uint64_t*, std::uint32_t*, std::uint64_t*, std::uint32_t*,
                                             std::size_t, unsigned, DeviceBuffer&, int, cudaStream_t);
template bool cub_radix_sort<std::uint32_t>(std::uint32_t*, std::uint32_t*, std::uint32_t*, std::uint32_t*, std::size_t,
                                            unsigned, DeviceBuffer&, cudaStream_t);
template bool cub_radix_sort<std::uint64_t>(std::uint64_t*, std::uint32_t*, std::uint64_t*, std::uint32_t*, std::size_t,
                                            unsigned, DeviceBuffer&, cudaStream_t);

}  // namespace marbles::broadphase::cuda

namespace marbles::broadphase {
namespace {

template <class Key>
void sort_on_device(std::vector<Key>& keys, std::vector<std::uint32_t>& values, unsigned key_bits, SortKind sort) {
  const DeviceInfo& dev = cuda_device();
  if (!dev.available) throw RuntimeFailure("sort_pairs_cuda: no CUDA device (" + dev.why_not + ")");
  const std::size_t n = keys.size();
  values.resize(n);
  cuda::DeviceBuffer k, ka, v, va, temp;
  Key* d_k = k.as<Key>(n);
  Key* d_ka = ka.as<Key>(n);
  auto* d_v = v.as<std::uint32_t>(n);
  auto* d_va = va.as<std::uint32_t>(n);
  MARBLES_CUDA_CHECK(cudaMemcpy(d_k, keys.data(), n * sizeof(Key), cudaMemcpyHostToDevice));
  MARBLES_CUDA_CHECK(cudaMemcpy(d_v, values.data(), n * sizeof(std::uint32_t), cudaMemcpyHostToDevice));
  const bool alt = sort == SortKind::seed
                       ? cuda::seed_radix_sort<Key>(d_k, d_v, d_ka, d_va, n, key_bits, temp, dev.multiprocessors, nullptr)
                       : cuda::cub_radix_sort<Key>(d_k, d_v, d_ka, d_va, n, key_bits, temp, nullptr);
  MARBLES_CUDA_CHECK(cudaMemcpy(keys.data(), alt ? d_ka : d_k, n * sizeof(Key), cudaMemcpyDeviceToHost));
  MARBLES_CUDA_CHECK(cudaMemcpy(values.data(), alt ? d_va : d_v, n * sizeof(std::uint32_t), cudaMemcpyDeviceToHost));
}

}  // namespace

void sort_pairs_cuda(std::vector<std::uint32_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                     SortKind sort) {
  sort_on_device(keys, values, key_bits, sort);
}
void sort_pairs_cuda(std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                     SortKind sort) {
  sort_on_device(keys, values, key_bits, sort);
}

}  // namespace marbles::broadphase
