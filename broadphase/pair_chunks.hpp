// broadphase/pair_chunks.hpp — the CPU traversals' per-chunk pair lists
// joined into one, in chunk order (shared by broadphase_cpu.cpp and
// home_cell_cpu.cpp).
#pragma once

#include <algorithm>
#include <atomic>
#include <new>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "core/error.hpp"
#include "core/host_memory.hpp"
#include "core/parallel.hpp"

namespace marbles::broadphase {

// The growth of one search's pair lists, held to the memory available. Where
// Linux overcommits memory a list growing past it is not refused by the
// allocator: the OOM killer ends the process, with nothing said. Once a
// search's lists have grown by kQuiet bytes, each further growth is checked
// against available_memory() and refused with std::bad_alloc, which
// gather_pair_chunks words with the pairs found so far. Lists kept between
// searches (a run's steady state) do not grow, and cost nothing here.
class PairGrowth {
 public:
  // Before a list holding room for `capacity` pairs is made to hold `needed`
  // (the vector then takes max(needed, 2 capacity)).
  void before(std::size_t capacity, std::size_t needed) {
    if (needed <= capacity) return;
    const std::size_t room = std::max(needed, 2 * capacity);
    const std::size_t grown = m_grown.fetch_add(room - capacity, std::memory_order_relaxed) + (room - capacity);
    if (grown * sizeof(Pair) < kQuiet) return;
    // The memory is read again each time the growth has risen by an eighth
    // since it was last read (not at every list's growth), and held as read.
    std::size_t next = m_next_read.load(std::memory_order_relaxed);
    if (grown >= next && m_next_read.compare_exchange_strong(next, grown + grown / 8, std::memory_order_relaxed))
      m_free.store(available_memory(), std::memory_order_relaxed);
    // The new block beside the old, and the gather's copy of what grew.
    const double free = m_free.load(std::memory_order_relaxed);
    if (free > 0 && double(room + grown) * sizeof(Pair) > free) throw std::bad_alloc();
  }

 private:
  static constexpr std::size_t kQuiet = std::size_t(64) << 20;
  std::atomic<std::size_t> m_grown{0};
  std::atomic<std::size_t> m_next_read{0};
  std::atomic<double> m_free{0};
};

// A pair set that does not fit in memory, as a RuntimeFailure that says how
// many pairs it had reached.
[[noreturn]] inline void pairs_beyond_memory(std::size_t found) {
  throw RuntimeFailure("out of memory for the candidate pairs: " + std::to_string(found) + " pairs (" +
                       std::to_string(found * sizeof(Pair) >> 20) +
                       " MiB) found before it ran out; so many spheres overlap (coincident centres?) that "
                       "their pairs do not fit");
}

// Rethrows what the traversal loop caught; a pair set that does not fit in
// memory becomes a RuntimeFailure that says how many pairs it had reached.
inline void gather_pair_chunks(const std::vector<std::vector<Pair>>& chunks, const ParallelErrors& errors,
                               std::vector<Pair>& out) {
  const auto count = static_cast<int>(chunks.size());
  const std::size_t total = parts_size(chunks, 0, count);
  try {
    errors.rethrow();
    put_parts(out, 0, chunks, 0, count, std::size_t(1) << 16);  // `out` replaced, each chunk on a thread of its own
  } catch (const std::bad_alloc&) {
    pairs_beyond_memory(total);
  }
}

}  // namespace marbles::broadphase
