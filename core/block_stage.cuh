// core/block_stage.cuh — a block's run of records moved through shared
// memory, so that global memory sees whole consecutive 16-byte words.
//
// A thread that stores its own 112-byte contact writes seven 16-byte words
// 112 bytes apart from its neighbours': every word of a warp's store lands in
// its own 32-byte sector, half written, and L2 merges the halves. A block
// whose records form one run of the output stages them in shared memory and
// copies the run out, consecutive threads consecutive words, each sector
// written whole (and the same for reading a run in). The bytes are the same;
// nothing else changes. Records too large to stage for a whole block in the
// 48 KB of static shared memory (the double build's contacts) go direct.
// Only .cu files include this header.
#pragma once

#include <cstdint>

#include "core/whole_record.hpp"

namespace marbles::cuda {

template <class T>
__device__ void copy_words(T* to, const T* from, std::uint32_t count) {
  const int4* src = reinterpret_cast<const int4*>(from);
  int4* dst = reinterpret_cast<int4*>(to);
  const std::uint32_t words = count * static_cast<std::uint32_t>(sizeof(T) / 16);
  for (std::uint32_t w = threadIdx.x; w < words; w += blockDim.x) dst[w] = src[w];
}

// The length of a block's run that starts at `base` of [0, n).
__device__ inline std::uint32_t run_length(std::uint32_t n, std::uint32_t base) {
  return n - base < blockDim.x ? n - base : blockDim.x;
}

// One run of up to Threads records of a block (declare it __shared__). Every
// thread of the block calls fill and flush; the caller synchronises the block
// between fill and get, and between put and flush, and before reusing it.
template <class T, int Threads>
struct RunStage {
  static_assert(sizeof(T) % 16 == 0 && alignof(T) >= 16, "staged records are 16-byte words");
  static constexpr bool kStaged = Threads * sizeof(T) <= 48 * 1024;
  // Raw bytes: a record with default member initialisers cannot be a
  // __shared__ array.
  alignas(16) unsigned char bytes[(kStaged ? Threads : 1) * sizeof(T)];
  __device__ T* records() { return reinterpret_cast<T*>(bytes); }

  // Reading run[0, count): fill, sync, get(run, i).
  __device__ void fill(const T* run, std::uint32_t count) {
    if constexpr (kStaged) copy_words(records(), run, count);
  }
  __device__ T get(const T* run, std::uint32_t i) {
    if constexpr (kStaged) return load_whole(records() + i);
    else return load_whole(run + i);
  }
  // Writing run[0, count): put(run, i, value), sync, flush.
  __device__ void put(T* run, std::uint32_t i, const T& value) {
    if constexpr (kStaged) store_whole(records() + i, value);
    else store_whole(run + i, value);
  }
  __device__ void flush(T* run, std::uint32_t count) {
    if constexpr (kStaged) copy_words(run, records(), count);
  }
};

}  // namespace marbles::cuda
