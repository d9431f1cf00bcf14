// broadphase/broadphase_cpu.cpp — the seed's spatial subdivision on the CPU.
//
// Stages (DESIGN.md "The broad phase"), each a loop over broadphase_math.hpp:
//   cell IDs    bounding box and r_max -> grid; per sphere its H and P cells
//               (count, prefix sum, write: only used entries are stored)
//   sort        stable LSD radix sort of (cell key, object-list value)
//   cell list   runs of equal keys with >= 2 occupants and >= 1 H; the
//               type-major key makes the list already split into 8 by type
//   traversal   8 passes (cell type 1..8), skip rule, exact test
// OpenMP splits the loops into fixed-size chunks whose results are joined in
// chunk order, so the output is the same for any number of threads.
#include <algorithm>
#include <chrono>
#include <cstring>
#include <limits>
#include <numeric>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "broadphase/broadphase.hpp"
#include "broadphase/grid.hpp"
#include "broadphase/pair_chunks.hpp"
#include "core/radix_sort.hpp"
#include "core/error.hpp"

namespace marbles::broadphase {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

constexpr std::size_t kSphereChunk = 1 << 14;
constexpr std::size_t kEntryChunk = 1 << 14;
constexpr std::size_t kCellChunk = 1 << 10;

// Exclusive prefix sum of counts[0, n) in place; returns the total.
std::size_t exclusive_scan_in_place(std::vector<std::uint32_t>& counts, std::size_t n) {
  std::size_t total = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t c = counts[i];
    counts[i] = static_cast<std::uint32_t>(total);
    total += c;
  }
  return total;
}

// Per-axis rank of the cell coordinate halves actually used: the exact key
// scheme for grids too wide for 63 bits (a sphere very far from the rest).
struct CompressedAxes {
  std::vector<std::int64_t> halves[3];

  void build(const SpheresIn& s, const Grid& g) {
    for (int k = 0; k < 3; ++k) halves[k].clear();
    for (std::size_t i = 0; i < s.count; ++i) {
      const Neighbourhood nb = sphere_neighbourhood(s.centre[i], s.radius[i], g);
      const std::int64_t h[3] = {nb.home.x, nb.home.y, nb.home.z};
      for (int k = 0; k < 3; ++k) {
        halves[k].push_back(h[k] >> 1);
        halves[k].push_back((h[k] + nb.step[k]) >> 1);
      }
    }
    for (int k = 0; k < 3; ++k) {
      std::sort(halves[k].begin(), halves[k].end());
      halves[k].erase(std::unique(halves[k].begin(), halves[k].end()), halves[k].end());
    }
  }
  std::uint64_t rank(int k, std::int64_t half) const {
    return static_cast<std::uint64_t>(std::lower_bound(halves[k].begin(), halves[k].end(), half) - halves[k].begin());
  }
  std::uint64_t key(const CellCoord& c, const Grid& g) const {
    return (static_cast<std::uint64_t>(cell_type(c) - 1u) << g.type_shift) | (rank(0, c.x >> 1) << g.shift[0]) |
           (rank(1, c.y >> 1) << g.shift[1]) | (rank(2, c.z >> 1) << g.shift[2]);
  }
};

class SubdivisionCpu final : public BroadPhase {
 public:
  void find_pairs(const SpheresIn& spheres, real margin, std::vector<Pair>& out) override;
  const Stats& last_stats() const override { return m_stats; }
  std::string name() const override { return "subdivision-cpu"; }

 private:
  template <class Key>
  void run(const SpheresIn& s, real margin, const GridChoice& gc, std::vector<Key>& keys, std::vector<Key>& keys_tmp,
           std::vector<Pair>& out, Clock::time_point t0);

  Stats m_stats;
  CompressedAxes m_axes;
  std::vector<std::uint32_t> m_offsets, m_values, m_values_tmp;
  std::vector<std::uint16_t> m_info;
  std::vector<std::uint32_t> m_keys32, m_keys32_tmp;
  std::vector<std::uint64_t> m_keys64, m_keys64_tmp;
  std::vector<CollisionCell> m_cells;
  std::vector<std::vector<CollisionCell>> m_cell_chunks;
  std::vector<std::vector<Pair>> m_pair_chunks;
  std::vector<std::size_t> m_test_chunks;
};

