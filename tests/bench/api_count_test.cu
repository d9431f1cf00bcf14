// The step benchmark's launch and wait counter (bench/api_count.hpp) against
// a known sequence of CUDA calls: every kind of launch the step makes, and
// every kind of wait; its device timeline against events. Label gpu: skipped
// without a device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <thread>

#include "bench/api_count.hpp"
#include "core/cuda_check.hpp"
#include "core/device_buffer.cuh"
#include "core/device.hpp"
#include "tests/require_device.hpp"

namespace {

__global__ void touch(int* x) { x[threadIdx.x] += 1; }

TEST(ApiCounter, CountsEachLaunchAndEachWait) {
  REQUIRE_DEVICE();
  marbles::cuda::DeviceBuffer memory;  // freed, as the stream is destroyed, however the test ends
  int* x = memory.as<int>(32);
  MARBLES_CUDA_CHECK(cudaMemset(x, 0, 32 * sizeof(int)));
  marbles::cuda::Stream s;
  s.create();
  marbles::bench::ApiCounter counter;
  if (!counter.counting()) GTEST_SKIP() << "skipped: CUPTI not available (another tool holds it, or no CUPTI)";
  const marbles::bench::ApiCounts start = counter.counts();
  // Launches: 3 plain, 2 extended, 1 cooperative; no waits between them.
  for (int k = 0; k < 3; ++k) touch<<<1, 32, 0, s>>>(x);
  cudaLaunchConfig_t config{};
  config.gridDim = dim3(1);
  config.blockDim = dim3(32);
  config.stream = s;
  for (int k = 0; k < 2; ++k) MARBLES_CUDA_CHECK(cudaLaunchKernelEx(&config, touch, x));
  void* args[] = {&x};
  MARBLES_CUDA_CHECK(cudaLaunchCooperativeKernel(reinterpret_cast<const void*>(&touch), dim3(1), dim3(32), args, 0, s));
  const marbles::bench::ApiCounts launched = counter.counts();
  EXPECT_EQ(launched.launches - start.launches, 6u);
  EXPECT_EQ(launched.waits - start.waits, 0u);
  // Waits: a stream synchronize, a synchronous copy, a device synchronize.
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  int host[32];
  MARBLES_CUDA_CHECK(cudaMemcpy(host, x, sizeof host, cudaMemcpyDeviceToHost));
  MARBLES_CUDA_CHECK(cudaDeviceSynchronize());
  const marbles::bench::ApiCounts end = counter.counts();
  EXPECT_EQ(end.launches - start.launches, 6u);
  EXPECT_EQ(end.waits - start.waits, 3u);
  for (int v : host) EXPECT_EQ(v, 6);  // every launch ran
}

}  // namespace

