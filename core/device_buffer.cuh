// core/device_buffer.cuh — launch sizes and launches, and the CUB scan
// every stage shares, with its temporary storage held by the caller and
// reused; the memory, streams and events themselves are
// core/device_memory.hpp's. Only .cu files include it.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>
#include <utility>

#include <cooperative_groups.h>
#include <cub/device/device_scan.cuh>

#include "core/bits.hpp"
#include "core/config.hpp"
#include "core/cuda_check.hpp"
#include "core/device.hpp"
#include "core/device_memory.hpp"

namespace marbles::cuda {

constexpr int kBlock = 256;

// Blocks for a grid-stride loop over n items.
inline int grid_for(std::size_t n, int sm_count, int per_sm = 8) {
  const std::size_t want = (n + kBlock - 1) / kBlock;
  const std::size_t cap = static_cast<std::size_t>(sm_count) * static_cast<std::size_t>(per_sm);
  return static_cast<int>(want < 1 ? 1 : (want < cap ? want : cap));
}

// Blocks of kBlock threads of `Kernel` that stay resident on one SM
// together: a cooperative launch's per_sm for grid_for (a grid-wide barrier
// needs every block resident at once). Asked once per kernel.
template <auto Kernel>
int resident_blocks() {
  static const int per_sm = [] {
    int n = 0;
    MARBLES_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&n, Kernel, kBlock, 0));
    return n > 1 ? n : 1;
  }();
  return per_sm;
}

// How `Kernel` fits a multiprocessor here (checked calls).
template <auto Kernel>
KernelFit kernel_fit() {
  cudaFuncAttributes attributes{};
  MARBLES_CUDA_CHECK(cudaFuncGetAttributes(&attributes, Kernel));
  KernelFit fit;
  fit.registers = attributes.numRegs;
  fit.local_bytes = attributes.localSizeBytes;
  MARBLES_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&fit.blocks_per_sm, Kernel, kBlock, 0));
  return fit;
}

// How a kernel is launched: plainly; cooperatively (its blocks may meet at
// a grid-wide barrier: every block resident at once, so the grid at most
// grid_for(n, sm_count, resident_blocks<kernel>())); dependent on the launch
// before it (programmatic stream serialization, sm_90: it may start while
// that one's last blocks run, its threads waiting in griddepcontrol.wait);
// or as one cluster (sm_90: the whole grid one cluster, its blocks resident
// together on one GPC and meeting at the cluster's barrier; at most
// largest_cluster<kernel>() blocks).
enum class Launch { plain, cooperative, dependent, cluster };

// `kernel` on `grid` blocks of kBlock threads, launched `how`, checked.
template <class... Params, class... Args>
void launch(Launch how, void (*kernel)(Params...), int grid, cudaStream_t s, Args&&... args) {
  cudaLaunchConfig_t config{};
  config.gridDim = dim3(static_cast<unsigned>(grid));
  config.blockDim = dim3(kBlock);
  config.stream = s;
  cudaLaunchAttribute attribute[1];
  if (how == Launch::cooperative) {
    attribute[0].id = cudaLaunchAttributeCooperative;
    attribute[0].val.cooperative = 1;
  } else if (how == Launch::dependent) {
    attribute[0].id = cudaLaunchAttributeProgrammaticStreamSerialization;
    attribute[0].val.programmaticStreamSerializationAllowed = 1;
  } else if (how == Launch::cluster) {
    attribute[0].id = cudaLaunchAttributeClusterDimension;
    attribute[0].val.clusterDim.x = static_cast<unsigned>(grid);
    attribute[0].val.clusterDim.y = 1;
    attribute[0].val.clusterDim.z = 1;
  }
  config.attrs = attribute;
  config.numAttrs = how == Launch::plain ? 0 : 1;
  MARBLES_CUDA_CHECK(cudaLaunchKernelEx(&config, kernel, std::forward<Args>(args)...));
  MARBLES_CUDA_CHECK_LAUNCH();  // with MARBLES_CUDA_SYNC=1: a wait, the kernel's error here
}

// The most blocks of kBlock threads one cluster of `Kernel` may have here
// (sizes past the portable 8 allowed where the device takes them), or 0
// where the kernel is not to be launched as a cluster: a device without
// cluster launches, or the kernel's code not made from sm_90 PTX. Asked once
// per kernel, of the device current then, and the kernel let take
// non-portable sizes there only: the step runs on device 0 alone
// (cuda_device()), as resident_blocks and the memory pools assume too.
template <auto Kernel>
int largest_cluster() {
  static const int most = [] {
    int device = 0, clusters = 0;
    if (cudaGetDevice(&device) != cudaSuccess ||
        cudaDeviceGetAttribute(&clusters, cudaDevAttrClusterLaunch, device) != cudaSuccess || clusters == 0)
      return 0;
    // The PTX the code was made from: code for an older architecture runs
    // here too, compiled at load (its binaryVersion then the device's), and
    // its cluster barrier is not there.
    cudaFuncAttributes attributes{};
    MARBLES_CUDA_CHECK(cudaFuncGetAttributes(&attributes, Kernel));
    if (attributes.ptxVersion < 90 || attributes.binaryVersion < 90) return 0;
    if (cudaFuncSetAttribute(Kernel, cudaFuncAttributeNonPortableClusterSizeAllowed, 1) != cudaSuccess)
      (void)cudaGetLastError();  // portable sizes only
    cudaLaunchConfig_t config{};
    config.gridDim = dim3(16);
    config.blockDim = dim3(kBlock);
    int size = 0;
    if (cudaOccupancyMaxPotentialClusterSize(&size, Kernel, &config) != cudaSuccess) {
      (void)cudaGetLastError();
      return 0;
    }
    return size < 1 ? 0 : (size < 16 ? size : 16);
  }();
  return most;
}