void SubdivisionCpu::find_pairs(const SpheresIn& s, real margin, std::vector<Pair>& out) {
  const auto t0 = Clock::now();
  out.clear();
  m_stats = Stats{};
  if (s.count >= kMaxObjects) throw RuntimeFailure("broad phase: more than 2^28 spheres");
  if (s.count < 2) return;

  // --- cell IDs: bounds -> grid -------------------------------------------
  GridChoice gc = choose_grid(bounds_of(s), margin);
  if (gc.width == KeyWidth::too_wide) {
    m_axes.build(s, gc.grid);
    const std::uint64_t half_max[3] = {m_axes.halves[0].size() - 1, m_axes.halves[1].size() - 1,
                                       m_axes.halves[2].size() - 1};
    set_key_layout(gc.grid, half_max);
    gc.width = key_width_for(gc.grid.key_bits);
    if (gc.width == KeyWidth::too_wide)
      throw RuntimeFailure("broad phase: the cell keys need more than 63 bits even after compression (" +
                           std::to_string(gc.grid.key_bits) + ")");
    m_stats.compressed_keys = true;
  }
  m_stats.cell_size = gc.grid.cell;
  m_stats.key_bits = gc.grid.key_bits;
  if (gc.width == KeyWidth::bits32) {
    m_stats.key_width = 32;
    run(s, margin, gc, m_keys32, m_keys32_tmp, out, t0);
  } else {
    m_stats.key_width = 64;
    run(s, margin, gc, m_keys64, m_keys64_tmp, out, t0);
  }
}

