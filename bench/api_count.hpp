// bench/api_count.hpp — what the host asks of the GPU, counted as it asks:
// kernel launches and host waits (stream, event and device synchronizes,
// synchronous copies, frees), through CUPTI's callbacks on the CUDA runtime,
// and the host's time within each runtime function. The step benchmark's
// launches, host waits and host time in the runtime per step.
//
// Counting is process-wide and costs a call per runtime call, so it is on
// only while an ApiCounter lives, and never over timed steps. Without CUPTI
// (a build with no CUDA) or where another tool holds CUPTI's one subscriber
// (Nsight Compute, compute-sanitizer), counting() is false and nothing is
// counted.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace marbles::bench {

struct ApiCounts {
  std::uint64_t launches = 0;  // kernels launched one by one (plain, extended, cooperative; CUB's each), not graphs
  std::uint64_t waits = 0;     // calls that block the host until the device is done with earlier work
};

// The host's time within one CUDA runtime function (from its entry to its
// return, as CUPTI's callbacks see them), and its calls.
struct ApiTime {
  std::string function;  // as the runtime names it: cudaLaunchKernel, cudaStreamSynchronize, ...
  std::uint64_t calls = 0;
  std::uint64_t ns = 0;
};

// The device's time in one kernel (or in every set, or every copy) over a
// stretch: its launches and the sum of their durations on the device.
struct KernelTime {
  std::string kernel;  // demangled, without its parameters; "(memset)" and "(memcpy)" for sets and copies
  std::uint64_t launches = 0;
  std::uint64_t ns = 0;
};

class ApiCounter {
 public:
  ApiCounter();
  ~ApiCounter();
  ApiCounter(const ApiCounter&) = delete;
  ApiCounter& operator=(const ApiCounter&) = delete;

  bool counting() const { return m_subscriber != nullptr; }
  ApiCounts counts() const;  // since this counter began
  // Since this counter began, each runtime function called, most time first.
  std::vector<ApiTime> host_times() const;

 private:
  void* m_subscriber = nullptr;
};

// The device's busy time over a stretch of host time, from CUPTI's activity
// records of kernels, copies and sets: the union of their intervals. The rest
// of the stretch the device waited for the host (its launches, its waits).
// Tracing is on only while a DeviceTimeline lives, one at a time; tracing()
// is false without CUPTI, where a tool already traces (Nsight Compute,
// compute-sanitizer) or while another DeviceTimeline lives.
class DeviceTimeline {
 public:
  DeviceTimeline();
  ~DeviceTimeline();
  DeviceTimeline(const DeviceTimeline&) = delete;
  DeviceTimeline& operator=(const DeviceTimeline&) = delete;

  bool tracing() const { return m_on; }
  // No record was dropped so far (a full buffer would make busy_ns short).
  bool complete() const;
  std::uint64_t now() const;  // ns, on the records' clock
  // The device's work that began in [t0, t1), as the length of the union of
  // its intervals (ns). Flushes the records first: call it once the work is done.
  std::uint64_t busy_ns(std::uint64_t t0, std::uint64_t t1);
  // The same stretch's work by kernel (sets and copies each as one), most
  // time first. Their times add up to busy_ns where nothing ran at once.
  std::vector<KernelTime> kernels(std::uint64_t t0, std::uint64_t t1);

 private:
  bool m_on = false;
};

// A profiler's window (cudaProfilerStart / cudaProfilerStop): the steps
// between on and off are the ones a profiler started with its collection
// off (`ncu --profile-from-start off`) looks at. No-op without CUDA.
void profiled_steps(bool on);

}  // namespace marbles::bench
