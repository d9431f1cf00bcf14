// bench/api_count.hpp — what the host asks of the GPU, counted as it asks:
// kernel launches and host waits (stream, event and device synchronizes,
// synchronous copies, frees), through CUPTI's callbacks on the CUDA runtime.
// The step benchmark's launches and host waits per step.
//
// Counting is process-wide and costs a call per runtime call, so it is on
// only while an ApiCounter lives, and never over timed steps. Without CUPTI
// (a build with no CUDA) or where another tool holds CUPTI's one subscriber
// (Nsight Compute, compute-sanitizer), counting() is false and nothing is
// counted.
#pragma once

#include <cstdint>

namespace marbles::bench {

struct ApiCounts {
  std::uint64_t launches = 0;  // kernels launched one by one (plain, extended, cooperative; CUB's each), not graphs
  std::uint64_t waits = 0;     // calls that block the host until the device is done with earlier work
};

class ApiCounter {
 public:
  ApiCounter();
  ~ApiCounter();
  ApiCounter(const ApiCounter&) = delete;
  ApiCounter& operator=(const ApiCounter&) = delete;

  bool counting() const { return m_subscriber != nullptr; }
  ApiCounts counts() const;  // since this counter began

 private:
  void* m_subscriber = nullptr;
};

// A profiler's window (cudaProfilerStart / cudaProfilerStop): the steps
// between on and off are the ones a profiler started with its collection
// off (`ncu --profile-from-start off`) looks at. No-op without CUDA.
void profiled_steps(bool on);

}  // namespace marbles::bench
