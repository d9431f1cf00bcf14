// core/config.hpp — the one place where the floating-point type and the
// host/device marker are chosen.
//
// `real` is float unless the build sets MARBLES_DOUBLE (CMake option
// MARBLES_DOUBLE=ON), so that the precision study can compare both without
// touching any stage.
#pragma once

#if defined(__CUDACC__)
#define MARBLES_HD __host__ __device__
#define MARBLES_HD_INLINE __host__ __device__ __forceinline__
#else
#define MARBLES_HD
#define MARBLES_HD_INLINE inline
#endif

namespace marbles {

#if defined(MARBLES_DOUBLE)
using real = double;
#else
using real = float;
#endif

inline constexpr const char* kRealName = sizeof(real) == 8 ? "double" : "float";

}  // namespace marbles