namespace {

std::uint64_t __device__ global_ns() {
  std::uint64_t t = 0;
  asm volatile("mov.u64 %0, %%globaltimer;" : "=l"(t));
  return t;
}

// Spins for about `ns` on the device's global timer and writes when it began
// and ended, on that timer.
__device__ void spin_for(std::uint64_t ns, std::uint64_t* began_ended) {
  const std::uint64_t start = global_ns();
  std::uint64_t now = start;
  while (now - start < ns) now = global_ns();
  began_ended[0] = start;
  began_ended[1] = now;
}
__global__ void spin(std::uint64_t ns, std::uint64_t* began_ended) { spin_for(ns, began_ended); }

// The timeline's busy time against the kernels' own clocks: a kernel alone,
// then a host pause, then two kernels at once on two streams (their union,
// not their sum), each spinning 2 ms.
TEST(DeviceTimeline, BusyIsTheUnionOfTheDevicesWorkAndTheRestIsIdle) {
  REQUIRE_DEVICE();
  constexpr std::uint64_t kSpin = 2000000;
  marbles::cuda::DeviceBuffer memory;  // freed, as the streams are destroyed, however the test ends
  auto* times = memory.as<std::uint64_t>(6);  // [began, ended] of each of the three kernels
  marbles::cuda::Stream s[2];
  for (auto& x : s) x.create(cudaStreamNonBlocking);
  spin<<<1, 32, 0, s[0]>>>(1000, times);  // the module loaded before tracing
  MARBLES_CUDA_CHECK(cudaDeviceSynchronize());

  marbles::bench::DeviceTimeline timeline;
  if (!timeline.tracing()) GTEST_SKIP() << "skipped: CUPTI activity not available (another tool traces, or no CUPTI)";
  const std::uint64_t t0 = timeline.now();
  spin<<<1, 32, 0, s[0]>>>(kSpin, times);
  MARBLES_CUDA_CHECK_LAUNCH();
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s[0]));
  const std::uint64_t between = timeline.now();
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  for (int k = 0; k < 2; ++k) {
    spin<<<1, 32, 0, s[k]>>>(kSpin, times + 2 + 2 * k);
    MARBLES_CUDA_CHECK_LAUNCH();
  }
  MARBLES_CUDA_CHECK(cudaDeviceSynchronize());
  const std::uint64_t t1 = timeline.now();
  const double busy = static_cast<double>(timeline.busy_ns(t0, t1)) * 1e-6;
  const double wall = static_cast<double>(t1 - t0) * 1e-6;
  const double first_part = static_cast<double>(timeline.busy_ns(t0, between)) * 1e-6;
  const double second_part = static_cast<double>(timeline.busy_ns(between, t1)) * 1e-6;

  std::uint64_t t[6] = {};
  MARBLES_CUDA_CHECK(cudaMemcpy(t, times, sizeof t, cudaMemcpyDeviceToHost));
  const double alone = static_cast<double>(t[1] - t[0]) * 1e-6;
  const double sum = static_cast<double>(t[3] - t[2] + t[5] - t[4]) * 1e-6;
  const double both = static_cast<double>(std::max(t[3], t[5]) - std::min(t[2], t[4])) * 1e-6;  // their union
  const std::string seen = "alone " + std::to_string(alone) + " ms, the two " + std::to_string(both) + " ms together (" +
                           std::to_string(sum) + " summed), busy " + std::to_string(busy) + " ms of " +
                           std::to_string(wall);
  ASSERT_LT(both, sum - 0.5) << "the two kernels did not overlap: the test proves nothing; " << seen;
  // Each kernel's record spans its launch on the device as well as its own
  // clock's span: a few microseconds more.
  EXPECT_GE(busy, alone + both - 0.01) << seen;
  EXPECT_LE(busy, alone + both + 0.1) << seen;
  EXPECT_GE(wall - busy, 5.0 - 0.05) << seen;  // the host's pause at least
  // A stretch holds the work that began in it: the kernel alone, then the two.
  EXPECT_NEAR(first_part, alone, 0.05) << seen;
  EXPECT_NEAR(second_part, both, 0.05) << seen;
  EXPECT_NEAR(first_part + second_part, busy, 1e-9) << seen;
  EXPECT_TRUE(timeline.complete());
  // Tracing is process-wide: a second timeline traces nothing while this one lives.
  marbles::bench::DeviceTimeline second;
  EXPECT_FALSE(second.tracing());
}

// The timeline by kernel against a known sequence: three launches of one
// kernel spinning 1 ms each, two of another kernel, and a set, on one
// stream; each kernel's launches counted, its time its spins' (measured on
// the device's own clock), the set as "(memset)", the kernels named without
// their parameters, and the parts adding up to the busy time (nothing ran
// at once).
__global__ void spin_other(std::uint64_t ns, std::uint64_t* began_ended) { spin_for(ns, began_ended); }

