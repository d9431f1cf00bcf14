// bench/broadphase_bench_cuda.cu — see broadphase_bench_cuda.hpp.
//
// The copy bandwidth is measured once per process: a 1 GiB device-to-device
// cudaMemcpy, median of 10 after 2 warm-ups, counting bytes read + written.
#include <cuda_runtime.h>

#include <algorithm>
#include <vector>

#include "bench/broadphase_bench_cuda.hpp"
#include "broadphase/broadphase_cuda.hpp"
#include "core/cuda_check.hpp"
#include "core/device.hpp"
#include "core/device_buffer.cuh"

namespace marbles::bench {
namespace {

double measure_copy_bytes_per_ms() {
  static double cached = 0;
  if (cached > 0) return cached;
  const std::size_t bytes = std::size_t(1) << 30;
  ::marbles::cuda::DeviceBuffer from, to;  // freed, as the events are destroyed, however this ends
  void* a = from.reserve(bytes);
  void* b = to.reserve(bytes);
  MARBLES_CUDA_CHECK(cudaMemset(a, 1, bytes));
  const ::marbles::cuda::Event e0, e1;
  std::vector<float> ms;
  for (int k = 0; k < 12; ++k) {
    MARBLES_CUDA_CHECK(cudaEventRecord(e0));
    MARBLES_CUDA_CHECK(cudaMemcpy(b, a, bytes, cudaMemcpyDeviceToDevice));
    MARBLES_CUDA_CHECK(cudaEventRecord(e1));
    MARBLES_CUDA_CHECK(cudaEventSynchronize(e1));
    float t = 0;
    MARBLES_CUDA_CHECK(cudaEventElapsedTime(&t, e0, e1));
    if (k >= 2) ms.push_back(t);
  }
  std::sort(ms.begin(), ms.end());
  cached = 2.0 * double(bytes) / double(ms[ms.size() / 2]);
  return cached;
}

}  // namespace

CudaBenchRun run_cuda_broadphase(const BenchSpheres& s, broadphase::Algorithm algorithm, broadphase::SortKind sort,
                                 int repeats, double margin) {
  CudaBenchRun run;
  const DeviceInfo& dev = cuda_device();
  if (!dev.available) throw RuntimeFailure("no CUDA device (" + dev.why_not + ")");
  run.device = dev.name;
  run.copy_bytes_per_ms = measure_copy_bytes_per_ms();

  const std::size_t n = s.centre.size();
  ::marbles::cuda::DeviceBuffer centre, radius;  // freed however the run ends
  Vec3* c = centre.as<Vec3>(n);
  real* r = radius.as<real>(n);
  MARBLES_CUDA_CHECK(cudaMemcpy(c, s.centre.data(), n * sizeof(Vec3), cudaMemcpyHostToDevice));
  MARBLES_CUDA_CHECK(cudaMemcpy(r, s.radius.data(), n * sizeof(real), cudaMemcpyHostToDevice));
  {
    broadphase::SubdivisionCuda bp(algorithm, sort);
    const SpheresIn view{c, r, n};
    for (int k = 0; k < 3; ++k) bp.find_pairs_device(view, real(margin));  // warm-up: buffers, modules
    for (int k = 0; k < repeats; ++k) {
      bp.find_pairs_device(view, real(margin));
      run.calls.push_back(bp.last_stats());
    }
  }
  return run;
}

}  // namespace marbles::bench
