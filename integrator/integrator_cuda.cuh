// integrator/integrator_cuda.cuh — the CUDA twin of symplectic_euler.cpp:
// one thread per sphere over integrator_math.hpp. Only .cu files include it.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "core/spheres.hpp"
#include "integrator/integrator_math.hpp"

namespace marbles::integrator::cuda {

void launch_apply_gravity(const BodiesView& bodies, const Vec3& g, real h, int sm_count, cudaStream_t stream);
// The kick (integrator_math.hpp drag_update), gravity's kick over h with it
// where g is given (one launch: no launch_apply_gravity then).
void launch_apply_drag(const BodiesView& bodies, real k1, real k2, real h, DragKick kick, const Vec3* g,
                       int sm_count, cudaStream_t stream);
// x += h v; sets *non_finite = 1 when a position, velocity or angular
// velocity is not finite afterwards (never clears it). Nothing where `skip`
// (not null) is set when it runs (cuda::skipped: a substep that outgrew a
// room in a step without waits).
// With `reach` (m a sphere, contact_reach) and `past` (a count, then room
// for `past_room` indices), the spheres that moved past their reach
// (moved_past_reach) are counted into past[0], all of them, and the first
// `past_room` of them, in no fixed order, written from past[1] on. `shift`:
// the impacts' shifts (drift; null: none).
void launch_integrate_positions(const BodiesView& bodies, real h, unsigned* non_finite, int sm_count,
                                cudaStream_t stream, const unsigned long long* skip = nullptr,
                                const real* reach = nullptr, std::uint32_t* past = nullptr,
                                std::uint32_t past_room = 0, const Vec3* shift = nullptr);

// Sets *non_finite = 1 when a position, velocity or angular velocity is not
// finite or its square overflows (body_in_range; never clears it): the check
// of a state written from outside.
void launch_check_finite(const BodiesView& bodies, unsigned* non_finite, int sm_count, cudaStream_t stream);

}  // namespace marbles::integrator::cuda
