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
  const auto count = static_cast<int>(chunks.size());
  const std::size_t total = parts_size(chunks, 0, count);
  try {
    errors.rethrow();
    put_parts(out, 0, chunks, 0, count, std::size_t(1) << 16);  // `out` replaced, each chunk on a thread of its own
  } catch (const std::bad_alloc&) {
    throw RuntimeFailure("out of memory for the candidate pairs: " + std::to_string(total) + " pairs (" +
                         std::to_string(total * sizeof(Pair) >> 20) +
                         " MiB) found before it ran out; so many spheres overlap (coincident centres?) that "
                         "their pairs do not fit");
  }
}

}  // namespace marbles::broadphase
