// tests/sim/watchdog_cases.hpp — what the watchdog's undo must give back,
// held alike on both backends.
#pragma once

#include <gtest/gtest.h>

#include "sim/simulation.hpp"
#include "tests/sim/test_scenes.hpp"

namespace marbles::testing {

// A step that fails every try (the next step's NaN on each retry) throws
// WatchdogFailure and leaves the world and the warm-start cache as they
// were at its start: the cache kept without a copy (ContactCache::keep, and
// the CUDA twin's). The simulation must hold cache entries already.
inline void expect_a_failed_step_leaves_its_start(Simulation& sim) {
  const World before = sim.world();
  const StepState state_before = sim.save_state();
  ASSERT_GT(state_before.cache.size(), 0u);
  sim.inject_fault_at(sim.steps() + 1, true);
  EXPECT_THROW(sim.step(), WatchdogFailure);
  EXPECT_EQ(state_hash(sim.world()), state_hash(before)) << "back at the step's start";
  const StepState state_after = sim.save_state();
  EXPECT_EQ(state_after.cache.key, state_before.cache.key);
  EXPECT_EQ(state_after.cache.normal_impulse, state_before.cache.normal_impulse);
  EXPECT_EQ(state_after.cache.colour, state_before.cache.colour);
}

}  // namespace marbles::testing
