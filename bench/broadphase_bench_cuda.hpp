// bench/broadphase_bench_cuda.hpp — the CUDA half of the broad-phase
// benchmark (compiled only with MARBLES_HAVE_CUDA): positions uploaded once,
// each call timed with CUDA events, pairs left on the device.
#pragma once

#include <string>
#include <vector>

#include "bench/bench_scenes.hpp"
#include "broadphase/broadphase.hpp"

namespace marbles::bench {

struct CudaBenchRun {
  std::vector<broadphase::Stats> calls;  // one per timed call
  double copy_bytes_per_ms = 0;          // measured device-to-device copy (read + write)
  std::string device;
};

// Throws RuntimeFailure when there is no device.
CudaBenchRun run_cuda_broadphase(const BenchSpheres& spheres, broadphase::Algorithm algorithm, broadphase::SortKind sort,
                                 int repeats, double margin);

}  // namespace marbles::bench