TEST(DeviceTimeline, ByKernelCountsEachKernelsLaunchesAndTime) {
  REQUIRE_DEVICE();
  constexpr std::uint64_t kSpin = 1000000;
  marbles::cuda::DeviceBuffer memory;  // freed, as the stream is destroyed, however the test ends
  auto* times = memory.as<std::uint64_t>(12);  // [began, ended] of each of the five kernels, two words set
  marbles::cuda::Stream s;
  s.create(cudaStreamNonBlocking);
  spin<<<1, 32, 0, s>>>(1000, times);  // the module loaded before tracing
  spin_other<<<1, 32, 0, s>>>(1000, times);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));

  marbles::bench::DeviceTimeline timeline;
  if (!timeline.tracing()) GTEST_SKIP() << "skipped: CUPTI activity not available (another tool traces, or no CUPTI)";
  const std::uint64_t t0 = timeline.now();
  for (int k = 0; k < 3; ++k) spin<<<1, 32, 0, s>>>(kSpin, times + 2 * k);
  MARBLES_CUDA_CHECK(cudaMemsetAsync(times + 10, 0, 2 * sizeof(std::uint64_t), s));
  for (int k = 3; k < 5; ++k) spin_other<<<1, 32, 0, s>>>(kSpin, times + 2 * k);
  MARBLES_CUDA_CHECK_LAUNCH();
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  const std::uint64_t t1 = timeline.now();
  std::uint64_t t[10] = {};
  MARBLES_CUDA_CHECK(cudaMemcpy(t, times, sizeof t, cudaMemcpyDeviceToHost));  // after t1: not in the stretch
  const double busy = static_cast<double>(timeline.busy_ns(t0, t1));
  const std::vector<marbles::bench::KernelTime> kernels = timeline.kernels(t0, t1);
  double own[2] = {0, 0};  // each kernel's spins, on the device's clock
  for (int k = 0; k < 5; ++k) own[k < 3 ? 0 : 1] += static_cast<double>(t[2 * k + 1] - t[2 * k]);

  std::string seen;
  for (const auto& k : kernels) seen += k.kernel + " " + std::to_string(k.launches) + "x " + std::to_string(k.ns) + " ns; ";
  const auto find = [&](const std::string& name) -> const marbles::bench::KernelTime* {
    for (const auto& k : kernels)
      if (k.kernel == name) return &k;
    return nullptr;
  };
  const auto* a = find("spin");
  const auto* b = find("spin_other");
  const auto* set = find("(memset)");
  ASSERT_NE(a, nullptr) << seen;
  ASSERT_NE(b, nullptr) << seen;
  ASSERT_NE(set, nullptr) << seen;
  EXPECT_EQ(set->launches, 1u) << seen;
  EXPECT_EQ(a->launches, 3u) << seen;
  EXPECT_EQ(b->launches, 2u) << seen;
  // A record spans its kernel's own clock and its launch on the device: a few
  // microseconds more a launch, never less.
  EXPECT_GE(static_cast<double>(a->ns), own[0] - 10000) << seen;
  EXPECT_LE(static_cast<double>(a->ns), own[0] + 3 * 50000) << seen;
  EXPECT_GE(static_cast<double>(b->ns), own[1] - 10000) << seen;
  EXPECT_LE(static_cast<double>(b->ns), own[1] + 2 * 50000) << seen;
  // Most time first. Which kernel that is depends on the spins' own times:
  // the gpu tests run side by side, and another process's work on the
  // device can stretch a spin (spin_other's two once took 4.0 ms against
  // spin's three 3.0), so the order is held to the times, not to the names.
  for (std::size_t k = 1; k < kernels.size(); ++k)
    EXPECT_GE(kernels[k - 1].ns, kernels[k].ns) << "most time first: " << seen;
  if (std::fabs(own[0] - own[1]) > 3 * 50000)  // apart by more than a record's slack
    EXPECT_EQ(kernels.front().kernel, own[0] > own[1] ? "spin" : "spin_other") << seen;
  double sum = 0;
  for (const auto& k : kernels) {
    EXPECT_TRUE(k.kernel == "spin" || k.kernel == "spin_other" || k.kernel == "(memset)") << seen;
    sum += static_cast<double>(k.ns);
  }
  EXPECT_NEAR(sum, busy, 10000) << "one stream, nothing at once: the parts add up to the busy time; " << seen;
  EXPECT_TRUE(timeline.complete());
}

// The host's time within each runtime function against a known wait: a
// stream synchronize behind a kernel that spins 2 ms holds the host at least
// the spin's rest; three launches are three launch calls; and no function's
// time exceeds the wall time around them all.
TEST(ApiCounter, TimesTheHostWithinEachRuntimeFunction) {
  REQUIRE_DEVICE();
  constexpr std::uint64_t kSpin = 2000000;
  marbles::cuda::DeviceBuffer memory;  // freed, as the stream is destroyed, however the test ends
  auto* times = memory.as<std::uint64_t>(2);
  marbles::cuda::Stream s;
  s.create();
  spin<<<1, 32, 0, s>>>(1000, times);  // the module loaded before counting
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  marbles::bench::ApiCounter counter;
  if (!counter.counting()) GTEST_SKIP() << "skipped: CUPTI not available (another tool holds it, or no CUPTI)";
  const auto t0 = std::chrono::steady_clock::now();
  for (int k = 0; k < 2; ++k) spin<<<1, 32, 0, s>>>(1000, times);
  spin<<<1, 32, 0, s>>>(kSpin, times);
  const auto launched = std::chrono::steady_clock::now();
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  const auto t1 = std::chrono::steady_clock::now();
  const double wall_ns = std::chrono::duration<double, std::nano>(t1 - t0).count();
  const double rest_ns = 2e6 - std::chrono::duration<double, std::nano>(launched - t0).count();

  std::uint64_t launch_calls = 0, sync_calls = 0;
  double sync_ns = 0;
  std::string seen;
  for (const marbles::bench::ApiTime& t : counter.host_times()) {
    seen += t.function + " " + std::to_string(t.calls) + " calls " + std::to_string(t.ns) + " ns; ";
    EXPECT_LE(static_cast<double>(t.ns), wall_ns) << t.function;
    if (t.function.find("LaunchKernel") != std::string::npos) launch_calls += t.calls;
    if (t.function == "cudaStreamSynchronize") sync_calls += t.calls, sync_ns += static_cast<double>(t.ns);
  }
  EXPECT_EQ(launch_calls, 3u) << seen;
  EXPECT_EQ(sync_calls, 1u) << seen;
  EXPECT_GE(sync_ns, rest_ns - 50000) << seen;  // the spin's rest, less its launch on the device
  EXPECT_LE(sync_ns, wall_ns) << seen;
}

}  // namespace
