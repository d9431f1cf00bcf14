// broadphase/broadphase_cuda.cu — SubdivisionCuda: the CUDA stages strung
// together, the same stages as the CPU backends (broadphase_cpu.cpp for the
// seed algorithm, home_cell_cpu.cpp for the home-cell variant).
//
// Seed algorithm:
//   cell IDs   bounds (one kernel, 1 readback) -> grid -> counts -> scan
//              (readback: entry count) -> cell IDs
//   sort       seed radix sort or CUB, over the key's used bits
//   cell list  flags -> scan -> write + 8 type ranges (cells sized by m / 2)
//   traversal  gather spheres in sorted order -> count per H entry -> scan
//              (readback: pair count) -> write
//
// Home-cell variant (home_cell_cuda.cu):
//   cell IDs   bounds -> grid (chosen on the device; the host reads the
//              bounds only where it has no plan yet: run_home) -> home keys
//   sort       the same two sorts, one (key, id) entry per sphere
//   cell list  spheres gathered into sorted order + dense lower-bound array
//   traversal  count per sphere -> scan (readback: pair count) -> write;
//              find_pairs_device_within: no readback, the count left on the
//              device, the pairs written if they fit the caller's capacity
//
// Every buffer is sized from a count (count, scan, allocate) and only grows;
// there is no fixed capacity. The home-cell variant carves its temporaries
// out of one scratch buffer, which a GPU step shares with its other stages
// (share_scratch). The readbacks named above are the only host
// syncs (seed: 3; home: 2, and within a room 1 without a plan, none with
// one). Grids too wide for 63 (seed) or 62 (home) key
// bits (a sphere very far from the rest) go through the CPU twin's exact
// key compression, then back to the device.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <optional>

#include "broadphase/broadphase_cuda.cuh"
#include "broadphase/broadphase_cuda.hpp"
#include "core/device.hpp"

namespace marbles::broadphase {

using namespace marbles::broadphase::cuda;

struct SubdivisionCuda::Impl {
  Algorithm algorithm = kDefaultCudaAlgorithm;
  SortKind sort = SortKind::cub;
  bool timing = true;
  int sm_count = 1;
  Stats stats;
  std::unique_ptr<BroadPhase> cpu_fallback;

  DeviceBuffer centre, radius;  // for the host entry point
  DeviceBuffer bounds, counts, offsets, info;
  // The seed algorithm's (the home-cell variant's temporaries are carved
  // out of `scratch`); the pairs and tests are both's.
  DeviceBuffer keys, keys_alt, values, values_alt;
  DeviceBuffer flags, cell_index, cells, pass_begin;
  DeviceBuffer pair_counts, pair_offsets, pairs, tests, sorted_sphere, sorted_info;
  DeviceBuffer cub_temp, seed_scratch;
  DeviceBuffer own_scratch;                 // the home-cell variant's temporaries, unless shared
  DeviceBuffer* scratch = &own_scratch;
  DeviceBuffer count_word;                  // the pair count and the plan outsized (find_pairs_device_within)
  DeviceBuffer grid_word;                   // the home grid of the call, chosen on the device
  std::size_t pair_count = 0;
  // Where the last call left its pairs: `pairs`, or the front of the
  // scratch (a home-cell call within a room that left its count on the
  // device; `pairs` then given back), or none.
  const IndexPair* last_pairs = nullptr;
  // The home-cell variant's plan: the shape its buffers and sort take from
  // the grid of the last call that read its bounds, and that grid (for the
  // stats of the calls that do not read theirs). None: the next call reads.
  std::optional<HomePlan> plan;
  HomeGrid planned_grid;
  std::uint64_t bytes = 0;  // host<->device bytes copied by the device entry points

  ::marbles::cuda::PinnedBuffer<BoundsAccum> h_bounds{1};
  ::marbles::cuda::PinnedBuffer<std::uint32_t> h_small{64};  // readbacks
  ::marbles::cuda::Event ev[5];

