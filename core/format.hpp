// core/format.hpp — numbers as text for output files.
//
//   shortest(v)      the shortest text that reads back as exactly v
//                    (std::to_chars): 0.1, 1e-07, 2.5
//   significant(v, n) v to n significant digits (%g): messages
//   time_text(t)     the shortest text within 1e-13 of t relative: a frame
//                    time k dt written as 0.03, not 0.030000000000000002
#pragma once

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace marbles {

inline std::string shortest(double v) {
  if (!std::isfinite(v)) return std::isnan(v) ? "nan" : (v > 0 ? "inf" : "-inf");
  char text[32];
  const auto result = std::to_chars(text, text + sizeof text, v);
  return std::string(text, result.ptr);
}

inline std::string significant(double v, int digits) {
  char text[40];
  std::snprintf(text, sizeof text, "%.*g", digits, v);
  return text;
}

inline std::string time_text(double t) {
  if (!std::isfinite(t)) return shortest(t);
  char text[40];
  for (int digits = 1; digits <= 17; ++digits) {
    std::snprintf(text, sizeof text, "%.*g", digits, t);
    if (std::fabs(std::strtod(text, nullptr) - t) <= 1e-13 * std::fabs(t)) return text;
  }
  return shortest(t);
}

}  // namespace marbles
