// core/environment.hpp — a switch read from the environment: a whole number
// within bounds, or the program refuses it, naming the variable and what it
// expects (the CUDA step's MARBLES_CUDA_TRIM_EVERY, MARBLES_CUDA_CLUSTER).
#pragma once

#include <cstdlib>
#include <string>

#include "core/error.hpp"

namespace marbles {

// The whole number `name` holds, from 0 to `most`; `unset` where it is not
// set. Anything else: RuntimeFailure("NAME=VALUE: " + expected).
inline long whole_from_environment(const char* name, long unset, long most, const std::string& expected) {
  const char* asked = std::getenv(name);
  if (asked == nullptr) return unset;
  char* end = nullptr;
  const long value = std::strtol(asked, &end, 10);
  if (end == asked || *end != '\0' || value < 0 || value > most)
    throw RuntimeFailure(std::string(name) + "=" + asked + ": " + expected);
  return value;
}

}  // namespace marbles
