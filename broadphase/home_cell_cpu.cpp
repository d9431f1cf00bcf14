// broadphase/home_cell_cpu.cpp — the home-cell broad phase on the CPU, the
// twin of home_cell_cuda.cu (same stages, same math, same output order):
//
//   keys       bounds -> grid (home_cell_math.hpp); per sphere its home key
//   sort       stable radix sort of (key, id) over the key's used bits
//   cell starts  lb(k) = first sorted index with key >= k: a dense array over
//              all cells, or a binary search for sparse grids
//   traversal  per sorted sphere: own row after it, four forward rows;
//              exact test; pairs as (smaller id, larger id)
//
// Grids wider than 62 key bits (a sphere very far from the rest) rank each
// axis's used coordinates h - 1, h, h + 1: consecutive integers keep
// consecutive ranks, so rows stay contiguous and the search stays exact.
// OpenMP loops run over fixed chunks joined in chunk order: the output does
// not depend on the number of threads.
#include <algorithm>
#include <chrono>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "broadphase/grid.hpp"
#include "broadphase/pair_chunks.hpp"
#include "core/counting_sort.hpp"
#include "core/radix_sort.hpp"
#include "core/error.hpp"

namespace marbles::broadphase {
namespace {

using Clock = std::chrono::steady_clock;
double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// The traversal's chunks of sorted spheres, taken by the threads in turn
// (their pairs joined in chunk order: the same list for any thread count).
// 4096: a settle scene of 10^5 has 25, so 16 threads share them; with
// 16384 its 7 chunks left 9 of 16 threads idle (the traversal 2.4 ms a
// step on 16 threads; on 2 threads 2048 and 16384 measured level).
constexpr std::size_t kChunk = 1 << 12;
// Below this many spheres a parallel loop costs more than it saves.
constexpr std::size_t kParallelMinimum = 1 << 14;

struct Record {
  Vec3 centre;
  real radius;
};

class HomeCellCpu final : public BroadPhase {
 public:
  void find_pairs(const SpheresIn& spheres, real margin, std::vector<Pair>& out) override;
  const Stats& last_stats() const override { return m_stats; }
  std::string name() const override { return "home-cell-cpu"; }

 private:
  template <class Key>
  void run(const SpheresIn& s, real margin, const HomeGrid& g, std::vector<Key>& keys, std::vector<Key>& keys_tmp,
           std::vector<Pair>& out, Clock::time_point t0);
  void compress_axes(const SpheresIn& s, HomeGrid& g);
  void find_pairs_of(const SpheresIn& s, real margin, std::vector<Pair>& out, Clock::time_point t0);

  Stats m_stats;
  std::vector<CellCoord> m_home;             // compressed grids only
  std::vector<std::int64_t> m_axis[3];       // compressed grids only: used coordinates per axis
  std::vector<std::uint32_t> m_keys32, m_keys32_tmp;
  std::vector<std::uint64_t> m_keys64, m_keys64_tmp;
  std::vector<std::uint32_t> m_ids, m_ids_tmp, m_lb;
  std::vector<Record> m_sorted;
  std::vector<std::vector<Pair>> m_pair_chunks;
  std::vector<std::size_t> m_test_chunks;
  bool m_compressed = false;
};

void HomeCellCpu::compress_axes(const SpheresIn& s, HomeGrid& g) {
  const std::size_t n = s.count;
  m_home.resize(n);
  for (auto& a : m_axis) a.clear();
  for (std::size_t i = 0; i < n; ++i) {
    const CellCoord h = home_cell(s.centre[i], g);
    m_home[i] = h;
    const std::int64_t c[3] = {h.x, h.y, h.z};
    for (int k = 0; k < 3; ++k)
      for (int d = -1; d <= 1; ++d) m_axis[k].push_back(c[k] + d);
  }
  for (auto& a : m_axis) {
    std::sort(a.begin(), a.end());
    a.erase(std::unique(a.begin(), a.end()), a.end());
  }
  auto rank = [&](int k, std::int64_t v) {
    return static_cast<std::int64_t>(std::lower_bound(m_axis[k].begin(), m_axis[k].end(), v) - m_axis[k].begin());
  };
  for (auto& h : m_home) h = {rank(0, h.x), rank(1, h.y), rank(2, h.z)};
  for (int k = 0; k < 3; ++k) g.dim[k] = m_axis[k].size();
  if (!set_home_layout(g))
    throw RuntimeFailure("broad phase: the home-cell keys need more than 62 bits even after compression");
}

void HomeCellCpu::find_pairs(const SpheresIn& s, real margin, std::vector<Pair>& out) {
  const auto t0 = Clock::now();
  // `out` is replaced where the pairs are gathered (gather_pair_chunks),
  // its elements reused: cleared first, every one of them was initialised
  // again on one thread.
  m_stats = Stats{};
  if (s.count >= kMaxObjects) {
    out.clear();
    throw RuntimeFailure("broad phase: more than 2^28 spheres");
  }
  if (s.count < 2) {
    out.clear();
    return;
  }
  try {
    find_pairs_of(s, margin, out, t0);
  } catch (...) {
    out.clear();  // no pairs of an earlier call left where this one failed
    throw;
  }
}

void HomeCellCpu::find_pairs_of(const SpheresIn& s, real margin, std::vector<Pair>& out, Clock::time_point t0) {
  HomeGridChoice hc = choose_home_grid(bounds_of(s), margin);
  m_compressed = hc.width == KeyWidth::too_wide;
  if (m_compressed) {
    compress_axes(s, hc.grid);
    hc.width = hc.grid.cells <= (std::uint64_t{1} << 31) ? KeyWidth::bits32 : KeyWidth::bits64;
  }
  m_stats.compressed_keys = m_compressed;
  m_stats.cell_size = hc.grid.cell;
  m_stats.key_bits = hc.grid.key_bits;
  m_stats.grid_cells = hc.grid.cells;
  if (hc.width == KeyWidth::bits32) {
    m_stats.key_width = 32;
    run(s, margin, hc.grid, m_keys32, m_keys32_tmp, out, t0);
  } else {
    m_stats.key_width = 64;
    run(s, margin, hc.grid, m_keys64, m_keys64_tmp, out, t0);
  }
}

template <class Key>
void HomeCellCpu::run(const SpheresIn& s, real margin, const HomeGrid& g, std::vector<Key>& keys,
                      std::vector<Key>& keys_tmp, std::vector<Pair>& out, Clock::time_point t0) {
  const std::size_t n = s.count;
  const auto chunks_of = [](std::size_t count) { return static_cast<std::ptrdiff_t>((count + kChunk - 1) / kChunk); };

  // --- keys ---------------------------------------------------------------------
  keys.resize(n);
  m_ids.resize(n);
#pragma omp parallel for schedule(static) if (n > kParallelMinimum)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) {
    const CellCoord h = m_compressed ? m_home[i] : home_cell(s.centre[i], g);
    keys[i] = static_cast<Key>(home_key(h, g));
    m_ids[i] = static_cast<std::uint32_t>(i);
  }
  m_stats.cell_entries = n;
  const auto t1 = Clock::now();

