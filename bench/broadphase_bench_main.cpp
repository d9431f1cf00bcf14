// bench/broadphase_bench_main.cpp — `marbles_bench_broadphase [options]`,
// the benchmark without the main program (options: broadphase_bench.hpp).
#include <iostream>
#include <stdexcept>

#include "bench/broadphase_bench.hpp"

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  try {
    return marbles::bench::run_broadphase_bench(marbles::bench::parse_broadphase_bench_args(args), std::cout);
  } catch (const std::exception& e) {
    std::cerr << "marbles_bench_broadphase: " << e.what() << "\n";
    return 2;
  }
}
