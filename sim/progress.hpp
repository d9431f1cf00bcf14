// sim/progress.hpp — one status line, rewritten in place on a terminal.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace marbles {

class Progress {
 public:
  // Active only when `enabled` and stderr is a terminal.
  explicit Progress(bool enabled);
  ~Progress() { finish(); }

  // Redraws at most ~10 times a second.
  void update(double sim_time, double sim_duration, std::uint64_t steps, std::uint64_t total_steps);
  void finish();

 private:
  bool m_active = false;
  bool m_drawn = false;
  std::chrono::steady_clock::time_point m_start, m_last;
};

}  // namespace marbles
