#include "sim/limits.hpp"

#include <cmath>
#include <cstdlib>

#include "core/error.hpp"

namespace marbles {

Limits& limits() {
  static Limits the_limits;
  return the_limits;
}

void raise_limit(const std::string& assignment) {
  const SourceLocation where{};
  const std::size_t eq = assignment.find('=');
  const std::string name = assignment.substr(0, eq);
  if (eq == std::string::npos)
    throw InputError(where, "--limit", "expected NAME=VALUE (e.g. spheres=2e9), got '" + assignment + "'");
  const std::string text = assignment.substr(eq + 1);
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  const bool number = !text.empty() && end == text.c_str() + text.size() && std::isfinite(value);
  Limits& l = limits();
  double* target = name == "scene_mib" ? &l.scene_mib
                   : name == "materials" ? &l.materials
                   : name == "substeps"  ? &l.substeps
                   : name == "spheres"   ? &l.spheres
                   : name == "memory"    ? &l.memory
                   : name == "study_runs" ? &l.study_runs
                                         : nullptr;
  if (!target)
    throw InputError(where, "--limit",
                     "unknown limit '" + name + "'; expected one of: scene_mib, materials, substeps, spheres, memory, study_runs");
  if (!number || value < 0 || (value == 0 && name != "memory"))
    throw InputError(where, "--limit", name + " must be a positive number, got '" + text + "'");
  if (name == "spheres" && value > 2147483647.0)
    throw InputError(where, "--limit", "spheres can be raised to 2147483647 at most (sphere ids are 32-bit), got " + text);
  *target = value;
}

}  // namespace marbles
