// sim/main.cpp — the `marbles` program: runs the command line of the float
// or the double build (sim/cli.hpp).
#include <cstdio>
#include <iostream>

#include "sim/cli.hpp"

namespace marbles_f64 {
int cli_main(int argc, char** argv);
}

int main(int argc, char** argv) {
  const int code = marbles::requested_precision(argc, argv) == "double" ? marbles_f64::cli_main(argc, argv)
                                                                        : marbles::cli_main(argc, argv);
  // What standard output could not take (`marbles pairs x.csv > /dev/full`) is lost: not a success.
  std::cout.flush();
  if (std::fflush(stdout) != 0 || std::ferror(stdout) || !std::cout) {
    std::cerr << "marbles: cannot write the standard output\n";
    return code != 0 ? code : 1;
  }
  return code;
}
