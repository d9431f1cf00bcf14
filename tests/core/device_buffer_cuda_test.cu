// core/device_memory.hpp's DeviceBuffer::reserve_keeping: a buffer grown
// keeps its first bytes (random contents, read back), a buffer that fits
// is not moved, and a stream-ordered buffer grows in its stream's order;
// reserve_copying hands the old memory to its copy where it grows;
// DeviceBuffer::trim frees exactly what the last asks left over, and
// release frees whatever was asked, the buffer still of its kind; the
// barriers of one launch (core/device_buffer.cuh GridSync, ClusterSync)
// let every thread read what other blocks wrote before them.
// Label `gpu`; every case skips, saying so, without a CUDA device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include "core/device_buffer.cuh"
#include "core/device_memory.hpp"
#include "tests/require_device.hpp"

namespace dev = ::marbles::cuda;

namespace {

std::vector<std::uint32_t> random_words(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<std::uint32_t> v(n);
  for (std::uint32_t& w : v) w = static_cast<std::uint32_t>(rng());
  return v;
}

// A buffer of `first` words filled, grown to `grown` words keeping `kept`.
void expect_kept(dev::DeviceBuffer& buffer, cudaStream_t s, std::size_t first, std::size_t kept, std::size_t grown,
                 std::uint64_t seed) {
  const std::vector<std::uint32_t> words = random_words(first, seed);
  auto* at = buffer.as_room<std::uint32_t>(first);
  ASSERT_EQ(cudaStreamSynchronize(s), cudaSuccess);  // a stream-ordered allocation, used from the default stream
  ASSERT_EQ(cudaMemcpy(at, words.data(), first * 4, cudaMemcpyHostToDevice), cudaSuccess);
  // A copy from pageable memory may return before its last DMA lands, and
  // the stream below does not wait for the default stream's work.
  ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  void* moved = buffer.reserve_keeping(grown * 4, kept * 4, s);
  ASSERT_NE(moved, nullptr);
  EXPECT_GE(buffer.bytes(), grown * 4);
  std::vector<std::uint32_t> back(kept, 0);
  ASSERT_EQ(cudaStreamSynchronize(s), cudaSuccess);
  ASSERT_EQ(cudaMemcpy(back.data(), moved, kept * 4, cudaMemcpyDeviceToHost), cudaSuccess);
  for (std::size_t i = 0; i < kept; ++i) ASSERT_EQ(back[i], words[i]) << "word " << i << " of " << kept;
}

}  // namespace

TEST(DeviceBuffer, ReserveKeepingKeepsTheFirstBytesWhereItGrows) {
  REQUIRE_DEVICE();
  dev::Stream stream;
  stream.create(cudaStreamNonBlocking);
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const std::size_t first = 1 + rng() % 100000, kept = 1 + rng() % first, grown = first + 1 + rng() % 300000;
    dev::DeviceBuffer plain;
    expect_kept(plain, stream, first, kept, grown, rng());
    dev::DeviceBuffer ordered(stream);
    expect_kept(ordered, stream, first, kept, grown, rng());
  }
}

TEST(DeviceBuffer, ReserveKeepingLeavesABufferThatFits) {
  REQUIRE_DEVICE();
  dev::DeviceBuffer buffer;
  void* at = buffer.reserve(4096, false);
  EXPECT_EQ(buffer.reserve_keeping(4096, 4096, nullptr), at);
  EXPECT_EQ(buffer.reserve_keeping(100, 100, nullptr), at);
  EXPECT_EQ(buffer.bytes(), 4096u);
}

// reserve_copying: where a buffer that holds memory grows, the callback is
// handed the new memory, the old and the bytes the old held, once, and what
// it copies is there after; where it fits or held nothing, no call. The
// most bytes asked of it count the new ask.
TEST(DeviceBuffer, ReserveCopyingHandsTheOldMemoryOverWhereItGrows) {
  REQUIRE_DEVICE();
  dev::Stream stream;
  stream.create(cudaStreamNonBlocking);
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 10; ++trial) {
    const std::size_t first = 1 + rng() % 50000, part = rng() % (first + 1);
    dev::DeviceBuffer buffer;
    int calls = 0;
    auto count_calls = [&](void*, const void*, std::size_t) { ++calls; };
    ASSERT_NE(buffer.reserve_copying(first * 4, stream, count_calls), nullptr);
    EXPECT_EQ(calls, 0) << "no memory held: nothing to hand over";
    const std::vector<std::uint32_t> words = random_words(first, rng());
    void* old = buffer.get();
    const std::size_t held = buffer.bytes(), grown = held / 4 + 1 + rng() % 100000;  // words: past what it holds
    ASSERT_EQ(cudaMemcpy(old, words.data(), first * 4, cudaMemcpyHostToDevice), cudaSuccess);
    ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
    EXPECT_EQ(buffer.reserve_copying(held, stream, count_calls), old) << "fits: not moved";
    EXPECT_EQ(calls, 0);
    void* handed_to = nullptr;
    void* moved = buffer.reserve_copying(grown * 4, stream, [&](void* to, const void* from, std::size_t bytes) {
      ++calls;
      handed_to = to;
      EXPECT_EQ(from, old);
      EXPECT_EQ(bytes, held);
      ASSERT_EQ(cudaMemcpyAsync(to, from, part * 4, cudaMemcpyDeviceToDevice, stream), cudaSuccess);
    });
    EXPECT_EQ(calls, 1);
    EXPECT_EQ(moved, handed_to);
    EXPECT_EQ(buffer.get(), moved);
    EXPECT_GE(buffer.bytes(), grown * 4);
    EXPECT_EQ(buffer.asked(), grown * 4);
    std::vector<std::uint32_t> back(part, 0);
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
    if (part > 0) ASSERT_EQ(cudaMemcpy(back.data(), moved, part * 4, cudaMemcpyDeviceToHost), cudaSuccess);
    for (std::size_t i = 0; i < part; ++i) ASSERT_EQ(back[i], words[i]) << "word " << i << " of " << part;
  }
}