  void mark(int k, cudaStream_t s) {
    if (timing) MARBLES_CUDA_CHECK(cudaEventRecord(ev[k], s));
  }
  std::uint32_t read_u32(const std::uint32_t* d, cudaStream_t s) {
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_small, d, sizeof(std::uint32_t), cudaMemcpyDeviceToHost, s));
    MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
    bytes += sizeof(std::uint32_t);
    return h_small[0];
  }

  // `within`: find_pairs_device_within's capacity (no wait for the pair
  // count where the home-cell variant runs on the device), or none.
  using Within = std::optional<std::size_t>;
  std::size_t run(const SpheresIn& d, real margin, cudaStream_t s, Within within = {});
  Bounds device_bounds(const SpheresIn& d, cudaStream_t s);
  std::size_t run_home(const SpheresIn& d, real margin, cudaStream_t s, Within within);
  template <class Key>
  std::size_t run_home_keys(const SpheresIn& d, real margin, const HomePlan& p, const HomeGrid* g, cudaStream_t s,
                            Within within);
  void finish_timing();
  template <class Key>
  std::size_t run_keys(const SpheresIn& d, real margin, const Grid& g, cudaStream_t s);
  std::size_t run_on_cpu(const SpheresIn& d, real margin, cudaStream_t s);
};

std::size_t SubdivisionCuda::Impl::run(const SpheresIn& d, real margin, cudaStream_t s, Within within) {
  stats = Stats{};
  pair_count = 0;
  last_pairs = nullptr;
  const std::size_t n = d.count;
  if (n >= kMaxObjects) throw RuntimeFailure("broad phase: more than 2^28 spheres");
  if (n < 2) return 0;
  mark(0, s);

  if (algorithm == Algorithm::home) return run_home(d, margin, s, within);

  // --- cell IDs: bounds -> grid ---------------------------------------------
  const GridChoice gc = choose_grid(device_bounds(d, s), margin);
  if (gc.width == KeyWidth::too_wide) return run_on_cpu(d, margin, s);
  stats.cell_size = gc.grid.cell;
  stats.key_bits = gc.grid.key_bits;
  if (gc.width == KeyWidth::bits32) {
    stats.key_width = 32;
    return run_keys<std::uint32_t>(d, margin, gc.grid, s);
  }
  stats.key_width = 64;
  return run_keys<std::uint64_t>(d, margin, gc.grid, s);
}

