// sim/signals.hpp — what the program does when a signal arrives.
//
//   SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, and an exception that escapes
//   (std::terminate): an internal error. One line on stderr names it and the
//   process exits 1. Every file under its final name is complete (each is
//   written under a temporary name and renamed once checked).
//   SIGINT, SIGTERM during `marbles run`'s steps: a request to stop. The run
//   ends the step it is in, writes a checkpoint and exits 1 with the command
//   that resumes it. A second one, a second or more after the first, ends
//   the process at once (sooner it is the first delivered twice, as a
//   sender that signals the process and then its group does).
#pragma once

namespace marbles {

// The internal-error handlers, for the whole process (cli_main).
void install_fatal_handlers();

// The stop request's handlers while it lives (the run's steps); the ones
// before it are put back after.
class StopRequests {
 public:
  StopRequests();
  ~StopRequests();
  StopRequests(const StopRequests&) = delete;
  StopRequests& operator=(const StopRequests&) = delete;
  // The signal that asked to stop (SIGINT, SIGTERM), or 0.
  int received() const;
};

// "SIGINT", "SIGSEGV", ... (the number for others).
const char* signal_name(int sig);

}  // namespace marbles
