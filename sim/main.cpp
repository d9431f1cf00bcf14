// sim/main.cpp — the `marbles` program: runs the command line of the float
// or the double build (sim/cli.hpp).
#include "sim/cli.hpp"

namespace marbles_f64 {
int cli_main(int argc, char** argv);
}

int main(int argc, char** argv) {
  if (marbles::requested_precision(argc, argv) == "double") return marbles_f64::cli_main(argc, argv);
  return marbles::cli_main(argc, argv);
}