template <class Key>
std::size_t SubdivisionCuda::Impl::run_keys(const SpheresIn& d, real margin, const Grid& g, cudaStream_t s) {
  const std::size_t n = d.count;
  auto* d_counts = counts.as<std::uint32_t>(n + 1);
  auto* d_offsets = offsets.as<std::uint32_t>(n + 1);
  auto* d_info = info.as<std::uint16_t>(n);
  launch_cell_counts(d.centre, d.radius, n, g, d_counts, d_info, sm_count, s);
  exclusive_sum(d_counts, d_offsets, n + 1, cub_temp, s);
  const std::size_t m = read_u32(d_offsets + n, s);
  auto* d_keys = keys.as<Key>(m);
  auto* d_keys_alt = keys_alt.as<Key>(m);
  auto* d_values = values.as<std::uint32_t>(m);
  auto* d_values_alt = values_alt.as<std::uint32_t>(m);
  launch_cell_ids<Key>(d.centre, d.radius, n, g, d_offsets, d_keys, d_values, sm_count, s);
  stats.cell_entries = m;
  mark(1, s);

  // --- sort -------------------------------------------------------------------
  const bool in_alt =
      sort == SortKind::seed
          ? seed_radix_sort<Key>(d_keys, d_values, d_keys_alt, d_values_alt, m, g.key_bits, seed_scratch, sm_count, s)
          : cub_radix_sort<Key>(d_keys, d_values, d_keys_alt, d_values_alt, m, g.key_bits, cub_temp, s);
  if (in_alt) {
    std::swap(d_keys, d_keys_alt);
    std::swap(d_values, d_values_alt);
  }
  stats.sort_passes = (std::min<unsigned>(g.key_bits, 8 * sizeof(Key)) + 7) / 8;
  mark(2, s);

  // --- collision-cell list ----------------------------------------------------
  // A collision cell holds >= 2 entries: m / 2 cells at most (no readback).
  auto* d_flags = flags.as<std::uint32_t>(m + 1);
  auto* d_index = cell_index.as<std::uint32_t>(m + 1);
  auto* d_cells = cells.as<CollisionCell>(m / 2 + 1);
  auto* d_pass = pass_begin.as<std::uint32_t>(9);
  launch_cell_flags<Key>(d_keys, d_values, m, d_flags, sm_count, s);
  exclusive_sum(d_flags, d_index, m + 1, cub_temp, s);
  launch_cell_write<Key>(d_keys, d_values, m, d_index, d_cells, d_pass, sm_count, s);
  mark(3, s);

  // --- traversal --------------------------------------------------------------
  auto* d_pair_counts = pair_counts.as<std::uint32_t>(m + 1);
  auto* d_pair_offsets = pair_offsets.as<std::uint32_t>(m + 1);
  auto* d_tests = tests.as<unsigned long long>(1);
  auto* d_sorted = sorted_sphere.as<SortedSphere>(m);
  auto* d_sorted_info = sorted_info.as<std::uint16_t>(m);
  MARBLES_CUDA_CHECK(cudaMemsetAsync(d_tests, 0, sizeof(unsigned long long), s));
  const TraversalInput in{d_cells, d_index, d_values, d.centre, d.radius, d_info, d_sorted, d_sorted_info, margin};
  launch_gather(in, m, sm_count, s);
  launch_traversal_count(in, m, d_pair_counts, d_tests, sm_count, s);
  exclusive_sum(d_pair_counts, d_pair_offsets, m + 1, cub_temp, s);
  // one readback: pair count, tests and the 8 type ranges (the last is the cell count)
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_small, d_pair_offsets + m, 4, cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_small + 2, d_tests, 8, cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_small + 4, d_pass, 9 * 4, cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  bytes += 4 + 8 + 9 * 4;
  pair_count = h_small[0];
  unsigned long long t = 0;
  std::memcpy(&t, h_small + 2, 8);
  stats.tests = t;
  for (int k = 0; k < 8; ++k) stats.cells_per_type[k] = h_small[4 + k + 1] - h_small[4 + k];
  stats.collision_cells = h_small[4 + 8];
  auto* d_pairs = pairs.as<IndexPair>(pair_count);
  last_pairs = d_pairs;
  launch_traversal_write(in, m, d_pair_offsets, d_pairs, sm_count, s);
  stats.pairs = pair_count;
  mark(4, s);
  finish_timing();
  return pair_count;
}

void SubdivisionCuda::Impl::finish_timing() {
  if (timing) {
    MARBLES_CUDA_CHECK(cudaEventSynchronize(ev[4]));
    float ms[4];
    for (int k = 0; k < 4; ++k) MARBLES_CUDA_CHECK(cudaEventElapsedTime(&ms[k], ev[k], ev[k + 1]));
    stats.ms_cell_ids = ms[0];
    stats.ms_sort = ms[1];
    stats.ms_cell_list = ms[2];
    stats.ms_traversal = ms[3];
    float total = 0;
    MARBLES_CUDA_CHECK(cudaEventElapsedTime(&total, ev[0], ev[4]));
    stats.ms_total = total;
  }
}

// The bounding box of the centres and the largest radius, reduced on the
// device and read back (the host sync before a grid is chosen on the host).
Bounds SubdivisionCuda::Impl::device_bounds(const SpheresIn& d, cudaStream_t s) {
  bytes += sizeof(BoundsAccum);
  return read_bounds(d.centre, d.radius, d.count, bounds.as<BoundsAccum>(1), h_bounds, sm_count, s);
}

