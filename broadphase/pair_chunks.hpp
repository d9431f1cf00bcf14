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
    out.resize(total);
  } catch (const std::bad_alloc&) {
    throw RuntimeFailure("out of memory for the candidate pairs: " + std::to_string(total) + " pairs (" +
                         std::to_string(total * sizeof(Pair) >> 20) +
                         " MiB) found before it ran out; so many spheres overlap (coincident centres?) that "
                         "their pairs do not fit");
  }
  std::size_t at = 0;
  for (const auto& local : chunks) {
    std::copy(local.begin(), local.end(), out.begin() + static_cast<std::ptrdiff_t>(at));
    at += local.size();
  }
}

}  // namespace marbles::broadphase
