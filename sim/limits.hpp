// sim/limits.hpp — the guards against absurd work, and raising them.
//
// A scene that would need more than these is refused up front (exit 2) with
// the number that broke the limit, before anything is allocated. A user who
// means it raises one with `--limit NAME=VALUE` (run, check, study).
#pragma once

#include <string>

namespace marbles {

struct Limits {
  double scene_mib = 64;       // a scene file's size, MiB (bulk particles go in CSV)
  double materials = 1024;     // the step keeps a coefficient table of every pair
  double substeps = 1e10;      // per run: duration / dt x substeps
  double spheres = 1e9;        // per particle block: lattice sites, random count
  double memory = 1;           // the spheres may take this fraction of the available memory (0: not checked)
  double study_runs = 1e4;     // a study's runs: its combinations x --repeats
};

// The process's limits: set by the command line before any scene is read.
Limits& limits();

// Applies `NAME=VALUE` (--limit); an unknown name or a value that is not a
// positive number (memory: not negative) is an InputError naming --limit.
void raise_limit(const std::string& assignment);

}  // namespace marbles