// `Kernel` launched cooperatively over n items: as many blocks as n asks
// for, at most as many as stay resident together.
template <auto Kernel, class... Args>
void launch_cooperative(std::size_t n, int sm_count, cudaStream_t s, Args&&... args) {
  launch(Launch::cooperative, Kernel, grid_for(n, sm_count, resident_blocks<Kernel>()), s, std::forward<Args>(args)...);
}

#if defined(__CUDACC__)
// What the blocks of one launch meet at: the whole grid of a cooperative
// launch (a barrier in memory), or the one cluster a Launch::cluster is
// (sm_90: the cluster's barrier in hardware). Both release the writes
// before them to every thread of the launch, and their reads after them
// see those writes (device_buffer_cuda_test: "Barriers").
struct GridSync {
  __device__ void sync() const { cooperative_groups::this_grid().sync(); }
};
struct ClusterSync {
  __device__ void sync() const {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
    cooperative_groups::this_cluster().sync();
#else
    __trap();  // never launched: clusters only for code made from sm_90 PTX (largest_cluster)
#endif
  }
};

// A word another block wrote before a barrier of the launch, read past any
// cached copy (every block reads the same value, so all take one branch).
__device__ __forceinline__ std::uint32_t read_volatile(const std::uint32_t* p) {
  return *static_cast<const volatile std::uint32_t*>(p);
}

// The items of a kernel over `items` that hold work when their count stays
// on the device (count_on_device not null: written by an earlier launch,
// read by the host later): that count where it fits, else none (the caller
// reads the count, grows the room and runs again). Null: all of them.
__device__ __forceinline__ std::size_t count_within(std::size_t items, const std::uint32_t* count_on_device) {
  if (!count_on_device) return items;
  const std::size_t count = *count_on_device;
  return count <= items ? count : 0;
}

// Whether a kernel that writes the step's state does nothing: a substep
// that outgrew a room it was given without a wait runs on (its results
// bounded by the rooms, and wrong), and the kernels that would make them
// the state's read this word (a substep's number past 0 once one has
// outgrown one: sim/cuda_step.cu, one wait a step). Null: never.
__device__ __forceinline__ bool skipped(const unsigned long long* skip) {
  return skip != nullptr && *static_cast<const volatile unsigned long long*>(skip) != 0;
}

#endif

// *target = max(*target, v) for the warp's values, one atomic per warp. Every
// thread of the warp must call it (after a grid-stride loop, not inside); a
// maximum of 0 writes nothing, so the target must start at 0.
__device__ inline void warp_atomic_max(unsigned long long* target, unsigned long long v) {
  for (int offset = 16; offset > 0; offset >>= 1) {
    const unsigned long long other = __shfl_down_sync(0xffffffffu, v, offset);
    v = other > v ? other : v;
  }
  if ((threadIdx.x & 31) == 0 && v != 0) atomicMax(target, v);
}

// Arrays carved in turn out of one allocation, each 256-byte aligned, for a
// stage's temporaries: stages that never run at the same time share one
// buffer (CudaStep's scratch), so the device holds the largest stage's
// temporaries, not their sum. A layout runs twice (carve()): on no memory to
// count the bytes, then on the reserved memory. A copy of a Carve taken at
// some point starts arrays that overlap those taken after that point (for
// arrays never live at the same time); merge() then goes on past both.
class Carve {
 public:
  explicit Carve(char* base = nullptr) : m_base(base) {}
  template <class T>
  T* take(std::size_t count) {
    T* p = m_base ? reinterpret_cast<T*>(m_base + m_used) : nullptr;
    m_used += (count * sizeof(T) + 255) / 256 * 256;
    return p;
  }
  void merge(const Carve& other) { m_used = m_used > other.m_used ? m_used : other.m_used; }
  std::size_t used() const { return m_used; }

 private:
  char* m_base = nullptr;
  std::size_t m_used = 0;
};

// carve(memory, layout) runs layout(Carve&) on `memory`, grown to fit: the
// pointers it takes are valid until the next carve of the same memory.
// carve_counted: the same, the layout's bytes already counted (`counted`:
// the layout run on no memory), so it runs once more, on the memory.
template <class Layout>
void carve_counted(DeviceBuffer& memory, Layout&& layout, const Carve& counted) {
  Carve at(static_cast<char*>(memory.reserve(counted.used())));
  layout(at);
}
template <class Layout>
void carve(DeviceBuffer& memory, Layout&& layout) {
  Carve count;
  layout(count);
  carve_counted(memory, layout, count);
}

// Temporary bytes of device_exclusive_sum over n items.
template <class T>
std::size_t exclusive_sum_bytes(std::size_t n) {
  std::size_t bytes = 0;
  MARBLES_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, bytes, static_cast<const T*>(nullptr),
                                                   static_cast<T*>(nullptr), static_cast<int>(n)));
  return bytes;
}

// Exclusive sum of in[0, n) into out[0, n); temp holds exclusive_sum_bytes<T>(n).
template <class T>
void device_exclusive_sum(const T* in, T* out, std::size_t n, void* temp, std::size_t temp_bytes,
                          cudaStream_t stream) {
  MARBLES_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp, temp_bytes, in, out, static_cast<int>(n), stream));
}

}  // namespace marbles::cuda
