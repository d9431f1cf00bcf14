// integrator/integrator_cuda.cuh — the CUDA twin of symplectic_euler.cpp:
// one thread per sphere over integrator_math.hpp. Only .cu files include it.
#pragma once

#include <cuda_runtime.h>

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
void launch_integrate_positions(const BodiesView& bodies, real h, unsigned* non_finite, int sm_count,
                                cudaStream_t stream, const unsigned long long* skip = nullptr);

// Sets *non_finite = 1 when a position, velocity or angular velocity is not
// finite or its square overflows (body_in_range; never clears it): the check
// of a state written from outside.
void launch_check_finite(const BodiesView& bodies, unsigned* non_finite, int sm_count, cudaStream_t stream);

}  // namespace marbles::integrator::cuda
