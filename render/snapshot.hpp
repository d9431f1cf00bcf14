// render/snapshot.hpp — a host-side copy of the world at one instant: what the
// writers and the renderer read. The simulation makes one only when output is
// due; nothing in render/ ever sees the live world.
#pragma once

#include <cstdint>
#include <vector>

#include "core/vec3.hpp"

namespace marbles::render {

struct Snapshot {
  double time = 0;          // s, simulated
  std::uint64_t step = 0;   // step index
  std::vector<Vec3> position;
  std::vector<Vec3> velocity;
  std::vector<Vec3> angular_velocity;
  std::vector<real> radius;
  std::vector<std::uint32_t> id;
  std::vector<std::uint32_t> material;
  std::vector<std::uint32_t> contacts;  // per sphere, contacts that press (walls too); filled when asked for
  std::size_t size() const { return position.size(); }
};

}  // namespace marbles::render
