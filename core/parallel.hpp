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
#pragma once

#include <atomic>
#include <exception>
#include <mutex>

#if defined(_OPENMP)
#include <omp.h>
#endif

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

}  // namespace marbles
