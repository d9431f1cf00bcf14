// Determinism of the whole step on the CPU: the same scene gives the same
// bits on every run and for every thread count (the solver's colours share
// no sphere, and every reduction has a fixed order). The CUDA backend's
// parity with these states is in step_cuda_test.cpp.
#include <gtest/gtest.h>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "tests/sim/test_scenes.hpp"

using namespace marbles;
using namespace marbles::testing;

namespace {

std::uint64_t run_pour(int threads, int steps) {
#if defined(_OPENMP)
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
#endif
  auto [s, g] = pour_scene(400, 3);
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < steps; ++k) sim.step();
#if defined(_OPENMP)
  omp_set_num_threads(before);
#endif
  return state_hash(sim.world());
}

}  // namespace

TEST(Determinism, PourIsTheSameOnEveryRunAndThreadCount) {
  const std::uint64_t one = run_pour(1, 300);
  EXPECT_EQ(run_pour(1, 300), one);
  EXPECT_EQ(run_pour(2, 300), one);
  EXPECT_EQ(run_pour(3, 300), one);
  EXPECT_NE(run_pour(1, 299), one) << "the hash must see the state change";
}
