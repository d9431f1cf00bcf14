// Determinism of the whole step on the CPU: the same scene gives the same
// bits on every run and for every thread count (the solver's colours share
// no sphere, and every reduction has a fixed order). The CUDA backend's
// parity with these states is in step_cuda_test.cpp.
#include <gtest/gtest.h>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include <random>

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

// A block of 48,000 touching spheres (a cubic lattice, slightly jittered)
// settling in a box: ~140,000 contacts, about 20,000 per colour, so every
// OpenMP path runs in parallel (contact gathering, reach, colours, cache).
std::uint64_t run_block(int threads, int steps) {
#if defined(_OPENMP)
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
#endif
  using scene::Effect;
  scene::Scene s = make_scene(1e-3, 1,
                              {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                               Effect::friction, Effect::rolling_resistance},
                              0.3, 0.5, 0.05);
  const real r = real(0.01);
  const int nx = 40, ny = 40, nz = 30;
  s.walls.push_back(box({0, 0, 0}, {real(2 * r * nx), real(2 * r * ny), real(4 * r * nz)}));
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> jitter(-0.002, 0.002);
  scene::GeneratedParticles g;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x)
        add_sphere(g, {real(r * (2 * x + 1) * (1 + jitter(rng))), real(r * (2 * y + 1) * (1 + jitter(rng))),
                       real(r * (2 * z + 1))},
                   r);
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < steps; ++k) sim.step();
#if defined(_OPENMP)
  omp_set_num_threads(before);
#endif
  EXPECT_GT(sim.last_step().contacts, 100000u) << "the block must be large enough to run the parallel paths";
  return state_hash(sim.world());
}

TEST(Determinism, LargeBlockIsTheSameForEveryThreadCount) {
  const std::uint64_t one = run_block(1, 4);
  EXPECT_EQ(run_block(2, 4), one);
  EXPECT_EQ(run_block(3, 4), one);
}

TEST(Determinism, PourIsTheSameOnEveryRunAndThreadCount) {
  const std::uint64_t one = run_pour(1, 300);
  EXPECT_EQ(run_pour(1, 300), one);
  EXPECT_EQ(run_pour(2, 300), one);
  EXPECT_EQ(run_pour(3, 300), one);
  EXPECT_NE(run_pour(1, 299), one) << "the hash must see the state change";
}
