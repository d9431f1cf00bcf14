#include "sim/progress.hpp"

#include <unistd.h>

namespace marbles {

Progress::Progress(bool enabled)
    : m_active(enabled && isatty(fileno(stderr))),
      m_start(std::chrono::steady_clock::now()),
      m_last(m_start) {}

void Progress::update(double sim_time, double sim_duration, std::uint64_t steps, std::uint64_t total_steps) {
  if (!m_active) return;
  const auto now = std::chrono::steady_clock::now();
  if (m_drawn && now - m_last < std::chrono::milliseconds(100) && steps < total_steps) return;
  m_last = now;
  const double wall = std::chrono::duration<double>(now - m_start).count();
  const double rate = wall > 0 ? steps / wall : 0;
  const double eta = rate > 0 ? (total_steps - steps) / rate : 0;
  std::fprintf(stderr, "\r\033[K  t = %.4g / %.4g s   step %llu / %llu   %.1f steps/s   ETA %.0f s", sim_time,
               sim_duration, static_cast<unsigned long long>(steps), static_cast<unsigned long long>(total_steps),
               rate, eta);
  std::fflush(stderr);
  m_drawn = true;
}

void Progress::finish() {
  if (m_active && m_drawn) std::fprintf(stderr, "\r\033[K");
  m_drawn = false;
}

}  // namespace marbles
