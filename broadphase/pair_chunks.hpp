// broadphase/pair_chunks.hpp — the CPU traversals' per-chunk pair lists
// joined into one, in chunk order (shared by broadphase_cpu.cpp and
// home_cell_cpu.cpp).
#pragma once

#include <algorithm>
#include <new>
#include <string>
#include <vector>

#include "broadphase/broadphase.hpp"
#include "core/error.hpp"
#include "core/parallel.hpp"

namespace marbles::broadphase {

// Rethrows what the traversal loop caught; a pair set that does not fit in
// memory becomes a RuntimeFailure that says how many pairs it had reached.
inline void gather_pair_chunks(const std::vector<std::vector<Pair>>& chunks, const ParallelErrors& errors,
                               std::vector<Pair>& out) {
  std::size_t total = 0;
  for (const auto& local : chunks) total += local.size();
  try {
    errors.rethrow();
    out.resize(total);  // `out` replaced: its elements reused, only what it grows by initialised
  } catch (const std::bad_alloc&) {
    throw RuntimeFailure("out of memory for the candidate pairs: " + std::to_string(total) + " pairs (" +
                         std::to_string(total * sizeof(Pair) >> 20) +
                         " MiB) found before it ran out; so many spheres overlap (coincident centres?) that "
                         "their pairs do not fit");
  }
  // Each chunk's place, then the copies on all threads.
  std::vector<std::size_t> place(chunks.size() + 1, 0);
  for (std::size_t c = 0; c < chunks.size(); ++c) place[c + 1] = place[c] + chunks[c].size();
  const auto count = static_cast<std::ptrdiff_t>(chunks.size());
#pragma omp parallel for schedule(dynamic, 1) if (total >= (std::size_t(1) << 16))
  for (std::ptrdiff_t c = 0; c < count; ++c)
    std::copy(chunks[c].begin(), chunks[c].end(), out.begin() + static_cast<std::ptrdiff_t>(place[c]));
}

}  // namespace marbles::broadphase
