// core/parallel.hpp — the CPU's threads, and exceptions out of OpenMP loops.
//
// thread_count() / set_thread_count(n): OpenMP's team size for the loops
// that follow (1 in a build without OpenMP).
//
// An exception that leaves an OpenMP parallel region calls std::terminate
// (SIGABRT). Loop bodies that can throw (allocations: std::bad_alloc) run
// through ParallelErrors::run, which keeps the first exception; after the
// loop, rethrow() throws it on the calling thread, where it can become a
// message and an exit code.
//
// collect_in_order: a list built on all threads in the sequential order.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <string>
#include <type_traits>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "core/error.hpp"

namespace marbles {

inline int thread_count() {
#if defined(_OPENMP)
  return omp_get_max_threads();
#else
  return 1;
#endif
}

// Inside a parallel region: this thread's number and the team's size.
inline int thread_index() {
#if defined(_OPENMP)
  return omp_get_thread_num();
#else
  return 0;
#endif
}
inline int team_size() {
#if defined(_OPENMP)
  return omp_get_num_threads();
#else
  return 1;
#endif
}

// The most threads a run takes, however given (--threads, Python's
// threads=, OMP_NUM_THREADS).
inline constexpr int kMostThreads = 4096;

// OpenMP's count where the run gives none (OMP_NUM_THREADS, else every
// core), held to kMostThreads as --threads is: OMP_NUM_THREADS=100000 was
// taken as it was.
inline int default_thread_count() {
  const int n = thread_count();
  if (n > kMostThreads)
    throw InputError(SourceLocation{}, "OMP_NUM_THREADS",
                     "must be <= " + std::to_string(kMostThreads) + ", got " + std::to_string(n) +
                         " (or give the run its count: --threads, or threads= in Python)");
  return n;
}

inline void set_thread_count(int n) {
#if defined(_OPENMP)
  if (n > 0) omp_set_num_threads(n);
#else
  (void)n;
#endif
}

class ParallelErrors {
 public:
  template <class F>
  void run(F&& body) noexcept {
    if (m_failed.load(std::memory_order_relaxed)) return;  // later bodies are skipped once one failed
    try {
      body();
    } catch (...) {
      const std::lock_guard<std::mutex> lock(m_mutex);
      if (!m_first) m_first = std::current_exception();
      m_failed.store(true, std::memory_order_relaxed);
    }
  }
  void rethrow() const {
    if (m_first) std::rethrow_exception(m_first);
  }

 private:
  std::mutex m_mutex;
  std::exception_ptr m_first;
  std::atomic<bool> m_failed{false};
};

// fill(v) on `slot`, pushing into a vector object of this call's own that
// holds slot's storage and contents, swapped back after. Vectors kept side by
// side (one a chunk or a thread) share cache lines: pushing into the slot
// itself would write a line that another thread's pushes write too (the CPU
// broad phase's traversal ran no faster on two threads than on one until
// its chunks filled so). If fill throws, the slot keeps what it had filled
// (a pair search out of memory says how many pairs it had found).
template <class T, class Fill>
void fill_apart(std::vector<T>& slot, Fill&& fill) {
  struct SwapBack {
    std::vector<T>& slot;
    std::vector<T> own;
    ~SwapBack() { own.swap(slot); }
  } apart{slot, {}};
  apart.own.swap(slot);
  fill(apart.own);
}

// What make(k, out) appends for k = 0..count-1, on all threads when count >=
// parallel_from: each thread fills its own buffer over a contiguous (static)
// chunk, the first thread's straight into `out` (no other thread touches
// it), thread t's into parts[t]. Read as `out` and then parts[1], parts[2],
// ... up to the returned thread count, they hold the sequential order.
// `parts`: the buffers, kept between calls (cleared here). An exception in
// make (an allocation) is rethrown here.
template <class T, class Make>
int collect_in_parts(std::size_t count, std::size_t parallel_from, std::vector<T>& out,
                     std::vector<std::vector<T>>& parts, Make&& make) {
  const int threads = count >= parallel_from ? thread_count() : 1;
  if (threads == 1) {
    for (std::size_t k = 0; k < count; ++k) make(k, out);
    return 1;
  }
  if (parts.size() < static_cast<std::size_t>(threads)) parts.resize(threads);
  for (auto& p : parts) p.clear();
  ParallelErrors errors;
#pragma omp parallel num_threads(threads)
  {
    // The thread's own copy of `make`: through the shared reference, its
    // captures were read again after every append.
    std::decay_t<Make> make_here = make;
    fill_apart(thread_index() == 0 ? out : parts[thread_index()], [&](std::vector<T>& mine) {
#pragma omp for schedule(static)
      for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(count); ++k)
        errors.run([&] { make_here(static_cast<std::size_t>(k), mine); });
    });
  }
  errors.rethrow();
  return threads;
}

// The parts [from, threads) copied to `to` from element `at` on, in order,
// each part on a thread of its own where they hold `parallel_from` or more
// in all; `to` must hold them (also the broad phase's chunks of pairs,
// gather_pair_chunks). Joined on one thread, the copy was the one
// part of the CPU step's contact search that did not shrink with more
// threads (settle scene of 10^5: the search 6 ms a step on 4, 8 and 16
// threads; docs/architecture.md "The CPU step on many threads").
template <class T>
void copy_parts(T* to, std::size_t at, const std::vector<std::vector<T>>& parts, int from, int threads,
                std::size_t parallel_from) {
  const int count = threads > from ? threads - from : 0;
  std::vector<std::size_t> place(static_cast<std::size_t>(count) + 1, at);
  for (int p = 0; p < count; ++p) place[p + 1] = place[p] + parts[from + p].size();
#pragma omp parallel for schedule(dynamic, 1) if (place[count] - at >= parallel_from && count > 1)
  for (int p = 0; p < count; ++p) std::copy(parts[from + p].begin(), parts[from + p].end(), to + place[p]);
}

// The parts' sizes [from, threads) summed.
template <class T>
std::size_t parts_size(const std::vector<std::vector<T>>& parts, int from, int threads) {
  std::size_t total = 0;
  for (int t = from; t < threads; ++t) total += parts[t].size();
  return total;
}

// parts[from, threads) put in `to` from element `at` on, in order, `to`
// sized to end with them (copy_parts): at to.size() they are appended, at
// 0 they replace its elements, which are reused (only what `to` grows by
// is initialised; cleared first, every element would be initialised
// again, on one thread).
template <class T>
void put_parts(std::vector<T>& to, std::size_t at, const std::vector<std::vector<T>>& parts, int from, int threads,
               std::size_t parallel_from = std::size_t(1) << 16) {
  to.resize(at + parts_size(parts, from, threads));
  copy_parts(to.data(), at, parts, from, threads, parallel_from);
}

// parts[from, threads) appended to `to`, in order.
template <class T>
void join_parts(std::vector<T>& to, std::vector<std::vector<T>>& parts, int from, int threads,
                std::size_t parallel_from = std::size_t(1) << 16) {
  put_parts(to, to.size(), parts, from, threads, parallel_from);
}

// Appends what make(k, out) appends for k = 0..count-1 to `out`, in order of
// k: collect_in_parts, then the other threads' buffers joined in thread
// order (join_parts).
template <class T, class Make>
void collect_in_order(std::size_t count, std::size_t parallel_from, std::vector<T>& out,
                      std::vector<std::vector<T>>& parts, Make&& make) {
  const int threads = collect_in_parts(count, parallel_from, out, parts, make);
  join_parts(out, parts, 1, threads);
}

}  // namespace marbles