// trim(): over random windows of asks (some far below what the buffer
// holds, some near it), the buffer is freed exactly where it holds more
// than an eighth and kTrimSlack beyond the window's largest ask (counted
// here from the asks themselves), kept untouched otherwise, and grows again
// to fit; the asks are counted afresh after each trim. Plain and
// stream-ordered buffers alike.
TEST(DeviceBuffer, TrimFreesWhatTheLastNeedLeftOver) {
  REQUIRE_DEVICE();
  dev::Stream stream;
  stream.create(cudaStreamNonBlocking);
  std::mt19937_64 rng(11);
  dev::DeviceBuffer plain, ordered(stream);
  for (dev::DeviceBuffer* b : {&plain, &ordered}) {
    dev::DeviceBuffer& buffer = *b;
    std::size_t freed = 0, kept = 0;
    for (int window = 0; window < 200; ++window) {
      // Asks around a level that jumps now and then (a transient, a fall).
      const std::size_t level = std::size_t{1} << (8 + rng() % 14);
      std::size_t largest = 0;
      const int asks = static_cast<int>(rng() % 4);  // a window may ask nothing
      for (int k = 0; k < asks; ++k) {
        const std::size_t bytes = level / 2 + rng() % level;
        largest = std::max(largest, bytes);
        auto* p = static_cast<unsigned char*>(buffer.reserve(bytes, rng() % 2 == 0));
        ASSERT_NE(p, nullptr);
        ASSERT_GE(buffer.bytes(), bytes);
        ASSERT_EQ(cudaMemsetAsync(p, 0x5a, bytes, stream), cudaSuccess);  // the memory is the buffer's, all of it
      }
      ASSERT_EQ(buffer.asked(), largest);
      const std::size_t held = buffer.bytes();
      const void* at = buffer.get();
      const bool over = held > largest + largest / 8 + dev::DeviceBuffer::kTrimSlack;
      ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
      const bool trimmed = buffer.trim();
      ASSERT_EQ(trimmed, over && held > 0) << "window " << window << ": held " << held << ", asked " << largest;
      if (trimmed) {
        EXPECT_EQ(buffer.bytes(), 0u);
        EXPECT_EQ(buffer.get(), nullptr);
        ++freed;
      } else {
        EXPECT_EQ(buffer.bytes(), held);
        EXPECT_EQ(buffer.get(), at);
        kept += held > 0 ? 1 : 0;
      }
      EXPECT_EQ(buffer.asked(), 0u);
    }
    EXPECT_GT(freed, 10u) << "the random levels should fall often";
    EXPECT_GT(kept, 10u) << "and often stay";
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
  }
}

// release(): the memory freed whatever was asked, the asks counted afresh,
// and the buffer still takes its memory as it did (a stream-ordered one in
// its stream's order: swapped with an empty buffer it would not be), and
// grows again to fit. Plain and stream-ordered buffers, held or empty.
TEST(DeviceBuffer, ReleaseFreesAndKeepsTheWayItTakesMemory) {
  REQUIRE_DEVICE();
  dev::Stream stream;
  stream.create(cudaStreamNonBlocking);
  dev::DeviceBuffer plain, ordered(stream);
  for (dev::DeviceBuffer* b : {&plain, &ordered}) {
    dev::DeviceBuffer& buffer = *b;
    const bool was_ordered = buffer.stream_ordered();
    for (const std::size_t bytes : {std::size_t{0}, std::size_t{1000}, std::size_t{1} << 20}) {
      if (bytes > 0) {
        auto* p = static_cast<unsigned char*>(buffer.reserve(bytes));
        ASSERT_NE(p, nullptr);
        ASSERT_EQ(cudaMemsetAsync(p, 0x5a, bytes, stream), cudaSuccess);
        ASSERT_EQ(buffer.asked(), bytes);
      }
      buffer.release();
      EXPECT_EQ(buffer.get(), nullptr);
      EXPECT_EQ(buffer.bytes(), 0u);
      EXPECT_EQ(buffer.asked(), 0u);
      EXPECT_EQ(buffer.stream_ordered(), was_ordered) << "after " << bytes << " bytes";
    }
    auto* again = static_cast<unsigned char*>(buffer.reserve(4096));
    ASSERT_NE(again, nullptr);
    EXPECT_GE(buffer.bytes(), 4096u);
    ASSERT_EQ(cudaMemsetAsync(again, 0, 4096, stream), cudaSuccess);
    ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
  }
  EXPECT_FALSE(plain.stream_ordered());
  std::printf("a stream's buffer is %s\n", ordered.stream_ordered() ? "stream-ordered" : "plain (no memory pools)");
}

