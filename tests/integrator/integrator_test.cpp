// Integrator stages against analytic motion.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "integrator/integrator_math.hpp"
#include "integrator/symplectic_euler.hpp"

using namespace marbles;

namespace {

struct OneBody {
  std::vector<Vec3> x{{0, 0, 0}}, v{{0, 0, 0}}, w{{0, 0, 0}};
  std::vector<real> r{real(0.1)}, inv_m{1}, inv_i{1};
  std::vector<std::uint32_t> mat{0};
  BodiesView view() { return {x.data(), v.data(), w.data(), r.data(), inv_m.data(), inv_i.data(), mat.data(), 1}; }
};

}  // namespace

// Symplectic Euler under constant g: x_n = x0 + v0 t - g t^2/2 - g h t/2 exactly.
TEST(SymplecticEuler, FreeFallMatchesClosedForm) {
  for (double h : {1e-3, 1e-2, 1.0 / 60}) {
    OneBody b;
    b.v[0] = {1, 0, 2};
    const Vec3 g(0, 0, real(-9.81));
    const int steps = static_cast<int>(std::round(1.0 / h));
    for (int k = 0; k < steps; ++k) {
      integrator::apply_gravity(b.view(), g, real(h));
      integrator::integrate_positions(b.view(), real(h));
    }
    const double t = steps * h;
    EXPECT_NEAR(b.x[0].x, t, 1e-4);
    EXPECT_NEAR(b.x[0].z, 2 * t - 9.81 * t * t / 2 - 9.81 * h * t / 2, 1e-4 * (1 + t * t)) << "h=" << h;
    EXPECT_NEAR(b.v[0].z, 2 - 9.81 * t, 1e-4);
  }
}

TEST(SymplecticEuler, ImmovableBodiesIgnoreGravity) {
  OneBody b;
  b.inv_m[0] = 0;
  integrator::apply_gravity(b.view(), {0, 0, -10}, real(0.1));
  EXPECT_EQ(b.v[0].z, 0);
}

// Linear drag: v(t) = v0 exp(-k t); the implicit update converges at first order.
TEST(Drag, LinearDecayIsExponential) {
  const double k = 2.0, t_end = 1.0;
  double previous_error = 1e9;
  for (double h : {1e-2, 5e-3, 2.5e-3}) {
    OneBody b;
    b.v[0] = {3, 0, 0};
    for (int s = 0; s < static_cast<int>(std::round(t_end / h)); ++s) integrator::apply_drag(b.view(), real(k), 0, real(h));
    const double error = std::abs(b.v[0].x - 3 * std::exp(-k * t_end));
    EXPECT_LT(error, 0.6 * previous_error) << "h=" << h;
    EXPECT_LT(error, 0.02 * 3 * std::exp(-k * t_end) * (h / 2.5e-3));
    previous_error = error;
  }
}

// Quadratic drag against gravity: the fall speed settles on sqrt(g / k2)
// itself, not within g h of it (the update is implicit in the new speed), at a
// substep of 1 ms and where drag is stiff for it (h k2 c = 44 at 0.1 s).
TEST(Drag, QuadraticDragGivesTerminalVelocity) {
  const double g = 9.81, k2 = 0.5, c = std::sqrt(g / k2);
  for (const double h : {1e-3, 0.1}) {
    OneBody b;
    for (int s = 0; s < static_cast<int>(20.0 / h); ++s) {
      integrator::apply_gravity(b.view(), {0, 0, real(-g)}, real(h));
      integrator::apply_drag(b.view(), 0, real(k2), real(h));
    }
    EXPECT_NEAR(-b.v[0].z, c, 1e-5 * c) << "h = " << h;
  }
}

// Stiff quadratic drag (h k2 |v| up to 10^4) falling from far above the
// terminal speed, and rising from rest: the speed approaches sqrt(g / k2)
// from one side, never past it (a |v| of the velocity before the update made
// it alternate about c), and each update moves it towards c.
TEST(Drag, StiffQuadraticDragApproachesTheTerminalSpeedFromOneSide) {
  const double g = 9.81, k2 = 50.0, h = 0.05, c = std::sqrt(g / k2);
  for (const double v0 : {-400.0, 0.0}) {
    OneBody b;
    b.v[0] = {0, 0, real(v0)};
    const Vec3 gravity{0, 0, real(-g)};
    double gap = std::abs(-v0 - c);
    for (int s = 0; s < 200; ++s) {
      integrator::apply_drag(b.view(), 0, real(k2), real(h), integrator::DragKick::whole, &gravity);
      const double speed = -static_cast<double>(b.v[0].z);
      ASSERT_TRUE(v0 < 0 ? speed >= c * (1 - 1e-6) : speed <= c * (1 + 1e-6)) << "step " << s << ": " << speed;
      EXPECT_LE(std::abs(speed - c), gap * (1 + 1e-6) + 1e-6 * c) << "step " << s;
      gap = std::abs(speed - c);
    }
    EXPECT_NEAR(-b.v[0].z, c, 1e-5 * c) << "from " << v0;
  }
}

// The implicit drag never reverses a velocity, even for h k >> 1.
TEST(Drag, NeverReversesVelocity) {
  const Vec3 v(5, -3, 1);
  const Vec3 out = integrator::drag_kick(v, real(1e4), real(1e4), real(1));
  EXPECT_GT(dot(out, v), 0);
  EXPECT_LT(length(out), length(v));
}
