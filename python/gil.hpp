// python/gil.hpp — the GIL let go for a step, and a daemon thread's step
// still running as the interpreter ends.
//
// Before Python 3.14 the interpreter's end stops a thread that takes the GIL
// back by unwinding it with no exception (pthread_exit), through frames that
// cannot be unwound: a step left running in a daemon thread as a script
// ended aborted the process ("terminate called without an active
// exception"). So the module's atexit hook (at_exit, python/module.cpp),
// which runs before the interpreter lets such threads go, sets `ending` and
// lets go of the GIL until every call that let go of it has either taken it
// back or parked: a call that meets `ending` off the main thread (a step
// between two of its steps, any call at its end) waits without the GIL until
// the process ends, as Python 3.14 makes such threads wait.
#pragma once

#include <atomic>
#include <chrono>
#include <thread>

#include <nanobind/nanobind.h>

namespace marbles::python {

inline std::atomic<bool> ending{false};
inline std::atomic<int> let_go{0};  // calls that let go of the GIL and have not taken it back
inline std::atomic<int> parked{0};  // of those, the ones waiting for the process's end

// Where the interpreter is ending, never returns (the process's end stops
// the thread); not on the main thread (`main`), which the end never stops
// and which may step in an atexit hook of its own, run after the module's.
inline void park_if_ending(bool main) {
  if (main) return;
#if PY_VERSION_HEX >= 0x030D0000
  const bool finalizing = Py_IsFinalizing() != 0;
#else
  const bool finalizing = _Py_IsFinalizing() != 0;
#endif
  if (!ending.load() && !finalizing) return;
  parked.fetch_add(1);
  while (true) std::this_thread::sleep_for(std::chrono::seconds(1));
}

// The GIL let go for a call (made with the GIL held), taken back at its end
// unless the interpreter is ending. Every call that lets the GIL go for long
// uses it (the step, pairs(), the study).
class GilLetGo {
 public:
  GilLetGo() : m_main(_PyOS_IsMainThread() != 0) {
    let_go.fetch_add(1);  // with the GIL held: at_exit, which holds it too, counts this call
    m_state = PyEval_SaveThread();
  }
  ~GilLetGo() {
    park_if_ending(m_main);
    PyEval_RestoreThread(m_state);
    let_go.fetch_sub(1);
  }
  GilLetGo(const GilLetGo&) = delete;
  GilLetGo& operator=(const GilLetGo&) = delete;

 private:
  bool m_main;  // on Python's main thread (asked with the GIL held)
  PyThreadState* m_state = nullptr;
};

}  // namespace marbles::python