namespace {

// Each round r, thread w of the launch writes r * n + w into word w +
// shift (mod n), shift being 1 to gridDim.x - 1 blocks' worth of threads in
// turn (so a word of another block's threads, never its own), meets the
// others at the barrier, reads its own word t, which thread t - shift (mod
// n) wrote, and meets them again before the next round's writes. A read
// that missed a write (a stale copy in the SM's L1, the barrier not
// ordering the write before it) counts in tally[0], a read that saw it in
// tally[1]. Word t was read, and so may be cached, in the round before,
// with another block's value.
template <class Sync>
__global__ void exchange_kernel(unsigned* words, int rounds, unsigned long long* tally) {
  const Sync barrier;
  const unsigned n = gridDim.x * blockDim.x, t = blockIdx.x * blockDim.x + threadIdx.x;
  unsigned long long missed = 0, seen = 0;
  for (int r = 1; r <= rounds; ++r) {
    const unsigned shift = (1 + static_cast<unsigned>(r - 1) % (gridDim.x - 1)) * blockDim.x;  // gridDim.x >= 2
    words[(t + shift) % n] = static_cast<unsigned>(r) * n + t;
    barrier.sync();
    const unsigned writer = (t + n - shift) % n;
    if (words[t] != static_cast<unsigned>(r) * n + writer) ++missed;
    else ++seen;
    barrier.sync();
  }
  atomicAdd(tally, missed);
  atomicAdd(tally + 1, seen);
}

// Runs exchange_kernel<Sync> on `blocks` blocks launched `how`: the reads
// that missed a write; every read is counted, missed or seen.
template <class Sync>
unsigned long long missed_reads(dev::Launch how, int blocks, int rounds) {
  const std::size_t n = std::size_t(blocks) * dev::kBlock;
  dev::DeviceBuffer memory, counts;
  auto* words = memory.as<unsigned>(n);
  auto* tally = counts.as<unsigned long long>(2);
  EXPECT_EQ(cudaMemset(words, 0xff, n * sizeof(unsigned)), cudaSuccess);
  EXPECT_EQ(cudaMemset(tally, 0, 2 * sizeof(unsigned long long)), cudaSuccess);
  dev::launch(how, exchange_kernel<Sync>, blocks, nullptr, words, rounds, tally);
  unsigned long long got[2] = {~0ull, 0};
  EXPECT_EQ(cudaMemcpy(got, tally, sizeof got, cudaMemcpyDeviceToHost), cudaSuccess);
  EXPECT_EQ(got[0] + got[1], n * static_cast<unsigned long long>(rounds)) << "not every read was counted";
  return got[0];
}

TEST(Barriers, EveryReadAfterTheGridsBarrierSeesTheWritesBeforeIt) {
  REQUIRE_DEVICE();
  const int blocks = dev::grid_for(std::size_t(1) << 30, ::marbles::cuda_device().multiprocessors,
                                   dev::resident_blocks<exchange_kernel<dev::GridSync>>());
  ASSERT_GT(blocks, 1) << "one block: no other block's writes to see";
  EXPECT_EQ(missed_reads<dev::GridSync>(dev::Launch::cooperative, blocks, 200), 0ull) << blocks << " blocks";
}

TEST(Barriers, EveryReadAfterTheClustersBarrierSeesTheWritesBeforeIt) {
  REQUIRE_DEVICE();
  const int most = dev::largest_cluster<exchange_kernel<dev::ClusterSync>>();
  if (most == 0) GTEST_SKIP() << "skipped: no cluster launches here (compute capability below 9, or no sm_90 code)";
  ASSERT_GT(most, 1) << "a cluster of one block: no other block's writes to see";
  // Every size the stages launch (launch_one: as many blocks as a range
  // asks for, up to the most).
  for (int blocks = 2; blocks <= most; ++blocks)
    EXPECT_EQ(missed_reads<dev::ClusterSync>(dev::Launch::cluster, blocks, 2000), 0ull) << blocks << " blocks";
}

}  // namespace