  // --- sort -----------------------------------------------------------------------
  m_stats.sort_passes = radix_sort_pairs(keys, m_ids, g.key_bits, keys_tmp, m_ids_tmp);
  const auto t2 = Clock::now();

  // --- cell starts: spheres in sorted order, lower bounds -------------------------
  m_sorted.resize(n);
#pragma omp parallel for schedule(static) if (n > kParallelMinimum)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i)
    m_sorted[i] = {s.centre[m_ids[i]], s.radius[m_ids[i]]};
  const bool dense = use_dense_cell_starts(g, n);
  m_stats.dense_cell_starts = dense;
  if (dense) {
    m_lb.resize(g.cells + 1);
    const Key* sorted_keys = keys.data();
    sorted_bucket_starts(
        static_cast<std::uint32_t>(n), g.cells, [sorted_keys](std::uint32_t i) { return sorted_keys[i]; },
        m_lb.data(), static_cast<std::uint32_t>(kParallelMinimum));
  }
  const Key* key_data = keys.data();
  const std::uint32_t* lb_data = m_lb.data();
  const auto count = static_cast<std::uint32_t>(n);
  auto lb = [&](Key k) -> std::uint32_t { return dense ? lb_data[k] : lower_bound_key(key_data, count, k); };
  const auto t3 = Clock::now();

  // --- traversal ------------------------------------------------------------------
  const std::ptrdiff_t chunks = chunks_of(n);
  m_pair_chunks.resize(static_cast<std::size_t>(chunks));
  for (std::vector<Pair>& chunk : m_pair_chunks) chunk.clear();  // a chunk skipped after a throw counts none
  m_test_chunks.assign(static_cast<std::size_t>(chunks), 0);
  ParallelErrors errors;
  PairGrowth growth;
#pragma omp parallel for schedule(dynamic, 1) if (chunks > 1 && n > kParallelMinimum)
  for (std::ptrdiff_t c = 0; c < chunks; ++c) {
    // Into a vector of the thread's own (fill_apart): the chunks' vectors lie
    // side by side.
    auto traverse_chunk = [&](std::vector<Pair>& local) {
      local.clear();
      std::size_t tests = 0;
      const std::size_t end = std::min(n, (static_cast<std::size_t>(c) + 1) * kChunk);
      for (std::size_t i = static_cast<std::size_t>(c) * kChunk; i < end; ++i) {
        const auto si = static_cast<std::uint32_t>(i);
        // Each candidate written, kept by moving on past it where it
        // overlaps: no branch on the test.
        const Record own = m_sorted[i];
        for_each_candidate_range(si, keys[i], g, lb, [&](std::uint32_t begin, std::uint32_t end) {
          if (end <= begin) return;
          std::size_t at = local.size();
          growth.before(local.capacity(), at + (end - begin));
          local.resize(at + (end - begin));
          Pair* to = local.data();
          for (std::uint32_t j = begin; j < end; ++j) {
            const Record& o = m_sorted[j];
            to[at] = ordered_pair(m_ids[i], m_ids[j]);
            at += spheres_overlap(own.centre, own.radius, o.centre, o.radius, margin) ? 1 : 0;
          }
          tests += end - begin;
          local.resize(at);
        });
      }
      m_test_chunks[static_cast<std::size_t>(c)] = tests;
    };
    errors.run([&] { fill_apart(m_pair_chunks[static_cast<std::size_t>(c)], traverse_chunk); });
  }
  gather_pair_chunks(m_pair_chunks, errors, out);
  for (std::size_t c = 0; c < m_pair_chunks.size(); ++c) m_stats.tests += m_test_chunks[c];
  m_stats.pairs = out.size();
  const auto t4 = Clock::now();
  m_stats.ms_cell_ids = ms_between(t0, t1);
  m_stats.ms_sort = ms_between(t1, t2);
  m_stats.ms_cell_list = ms_between(t2, t3);
  m_stats.ms_traversal = ms_between(t3, t4);
  m_stats.ms_total = ms_between(t0, t4);
}

}  // namespace

std::unique_ptr<BroadPhase> make_home_cell_cpu() { return std::make_unique<HomeCellCpu>(); }

}  // namespace marbles::broadphase
