// bench/broadphase_bench.hpp — the broad-phase benchmark, callable from the
// command line (`marbles bench broadphase ...`) and from the standalone
// program marbles_bench_broadphase.
//
// For each N it builds the scene, calls the broad phase `repeats` times
// after warm-up and prints a short table of the median and minimum time per
// stage (cell IDs, sort, cell list, traversal, total), the pair count and,
// for CUDA, the bandwidth floor (bytes the stages must move / measured
// device-to-device copy bandwidth). With `json` it also prints one JSON
// object per line before the table.
#pragma once

#include <cstddef>
#include <iosfwd>
#include <string>
#include <vector>

namespace marbles::bench {

struct BroadphaseBenchOptions {
  std::string backend = "cpu";   // cpu | cuda
  std::string algorithm = "home";  // seed | home
  std::string sort = "cub";      // seed | cub (cuda only)
  std::string scene = "gas";     // gas | pile | poly
  std::vector<std::size_t> n;    // empty: 10^4, 10^5, 10^6
  int repeats = 20;
  bool json = false;
  unsigned long long seed = 1;
  double margin = 0;
};

// Returns 0 on success, 2 on a bad option (message on `out`), 1 when the
// backend cannot run (e.g. no CUDA device; message on `out`).
int run_broadphase_bench(const BroadphaseBenchOptions& options, std::ostream& out);

// Parses `--backend X --algorithm X --sort X --scene X --n N[,N...] --repeats K --json --seed S --margin M`
// (argv without the program and verb names). Throws std::invalid_argument.
BroadphaseBenchOptions parse_broadphase_bench_args(const std::vector<std::string>& args);

}  // namespace marbles::bench
