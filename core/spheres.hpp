// core/spheres.hpp — views of the sphere state: raw pointers and a count,
// passed by value to CPU loops and CUDA kernels alike.
//
// The world (sim/world.hpp) owns the arrays; a stage sees only the view it
// needs, so narrowphase/ and integrator/ never depend on sim/.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/vec3.hpp"

namespace marbles {

// Read-only centres and radii: what the broad phase needs.
struct SpheresIn {
  const Vec3* centre = nullptr;
  const real* radius = nullptr;
  std::size_t count = 0;
};

// The mutable body state the narrow phase, solver and integrator work on.
struct BodiesView {
  Vec3* position = nullptr;          // m
  Vec3* velocity = nullptr;          // m/s
  Vec3* angular_velocity = nullptr;  // rad/s
  const real* radius = nullptr;      // m
  const real* inv_mass = nullptr;    // 1/kg   (0 = immovable)
  const real* inv_inertia = nullptr; // 1/(kg m^2), solid sphere: 1 / (2/5 m r^2)
  const std::uint32_t* material = nullptr;
  std::size_t count = 0;

  SpheresIn spheres() const { return {position, radius, count}; }
};

}  // namespace marbles
