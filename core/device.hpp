// core/device.hpp — is there a CUDA device to run on?
//
// Any failure of the runtime (no driver: error 35, no device, a build without
// CUDA) counts as "no device"; `why` then says which.
#pragma once

#include <string>

namespace marbles {

struct DeviceInfo {
  bool available = false;
  std::string name;       // e.g. "NVIDIA H100 80GB HBM3"
  std::string why_not;    // set when !available
  int multiprocessors = 0;
};

// True when this build has the CUDA backend compiled in.
bool cuda_compiled();

// Queries device 0 once per process (cached).
const DeviceInfo& cuda_device();

}  // namespace marbles
