// core/parallel.hpp — exceptions out of OpenMP loops.
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

namespace marbles {

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