// The grid is chosen on the device, from the bounds reduced there, by the
// host's function (home_grid_of): the same grid, so the same keys and
// order. The host lays out the buffers and the sort for a plan. A call that
// waits (no plan yet, or no `within`) reads the bounds first and plans from
// the grid it chooses itself; a call within a room does not read them: the
// device's grid must fit the plan, else it is kNoGrid, the count
// kNoPairCount, and the caller plans again (replan) and asks again.
std::size_t SubdivisionCuda::Impl::run_home(const SpheresIn& d, real margin, cudaStream_t s, Within within) {
  if (!within || !plan) {
    const HomeGridChoice hc = choose_home_grid(device_bounds(d, s), margin);
    if (hc.width == KeyWidth::too_wide) {
      plan.reset();
      return run_on_cpu(d, margin, s);
    }
    plan = plan_of(hc.grid, hc.width, d.count);
    planned_grid = hc.grid;
  } else {
    check_margin(margin);  // the bounds the device checks
    launch_bounds(d.centre, d.radius, d.count, bounds.as<BoundsAccum>(1), sm_count, s);
  }
  const HomePlan p = *plan;
  auto* g = grid_word.as<HomeGrid>(1);
  auto* count = count_word.as<std::uint32_t>(SubdivisionCuda::kPairCountWords);  // [1]: the plan outsized
  launch_home_grid(bounds.get_as<BoundsAccum>(), margin, p, d.count, g, count + 1, s);
  stats.cell_size = planned_grid.cell;
  stats.key_bits = planned_grid.key_bits;
  stats.grid_cells = planned_grid.cells;
  stats.key_width = p.bits32 ? 32 : 64;
  return p.bits32 ? run_home_keys<std::uint32_t>(d, margin, p, g, s, within)
                  : run_home_keys<std::uint64_t>(d, margin, p, g, s, within);
}

