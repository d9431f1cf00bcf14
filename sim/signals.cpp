#include "sim/signals.hpp"

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdint>
#include <ctime>
#include <cstring>
#include <exception>
#include <initializer_list>

namespace marbles {
namespace {

// The signal that asked to stop, or 0. Atomic (and stored after the time
// below): the run's OpenMP threads may take the two deliveries of one
// request at once, and the second must see the first's time.
std::atomic<int> g_stop{0};
static_assert(std::atomic<int>::is_always_lock_free, "read and written in a signal handler");
// When the first stop request came (CLOCK_MONOTONIC, ms). A sender that
// signals the process and then its group (`timeout`, a job control kill)
// delivers one request twice within microseconds: a repeat this soon is
// that request again, not a second one.
std::atomic<std::int64_t> g_first_ms{0};
static_assert(std::atomic<std::int64_t>::is_always_lock_free, "read and written in a signal handler");
constexpr std::int64_t kSameRequestMs = 1000;

std::int64_t now_ms() {  // clock_gettime is async-signal-safe
  timespec t{};
  ::clock_gettime(CLOCK_MONOTONIC, &t);
  return std::int64_t(t.tv_sec) * 1000 + t.tv_nsec / 1000000;
}
struct sigaction g_previous_int, g_previous_term;

// Async-signal-safe: write(2) and _exit only.
void say(const char* text) {
  for (std::size_t n = std::strlen(text); n > 0;) {
    const ssize_t k = ::write(STDERR_FILENO, text, n);
    if (k <= 0) return;
    text += k;
    n -= static_cast<std::size_t>(k);
  }
}

void on_fatal(int sig) {
  say("marbles: internal error: fatal signal ");
  say(signal_name(sig));
  say("; files under their final names are complete. Please report it with the scene and the command line.\n");
  ::_exit(1);
}

void on_terminate() {
  say("marbles: internal error: ");
  if (std::exception_ptr e = std::current_exception()) {
    try {
      std::rethrow_exception(e);
    } catch (const std::exception& x) {
      say("an exception escaped: ");
      say(x.what());
    } catch (...) {
      say("an exception escaped");
    }
  } else {
    say("std::terminate");
  }
  say("; files under their final names are complete. Please report it with the scene and the command line.\n");
  ::_exit(1);
}

void on_stop(int sig) {
  if (g_stop.load() != 0) {
    const std::int64_t first = g_first_ms.load();
    if (first == 0 || now_ms() - first < kSameRequestMs) return;  // the first request, delivered again
    ::signal(sig, SIG_DFL);  // a second request: now
    ::raise(sig);
    return;
  }
  g_first_ms.store(now_ms());
  g_stop.store(sig);
}

}  // namespace

const char* signal_name(int sig) {
  switch (sig) {
    case SIGSEGV: return "SIGSEGV (invalid memory access)";
    case SIGBUS: return "SIGBUS (bus error)";
    case SIGFPE: return "SIGFPE (arithmetic exception)";
    case SIGILL: return "SIGILL (illegal instruction)";
    case SIGABRT: return "SIGABRT (abort)";
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    default: return "(another signal)";
  }
}

void install_fatal_handlers() {
  // An alternate stack, so that a stack overflow still gets its message.
  static char alternate[64 * 1024];
  stack_t stack{};
  stack.ss_sp = alternate;
  stack.ss_size = sizeof alternate;
  ::sigaltstack(&stack, nullptr);
  struct sigaction action {};
  action.sa_handler = on_fatal;
  action.sa_flags = SA_ONSTACK | SA_RESETHAND;
  sigemptyset(&action.sa_mask);
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) ::sigaction(sig, &action, nullptr);
  std::set_terminate(on_terminate);
}

StopRequests::StopRequests() {
  g_stop.store(0);
  g_first_ms.store(0);
  struct sigaction action {};
  action.sa_handler = on_stop;
  sigemptyset(&action.sa_mask);
  ::sigaction(SIGINT, &action, &g_previous_int);
  ::sigaction(SIGTERM, &action, &g_previous_term);
}

StopRequests::~StopRequests() {
  ::sigaction(SIGINT, &g_previous_int, nullptr);
  ::sigaction(SIGTERM, &g_previous_term, nullptr);
}

int StopRequests::received() const { return g_stop.load(); }

}  // namespace marbles
