// The step benchmark's launch and wait counter (bench/api_count.hpp) against
// a known sequence of CUDA calls: every kind of launch the step makes, and
// every kind of wait; its device timeline against events. Label gpu: skipped
// without a device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <thread>

#include "bench/api_count.hpp"
#include "core/cuda_check.hpp"
#include "core/device.hpp"

namespace {

__global__ void touch(int* x) { x[threadIdx.x] += 1; }

TEST(ApiCounter, CountsEachLaunchAndEachWait) {
  if (!marbles::cuda_device().available) GTEST_SKIP() << "skipped: no CUDA device";
  int* x = nullptr;
  MARBLES_CUDA_CHECK(cudaMalloc(&x, 32 * sizeof(int)));
  MARBLES_CUDA_CHECK(cudaMemset(x, 0, 32 * sizeof(int)));
  cudaStream_t s = nullptr;
  MARBLES_CUDA_CHECK(cudaStreamCreate(&s));
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
  MARBLES_CUDA_CHECK(cudaStreamDestroy(s));
  MARBLES_CUDA_CHECK(cudaFree(x));
}

}  // namespace

namespace {

__global__ void spin(long long cycles) {
  const long long start = clock64();
  while (clock64() - start < cycles) {
  }
}

float elapsed_ms(cudaEvent_t a, cudaEvent_t b) {
  float ms = 0;
  MARBLES_CUDA_CHECK(cudaEventElapsedTime(&ms, a, b));
  return ms;
}

// The timeline's busy time against events: a kernel alone, then a host
// pause, then two kernels at once on two streams (their union, not their
// sum), each kernel spinning about 2 ms.
TEST(DeviceTimeline, BusyIsTheUnionOfTheDevicesWorkAndTheRestIsIdle) {
  if (!marbles::cuda_device().available) GTEST_SKIP() << "skipped: no CUDA device";
  int khz = 0;
  MARBLES_CUDA_CHECK(cudaDeviceGetAttribute(&khz, cudaDevAttrClockRate, 0));
  const long long cycles = 2LL * khz;  // ~2 ms at the base clock
  cudaStream_t s[2] = {};
  cudaEvent_t e[6] = {};
  for (auto& x : s) MARBLES_CUDA_CHECK(cudaStreamCreateWithFlags(&x, cudaStreamNonBlocking));
  for (auto& x : e) MARBLES_CUDA_CHECK(cudaEventCreate(&x));
  spin<<<1, 32, 0, s[0]>>>(1000);  // the module loaded before tracing
  MARBLES_CUDA_CHECK(cudaDeviceSynchronize());

  marbles::bench::DeviceTimeline timeline;
  if (!timeline.tracing()) GTEST_SKIP() << "skipped: CUPTI activity not available (another tool traces, or no CUPTI)";
  const std::uint64_t t0 = timeline.now();
  MARBLES_CUDA_CHECK(cudaEventRecord(e[0], s[0]));
  spin<<<1, 32, 0, s[0]>>>(cycles);
  MARBLES_CUDA_CHECK_LAUNCH();
  MARBLES_CUDA_CHECK(cudaEventRecord(e[1], s[0]));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s[0]));
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  for (int k = 0; k < 2; ++k) {
    MARBLES_CUDA_CHECK(cudaEventRecord(e[2 + 2 * k], s[k]));
    spin<<<1, 32, 0, s[k]>>>(cycles);
    MARBLES_CUDA_CHECK_LAUNCH();
    MARBLES_CUDA_CHECK(cudaEventRecord(e[3 + 2 * k], s[k]));
  }
  MARBLES_CUDA_CHECK(cudaDeviceSynchronize());
  const std::uint64_t t1 = timeline.now();
  const double busy = static_cast<double>(timeline.busy_ns(t0, t1)) * 1e-6;
  const double wall = static_cast<double>(t1 - t0) * 1e-6;

  const double alone = elapsed_ms(e[0], e[1]);
  const double first = elapsed_ms(e[2], e[3]), second = elapsed_ms(e[4], e[5]);
  const double longer = std::max(first, second);
  const double together = std::max(elapsed_ms(e[2], e[5]), elapsed_ms(e[4], e[3]));  // from one's start to the other's end
  EXPECT_GT(alone, 1.0);
  EXPECT_LT(together, first + second - 0.5) << "the two kernels did not overlap: the test proves nothing";
  EXPECT_GE(busy, alone + longer - 0.05);
  EXPECT_LE(busy, alone + std::max(together, longer) + 0.05);
  EXPECT_GE(wall - busy, 5.0 - 0.05);  // the host's pause at least
  // A stretch with none of the work in it is idle throughout.
  EXPECT_EQ(timeline.busy_ns(t1, t1 + 1000000), 0u);
  for (auto& x : e) MARBLES_CUDA_CHECK(cudaEventDestroy(x));
  for (auto& x : s) MARBLES_CUDA_CHECK(cudaStreamDestroy(x));
}

}  // namespace
