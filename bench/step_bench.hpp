// bench/step_bench.hpp — time one full step (forces, broad phase, contacts,
// solver, integration) of a gas at volume fraction 0.1 in a box.
#pragma once

#include <cstddef>
#include <iosfwd>
#include <string>
#include <vector>

namespace marbles::bench {

struct StepBenchOptions {
  std::string backend = "cpu";       // cpu | cuda (broad phase)
  std::vector<std::size_t> n{10000, 100000, 1000000};
  int repeats = 10;                  // timed steps per size (after 2 warm-up steps)
  bool json = false;
  std::vector<std::string> effects{"gravity", "collisions", "walls", "restitution"};
};

int run_step_bench(const StepBenchOptions& options, std::ostream& out);

// The cost of each effect: the same dense gas stepped with collisions and
// walls only, then with each effect added, then with all of them.
struct EffectsBenchOptions {
  std::string backend = "cpu";
  std::size_t n = 20000;
  double volume_fraction = 0.4;
  int repeats = 20;
  bool json = false;
};

int run_effects_bench(const EffectsBenchOptions& options, std::ostream& out);

}  // namespace marbles::bench
