#include "core/device.hpp"

#if defined(MARBLES_HAVE_CUDA)
#include <cuda_runtime.h>
#endif

namespace marbles {

bool cuda_compiled() {
#if defined(MARBLES_HAVE_CUDA)
  return true;
#else
  return false;
#endif
}

static DeviceInfo query() {
  DeviceInfo info;
#if defined(MARBLES_HAVE_CUDA)
  int count = 0;
  cudaError_t err = cudaGetDeviceCount(&count);
  if (err != cudaSuccess) {
    info.why_not = std::string("cudaGetDeviceCount failed: ") + cudaGetErrorName(err) + " (" +
                   cudaGetErrorString(err) + ")";
    cudaGetLastError();  // clear the sticky error state
    return info;
  }
  if (count <= 0) {
    info.why_not = "no CUDA device";
    return info;
  }
  cudaDeviceProp prop{};
  err = cudaGetDeviceProperties(&prop, 0);
  if (err != cudaSuccess) {
    info.why_not = std::string("cudaGetDeviceProperties failed: ") + cudaGetErrorName(err);
    cudaGetLastError();
    return info;
  }
  info.available = true;
  info.name = prop.name;
  info.multiprocessors = prop.multiProcessorCount;
#else
  info.why_not = "this build has no CUDA backend (configured with MARBLES_CUDA=OFF or no nvcc)";
#endif
  return info;
}

const DeviceInfo& cuda_device() {
  static const DeviceInfo info = query();
  return info;
}

}  // namespace marbles
