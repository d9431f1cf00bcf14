// core/cuda_check.hpp — checks for every CUDA runtime call and every launch.
//
// MARBLES_CUDA_CHECK(call) throws RuntimeFailure naming the file, the line,
// the call and the CUDA error. MARBLES_CUDA_CHECK_LAUNCH() checks the last
// launch; with the environment variable MARBLES_CUDA_SYNC=1 (or the CMake
// option MARBLES_CUDA_DEBUG_SYNC) it also synchronises, so an error inside a
// kernel is reported at the launch that caused it.
//
// Include only from .cu files or from .cpp files compiled with the CUDA
// runtime on their include path.
#pragma once

#include <cuda_runtime.h>

#include <cstdlib>
#include <string>

#include "core/error.hpp"

namespace marbles::cuda {

[[noreturn]] inline void throw_cuda_error(cudaError_t err, const char* what, const char* file, int line) {
  throw RuntimeFailure(std::string("CUDA error at ") + file + ":" + std::to_string(line) + ": " + what +
                       ": " + cudaGetErrorName(err) + " (" + cudaGetErrorString(err) + ")");
}

inline bool sync_after_launch() {
#if defined(MARBLES_CUDA_DEBUG_SYNC)
  return true;
#else
  static const bool on = [] {
    const char* v = std::getenv("MARBLES_CUDA_SYNC");
    return v != nullptr && v[0] == '1';
  }();
  return on;
#endif
}

}  // namespace marbles::cuda

#define MARBLES_CUDA_CHECK(call)                                                 \
  do {                                                                           \
    cudaError_t marbles_err_ = (call);                                           \
    if (marbles_err_ != cudaSuccess)                                             \
      ::marbles::cuda::throw_cuda_error(marbles_err_, #call, __FILE__, __LINE__); \
  } while (0)

#define MARBLES_CUDA_CHECK_LAUNCH()                                                      \
  do {                                                                                   \
    cudaError_t marbles_err_ = cudaGetLastError();                                       \
    if (marbles_err_ == cudaSuccess && ::marbles::cuda::sync_after_launch())             \
      marbles_err_ = cudaDeviceSynchronize();                                            \
    if (marbles_err_ != cudaSuccess)                                                     \
      ::marbles::cuda::throw_cuda_error(marbles_err_, "kernel launch", __FILE__, __LINE__); \
  } while (0)