template <class Key>
std::size_t SubdivisionCuda::Impl::run_home_keys(const SpheresIn& d, real margin, const HomePlan& p,
                                                 const HomeGrid* g, cudaStream_t s, Within within) {
  const std::size_t n = d.count;
  // Every temporary in the scratch memory, live only during this call;
  // within a room of a shared scratch the pairs too, first (they outlive
  // the temporaries).
  const bool dense = p.dense;
  const bool front_pairs = within && scratch != &own_scratch;
  Key *d_keys = nullptr, *d_keys_alt = nullptr;
  std::uint32_t *d_ids = nullptr, *d_ids_alt = nullptr, *d_lb = nullptr, *d_counts = nullptr, *d_offsets = nullptr;
  SortedSphere* d_sorted = nullptr;
  IndexPair* front = nullptr;
  ::marbles::cuda::carve(*scratch, [&](::marbles::cuda::Carve& c) {
    if (front_pairs) front = c.take<IndexPair>(*within);
    d_keys = c.take<Key>(n);
    d_keys_alt = c.take<Key>(n);
    d_ids = c.take<std::uint32_t>(n);
    d_ids_alt = c.take<std::uint32_t>(n);
    d_lb = dense ? c.take<std::uint32_t>(p.cells + 1) : nullptr;
    d_sorted = c.take<SortedSphere>(n);
    d_counts = c.take<std::uint32_t>(n + 1);
    d_offsets = c.take<std::uint32_t>(n + 1);
  });
  launch_home_keys<Key>(d.centre, n, g, d_keys, d_ids, sm_count, s);
  stats.cell_entries = n;
  mark(1, s);

  // --- sort: (home key, id), one entry per sphere -----------------------------------
  const bool in_alt =
      sort == SortKind::seed
          ? seed_radix_sort<Key>(d_keys, d_ids, d_keys_alt, d_ids_alt, n, p.key_bits, seed_scratch, sm_count, s)
          : cub_radix_sort<Key>(d_keys, d_ids, d_keys_alt, d_ids_alt, n, p.key_bits, cub_temp, s);
  if (in_alt) {
    std::swap(d_keys, d_keys_alt);
    std::swap(d_ids, d_ids_alt);
  }
  stats.sort_passes = sort_digits(p.key_bits);
  mark(2, s);

  // --- cell list: spheres in sorted order, cell lower bounds -------------------------
  // (up to the grid's cells: the plan's array may hold more, never read)
  stats.dense_cell_starts = dense;
  launch_home_reorder<Key>(d_keys, d_ids, n, d.centre, d.radius, g, d_sorted, d_lb, sm_count, s);
  mark(3, s);

  // --- traversal: count -> scan -> count word -> (readback) -> write ------------------
  auto* d_tests = tests.as<unsigned long long>(1);
  MARBLES_CUDA_CHECK(cudaMemsetAsync(d_tests, 0, sizeof(unsigned long long), s));
  const HomeTraversal<Key> in{d_keys, d_ids, d_sorted, d_lb, g, static_cast<std::uint32_t>(n), margin};
  launch_home_count<Key>(in, d_counts, d_tests, sm_count, s);
  exclusive_sum(d_counts, d_offsets, n + 1, cub_temp, s);
  // The count out of the scratch (its next user overwrites offsets[n]) into
  // a word of its own: kNoPairCount where the device's grid did not fit.
  auto* d_count = count_word.get_as<std::uint32_t>();
  launch_home_pair_count<Key>(in, d_offsets, d_count, s);
  if (within) {
    // No readback: the pairs only if they fit, at a shared scratch's front
    // (the pairs' own buffer, from a call that waited, then goes: once after
    // each such call), else in their own.
    IndexPair* to = front_pairs ? front : pairs.as_room<IndexPair>(*within);
    launch_home_write<Key>(in, d_offsets, *within, to, sm_count, s);
    last_pairs = to;
    if (front_pairs && pairs.get()) DeviceBuffer().swap(pairs);
    mark(4, s);
    finish_timing();
    return SubdivisionCuda::kCountOnDevice;  // stats.pairs and stats.tests stay 0: not read
  }
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_small, d_count, 4, cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(h_small + 2, d_tests, 8, cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  bytes += 12;
  // This call planned from the grid it chose on the host: the device's is the same.
  if (h_small[0] == kNoPairCount) throw std::logic_error("broad phase: the device chose another home grid than the host");
  pair_count = h_small[0];
  unsigned long long t = 0;
  std::memcpy(&t, h_small + 2, 8);
  stats.tests = t;
  auto* d_pairs = pairs.as<IndexPair>(pair_count);
  last_pairs = d_pairs;
  if (pair_count > 0) launch_home_write<Key>(in, d_offsets, pair_count, d_pairs, sm_count, s);
  stats.pairs = pair_count;
  mark(4, s);
  finish_timing();
  return pair_count;
}

std::size_t SubdivisionCuda::Impl::run_on_cpu(const SpheresIn& d, real margin, cudaStream_t s) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t n = d.count;
  std::vector<Vec3> c(n);
  std::vector<real> r(n);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(c.data(), d.centre, n * sizeof(Vec3), cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(r.data(), d.radius, n * sizeof(real), cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  bytes += n * (sizeof(Vec3) + sizeof(real));
  if (!cpu_fallback) cpu_fallback = make_subdivision_cpu(algorithm);
  std::vector<Pair> out;
  cpu_fallback->find_pairs({c.data(), r.data(), n}, margin, out);
  auto* d_pairs = pairs.as<IndexPair>(out.size());
  last_pairs = d_pairs;
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(d_pairs, out.data(), out.size() * sizeof(Pair), cudaMemcpyHostToDevice, s));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  bytes += out.size() * sizeof(Pair);
  stats = cpu_fallback->last_stats();
  stats.ms_total = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  pair_count = out.size();
  return pair_count;
}

SubdivisionCuda::SubdivisionCuda(Algorithm algorithm, SortKind sort) {
  const DeviceInfo& dev = cuda_device();
  if (!dev.available) throw RuntimeFailure("broad phase: no CUDA device (" + dev.why_not + ")");
  m = std::make_unique<Impl>();
  m->algorithm = algorithm;
  m->sort = sort;
  m->sm_count = std::max(1, dev.multiprocessors);
}

SubdivisionCuda::~SubdivisionCuda() = default;

const Stats& SubdivisionCuda::last_stats() const { return m->stats; }
std::string SubdivisionCuda::name() const {
  const std::string sort = m->sort == SortKind::seed ? "seed-sort" : "cub-sort";
  return (m->algorithm == Algorithm::seed ? "subdivision-cuda-" : "home-cell-cuda-") + sort;
}
void SubdivisionCuda::set_stage_timing(bool on) { m->timing = on; }
void SubdivisionCuda::share_scratch(::marbles::cuda::DeviceBuffer& scratch) { m->scratch = &scratch; }
SortKind SubdivisionCuda::sort_kind() const { return m->sort; }
Algorithm SubdivisionCuda::algorithm() const { return m->algorithm; }
const Pair* SubdivisionCuda::device_pairs() const { return reinterpret_cast<const Pair*>(m->last_pairs); }
bool SubdivisionCuda::pairs_in_scratch() const { return m->last_pairs && m->last_pairs != m->pairs.get(); }

std::size_t SubdivisionCuda::find_pairs_device(const SpheresIn& device_spheres, real margin, void* stream) {
  return m->run(device_spheres, margin, static_cast<cudaStream_t>(stream));
}

std::size_t SubdivisionCuda::find_pairs_device_within(const SpheresIn& device_spheres, real margin,
                                                      std::size_t capacity, void* stream) {
  return m->run(device_spheres, margin, static_cast<cudaStream_t>(stream), capacity);
}

const std::uint32_t* SubdivisionCuda::device_pair_count() const { return m->count_word.get_as<std::uint32_t>(); }
void SubdivisionCuda::replan() { m->plan.reset(); }
std::uint64_t SubdivisionCuda::bytes_copied() const { return m->bytes; }

std::size_t SubdivisionCuda::device_bytes() const {
  const Impl& i = *m;
  return ::marbles::cuda::bytes_of(i.centre, i.radius, i.bounds, i.counts, i.offsets, i.info, i.keys, i.keys_alt, i.values,
                                   i.values_alt, i.flags, i.cell_index, i.cells, i.pass_begin, i.pair_counts,
                                   i.pair_offsets, i.pairs, i.tests, i.sorted_sphere, i.sorted_info, i.cub_temp,
                                   i.seed_scratch, i.own_scratch, i.count_word, i.grid_word);
}

void SubdivisionCuda::find_pairs(const SpheresIn& s, real margin, std::vector<Pair>& out) {
  out.clear();
  const std::size_t n = s.count;
  cudaStream_t stream = nullptr;
  auto* c = m->centre.as<Vec3>(n);
  auto* r = m->radius.as<real>(n);
  if (n > 0) {
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(c, s.centre, n * sizeof(Vec3), cudaMemcpyHostToDevice, stream));
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(r, s.radius, n * sizeof(real), cudaMemcpyHostToDevice, stream));
  }
  const std::size_t count = m->run({c, r, n}, margin, stream);
  out.resize(count);
  if (count > 0)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(out.data(), m->last_pairs, count * sizeof(Pair), cudaMemcpyDeviceToHost, stream));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(stream));
}

std::unique_ptr<BroadPhase> make_subdivision_cuda(Algorithm algorithm, SortKind sort) {
  return std::make_unique<SubdivisionCuda>(algorithm, sort);
}

}  // namespace marbles::broadphase
