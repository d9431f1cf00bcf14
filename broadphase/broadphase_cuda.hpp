// broadphase/broadphase_cuda.hpp — the CUDA subdivision backend as callers
// see it (plain C++: no CUDA types). Defined only in builds with the CUDA
// backend (MARBLES_HAVE_CUDA); make_subdivision_cuda() in broadphase.hpp is
// the portable way to get one.
//
// Two entry points:
//   find_pairs()        host arrays in, host pairs out (uploads, runs, downloads);
//   find_pairs_device() centres and radii already on the device, pairs left
//                       on the device (device_pairs(), valid until the next
//                       call): the entry point for a GPU step and the bench.
// Both emit the same pairs in the same order as the CPU backend of the same
// algorithm (seed: make_subdivision_cpu(Algorithm::seed), home:
// make_home_cell_cpu()).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"

namespace marbles::cuda {
class DeviceBuffer;  // core/device_memory.hpp
}

namespace marbles::broadphase {

class SubdivisionCuda final : public BroadPhase {
 public:
  // Throws RuntimeFailure("... no CUDA device") when there is none.
  explicit SubdivisionCuda(Algorithm algorithm = kDefaultCudaAlgorithm, SortKind sort = SortKind::cub);
  ~SubdivisionCuda() override;
  SubdivisionCuda(const SubdivisionCuda&) = delete;
  SubdivisionCuda& operator=(const SubdivisionCuda&) = delete;

  void find_pairs(const SpheresIn& spheres, real margin, std::vector<Pair>& out) override;
  const Stats& last_stats() const override;
  std::string name() const override;

  // `device_spheres` holds device pointers. `stream` is a cudaStream_t (null:
  // the default stream). Returns the number of pairs; the call synchronises
  // the stream to size its buffers (count, scan, allocate): 3 times for the
  // seed algorithm, twice (bounds, pair count) for the home-cell variant,
  // which plans from the bounds it read (device_pair_count).
  std::size_t find_pairs_device(const SpheresIn& device_spheres, real margin, void* stream = nullptr);
  const Pair* device_pairs() const;  // device pointer (null after a call on fewer than two spheres)

  // The same without the wait for the pair count where the call can do
  // without (the home-cell variant on the device's keys): the pairs are
  // written only if all of them fit in `capacity`, and their count is left
  // in device_pair_count() for the caller to read with its own (it may be
  // larger than `capacity`: then nothing was written, and the caller asks
  // again with room for them). Returns kCountOnDevice then, with the pairs'
  // room at the front of a shared scratch (pairs_in_scratch(): the first
  // array a Carve of it takes, `capacity` pairs; see share_scratch), else in
  // a buffer of its own; otherwise the
  // call waited for the count anyway (the seed algorithm, a grid too wide
  // for the device's keys, fewer than two spheres) and returns it, with
  // every pair written whatever `capacity`.
  static constexpr std::size_t kCountOnDevice = ~std::size_t{0};
  std::size_t find_pairs_device_within(const SpheresIn& device_spheres, real margin, std::size_t capacity,
                                       void* stream = nullptr);
  // Device pointer: the pair count of the last find_pairs_device_within
  // that returned kCountOnDevice, once the stream has got there; or
  // kNoPairCount (every bit set) where that call did not read its bounds and
  // the grid the device chose from them does not fit the plan made at the
  // last read (the key type, the sort's bits, the dense lower bounds'
  // cells): then nothing was written, and the caller calls replan() and
  // asks again. A call within a room reads its bounds only without a plan
  // (the first, or after replan()); find_pairs_device always does. The word
  // after the count is 1 where the grid fit a plan larger than it asks
  // (plan_outsized, grid.hpp: more sort passes, wider keys or a larger
  // lower-bound array than a plan made now would take, by a margin): the
  // pairs are right, and a caller may replan() for a smaller plan (the next
  // call then reads its bounds).
  const std::uint32_t* device_pair_count() const;
  // Whether the last call left its pairs at the front of the scratch (a
  // call within a room that returned kCountOnDevice) rather than in a
  // buffer of the broad phase's own.
  bool pairs_in_scratch() const;
  static constexpr std::uint32_t kNoPairCount = 0xffffffffu;
  static constexpr std::size_t kPairCountWords = 2;  // the count, the plan outsized
  // The next call reads its bounds and plans from its grid.
  void replan();
  // Host<->device bytes the device entry points copied so far (readbacks,
  // and the CPU fallback's copies; find_pairs' uploads and downloads too).
  std::uint64_t bytes_copied() const;
  // Device bytes it holds of its own (not a shared scratch).
  std::size_t device_bytes() const;

  // The home-cell variant's temporaries (keys, ids and their alternates,
  // the spheres in sorted order, lower bounds, pair counts and offsets) live
  // in `scratch` from here on: memory that stages which never run at the
  // same time share (a GPU step's; core/device_buffer.cuh: Carve). The
  // call's last kernel still reads them when it returns, so the scratch's
  // next user must run after it on the same stream. By default in the broad
  // phase's own. A call within a room that leaves its count on the device
  // puts its pairs in a shared scratch too, first: its next user keeps them by
  // taking that room of pairs first in its own Carve (the same pointer), and
  // must not grow the scratch until it is done with them (reserve it to its
  // size before the call). The other calls' pairs are the broad phase's own,
  // a buffer it gives back at its next call that puts them in the scratch
  // (a free, which waits for the device: once after the first call of a
  // step's run and after each replan, both rare).
  void share_scratch(::marbles::cuda::DeviceBuffer& scratch);

  // Record CUDA events between the stages so that last_stats() carries
  // per-stage times (on by default; costs a few microseconds).
  void set_stage_timing(bool on);
  SortKind sort_kind() const;
  Algorithm algorithm() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m;
};

// The GPU sorts on host vectors (upload, sort bits [0, key_bits), download):
// for tests and comparisons.
void sort_pairs_cuda(std::vector<std::uint32_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                     SortKind sort);
void sort_pairs_cuda(std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& values, unsigned key_bits,
                     SortKind sort);

}  // namespace marbles::broadphase
