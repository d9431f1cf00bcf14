// core/whole_record.hpp — load or store a record whole.
//
// On the GPU a record of 16-byte multiples (alignas(16) or more) moves in
// 16-byte words: one wide access per 16 bytes instead of one per field. A
// warp whose 32 threads each touch their own record then makes one memory
// request per word, not per field; the solver's sweep was bound by L2
// traffic made of such per-field requests (docs/architecture.md). On the host
// it is a plain copy. Either way the bytes moved are the same, so no
// arithmetic changes.
#pragma once

#include <cstddef>
#include <type_traits>

#include "core/config.hpp"

namespace marbles {

namespace whole_record_detail {
#if defined(__CUDA_ARCH__)
// T moved as 16-byte words, plain or with the evict-first hint.
template <bool Streaming, class T>
__device__ __forceinline__ T load_words(const T* p) {
  static_assert(sizeof(T) % 16 == 0 && alignof(T) >= 16, "whole records are 16-byte words");
  T out;
  const int4* from = reinterpret_cast<const int4*>(p);
  int4* to = reinterpret_cast<int4*>(&out);
#pragma unroll
  for (std::size_t i = 0; i < sizeof(T) / 16; ++i) {
    if constexpr (Streaming) to[i] = __ldcs(from + i);
    else to[i] = from[i];
  }
  return out;
}
template <bool Streaming, class T>
__device__ __forceinline__ void store_words(T* p, const T& value) {
  static_assert(sizeof(T) % 16 == 0 && alignof(T) >= 16, "whole records are 16-byte words");
  const int4* from = reinterpret_cast<const int4*>(&value);
  int4* to = reinterpret_cast<int4*>(p);
#pragma unroll
  for (std::size_t i = 0; i < sizeof(T) / 16; ++i) {
    if constexpr (Streaming) __stcs(to + i, from[i]);
    else to[i] = from[i];
  }
}
#endif
}  // namespace whole_record_detail

template <class T>
MARBLES_HD_INLINE T load_whole(const T* p) {
#if defined(__CUDA_ARCH__)
  return whole_record_detail::load_words<false>(p);
#else
  return *p;
#endif
}

template <class T>
MARBLES_HD_INLINE void store_whole(T* p, const T& value) {
#if defined(__CUDA_ARCH__)
  whole_record_detail::store_words<false>(p, value);
#else
  *p = value;
#endif
}

// The same for data a pass reads or writes once (the sweep's records): on
// the GPU each word moves with the evict-first hint (ld.global.cs /
// st.global.cs), so the streamed records do not push out of L2 what every
// launch reads again (the solver's bodies: 32 MB at 10^6 spheres, within the
// H100's 50 MB L2). Pile of 10^6, H100: solve 9.32 -> 8.38 ms per step. An
// 8-byte record moves as one 8-byte word, a float or double as itself.
template <class T>
MARBLES_HD_INLINE T load_streaming(const T* p) {
#if defined(__CUDA_ARCH__)
  if constexpr (std::is_same_v<T, float> || std::is_same_v<T, double>) {
    return __ldcs(p);
  } else if constexpr (sizeof(T) == 8 && alignof(T) >= 8) {
    const uint2 w = __ldcs(reinterpret_cast<const uint2*>(p));
    T out;
    *reinterpret_cast<uint2*>(&out) = w;
    return out;
  } else {
    return whole_record_detail::load_words<true>(p);
  }
#else
  return *p;
#endif
}

template <class T>
MARBLES_HD_INLINE void store_streaming(T* p, const T& value) {
#if defined(__CUDA_ARCH__)
  if constexpr (std::is_same_v<T, float> || std::is_same_v<T, double>) __stcs(p, value);
  else whole_record_detail::store_words<true>(p, value);
#else
  *p = value;
#endif
}

}  // namespace marbles
