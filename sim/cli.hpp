// sim/cli.hpp — the command line as a function, one per precision.
//
// Every library is built twice (float, and double with the namespace
// marbles_f64: CMakeLists.txt, "Runtime precision"), so one program runs
// either: sim/main.cpp asks requested_precision and calls the cli_main of
// that build.
#pragma once

#include <string>

namespace marbles {

// The whole command line; returns the exit code.
int cli_main(int argc, char** argv);

// "double" when the arguments ask for it (--precision double, or
// --set solver.precision=double), when `--restart` names a double
// checkpoint, or when the scene file of `run` or `check` says
// `solver.precision: double`; "float" otherwise (also when the scene
// cannot be read: the float build then reports why).
std::string requested_precision(int argc, char** argv);

}  // namespace marbles
