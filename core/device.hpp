// core/device.hpp — is there a CUDA device to run on?
//
// Any failure of the runtime (no driver: error 35, no device, a build without
// CUDA) counts as "no device"; `why` then says which.
#pragma once

#include <cstddef>
#include <string>

namespace marbles {

struct DeviceInfo {
  bool available = false;
  std::string name;       // e.g. "NVIDIA H100 80GB HBM3"
  std::string why_not;    // set when !available
  int multiprocessors = 0;
};

// How one kernel fits a multiprocessor of the device: registers a thread,
// local memory a thread (spills and local arrays; 0 where there are none),
// and blocks of kBlock threads a multiprocessor holds at once.
struct KernelFit {
  int registers = 0;
  std::size_t local_bytes = 0;
  int blocks_per_sm = 0;
};

// True when this build has the CUDA backend compiled in.
bool cuda_compiled();

// Queries device 0 once per process (cached).
const DeviceInfo& cuda_device();

}  // namespace marbles