template <class Key>
void SubdivisionCpu::run(const SpheresIn& s, real margin, const GridChoice& gc, std::vector<Key>& keys,
                         std::vector<Key>& keys_tmp, std::vector<Pair>& out, Clock::time_point t0) {
  const Grid g = gc.grid;
  const std::size_t n = s.count;
  const bool compressed = m_stats.compressed_keys;
  const auto n_chunks = [](std::size_t count, std::size_t chunk) { return (count + chunk - 1) / chunk; };

  // --- cell IDs: count per sphere, prefix sum, write ------------------------
  m_offsets.resize(n + 1);
  m_info.resize(n);
  {
    const std::ptrdiff_t chunks = static_cast<std::ptrdiff_t>(n_chunks(n, kSphereChunk));
#pragma omp parallel for schedule(static) if (chunks > 1)
    for (std::ptrdiff_t c = 0; c < chunks; ++c) {
      const std::size_t end = std::min(n, (static_cast<std::size_t>(c) + 1) * kSphereChunk);
      for (std::size_t i = static_cast<std::size_t>(c) * kSphereChunk; i < end; ++i) {
        const Neighbourhood nb = sphere_neighbourhood(s.centre[i], s.radius[i], g);
        m_offsets[i] = occupied_count(nb.occupied);
        m_info[i] = make_info(cell_type(nb.home), type_mask(nb));
      }
    }
  }
  m_offsets[n] = 0;
  const std::size_t entries = exclusive_scan_in_place(m_offsets, n + 1);
  if (entries > std::numeric_limits<std::uint32_t>::max())
    throw RuntimeFailure("broad phase: more than 2^32 cell entries");
  keys.resize(entries);
  m_values.resize(entries);
  {
    const std::ptrdiff_t chunks = static_cast<std::ptrdiff_t>(n_chunks(n, kSphereChunk));
#pragma omp parallel for schedule(static) if (chunks > 1)
    for (std::ptrdiff_t c = 0; c < chunks; ++c) {
      const std::size_t end = std::min(n, (static_cast<std::size_t>(c) + 1) * kSphereChunk);
      for (std::size_t i = static_cast<std::size_t>(c) * kSphereChunk; i < end; ++i) {
        std::size_t at = m_offsets[i];
        const auto id = static_cast<std::uint32_t>(i);
        if (!compressed) {
          const SphereCellIds ids = sphere_cell_ids(s.centre[i], s.radius[i], g);
          for (unsigned e = 0; e < ids.count; ++e, ++at) {
            keys[at] = static_cast<Key>(ids.key[e]);
            m_values[at] = make_value(id, e != 0, key_type(ids.key[e], g));
          }
        } else {
          const Neighbourhood nb = sphere_neighbourhood(s.centre[i], s.radius[i], g);
          for (unsigned o = 0; o < 8; ++o) {
            if (!(nb.occupied & (1u << o))) continue;
            const CellCoord cc = neighbour_cell(nb, o);
            keys[at] = static_cast<Key>(m_axes.key(cc, g));
            m_values[at] = make_value(id, o != 0, cell_type(cc));
            ++at;
          }
        }
      }
    }
  }
  m_stats.cell_entries = entries;
  const auto t1 = Clock::now();
  m_stats.ms_cell_ids = std::chrono::duration<double, std::milli>(t1 - t0).count();

  // --- sort -----------------------------------------------------------------
  m_stats.sort_passes = radix_sort_pairs(keys, m_values, g.key_bits, keys_tmp, m_values_tmp);
  const auto t2 = Clock::now();
  m_stats.ms_sort = std::chrono::duration<double, std::milli>(t2 - t1).count();

  // --- collision-cell list: runs that start in each chunk -----------------
  {
    const std::size_t chunks = n_chunks(entries, kEntryChunk);
    m_cell_chunks.resize(chunks);
#pragma omp parallel for schedule(static) if (chunks > 1)
    for (std::ptrdiff_t c = 0; c < static_cast<std::ptrdiff_t>(chunks); ++c) {
      // Into a vector of the thread's own (fill_apart): the chunks' vectors lie side by side.
      auto cells_of_chunk = [&](std::vector<CollisionCell>& local) {
        local.clear();
        const std::size_t begin = static_cast<std::size_t>(c) * kEntryChunk;
        const std::size_t end = std::min(entries, begin + kEntryChunk);
        std::size_t i = begin;
        while (i < end && i > 0 && keys[i] == keys[i - 1]) ++i;  // a run begun in the chunk before
        while (i < end) {
          std::size_t j = i;
          std::uint32_t homes = 0;
          while (j < entries && keys[j] == keys[i]) homes += value_phantom(m_values[j++]) ? 0u : 1u;
          const auto count = static_cast<std::uint32_t>(j - i);
          if (count >= 2 && homes >= 1)
            local.push_back({static_cast<std::uint32_t>(i), homes, count - homes});
          i = j;
        }
      };
      fill_apart(m_cell_chunks[static_cast<std::size_t>(c)], cells_of_chunk);
    }
    std::size_t total = 0;
    for (const auto& local : m_cell_chunks) total += local.size();
    m_cells.resize(total);
    std::size_t at = 0;
    for (const auto& local : m_cell_chunks) {
      std::copy(local.begin(), local.end(), m_cells.begin() + static_cast<std::ptrdiff_t>(at));
      at += local.size();
    }
    for (const CollisionCell& cell : m_cells) ++m_stats.cells_per_type[value_type(m_values[cell.start]) - 1];
  }
  m_stats.collision_cells = m_cells.size();
  const auto t3 = Clock::now();
  m_stats.ms_cell_list = std::chrono::duration<double, std::milli>(t3 - t2).count();

  // --- traversal: passes T = 1..8 are the consecutive type ranges ---------
  {
    const std::size_t cells = m_cells.size();
    const std::size_t chunks = n_chunks(cells, kCellChunk);
    m_pair_chunks.resize(chunks);
    for (std::vector<Pair>& chunk : m_pair_chunks) chunk.clear();  // a chunk skipped after a throw counts none
    m_test_chunks.assign(chunks, 0);
    ParallelErrors errors;
    PairGrowth growth;
#pragma omp parallel for schedule(dynamic, 4) if (chunks > 1)
    for (std::ptrdiff_t c = 0; c < static_cast<std::ptrdiff_t>(chunks); ++c) {
      auto traverse_chunk = [&](std::vector<Pair>& local) {  // into a vector of the thread's own (fill_apart)
        local.clear();
        std::size_t tests = 0;
        const std::size_t end = std::min(cells, (static_cast<std::size_t>(c) + 1) * kCellChunk);
        for (std::size_t k = static_cast<std::size_t>(c) * kCellChunk; k < end; ++k) {
          tests += traverse_cell(m_cells[k], m_values.data(), s.centre, s.radius, m_info.data(), margin,
                                 [&](std::uint32_t i, std::uint32_t j) {
                                   growth.before(local.capacity(), local.size() + 1);
                                   local.push_back({i, j});
                                 });
        }
        m_test_chunks[static_cast<std::size_t>(c)] = tests;
      };
      errors.run([&] { fill_apart(m_pair_chunks[static_cast<std::size_t>(c)], traverse_chunk); });
    }
    gather_pair_chunks(m_pair_chunks, errors, out);
    for (std::size_t c = 0; c < chunks; ++c) m_stats.tests += m_test_chunks[c];
  }
  m_stats.pairs = out.size();
  m_stats.ms_traversal = ms_since(t3);
  m_stats.ms_total = ms_since(t0);
}

}  // namespace

std::unique_ptr<BroadPhase> make_subdivision_cpu(Algorithm algorithm) {
  if (algorithm == Algorithm::home) return make_home_cell_cpu();
  return std::make_unique<SubdivisionCpu>();
}

void brute_force_pairs(const SpheresIn& s, real margin, std::vector<Pair>& out) {
  out.clear();
  PairGrowth growth;
  const std::size_t n = s.count;
  try {
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = i + 1; j < n; ++j)
        if (spheres_overlap(s.centre[i], s.radius[i], s.centre[j], s.radius[j], margin)) {
          growth.before(out.capacity(), out.size() + 1);
          out.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j)});
        }
  } catch (const std::bad_alloc&) {
    pairs_beyond_memory(out.size());
  }
}

#if !defined(MARBLES_BROADPHASE_CUDA)
std::unique_ptr<BroadPhase> make_subdivision_cuda(Algorithm, SortKind) {
  throw RuntimeFailure("broad phase: this build has no CUDA backend (no CUDA device)");
}
#endif

}  // namespace marbles::broadphase
