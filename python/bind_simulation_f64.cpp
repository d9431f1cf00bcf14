// python/bind_simulation_f64.cpp — bind_simulation.cpp in double precision
// (compiled with MARBLES_DOUBLE and marbles=marbles_f64: python/CMakeLists.txt).
#include "bind_simulation.cpp"
