// The step benchmark's launch and wait counter (bench/api_count.hpp) against
// a known sequence of CUDA calls: every kind of launch the step makes, and
// every kind of wait. Label gpu: skipped without a device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

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
