// sim/settings_check.hpp — warnings about settings that are valid but likely
// to give a poor run: spheres tunnelling through each other or the walls,
// a stack too tall for the solver's sweeps, substeps too coarse for a
// resting contact, positions too large for float.
//
// Estimates from the scene and its initial spheres only (nothing is
// simulated). `marbles check` and `marbles run` print them; the rules are
// stated for users in docs/scene-format.md ("Warnings").
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "sim/particles.hpp"
#include "sim/scene.hpp"

namespace marbles {

// One message per rule that fires, quoting the number that triggered it, the
// threshold and what to change. `single_precision`: positions are floats.
std::vector<std::string> risky_settings(const scene::Scene& scene, const scene::GeneratedParticles& particles,
                                        bool single_precision);

// The speed the fast-motion rule finds for the fastest sphere, m/s: the
// largest initial speed, or twice a moving wall's speed (a spinning wall's
// surface speed), plus a fall under gravity from the highest centre to the
// lowest centre or wall bottom. make_world holds the contact impulses to it.
// `without_wall`: as if that wall (an index into scene.walls) did not move.
double fastest_speed(const scene::Scene& scene, const scene::GeneratedParticles& particles,
                     std::optional<std::size_t> without_wall = std::nullopt);

// The wall whose motion sets that speed (twice its speed, or a spinning
// wall's surface speed, past every sphere's initial speed), where one does:
// its index, the key of its speed and the speed it gives.
struct SpeedingWall {
  std::size_t index = 0;
  std::string key;
  double push = 0;
};
std::optional<SpeedingWall> speeding_wall(const scene::Scene& scene, const scene::GeneratedParticles& particles);

}  // namespace marbles
