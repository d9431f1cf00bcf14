#pragma once
// available_memory(): the bytes of host memory a run may still take.
//
// MemAvailable of /proc/meminfo, or MARBLES_MEMORY_AVAILABLE (bytes) where
// set: a container whose /proc shows the host's memory, or a test that needs
// a small machine. Read where memory is about to be committed (a scene's
// spheres, a pair set growing), never in a step's steady state.

#include <cstdlib>
#include <fstream>
#include <string>

namespace marbles {

// Bytes available now, or 0 when unknown.
inline double available_memory() {
  if (const char* given = std::getenv("MARBLES_MEMORY_AVAILABLE"); given && *given) {
    char* end = nullptr;
    const double bytes = std::strtod(given, &end);
    if (end && *end == '\0' && bytes > 0 && bytes < 1e300) return bytes;
  }
  std::ifstream in("/proc/meminfo");
  std::string key;
  double kib = 0;
  std::string unit;
  while (in >> key >> kib >> unit)
    if (key == "MemAvailable:") return kib * 1024;
  return 0;
}

}  // namespace marbles
