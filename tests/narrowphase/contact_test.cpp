// Contact generation and single-contact impulses against analytic results.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "core/parallel.hpp"
#include "integrator/integrator_math.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contact_cache_math.hpp"
#include "narrowphase/contact_math.hpp"
#include "narrowphase/contacts.hpp"
#include "narrowphase/solver.hpp"

using namespace marbles;
using namespace marbles::narrowphase;

namespace {

Vec3 random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0, 1);
  for (;;) {
    Vec3 v(real(g(rng)), real(g(rng)), real(g(rng)));
    const real l = length(v);
    if (l > real(1e-3)) return v / l;
  }
}

// Random motion, sphere by sphere: each velocity component uniform in
// (-speed, speed) m/s, each spin component `spin` times one such draw (rad/s).
void random_motion(std::mt19937_64& rng, double speed, double spin, std::vector<Vec3>& vel, std::vector<Vec3>& omega) {
  std::uniform_real_distribution<double> u(-speed, speed);
  for (std::size_t i = 0; i < vel.size(); ++i) {
    vel[i] = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
    omega[i] = Vec3(real(u(rng)), real(u(rng)), real(u(rng))) * real(spin);
  }
}

// side^3 spheres of radius r (about 4.2 g) on a cubic lattice of pitch
// `pitch` over a floor plane at z = 0, the lowest centres at height z0, each
// coordinate jittered by up to `jitter` (m); the lattice neighbours are the
// candidate pairs. contacts() makes the sphere and floor contacts at the
// given positions and velocities, in colour-major order.
struct Lattice {
  std::size_t n;
  std::vector<Vec3> position;
  std::vector<real> radius, inv_mass, inv_inertia;
  std::vector<std::uint32_t> material;
  std::vector<IndexPair> pairs;
  std::vector<WallShape> floor;

  Lattice(int side, real r, double pitch, double z0, double jitter, std::mt19937_64& rng)
      : n(std::size_t(side) * side * side), position(n), radius(n, r), inv_mass(n, real(1 / 0.0042)),
        inv_inertia(n, real(1 / (0.4 * 0.0042 * r * r))), material(n, 0) {
    std::uniform_real_distribution<double> u(-jitter, jitter);
    auto index = [&](int x, int y, int z) { return std::uint32_t((z * side + y) * side + x); };
    for (int z = 0; z < side; ++z)
      for (int y = 0; y < side; ++y)
        for (int x = 0; x < side; ++x) {
          const std::uint32_t i = index(x, y, z);
          position[i] = Vec3(real(pitch * x + u(rng)), real(pitch * y + u(rng)), real(z0 + pitch * z + u(rng)));
          if (x + 1 < side) pairs.push_back({i, index(x + 1, y, z)});
          if (y + 1 < side) pairs.push_back({i, index(x, y + 1, z)});
          if (z + 1 < side) pairs.push_back({i, index(x, y, z + 1)});
        }
    Walls walls;
    walls.planes.push_back({{0, 0, 0}, {0, 0, 1}, 0, {}});
    floor = wall_shapes(walls);
  }

  BodiesView view(Vec3* pos, Vec3* vel, Vec3* omega) {
    return {pos, vel, omega, radius.data(), inv_mass.data(), inv_inertia.data(), material.data(), n};
  }

  // Contacts whose gap closes within h or lies within `reach` of each sphere.
  // With `loads`: a random half of the contacts carry a load in (impulses
  // as a restore gives them), and the colouring is told which (the solver's
  // records of each colour hold those first).
  std::vector<Contact> contacts(const BodiesView& bodies, const PairTable& table, real h, real reach,
                                ColourRanges& colours, std::mt19937_64* loads = nullptr) const {
    const std::vector<real> reaches(n, reach);
    std::vector<Contact> out, wall;
    sphere_contacts(bodies, pairs.data(), pairs.size(), table, h, reaches.data(), out);
    wall_contacts(bodies, floor, table, h, reaches.data(), wall);
    out.insert(out.end(), wall.begin(), wall.end());
    std::vector<std::uint8_t> loaded;
    if (loads) {
      std::uniform_real_distribution<double> u(0.1, 1);
      for (Contact& c : out) {
        const bool carries = (*loads)() % 2 == 0;
        c.normal_impulse = carries ? real(1e-4 * u(*loads)) : real(0);
        c.tangent_impulse = carries ? Vec3(real(1e-6 * u(*loads)), 0, real(-1e-6 * u(*loads))) : Vec3{};
        c.tangent_impulse = c.tangent_impulse - c.normal * dot(c.tangent_impulse, c.normal);
        loaded.push_back(carries_load(c.normal_impulse) ? 1 : 0);
      }
    }
    ContactColouring().colour_and_sort(out, n, colours, nullptr, &bodies, 0, loads ? loaded.data() : nullptr);
    return out;
  }
};

// A lattice in random motion with one pair of coefficients: packed, touching
// spheres pressed slightly together and moving slowly (resting contacts, all
// four terms); or thrown, a hair apart and thrown at each other and at the
// floor (impacts).
struct MovingLattice {
  Lattice lattice;
  std::vector<Vec3> vel, omega;
  PairCoefficients coeff;

  static MovingLattice packed(int side, real r, std::mt19937_64& rng) {
    MovingLattice m{Lattice(side, r, 2 * r * 0.995, r * 0.999, 1e-4, rng), {}, {},
                    {real(0.3), real(0.5), real(0.02), real(0.01)}};
    m.move(rng, 0.05, 100);
    return m;
  }
  static MovingLattice thrown(int side, real r, std::mt19937_64& rng) {
    MovingLattice m{Lattice(side, r, 2 * r * 1.002, r * 1.001, 2e-5, rng), {}, {},
                    {real(0.6), real(0.4), real(0.02), real(0.01)}};
    m.move(rng, 0.5, 50);
    return m;
  }
  PairTable table() const { return {&coeff, 1}; }
  BodiesView view() { return lattice.view(lattice.position.data(), vel.data(), omega.data()); }

 private:
  void move(std::mt19937_64& rng, double speed, double spin) {
    vel.resize(lattice.n);
    omega.resize(lattice.n);
    random_motion(rng, speed, spin, vel, omega);
  }
};


// Loads as a store would keep them: every 9th contact none, the others a
// random normal, tangential and rolling impulse.
void give_random_loads(std::vector<Contact>& contacts, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.1, 1);
  for (std::size_t k = 0; k < contacts.size(); ++k) {
    Contact& c = contacts[k];
    c.normal_impulse = k % 9 == 0 ? real(0) : real(u(rng));
    c.tangent_impulse = random_unit(rng) * real(0.1 * u(rng));
    c.rolling_impulse = random_unit(rng) * real(0.01 * u(rng));
  }
}

}  // namespace

TEST(SphereSphere, SeparationAndNormalMatchGeometry) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.1, 2.0);
  for (int k = 0; k < 1000; ++k) {
    const real ra = real(u(rng)), rb = real(u(rng));
    const Vec3 n = random_unit(rng);
    const real gap = real((u(rng) - 1.05) * 0.5 * std::min(ra, rb));  // both signs
    const Vec3 pb(real(u(rng)), real(u(rng)), real(u(rng)));
    const Vec3 pa = pb + n * (ra + rb + gap);
    Vec3 normal;
    real separation = 0;
    const bool hit = sphere_sphere(pa, ra, pb, rb, real(0), normal, separation);
    ASSERT_EQ(hit, gap < 0) << "gap " << gap;
    if (!hit) continue;
    EXPECT_NEAR(separation, gap, 1e-5 * (ra + rb));
    EXPECT_NEAR(dot(normal, n), 1.0, 1e-5);
    // The contact point lies midway across the overlap, on the centre line.
    Contact c;
    c.normal = normal;
    c.separation = separation;
    c.ra = ra;
    const Vec3 expected_point = pb + n * (rb + real(0.5) * gap);
    EXPECT_NEAR(length(c.point(pa) - expected_point), 0.0, 1e-5 * (ra + rb + length(pb)));
  }
}

TEST(SphereSphere, CoincidentCentresGiveAFiniteUnitNormal) {
  Vec3 normal;
  real separation;
  const Vec3 p(1, 2, 3);
  ASSERT_TRUE(sphere_sphere(p, real(0.5), p, real(0.25), real(0), normal, separation));
  EXPECT_TRUE(is_finite(normal));
  EXPECT_NEAR(length(normal), 1.0, 1e-6);
  EXPECT_NEAR(separation, -0.75, 1e-6);
}

TEST(SpherePlane, SeparationIsSignedDistanceMinusRadius) {
  real s;
  EXPECT_TRUE(sphere_plane({0, 0, real(0.05)}, real(0.1), {0, 0, 0}, {0, 0, 1}, real(0), s));
  EXPECT_NEAR(s, -0.05, 1e-7);
  EXPECT_FALSE(sphere_plane({0, 0, real(0.3)}, real(0.1), {0, 0, 0}, {0, 0, 1}, real(0.1), s));
  EXPECT_TRUE(sphere_plane({0, 0, real(0.15)}, real(0.1), {0, 0, 0}, {0, 0, 1}, real(0.1), s));  // speculative
  EXPECT_NEAR(s, 0.05, 1e-7);
}

TEST(BoxWall, SixInwardFacesKeepSpheresInside) {
  Walls walls;
  walls.boxes.push_back({{-1, -2, -3}, {1, 2, 3}, 0, {}});
  const auto faces = wall_shapes(walls);
  ASSERT_EQ(faces.size(), 6u);
  // The centre is in free space for every face; a point beyond any face is not.
  for (const WallShape& f : faces) EXPECT_GT(dot(Vec3{} - f.point, f.direction), 0);
  for (const WallShape& f : faces) EXPECT_LT(dot(f.point + f.direction * real(-0.5) - f.point, f.direction), 0);
}

// A finite post is a solid with flat ends: the gap is the distance to the
// solid less r, against the clamp oracle (the solid's nearest point: the
// axial coordinate clamped to [0, L], the radial one to R; a point inside
// goes out by its nearest face), at random points around posts of random
// axes, all around the ends and rims. Beside the post (the axial coordinate
// within [0, L], outside the radius) the gap is the endless cylinder's, bit
// for bit; a tube's ends stay open.
TEST(PostWall, FiniteEndsAreClosedDiscs) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  int over_ends = 0, rims = 0, inside = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    WallShape w;
    w.kind = WallShape::Kind::cylinder_outside;
    w.point = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
    const Vec3 d(real(u(rng)), real(u(rng)), real(u(rng)) + real(1.5));
    w.direction = d / length(d);
    w.radius = real(0.5 + 0.4 * u(rng));
    w.length = real(1.5 + u(rng));
    const real r = real(0.2);
    const Vec3 p = w.point + w.direction * real(w.length * (0.5 + 0.9 * u(rng))) +
                   Vec3(real(1.5 * u(rng)), real(1.5 * u(rng)), real(1.5 * u(rng)));
    // The oracle, in double.
    const double px[3] = {p.x - w.point.x, p.y - w.point.y, p.z - w.point.z};
    const double ax[3] = {w.direction.x, w.direction.y, w.direction.z};
    const double t = px[0] * ax[0] + px[1] * ax[1] + px[2] * ax[2];
    double radial[3], dist = 0;
    for (int k = 0; k < 3; ++k) radial[k] = px[k] - t * ax[k], dist += radial[k] * radial[k];
    dist = std::sqrt(dist);
    const double L = w.length, R = w.radius;
    double want = 0, want_normal[3];
    if (t >= 0 && t <= L && dist <= R) {  // inside: out by the nearest face
      ++inside;
      const double side = R - dist, top = L - t, bottom = t;
      want = -std::min({side, top, bottom}) - r;
      for (int k = 0; k < 3; ++k)
        want_normal[k] = side <= top && side <= bottom ? radial[k] / dist : (top <= bottom ? ax[k] : -ax[k]);
    } else {
      const double tc = std::clamp(t, 0.0, L), rc = std::min(dist, R);
      double gap[3], g = 0;
      for (int k = 0; k < 3; ++k) gap[k] = px[k] - (tc * ax[k] + rc * radial[k] / dist), g += gap[k] * gap[k];
      g = std::sqrt(g);
      want = g - r;
      for (int k = 0; k < 3; ++k) want_normal[k] = gap[k] / g;
      over_ends += (t < 0 || t > L) && dist <= R ? 1 : 0;
      rims += (t < 0 || t > L) && dist > R ? 1 : 0;
    }
    Vec3 normal;
    real separation = 0;
    ASSERT_TRUE(wall_gap(w, p, r, normal, separation)) << trial;
    EXPECT_NEAR(separation, want, 2e-6) << trial;
    if (std::fabs(want + r) > 1e-3) {  // a normal is defined away from the surface's edges
      EXPECT_NEAR(normal.x, want_normal[0], 1e-4) << trial;
      EXPECT_NEAR(normal.y, want_normal[1], 1e-4) << trial;
      EXPECT_NEAR(normal.z, want_normal[2], 1e-4) << trial;
    }
    if (t >= 0 && t <= L && dist >= R) {
      WallShape endless = w;
      endless.length = 0;
      Vec3 n_endless;
      real s_endless = 0;
      ASSERT_TRUE(wall_gap(endless, p, r, n_endless, s_endless));
      EXPECT_EQ(separation, s_endless) << trial;
      EXPECT_EQ(normal, n_endless) << trial;
    }
    WallShape tube = w;
    tube.kind = WallShape::Kind::cylinder_inside;
    EXPECT_EQ(wall_gap(tube, p, r, normal, separation), t >= 0 && t <= L) << trial;
  }
  EXPECT_GT(over_ends, 1000);
  EXPECT_GT(rims, 2000);
  EXPECT_GT(inside, 500);
}

// Head-on impact of two free spheres: the 1-D rigid-body impact law
//   v1' = (m1 v1 + m2 v2 - m2 e (v1 - v2)) / (m1 + m2), and symmetric for v2'.
TEST(Solver, HeadOnImpactFollowsImpactLaw) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.2, 5.0), e_dist(0.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    const double m1 = u(rng), m2 = u(rng), e = e_dist(rng);
    const double v1 = -u(rng), v2 = u(rng);  // approaching along x (sphere 0 on +x side)
    const real r = real(0.5);
    std::vector<Vec3> pos{{real(r * 2 - 0.001), 0, 0}, {0, 0, 0}};
    std::vector<Vec3> vel{{real(v1), 0, 0}, {real(v2), 0, 0}}, omega(2);
    std::vector<real> radius{r, r}, inv_mass{real(1 / m1), real(1 / m2)};
    std::vector<real> inv_inertia{real(1 / (0.4 * m1 * r * r)), real(1 / (0.4 * m2 * r * r))};
    std::vector<std::uint32_t> material{0, 0};
    BodiesView bodies{pos.data(), vel.data(), omega.data(), radius.data(), inv_mass.data(), inv_inertia.data(),
                      material.data(), 2};
    PairCoefficients coeff{real(e), 0, 0, 0};
    PairTable table{&coeff, 1};
    std::vector<Contact> contacts;
    IndexPair pair{0, 1};
    const std::vector<real> reach(2, 0);
    sphere_contacts(bodies, &pair, 1, table, real(0), reach.data(), contacts);
    ASSERT_EQ(contacts.size(), 1u);
    SolverSettings s;
    s.rest_speed = real(1e-3);
    ColourRanges colours;
    ContactColouring().colour_and_sort(contacts, bodies.count, colours, nullptr, &bodies);
    ContactSolver(s).solve_velocities(contacts, colours, bodies, real(1e-3));
    const double v1_expect = (m1 * v1 + m2 * v2 - m2 * e * (v1 - v2)) / (m1 + m2);
    const double v2_expect = (m1 * v1 + m2 * v2 + m1 * e * (v1 - v2)) / (m1 + m2);
    EXPECT_NEAR(vel[0].x, v1_expect, 1e-4 * (std::abs(v1) + std::abs(v2))) << "e=" << e;
    EXPECT_NEAR(vel[1].x, v2_expect, 1e-4 * (std::abs(v1) + std::abs(v2))) << "e=" << e;
  }
}

// Friction never exceeds the Coulomb cone and stops sliding when it can.
TEST(Solver, FrictionStaysInsideTheCone) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-3, 3), mu_dist(0.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    const real r = real(0.1);
    std::vector<Vec3> pos{{0, 0, real(r * 0.999)}};
    std::vector<Vec3> vel{{real(u(rng)), real(u(rng)), real(-std::abs(u(rng)) - 0.1)}}, omega{{0, 0, 0}};
    std::vector<real> radius{r}, inv_mass{1}, inv_inertia{real(1 / (0.4 * r * r))};
    std::vector<std::uint32_t> material{0};
    BodiesView bodies{pos.data(), vel.data(), omega.data(), radius.data(), inv_mass.data(), inv_inertia.data(),
                      material.data(), 1};
    PairCoefficients coeff{0, real(mu_dist(rng)), 0, 0};
    PairTable table{&coeff, 1};
    Walls walls;
    walls.planes.push_back({{0, 0, 0}, {0, 0, 1}, 0, {}});
    std::vector<Contact> contacts;
    const std::vector<real> reach(1, 0);
    wall_contacts(bodies, wall_shapes(walls), table, real(0), reach.data(), contacts);
    ASSERT_EQ(contacts.size(), 1u);
    SolverSettings s;
    s.friction = true;
    s.restitution = false;
    ColourRanges colours;
    ContactColouring().colour_and_sort(contacts, bodies.count, colours, nullptr, &bodies);
    ContactSolver(s).solve_velocities(contacts, colours, bodies, real(1e-3));
    const Contact& c = contacts[0];
    EXPECT_LE(length(c.tangent_impulse), coeff.friction * c.normal_impulse * (1 + 1e-5) + 1e-7);
    EXPECT_NEAR(vel[0].z, 0, 1e-4);  // e = 0: normal velocity removed
    // Contact point slip after the solve: zero (sticking) or the impulse saturated (sliding).
    const Vec3 slip = vel[0] + cross(omega[0], Vec3(0, 0, -r));
    const real slip_t = std::hypot(slip.x, slip.y);
    const bool saturated = length(c.tangent_impulse) > coeff.friction * c.normal_impulse * (1 - 1e-3);
    EXPECT_TRUE(saturated || slip_t < 1e-3) << "slip " << slip_t;
  }
}

// MARBLES_LANES lowers the sweep's lanes to a kind it names, never past
// what the CPU has, and refuses a name that is none (naming the variable).
TEST(Solver, LanesAskedForAreLoweredOrRefused) {
  const char* before = std::getenv("MARBLES_LANES");
  const std::string kept = before ? before : "";
  auto ask = [](const char* value) {
    if (value) ::setenv("MARBLES_LANES", value, 1);
    else ::unsetenv("MARBLES_LANES");
  };
  const SweepLanes has = supported_lanes();
  ask(nullptr);
  EXPECT_EQ(best_lanes(), has);
  ask("");
  EXPECT_EQ(best_lanes(), has);
  ask("sse2");
  EXPECT_EQ(best_lanes(), SweepLanes::sse2);
  ask("avx2");
  EXPECT_EQ(best_lanes(), std::min(SweepLanes::avx2, has));
  ask("avx512");
  EXPECT_EQ(best_lanes(), has);
  for (const char* bad : {"avx9", "SSE2", "sse2 ", "neon"}) {
    ask(bad);
    try {
      (void)best_lanes();
      ADD_FAILURE() << "MARBLES_LANES=" << bad << " was taken";
    } catch (const RuntimeFailure& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("MARBLES_LANES=") + bad + ": expected sse2, avx2 or avx512"),
                std::string::npos)
          << e.what();
    }
  }
  ask(before ? kept.c_str() : nullptr);
}

// A lattice's contacts and velocities after a solve (the solver tests that
// compare two ways of solving it).
struct LatticeRun {
  std::vector<Contact> contacts;
  std::vector<Vec3> vel, omega;
};

// Every SIMD lane kind this CPU has (solver.hpp: SweepLanes) gives the
// sweeps' bits of the 16-byte lanes, which solver_lanes_test holds to
// solve_one: a jittered lattice of 24^3 touching spheres on a floor (~40 000
// contacts, colours of thousands, so the threads' path and every tail of
// blocks), each combination of the terms, two substeps (the second warm).
TEST(Solver, EveryLaneKindGivesTheSameBits) {
  const real r = real(0.01);
  std::mt19937_64 rng(21);
  MovingLattice packed = MovingLattice::packed(24, r, rng);
  Lattice& lattice = packed.lattice;
  const std::size_t n = lattice.n;
  const std::vector<Vec3>&vel0 = packed.vel, &omega0 = packed.omega;
  const PairTable table = packed.table();
  const real h = real(1e-3);

  auto run = [&](const SolverSettings& s, SweepLanes lanes) {
    LatticeRun out{{}, vel0, omega0};
    const BodiesView bodies = lattice.view(lattice.position.data(), out.vel.data(), out.omega.data());
    ColourRanges colours;
    out.contacts = lattice.contacts(bodies, table, h, real(1e-4), colours);
    ContactSolver solver(s, lanes);
    EXPECT_EQ(solver.lanes(), lanes);
    for (int substep = 0; substep < 2; ++substep) solver.solve_velocities(out.contacts, colours, bodies, h);
    return out;
  };
  int kinds = 0;
  for (SweepLanes lanes : {SweepLanes::avx2, SweepLanes::avx512}) {
    if (lanes > supported_lanes()) continue;
    ++kinds;
    for (int terms = 0; terms < 4; ++terms) {
      SolverSettings s;
      s.friction = terms & 1, s.rolling = terms & 2;
      const LatticeRun base = run(s, SweepLanes::sse2), wide = run(s, lanes);
      ASSERT_GT(base.contacts.size(), 30000u);
      ASSERT_EQ(base.contacts.size(), wide.contacts.size());
      EXPECT_EQ(std::memcmp(base.contacts.data(), wide.contacts.data(), sizeof(Contact) * base.contacts.size()), 0)
          << name(lanes) << " terms " << terms;
      EXPECT_EQ(std::memcmp(base.vel.data(), wide.vel.data(), sizeof(Vec3) * n), 0) << name(lanes);
      EXPECT_EQ(std::memcmp(base.omega.data(), wide.omega.data(), sizeof(Vec3) * n), 0) << name(lanes);
      EXPECT_NE(std::memcmp(base.vel.data(), vel0.data(), sizeof(Vec3) * n), 0);  // the sweeps did work
    }
  }
  if (kinds == 0) GTEST_SKIP() << "skipped: this CPU has only the 16-byte lanes";
}

// No bit of the solve depends on the order of a colour's records, nor on
// where a colour's sweeps cut its two parts (ColourRanges::unloaded: the
// blocks of lanes and the threads' halves are cut there, and the warm start
// walks the first part alone): the packed lattice (~40 000 contacts, colours
// of thousands), a random half of its contacts carrying a load in, solved
// with its records in the contacts' order (the colouring not told the
// loads), with each colour's loaded records first, and with those records
// but every colour's cut moved to a random place at or past the last loaded
// one, each combination of the terms, on two threads: the bodies and every
// contact bit for bit.
TEST(Solver, TheRecordsOrderWithinAColourAndItsCutChangeNoBit) {
  const real r = real(0.01);
  std::mt19937_64 rng(29);
  MovingLattice packed = MovingLattice::packed(24, r, rng);
  Lattice& lattice = packed.lattice;
  const std::size_t n = lattice.n;
  const PairTable table = packed.table();
  const real h = real(1e-3);
  const int was = thread_count();
  set_thread_count(2);
  // Each run's loads drawn alike (the same seed); told to the colouring or not.
  auto run = [&](const SolverSettings& s, bool told, bool cut_anywhere) {
    LatticeRun out{{}, packed.vel, packed.omega};
    const BodiesView bodies = lattice.view(lattice.position.data(), out.vel.data(), out.omega.data());
    ColourRanges colours;
    std::mt19937_64 loads(31);
    out.contacts = lattice.contacts(bodies, table, h, real(1e-4), colours, &loads);
    if (!told) colours.record.clear(), colours.unloaded.clear();
    if (cut_anywhere)  // the loaded records must stay before the cut (the warm start's part)
      for (std::uint32_t c = 0; c < colours.colours; ++c)
        colours.unloaded[c] += static_cast<std::uint32_t>(rng() % (colours.begin[c + 1] - colours.unloaded[c] + 1));
    ContactSolver solver(s);
    solver.solve_velocities(out.contacts, colours, bodies, h);
    return out;
  };
  for (int terms = 0; terms < 4; ++terms) {
    SolverSettings s;
    s.friction = terms & 1, s.rolling = terms & 2;
    const LatticeRun plain = run(s, false, false);
    ASSERT_GT(plain.contacts.size(), 30000u);
    EXPECT_NE(std::memcmp(plain.vel.data(), packed.vel.data(), sizeof(Vec3) * n), 0);  // the sweeps did work
    for (const bool cut_anywhere : {false, true}) {
      const LatticeRun other = run(s, true, cut_anywhere);
      ASSERT_EQ(plain.contacts.size(), other.contacts.size());
      EXPECT_EQ(std::memcmp(plain.contacts.data(), other.contacts.data(), sizeof(Contact) * plain.contacts.size()), 0)
          << "terms " << terms << (cut_anywhere ? ", cut anywhere" : "");
      EXPECT_EQ(std::memcmp(plain.vel.data(), other.vel.data(), sizeof(Vec3) * n), 0) << "terms " << terms;
      EXPECT_EQ(std::memcmp(plain.omega.data(), other.omega.data(), sizeof(Vec3) * n), 0) << "terms " << terms;
    }
  }
  set_thread_count(was);
}

// The impulses left in the sweep's records (Unpack::when_asked, as the CPU
// step solves): the cache stored from the records keeps the entries the
// cache stored from the unpacked contacts keeps, bit for bit, and the
// contacts unpacked when asked equal those of a solve that unpacked at once.
TEST(Solver, CacheFromTheRecordsEqualsCacheFromTheContacts) {
  const real r = real(0.01);
  std::mt19937_64 rng(23);
  MovingLattice packed = MovingLattice::packed(12, r, rng);
  Lattice& lattice = packed.lattice;
  const std::vector<Vec3>&vel0 = packed.vel, &omega0 = packed.omega;
  const PairTable table = packed.table();
  const real h = real(1e-3);
  auto same = [](const auto& a, const auto& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(a[0]) * a.size()) == 0;
  };
  // With loads (a random half of the contacts carrying one in) the records
  // are each colour's loaded contacts first, not the contacts' order.
  for (int terms = 0; terms < 8; ++terms) {
    SolverSettings s;
    s.friction = terms & 1, s.rolling = terms & 2;
    std::vector<Vec3> vel = vel0, omega = omega0, vel_now = vel0, omega_now = omega0;
    const BodiesView bodies = lattice.view(lattice.position.data(), vel.data(), omega.data());
    const BodiesView bodies_now = lattice.view(lattice.position.data(), vel_now.data(), omega_now.data());
    ColourRanges colours;
    std::mt19937_64 loads(37);
    std::vector<Contact> contacts = lattice.contacts(bodies, table, h, real(1e-4), colours, terms & 4 ? &loads : nullptr);
    if (terms & 4) {
      ASSERT_EQ(colours.record.size(), contacts.size());
      std::size_t moved = 0;
      for (std::uint32_t k = 0; k < contacts.size(); ++k) moved += colours.record[k] != k ? 1 : 0;
      EXPECT_GT(moved, contacts.size() / 4) << "premise: the records are not the contacts' order";
    }
    std::vector<Contact> contacts_now = contacts;
    ContactSolver asked(s), now(s);
    asked.solve_velocities(contacts, colours, bodies, h, ContactSolver::Unpack::when_asked);
    now.solve_velocities(contacts_now, colours, bodies_now, h);
    EXPECT_EQ(now.pending_records(contacts_now), nullptr);
    const SweepRecords* records = asked.pending_records(contacts);
    ASSERT_NE(records, nullptr);
    ContactCache from_records, from_contacts;
    from_records.store(*records, static_cast<std::uint32_t>(contacts.size()), s.rolling, colours,
                       static_cast<std::uint32_t>(bodies.count));
    asked.unpack_impulses(contacts, colours);
    EXPECT_EQ(asked.pending_records(contacts), nullptr);
    from_contacts.store(contacts, colours);
    EXPECT_TRUE(same(contacts, contacts_now)) << "terms " << terms;
    const CacheEntries &a = from_records.entries(), &b = from_contacts.entries();
    ASSERT_GT(b.size(), contacts.size() / 2) << "terms " << terms;  // most contacts carry a load
    EXPECT_TRUE(same(a.key, b.key) && same(a.normal_impulse, b.normal_impulse) &&
                same(a.tangent_impulse, b.tangent_impulse) && same(a.rolling_impulse, b.rolling_impulse) &&
                same(a.colour, b.colour))
        << "terms " << terms;
    // The restore after a store reads the runs by sphere the store's sort
    // left instead of finding them in the keys: it restores what a cache
    // given the same entries does; and after a store of other contacts and
    // back_to_kept, what one given the kept entries does.
    auto restores_alike = [&](ContactCache& cache, const CacheEntries& entries, const char* what) {
      ContactCache fresh;
      CacheEntries plain = entries;
      plain.rolling_zero = false;  // its rolling impulses read, not taken as +0
      fresh.set_entries(plain);
      std::vector<Contact> x = contacts, y = contacts;
      std::vector<std::uint8_t> kept_x, kept_y, loaded_x, loaded_y;
      const std::size_t nx = cache.restore(x, bodies, real(9.81e-3), kept_x, &loaded_x);
      const std::size_t ny = fresh.restore(y, bodies, real(9.81e-3), kept_y, &loaded_y);
      EXPECT_GT(ny, contacts.size() / 4) << what << ", terms " << terms;
      EXPECT_TRUE(nx == ny && same(kept_x, kept_y) && same(loaded_x, loaded_y) && same(x, y))
          << what << ", terms " << terms;
    };
    const CacheEntries stored = from_records.entries();
    EXPECT_EQ(stored.rolling_zero, !s.rolling) << "terms " << terms;
    restores_alike(from_records, stored, "after the store");
    from_records.keep();
    from_records.store(*records, static_cast<std::uint32_t>(contacts.size() / 3), s.rolling, ColourRanges{},
                       static_cast<std::uint32_t>(bodies.count));
    ASSERT_LT(from_records.size(), stored.size());
    from_records.back_to_kept();
    restores_alike(from_records, stored, "back to the kept entries");
    // The comparison sees one impulse changed in the records.
    Real4& first = records->impulse[0];
    first.x = first.x > 0 ? first.x * 2 : real(1);
    ContactCache changed;
    changed.store(*records, static_cast<std::uint32_t>(contacts.size()), s.rolling, colours,
                  static_cast<std::uint32_t>(bodies.count));
    EXPECT_FALSE(same(changed.entries().normal_impulse, b.normal_impulse)) << "terms " << terms;
  }
}

// Without rolling resistance a store writes the rolling impulses +0 once
// and then leaves them (CacheEntries::rolling_zero): entries that held
// others, set from outside, are made +0 by the first store, and every later
// store's entries, grown or shrunk, hold +0 alone.
TEST(Solver, CacheWithoutRollingKeepsItsRollingImpulsesZero) {
  const real r = real(0.01);
  std::mt19937_64 rng(29);
  MovingLattice packed = MovingLattice::packed(10, r, rng);
  Lattice& lattice = packed.lattice;
  const PairTable table = packed.table();
  const real h = real(1e-3);
  SolverSettings s;
  s.friction = true, s.rolling = false;
  std::vector<Vec3> vel = packed.vel, omega = packed.omega;
  const BodiesView bodies = lattice.view(lattice.position.data(), vel.data(), omega.data());
  ColourRanges colours;
  std::vector<Contact> contacts = lattice.contacts(bodies, table, h, real(1e-4), colours, nullptr);
  ContactSolver solver(s);
  solver.solve_velocities(contacts, colours, bodies, h, ContactSolver::Unpack::when_asked);
  const SweepRecords* records = solver.pending_records(contacts);
  ASSERT_NE(records, nullptr);
  const auto n = static_cast<std::uint32_t>(contacts.size());
  const auto spheres = static_cast<std::uint32_t>(bodies.count);
  auto all_plus_zero = [](const CacheEntries& e) {
    const Vec3 zero{};
    for (const Vec3& v : e.rolling_impulse)
      if (std::memcmp(&v, &zero, sizeof v) != 0) return false;
    return e.rolling_impulse.size() == e.size();
  };
  // Entries from outside with rolling impulses, some -0 (a renumbering's turn).
  ContactCache cache;
  cache.store(*records, n, false, colours, spheres);
  CacheEntries other = cache.entries();
  ASSERT_GT(other.size(), n / 2);
  for (std::size_t k = 0; k < other.size(); ++k)
    other.rolling_impulse[k] = k % 3 == 0 ? Vec3(-real(0), real(0), -real(0)) : Vec3(real(k), -real(1), real(2));
  other.rolling_zero = false;
  cache.set_entries(other);
  EXPECT_FALSE(all_plus_zero(cache.entries()));
  cache.store(*records, n, false, colours, spheres);
  EXPECT_TRUE(cache.entries().rolling_zero);
  EXPECT_TRUE(all_plus_zero(cache.entries()));
  // Shrunk, grown back, and after keep() into the other set.
  cache.store(*records, n / 2, false, ColourRanges{}, spheres);
  EXPECT_TRUE(all_plus_zero(cache.entries()));
  cache.keep();
  cache.store(*records, n, false, colours, spheres);
  EXPECT_TRUE(all_plus_zero(cache.entries()));
  cache.back_to_kept();
  EXPECT_TRUE(all_plus_zero(cache.entries()));
}

// The projection sweeps until one moves no contact by more than
// settled_move (position_iterations at most), and past that while one moves
// some contact by more than deep_move (deep_position_iterations at most):
// the positions of a plain serial loop over the colour-major contacts that
// stops at that sweep, bit for bit, on lattices of touching spheres on a
// floor: one jittered by 1 % of a radius (overlaps of a few per cent here
// and there: several sweeps), one pressed evenly just past the slop (one
// sweep), one jittered by 15 % (deep overlaps: more sweeps than
// position_iterations, and other bits than stopping there).
TEST(Solver, ProjectionEndsAtTheFirstSettledSweep) {
  const real r = real(0.01);
  enum class Sweeps { one, several, deep };
  struct Case {
    double squeeze, jitter;  // pitch 2 r squeeze; m
    Sweeps expect;
  };
  for (const Case& cs : {Case{1.0, 1e-4, Sweeps::several}, Case{0.99745, 2e-7, Sweeps::one},
                         Case{1.0, 1.5e-3, Sweeps::deep}}) {
    const double squeeze = cs.squeeze;
    std::mt19937_64 rng(5);
    Lattice lattice(16, r, 2 * r * squeeze, r * squeeze, cs.jitter, rng);
    const std::size_t n = lattice.n;
    const std::vector<Vec3>& pos0 = lattice.position;
    const std::vector<WallShape>& shapes = lattice.floor;
    std::vector<Vec3> pos = pos0, vel(n), omega(n);
    BodiesView bodies = lattice.view(pos.data(), vel.data(), omega.data());
    PairCoefficients coeff{};
    PairTable table{&coeff, 1};
    ColourRanges colours;
    const std::vector<Contact> contacts = lattice.contacts(bodies, table, real(0), real(0), colours);
    ASSERT_GT(contacts.size(), n);  // the overlapping pairs

    // The oracle: whole sweeps in the solver's forward order, one by one.
    const SolverSettings s;
    std::vector<Vec3> expected = pos0;
    BodiesView oracle = bodies;
    oracle.position = expected.data();
    int sweeps = 0;
    const int most = std::max(s.position_iterations, s.deep_position_iterations);
    for (bool moved = true; moved && sweeps < most; ++sweeps) {
      SolverSettings t = s;  // from the last regular sweep on, only a deep move goes on
      if (sweeps + 1 >= s.position_iterations) t.settled_move = s.deep_move;
      moved = false;
      for (const Contact& c : contacts) moved = project_one(c, oracle, shapes.data(), t) || moved;
    }
    EXPECT_EQ(ContactSolver(s).project_positions(contacts, colours, bodies, shapes), sweeps) << "squeeze " << squeeze;
    EXPECT_EQ(std::memcmp(pos.data(), expected.data(), sizeof(Vec3) * n), 0) << "squeeze " << squeeze;
    if (cs.expect == Sweeps::deep) {
      EXPECT_GT(sweeps, s.position_iterations) << "deep overlaps sweep on";
      SolverSettings regular = s;
      regular.deep_position_iterations = 0;  // the limit alone, as before
      std::vector<Vec3> stopped = pos0;
      bodies.position = stopped.data();
      EXPECT_EQ(ContactSolver(regular).project_positions(contacts, colours, bodies, shapes), s.position_iterations);
      EXPECT_NE(std::memcmp(stopped.data(), expected.data(), sizeof(Vec3) * n), 0);
    } else if (cs.expect == Sweeps::several) {
      EXPECT_GT(sweeps, 1);
      EXPECT_LT(sweeps, s.position_iterations);  // ended early, so the sweeps' limit alone gives other bits:
      SolverSettings all = s;
      all.settled_move = 0;
      std::vector<Vec3> full = pos0;
      bodies.position = full.data();
      ContactSolver(all).project_positions(contacts, colours, bodies, shapes);
      EXPECT_NE(std::memcmp(full.data(), expected.data(), sizeof(Vec3) * n), 0);
    } else {
      EXPECT_EQ(sweeps, 1);
    }
    EXPECT_NE(std::memcmp(expected.data(), pos0.data(), sizeof(Vec3) * n), 0);  // it moved spheres
  }
}

// The contact pass asks of each contact whether it will be an impact
// candidate from approach_from_world alone: the same bits as the approach
// speed prepare_from_world gives the record, on sphere and floor contacts
// thrown at each other, candidates and not.
TEST(Solver, ApproachFromWorldIsThePreparedApproach) {
  const real r = real(0.01);
  std::mt19937_64 rng(31);
  MovingLattice thrown = MovingLattice::thrown(8, r, rng);
  const BodiesView world = thrown.view();
  ColourRanges colours;
  const std::vector<Contact> contacts = thrown.lattice.contacts(world, thrown.table(), real(1e-3), real(2e-4), colours);
  ASSERT_GT(contacts.size(), 1000u);
  const real rest = real(0.01);
  std::size_t candidates = 0, walls = 0;
  for (const Contact& c : contacts) {
    Contact prepared = c;
    prepare_from_world(prepared, world);
    const real alone = approach_from_world(c, world);
    ASSERT_EQ(std::memcmp(&alone, &prepared.approach_speed, sizeof(real)), 0) << c.a << " " << c.b;
    Contact asked = c;
    asked.approach_speed = alone;
    ASSERT_EQ(is_impact_candidate(asked, rest), is_impact_candidate(prepared, rest));
    candidates += is_impact_candidate(prepared, rest) ? 1 : 0;
    walls += is_wall(c.b) ? 1 : 0;
  }
  EXPECT_GT(candidates, contacts.size() / 10);
  EXPECT_LT(candidates, contacts.size());
  EXPECT_GT(walls, 0u);
}

// The CPU step's form (make_records over the colouring's places, the
// solve and the projection on the made records, the contacts made whole
// from them) against the colour-major contacts (colour_and_sort,
// solve_velocities, project_positions), the found contacts in two runs
// split anywhere: the same colours and records' places, the same approach
// flag, the same bodies, positions (the impacts' drifts in them), contacts
// (every byte, impact impulses included), impacts passed over, projection
// sweeps, deepest overlap and cache. A lattice thrown at itself and at the
// floor (impacts, speculative ones and later impact passes), with the last substep's
// impulses and colours restored from a cache; with and without
// restitution, friction and rolling resistance.
TEST(Solver, RecordsMadeFromTheFoundContactsEqualTheColourMajorSolve) {
  const real r = real(0.01), h = real(1e-3);
  std::uint64_t hits = 0, rebounds = 0, passed = 0;
  for (int form = 0; form < 6; ++form) {
    std::mt19937_64 rng(71 + form);
    MovingLattice start = MovingLattice::thrown(12, r, rng);
    const PairTable table = start.table();
    const std::vector<WallShape>& floor = start.lattice.floor;
    SolverSettings s;
    s.restitution = form != 5;
    s.friction = form % 3 != 0;
    s.rolling = form % 3 == 2;
    const std::vector<real> reaches(start.lattice.n, real(0));
    std::vector<Contact> found;
    const BodiesView start_view = start.view();
    sphere_contacts(start_view, start.lattice.pairs.data(), start.lattice.pairs.size(), table, h, reaches.data(), found);
    wall_contacts(start_view, floor, table, h, reaches.data(), found);
    const auto n = found.size();
    ASSERT_GT(n, 1000u);
    // The last substep's cache: most contacts with loads and colours.
    {
      std::vector<Contact> stored = found;
      ColourRanges colours;
      ContactColouring().colour_and_sort(stored, start_view.count, colours);
      std::uniform_real_distribution<double> u(0.1, 1);
      for (std::size_t k = 0; k < stored.size(); ++k) {
        stored[k].normal_impulse = k % 5 == 0 ? real(0) : real(u(rng) * 1e-5);
        stored[k].tangent_impulse = random_unit(rng) * real(u(rng) * 1e-6);
        stored[k].rolling_impulse = s.rolling ? random_unit(rng) * real(u(rng) * 1e-8) : Vec3{};
      }
      ContactCache cache;
      cache.store(stored, colours);
      std::vector<std::uint8_t> kept, loaded;
      cache.restore(found, start_view, real(1e3), kept, &loaded);
      for (std::size_t k = 0; k < n; k += 6) kept[k] = kNoKeptColour;  // every 6th contact new
      const std::string at = "form " + std::to_string(form);

      // The oracle: the contacts in colour-major order, solved and projected.
      MovingLattice one = start;
      const BodiesView one_view = one.view();
      std::vector<Contact> sorted = found;
      ColourRanges sorted_ranges;
      ContactColouring().colour_and_sort(sorted, one_view.count, sorted_ranges, kept.data(), &one_view, s.rest_speed,
                                         loaded.data());
      ContactSolver oracle(s);
      oracle.solve_velocities(sorted, sorted_ranges, one_view, h);
      for (std::size_t i = 0; i < one.lattice.n; ++i)
        one.lattice.position[i] = integrator::drift(one.lattice.position[i], one.vel[i], h, oracle.impact_shift(), i);
      const int sweeps = oracle.project_positions(sorted, sorted_ranges, one_view, floor);
      const real deepest = oracle.deepest_overlap(one_view, floor);
      ContactCache oracle_cache;
      oracle_cache.store(sorted, sorted_ranges);
      for (const Contact& c : sorted) {
        hits += c.impact_impulse > 0 ? 1 : 0;
        rebounds += c.impact_impulse > 0 && c.separation > 0 ? 1 : 0;  // a speculative hit: its spheres drift
      }
      passed += oracle.impact_passed_over();

      for (const std::size_t split : {std::size_t(0), n / 3, n}) {
        MovingLattice two = start;
        const BodiesView two_view = two.view();
        std::vector<Contact> head(found.begin(), found.begin() + static_cast<std::ptrdiff_t>(split)),
            tail(found.begin() + static_cast<std::ptrdiff_t>(split), found.end());
        const ContactRuns runs(head.data(), head.size(), tail.data());
        ColourRanges ranges;
        ranges.fast_approach = !sorted_ranges.fast_approach;  // make_records must set it
        ContactColouring colouring;
        colouring.colour_and_place(runs, n, two_view.count, ranges, kept.data(), loaded.data());
        ContactSolver made(s);
        made.make_records(runs, colouring.places(), ranges, two_view);
        const std::string where = at + ", split " + std::to_string(split);
        EXPECT_EQ(ranges.begin, sorted_ranges.begin) << where;
        EXPECT_EQ(ranges.record, sorted_ranges.record) << where;
        EXPECT_EQ(ranges.fast_approach, sorted_ranges.fast_approach) << where;
        made.solve_records(ranges, two_view, h);
        for (std::size_t i = 0; i < two.lattice.n; ++i)
          two.lattice.position[i] = integrator::drift(two.lattice.position[i], two.vel[i], h, made.impact_shift(), i);
        EXPECT_EQ(made.project_records(ranges, two_view, floor), sweeps) << where;
        EXPECT_EQ(made.impact_passed_over(), oracle.impact_passed_over()) << where;
        auto same_bytes = [](const auto& a, const auto& b) {
          return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0;
        };
        EXPECT_TRUE(same_bytes(two.vel, one.vel)) << where;
        EXPECT_TRUE(same_bytes(two.omega, one.omega)) << where;
        EXPECT_TRUE(same_bytes(two.lattice.position, one.lattice.position)) << where;
        const real made_deepest = made.deepest_overlap(two_view, floor);
        EXPECT_EQ(std::memcmp(&made_deepest, &deepest, sizeof(real)), 0) << where;
        std::vector<Contact> whole;
        made.contacts_of_records(ranges, two_view, table, floor, whole);
        EXPECT_TRUE(same_bytes(whole, sorted)) << where;
        ASSERT_NE(made.made_records(), nullptr);
        ContactCache made_cache;
        made_cache.store(*made.made_records(), static_cast<std::uint32_t>(n), s.rolling, ranges,
                         static_cast<std::uint32_t>(two_view.count));
        const CacheEntries &a = made_cache.entries(), &b = oracle_cache.entries();
        EXPECT_GT(b.size(), n / 2) << where;
        EXPECT_TRUE(same_bytes(a.key, b.key) && same_bytes(a.normal_impulse, b.normal_impulse) &&
                    same_bytes(a.tangent_impulse, b.tangent_impulse) &&
                    same_bytes(a.rolling_impulse, b.rolling_impulse) && same_bytes(a.colour, b.colour))
            << where;
        made.forget_records();
        EXPECT_EQ(made.made_records(), nullptr);
      }
    }
  }
  EXPECT_GT(hits, 1000u) << "premise: impacts";
  EXPECT_GT(rebounds, 100u) << "premise: speculative hits (drifts)";
  EXPECT_GT(passed, 0u) << "premise: later impact passes that pass contacts over";
}

// The impact stage's later passes pass over the contacts no hit of the
// stage has reached (impact_passed_over): the same bits as trying every
// contact. Lattices thrown a hair apart, in which only some spheres move
// (the others at rest, or drifting slower than the rest speed), so that a
// pass after the first meets contacts of every kind: reached by a hit,
// candidates, slow, and between spheres no hit has moved; with and without
// friction. The bodies after the whole solve (impacts, warm start, sweeps),
// every contact's impact impulse, and the positions after the integration
// and the projection (the impacts' drifts in them), bit for bit; the
// premise that contacts were passed over, and only with the pass-over on.
TEST(Solver, ImpactPassOverGivesTheSameBits) {
  const real r = real(0.01), h = real(1e-3);
  std::uint64_t passed = 0, runs_with_later_passes = 0;
  for (const std::uint64_t seed : {3u, 5u, 8u, 13u, 21u, 34u}) {
    for (const double moving : {0.02, 0.1, 0.4}) {
      for (const bool friction : {true, false}) {
        std::mt19937_64 rng(seed);
        MovingLattice thrown = MovingLattice::thrown(7, r, rng);
        std::bernoulli_distribution moves(moving), drifts(0.5);
        for (std::size_t i = 0; i < thrown.lattice.n; ++i) {
          if (moves(rng)) continue;
          const real slow = drifts(rng) ? real(0.004) : real(0);  // below the rest speed of 0.01
          thrown.vel[i] = thrown.vel[i] * (slow / std::max(length(thrown.vel[i]), real(1e-9)));
          thrown.omega[i] = Vec3{};
        }
        SolverSettings s;
        s.friction = friction;
        s.rest_speed = real(0.01);
        MovingLattice tried = thrown;
        ColourRanges colours;
        std::vector<Contact> over = thrown.lattice.contacts(thrown.view(), thrown.table(), h, real(2e-4), colours);
        std::vector<Contact> all = over;
        ASSERT_GT(over.size(), 500u);
        ContactSolver passing(s);
        passing.solve_velocities(over, colours, thrown.view(), h);
        s.impact_pass_over = false;
        ContactSolver trying(s);
        trying.solve_velocities(all, colours, tried.view(), h);
        const std::string at = "seed " + std::to_string(seed) + ", moving " + std::to_string(moving) +
                               (friction ? ", friction" : "");
        EXPECT_EQ(trying.impact_passed_over(), 0u) << at;
        ASSERT_EQ(std::memcmp(thrown.vel.data(), tried.vel.data(), thrown.vel.size() * sizeof(Vec3)), 0) << at;
        ASSERT_EQ(std::memcmp(thrown.omega.data(), tried.omega.data(), thrown.omega.size() * sizeof(Vec3)), 0) << at;
        for (std::size_t k = 0; k < over.size(); ++k) {
          ASSERT_EQ(std::memcmp(&over[k].impact_impulse, &all[k].impact_impulse, sizeof(real)), 0) << at << ", " << k;
        }
        for (std::size_t i = 0; i < thrown.lattice.n; ++i) {
          thrown.lattice.position[i] =
              integrator::drift(thrown.lattice.position[i], thrown.vel[i], h, passing.impact_shift(), i);
          tried.lattice.position[i] =
              integrator::drift(tried.lattice.position[i], tried.vel[i], h, trying.impact_shift(), i);
        }
        EXPECT_EQ(passing.project_positions(over, colours, thrown.view(), thrown.lattice.floor),
                  trying.project_positions(all, colours, tried.view(), tried.lattice.floor))
            << at;
        ASSERT_EQ(std::memcmp(thrown.lattice.position.data(), tried.lattice.position.data(),
                              thrown.lattice.position.size() * sizeof(Vec3)),
                  0)
            << at;
        passed += passing.impact_passed_over();
        runs_with_later_passes += passing.impact_passed_over() > 0 ? 1 : 0;
      }
    }
  }
  EXPECT_GT(runs_with_later_passes, 20u) << "premise: later passes that pass contacts over";
  EXPECT_GT(passed, 10000u) << "premise";
}

// The GPU holds a substep's contacts only as the sweep's records and their
// impact records (solver_math.hpp): the impact stage on them (impact_record)
// gives impact_one's bodies and contacts bit for bit, and the whole contacts
// made from them (contact_of_record) equal the contacts, every field. A
// lattice of spheres thrown at each other and at the floor (so that most
// contacts hit), with and without friction, the accumulated impulses random;
// the records with the extra word and without it (the GPU's where no wall
// moves: the floor here is at rest), and with the arms word and without it
// (the GPU's where every sphere has one radius and every pair the same
// coefficients, as here: UniformArms), and with each contact's restitution
// kept (the CPU's) and looked up from the pair table (the GPU's:
// ImpactParams). Without the arms word a sweep also leaves the same bodies
// and impulses as with it.
TEST(Solver, RecordsHoldTheWholeContactAndItsImpacts) {
  const real r = real(0.01);
  std::mt19937_64 rng(29);
  MovingLattice thrown = MovingLattice::thrown(10, r, rng);
  const std::size_t n = thrown.lattice.n;
  // Two materials, alternating, the floor of the second: every pair's
  // restitution its own (the friction the same: UniformArms).
  for (std::size_t i = 0; i < n; ++i) thrown.lattice.material[i] = static_cast<std::uint32_t>(i % 2);
  thrown.lattice.floor[0].material = 1;
  PairCoefficients pairs[4] = {thrown.coeff, thrown.coeff, thrown.coeff, thrown.coeff};
  pairs[0].restitution = real(0.3);
  pairs[1].restitution = pairs[2].restitution = real(0.6);
  pairs[3].restitution = real(0.9);
  const PairTable table{pairs, 2};
  std::uniform_real_distribution<double> u(0, 1);
  const real h = real(1e-3);
  const BodiesView world = thrown.view();
  ColourRanges colours;
  std::vector<Contact> contacts = thrown.lattice.contacts(world, table, h, real(2e-4), colours);
  const auto m = static_cast<std::uint32_t>(contacts.size());
  ASSERT_GT(m, 2000u);
  for (Contact& c : contacts) {  // as a warm start restores them
    c.normal_impulse = real(u(rng) * 1e-4);
    c.tangent_impulse = random_unit(rng) * real(u(rng) * 1e-5);
    c.rolling_impulse = random_unit(rng) * real(u(rng) * 1e-7);
  }
  for (std::size_t i = 1; i < n; ++i) ASSERT_EQ(world.radius[i], world.radius[0]);
  const UniformArms uniform{world.radius[0], thrown.coeff.friction, thrown.coeff.rolling_friction};
  const WallShape* floor = thrown.lattice.floor.data();
  std::vector<Real4> after_sweep[2][2];  // [friction][arms]: impulses after a sweep, then the bodies
  for (int form = 0; form < 16; ++form) {
    const bool extra = form % 4 < 2, friction = form % 2 == 1, arms = form % 8 < 4, looked_up = form >= 8;
    ImpactParams params{real(0.01), h, Vec3(0, 0, real(-9.81))};
    if (looked_up) params.material = world.material, params.walls = floor, params.table = table;
    std::vector<SolverBody> expect_bodies(n), got_bodies(n);
    for (std::size_t i = 0; i < n; ++i) expect_bodies[i] = got_bodies[i] = gather_solver_body(world, i);
    std::vector<Contact> expect = contacts;
    const std::size_t record_words = (SweepRecords::bytes_for(m, extra, arms) + 15) / 16;
    std::vector<Real4> memory(record_words + ImpactRecords::real4_words(m, true, true));
    const SweepRecords records = SweepRecords::in(memory.data(), m, extra, arms, uniform);
    ASSERT_EQ(records.extra != nullptr, extra);
    ASSERT_EQ(records.arms != nullptr, arms);
    ASSERT_EQ(reinterpret_cast<const char*>(records.bodies + m) - reinterpret_cast<const char*>(memory.data()) + 64,
              static_cast<std::ptrdiff_t>(SweepRecords::bytes_for(m, extra, arms)));
    const ImpactRecords impact = ImpactRecords::in(memory.data() + record_words, m, true, !looked_up);
    for (std::uint32_t k = 0; k < m; ++k) {
      pack_sweep_record(contacts[k], records, k);  // as the GPU makes them
      pack_impact(contacts[k], impact, k);
    }
    std::uint32_t hits = 0;
    for (std::uint32_t k = 0; k < m; ++k) {
      const bool hit = friction ? impact_one<true>(expect[k], expect_bodies.data(), params)
                                : impact_one<false>(expect[k], expect_bodies.data(), params);
      const bool got = friction ? impact_record<true>(records, impact, k, got_bodies.data(), params)
                                : impact_record<false>(records, impact, k, got_bodies.data(), params);
      ASSERT_EQ(hit, got) << "contact " << k << " looked up " << looked_up;
      hits += hit ? 1 : 0;
    }
    EXPECT_GT(hits, m / 10) << "friction " << friction;  // the impacts did work
    EXPECT_EQ(std::memcmp(expect_bodies.data(), got_bodies.data(), n * sizeof(SolverBody)), 0) << friction;
    std::uint32_t walls = 0, rebounds = 0;
    std::set<real> restitutions;
    for (std::uint32_t k = 0; k < m; ++k) {
      const Contact c = contact_of_record(records, impact, k, world, table, floor);
      ASSERT_EQ(std::memcmp(&c, &expect[k], sizeof(Contact)), 0)
          << "contact " << k << " friction " << friction << " extra " << extra << " looked up " << looked_up;
      walls += is_wall(c.b) ? 1 : 0;
      rebounds += c.impact_impulse > 0 && c.separation > 0 ? 1 : 0;
      restitutions.insert(c.coeff.restitution);
    }
    EXPECT_GT(walls, 0u);
    EXPECT_GT(rebounds, 0u);
    EXPECT_EQ(restitutions.size(), 3u);
    // One sweep (friction and rolling, or rolling alone: both read the
    // arms) on the records as they are now: the same with and without the
    // arms word.
    std::vector<Real4>& out = after_sweep[friction][arms];
    for (std::uint32_t k = 0; k < m; ++k) {
      if (friction) solve_record<true, true>(records, k, got_bodies.data(), real(1) / h);
      else solve_record<false, true>(records, k, got_bodies.data(), real(1) / h);
      out.push_back(records.impulse[k]);
      out.push_back(records.rolling[k]);
    }
    for (const SolverBody& b : got_bodies) out.push_back({b.v.x, b.v.y, b.v.z, b.w.x}), out.push_back({b.w.y, b.w.z});
  }
  for (const bool friction : {false, true}) {
    const std::vector<Real4>& with = after_sweep[friction][true];
    const std::vector<Real4>& without = after_sweep[friction][false];
    ASSERT_EQ(with.size(), 8 * (std::size_t(m) + n));  // both extra and restitution forms, appended in turn
    ASSERT_EQ(without.size(), with.size());
    EXPECT_EQ(std::memcmp(with.data(), without.data(), with.size() * sizeof(Real4)), 0) << "friction " << friction;
  }
}

// A substep without impact candidates keeps the approach speeds alone beside
// the records (ImpactRecords): no impact stage runs, and the contacts made
// from them are the contacts as made, every field, each one's restitution
// looked up again from its pair (two materials here, alternating, the floor
// of the second, every pair's restitution its own).
TEST(Solver, RecordsWithApproachSpeedsOnlyHoldTheWholeContact) {
  const real r = real(0.01);
  std::mt19937_64 rng(31);
  MovingLattice thrown = MovingLattice::thrown(10, r, rng);
  Lattice& lattice = thrown.lattice;
  for (std::size_t i = 0; i < lattice.n; ++i) lattice.material[i] = static_cast<std::uint32_t>(i % 2);
  lattice.floor[0].material = 1;
  PairCoefficients pairs[4] = {thrown.coeff, thrown.coeff, thrown.coeff, thrown.coeff};
  pairs[0].restitution = real(0.1);
  pairs[1].restitution = pairs[2].restitution = real(0.5);
  pairs[3].restitution = real(0.9);
  const PairTable table{pairs, 2};
  const BodiesView world = thrown.view();
  ColourRanges colours;
  const std::vector<Contact> contacts = lattice.contacts(world, table, real(1e-3), real(2e-4), colours);
  const auto m = static_cast<std::uint32_t>(contacts.size());
  ASSERT_GT(m, 2000u);
  std::vector<Real4> memory((SweepRecords::bytes_for(m, false) + 15) / 16);
  const SweepRecords records = SweepRecords::in(memory.data(), m, false);
  std::vector<real> approach(m);
  const ImpactRecords speeds{approach.data()};
  for (std::uint32_t k = 0; k < m; ++k) {
    pack_sweep_record(contacts[k], records, k);
    pack_impact(contacts[k], speeds, k);
  }
  std::set<real> restitutions;
  std::uint32_t walls = 0;
  for (std::uint32_t k = 0; k < m; ++k) {
    const Contact c = contact_of_record(records, speeds, k, world, table, lattice.floor.data());
    ASSERT_EQ(std::memcmp(&c, &contacts[k], sizeof(Contact)), 0) << "contact " << k;
    restitutions.insert(c.coeff.restitution);
    walls += is_wall(c.b) ? 1 : 0;
  }
  EXPECT_EQ(restitutions.size(), 3u);
  EXPECT_GT(walls, 0u);
}

// Lean records, as the GPU lays them out: without the rolling word where no
// contact has rolling resistance, and keeping the normal impulse alone (a
// real a contact, rounded up to a word) where none has friction either.
// Each form holds the whole contact as made (rolling impulse +0 and the pair
// table's twisting friction; without friction a tangent impulse of +0), and
// a warm start and two sweeps leave the same bodies and impulses as on the
// whole records.
struct LeanRun {
  std::vector<SolverBody> bodies;
  std::vector<Real4> impulses;
};
template <bool Friction>
LeanRun run_on_records(MovingLattice& packed, const std::vector<Contact>& contacts, bool rolling, bool friction) {
  const BodiesView world = packed.view();
  const auto m = static_cast<std::uint32_t>(contacts.size());
  std::vector<Real4> memory((SweepRecords::bytes_for(m, false, true, rolling, friction) + 15) / 16);
  std::vector<real> approach(m);
  const SweepRecords records = SweepRecords::in(memory.data(), m, false, true, {}, rolling, friction);
  EXPECT_EQ(records.rolling != nullptr, rolling);
  EXPECT_EQ(records.impulse != nullptr, friction);
  EXPECT_EQ(records.normal != nullptr, !friction);
  EXPECT_EQ(reinterpret_cast<const char*>(records.bodies + m) - reinterpret_cast<const char*>(memory.data()) + 64,
            static_cast<std::ptrdiff_t>(SweepRecords::bytes_for(m, false, true, rolling, friction)));
  const ImpactRecords speeds{approach.data()};
  for (std::uint32_t k = 0; k < m; ++k) {
    pack_sweep_record(contacts[k], records, k);  // as the GPU makes them
    pack_impact(contacts[k], speeds, k);
  }
  for (std::uint32_t k = 0; k < m; ++k) {
    const Contact c = contact_of_record(records, speeds, k, world, packed.table(), packed.lattice.floor.data());
    EXPECT_EQ(std::memcmp(&c, &contacts[k], sizeof(Contact)), 0) << "contact " << k;
    if (::testing::Test::HasFailure()) break;
  }
  LeanRun run;
  for (std::size_t i = 0; i < packed.lattice.n; ++i) run.bodies.push_back(gather_solver_body(world, i));
  for (std::uint32_t k = 0; k < m; ++k) warm_start_record<Friction, false>(records, k, run.bodies.data());
  for (int sweep = 0; sweep < 2; ++sweep)
    for (std::uint32_t k = 0; k < m; ++k) solve_record<Friction, false>(records, k, run.bodies.data(), real(1e3));
  for (std::uint32_t k = 0; k < m; ++k) run.impulses.push_back(impulse_word(records, k));
  return run;
}

TEST(Solver, LeanRecordsHoldTheWholeContact) {
  for (const std::uint32_t n : {1u, 2u, 3u, 4u, 5u, 1001u}) {
    EXPECT_EQ(SweepRecords::bytes_for(n, false, true, true) - SweepRecords::bytes_for(n, false, true, false),
              n * sizeof(Real4));
    EXPECT_EQ(SweepRecords::bytes_for(n, false, true, false, true) - SweepRecords::bytes_for(n, false, true, false, false),
              n * sizeof(Real4) - (n * sizeof(real) + 15) / 16 * 16)
        << n;
  }
  const real r = real(0.01);
  std::mt19937_64 rng(37);
  MovingLattice packed = MovingLattice::packed(10, r, rng);
  ASSERT_GT(packed.coeff.twisting_friction, 0);
  ColourRanges colours;
  const std::vector<Contact> made =
      packed.lattice.contacts(packed.view(), packed.table(), real(1e-3), real(2e-4), colours);
  const auto m = static_cast<std::uint32_t>(made.size());
  ASSERT_GT(m, 2000u);
  std::uniform_real_distribution<double> u(0, 1);
  for (const bool friction : {true, false}) {
    SCOPED_TRACE(friction ? "friction, no rolling word" : "no friction: the normal impulse alone");
    std::vector<Contact> contacts = made;  // a warm start's, some unloaded, without rolling impulses
    for (Contact& c : contacts) {
      c.normal_impulse = u(rng) < 0.3 ? real(0) : real(u(rng) * 1e-4);
      if (friction) c.tangent_impulse = random_unit(rng) * real(u(rng) * 1e-5);
    }
    const LeanRun whole = friction ? run_on_records<true>(packed, contacts, true, true)
                                   : run_on_records<false>(packed, contacts, true, true);
    const LeanRun lean = friction ? run_on_records<true>(packed, contacts, false, true)
                                  : run_on_records<false>(packed, contacts, false, false);
    ASSERT_FALSE(::testing::Test::HasFailure());
    EXPECT_EQ(std::memcmp(whole.bodies.data(), lean.bodies.data(), whole.bodies.size() * sizeof(SolverBody)), 0);
    EXPECT_EQ(std::memcmp(whole.impulses.data(), lean.impulses.data(), m * sizeof(Real4)), 0);
    std::size_t moved = 0;  // the sweeps did work
    for (std::uint32_t k = 0; k < m; ++k) moved += lean.impulses[k].x != contacts[k].normal_impulse ? 1 : 0;
    EXPECT_GT(moved, m / 10);
  }
}

// A wall at rest (surface_at_rest) has the surface velocity +0 in every
// component at every point, whatever the signs of its axis and of a zero
// spin: the value a contact without the extra word takes. A zero of the
// other sign in its velocity, a translation or a spin is not at rest, and
// the surface velocity shows why (-0, or not zero).
TEST(Walls, ASurfaceAtRestHasTheVelocityPlusZero) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  const auto bits_of = [](real v) {
    std::uint64_t b = 0;
    std::memcpy(&b, &v, sizeof v);
    return b;
  };
  for (int t = 0; t < 200; ++t) {
    WallShape w;
    w.kind = t % 2 ? WallShape::Kind::cylinder_inside : WallShape::Kind::half_space;
    w.point = Vec3(real(u(rng)), real(u(rng)), real(u(rng)));
    w.direction = random_unit(rng);
    w.angular_velocity = t % 3 == 0 ? real(-0.0) : real(0);
    ASSERT_TRUE(surface_at_rest(w));
    for (int p = 0; p < 20; ++p) {
      const Vec3 v = wall_surface_velocity(w, Vec3(real(u(rng)), real(u(rng)), real(u(rng))));
      ASSERT_EQ(bits_of(v.x) | bits_of(v.y) | bits_of(v.z), 0u) << "wall " << t;
    }
  }
  WallShape negative_zero;
  negative_zero.velocity = Vec3(0, 0, real(-0.0));
  EXPECT_FALSE(surface_at_rest(negative_zero));
  EXPECT_NE(bits_of(wall_surface_velocity(negative_zero, Vec3(1, -1, 1)).z), 0u);  // -0 + (+0 * -1 - +0 * 1)
  WallShape sliding, spinning;
  sliding.velocity = Vec3(real(0.1), 0, 0);
  spinning.angular_velocity = real(2);
  EXPECT_FALSE(surface_at_rest(sliding));
  EXPECT_FALSE(surface_at_rest(spinning));
  EXPECT_NE(wall_surface_velocity(spinning, Vec3(1, 0, 0)).y, 0);
}

// wall_contacts passes over a wall at rest where a bound says the whole test
// (make_wall_contact) must refuse the sphere: the same contacts as the whole
// test on every sphere and wall. n spheres of mixed radii near `walls`
// (among them a box and a plane through (0.5, 0, 0) with the normal
// (1, 2, 3), both at rest); gaps drawn around the skin, the reach and what
// the approach closes in h, and spheres moving straight at the box's floor
// with the gap set to that distance as computed and one float either side
// of it. `odd`: some spheres also with a NaN or infinite velocity or
// position, or a velocity of signed zeros.
void expect_passed_over_only_where_refused(const Walls& walls, std::size_t n, std::uint64_t seed, bool odd) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  const real h = real(1e-3);
  const std::vector<WallShape> shapes = wall_shapes(walls);
  const Vec3 incline = Vec3(1, 2, 3) / length(Vec3(1, 2, 3));
  std::size_t floor_at = shapes.size(), incline_at = shapes.size();
  for (std::size_t k = 0; k < shapes.size(); ++k) {
    if (shapes[k].kind != WallShape::Kind::half_space) continue;
    if (shapes[k].direction == Vec3(0, 0, 1) && shapes[k].point.z == 0) floor_at = std::min(floor_at, k);
    if (shapes[k].direction == incline) incline_at = k;
  }
  ASSERT_LT(floor_at, shapes.size()) << "premise: a box's floor";
  ASSERT_LT(incline_at, shapes.size()) << "premise: the inclined plane";
  const WallShape &floor = shapes[floor_at], &inclined = shapes[incline_at];
  std::vector<Vec3> pos(n), vel(n), omega(n);
  std::vector<real> radius(n), inv_mass(n, 1), inv_inertia(n, 1), reach(n);
  std::vector<std::uint32_t> material(n, 0);
  const real nan = std::numeric_limits<real>::quiet_NaN(), inf = std::numeric_limits<real>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const real r = real(0.005 + 0.015 * u(rng));
    radius[i] = r;
    reach[i] = i % 3 == 0 ? real(0) : real(0.002 * u(rng));
    const double speed = 20 * u(rng) * u(rng);  // up to 0.02 m in h
    vel[i] = random_unit(rng) * real(speed);
    Vec3 p(real(u(rng)), real(u(rng)), real(u(rng)));
    const int face = static_cast<int>(i % 4);  // the floor, the -x face, the inclined plane, anywhere
    const double gaps[] = {kContactSkin * r, reach[i], speed * h, 0.03 * u(rng)};
    const real gap = real(gaps[i % 4 == 3 ? 3 : (i / 4) % 4] * (0.98 + 0.04 * u(rng)));
    if (face == 0) p.z = r + gap;
    if (face == 1) p.x = r + gap;
    if (face == 2) p = p - inclined.direction * (dot(p - inclined.point, inclined.direction) - r - gap);
    if (i % 16 == 5) {  // straight at the floor, the gap what the approach closes, as computed, and a float off
      const real s = real(10 * u(rng));
      vel[i] = Vec3(0, 0, -s);
      const real closes = -(-s) * h;
      const int off = static_cast<int>((i / 16) % 3) - 1;
      const real target = off == 0 ? closes : std::nextafter(closes, off < 0 ? real(0) : real(1));
      p = Vec3(p.x, p.y, r);
      for (int t = 0; t < 64 && dot(p - floor.point, floor.direction) - r != target; ++t)
        p.z = p.z + (target - (dot(p - floor.point, floor.direction) - r));
    }
    if (odd && i % 7 == 2) {
      switch ((i / 7) % 5) {
        case 0: vel[i].y = nan; break;
        case 1: vel[i].x = -inf; break;
        case 2: p.z = nan; break;
        case 3: p.x = inf; break;
        default: vel[i] = Vec3(real(-0.0), real(0), real(-0.0)); break;
      }
    }
    pos[i] = p;
  }
  const BodiesView bodies{pos.data(), vel.data(), omega.data(), radius.data(), inv_mass.data(), inv_inertia.data(),
                          material.data(), n};
  PairCoefficients coeff{real(0.5), real(0.5), real(0.01), real(0.01)};
  const PairTable table{&coeff, 1};
  std::vector<Contact> whole;
  std::size_t by_approach = 0, on_the_edge = 0;  // contacts at rest walls made by the approach alone; edge cases met
  for (std::uint32_t i = 0; i < n; ++i) {
    Contact c;
    for (std::uint32_t k = 0; k < shapes.size(); ++k) {
      if (!make_wall_contact(bodies, i, shapes[k], k, table, h, reach.data(), c)) continue;
      whole.push_back(c);
      if (shapes[k].kind == WallShape::Kind::half_space && surface_at_rest(shapes[k]) &&
          c.separation >= kContactSkin * radius[i] && c.separation >= reach[i])
        ++by_approach;
    }
    if (i % 16 == 5) {
      const real gap = dot(pos[i] - floor.point, floor.direction) - radius[i];
      on_the_edge += gap == -vel[i].z * h ? 1 : 0;
    }
  }
  std::vector<Contact> passed;
  wall_contacts(bodies, shapes, table, h, reach.data(), passed);
  ASSERT_EQ(passed.size(), whole.size());
  EXPECT_EQ(std::memcmp(passed.data(), whole.data(), sizeof(Contact) * whole.size()), 0);
  EXPECT_GT(by_approach, n / 50) << "premise: contacts the approach alone makes at walls at rest";
  EXPECT_GT(on_the_edge, n / 200) << "premise: gaps exactly what the approach closes";
}

// Among a sliding plane, a plane at rest whose normal is not of unit length
// (never passed over), a spinning and a resting drum: each sphere's walls
// tested one by one.
TEST(Walls, PassedOverOnlyWhereTheWholeTestRefuses) {
  Walls walls;
  walls.boxes.push_back({{0, 0, 0}, {1, 1, 1}, 0, {}});
  walls.planes.push_back({{real(0.5), 0, 0}, Vec3(1, 2, 3) / length(Vec3(1, 2, 3)), 0, {}});
  walls.planes.push_back({{0, 0, real(0.9)}, {0, 0, -1}, 0, {0, 0, real(0.2)}});
  walls.planes.push_back({{0, 0, real(0.02)}, {0, 0, 2}, 0, {}});  // not unit: never passed over
  walls.cylinders.push_back({{real(0.5), real(0.5), 0}, {0, 0, 1}, real(0.45), 0, true, real(3), 0});
  walls.cylinders.push_back({{real(0.5), real(0.5), 0}, {0, 0, 1}, real(0.48), 0, true, 0, 0});
  ASSERT_EQ(wall_shapes(walls).size(), 11u);
  expect_passed_over_only_where_refused(walls, 30000, 97, false);
}

// Where every wall is passable (here the box and the inclined plane), the
// spheres near none are found four at a time first (near_walls): the same
// contacts, past the parallel threshold and below it, with a count that
// leaves a tail of one to three, and with odd values among the spheres.
TEST(Walls, SpheresNearNoWallFoundInLanesAreThoseTheWholeTestRefuses) {
  Walls walls;
  walls.boxes.push_back({{0, 0, 0}, {1, 1, 1}, 0, {}});
  walls.planes.push_back({{real(0.5), 0, 0}, Vec3(1, 2, 3) / length(Vec3(1, 2, 3)), 0, {}});
  ASSERT_EQ(wall_shapes(walls).size(), 7u);
  expect_passed_over_only_where_refused(walls, 30001, 98, false);
  expect_passed_over_only_where_refused(walls, 30003, 99, true);
  expect_passed_over_only_where_refused(walls, 4003, 100, true);
}

// Two runs read as one list (Runs, the CPU's contact search): the search's
// runs hold the joined list's contacts in its order for 1 to 16 threads,
// into buffers kept from the search before (30 492 candidate pairs, past
// the parallel threshold, thrown apart and
// together so that some make no contact); and the cache's restore and the
// colouring on runs split anywhere (empty runs included) give what they give
// on the one list: the same impulses, kept colours, cold starts, colours and
// colour-major order.
TEST(ContactRuns, SearchRestoreAndColouringOnRunsEqualTheOneList) {
  auto same = [](const std::vector<Contact>& a, const std::vector<Contact>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(Contact) * a.size()) == 0;
  };
  const real r = real(0.01), h = real(1e-3);
  std::mt19937_64 rng(41);
  MovingLattice thrown = MovingLattice::thrown(22, r, rng);
  const BodiesView bodies = thrown.view();
  const PairTable table = thrown.table();
  const std::vector<IndexPair>& pairs = thrown.lattice.pairs;
  ASSERT_GT(pairs.size(), 20000u) << "premise: the search runs on several threads";
  const std::vector<real> reaches(bodies.count, real(0));
  std::vector<Contact> joined;
  sphere_contacts(bodies, pairs.data(), pairs.size(), table, h, reaches.data(), joined);
  wall_contacts(bodies, thrown.lattice.floor, table, h, reaches.data(), joined);
  ASSERT_GT(joined.size(), pairs.size() / 10);
  ASSERT_LT(joined.size(), pairs.size()) << "premise: some pairs make no contact";
  const int was = thread_count();
  // The buffers kept from search to search, as the step keeps them: `first`
  // cleared, `rest` replaced (its stale contacts, more than any search
  // makes at first, marked so that one left over shows).
  std::vector<Contact> first, rest(joined.size() + 5);
  ContactScratch scratch;
  for (int threads : {1, 2, 3, 5, 16, 3, 2, 5}) {
    set_thread_count(threads);
    first.clear();
    for (Contact& c : rest) c.a = 0xdeadbeefu;
    sphere_contacts(bodies, pairs.data(), pairs.size(), table, h, reaches.data(), first, rest, scratch);
    wall_contacts(bodies, thrown.lattice.floor, table, h, reaches.data(), rest.empty() ? first : rest, &scratch);
    set_thread_count(was);
    EXPECT_EQ(rest.empty(), threads == 1) << threads << " thread(s)";
    std::vector<Contact> read(first);
    read.insert(read.end(), rest.begin(), rest.end());
    EXPECT_TRUE(same(read, joined)) << threads << " thread(s)";
  }

  // A cache of the list's contacts with loads (every 9th none), then a
  // substep in which every 7th contact is gone.
  ColourRanges colours;
  std::vector<Contact> stored = joined;
  ContactColouring().colour_and_sort(stored, bodies.count, colours);
  give_random_loads(stored, rng);
  ContactCache cache;
  cache.store(stored, colours);
  std::vector<Contact> next;
  for (std::size_t k = 0; k < joined.size(); ++k)
    if (k % 7 != 3) next.push_back(joined[k]);
  const std::size_t n = next.size();
  std::vector<std::size_t> loaded_by_weight;
  std::vector<Contact> restored_heavy;  // the restore without a lost load
  for (const real weight : {real(1e3), real(1e-6)}) {  // no lost load; every gone contact's a lost load
    std::vector<Contact> one = next;
    std::vector<std::uint8_t> kept_one, loaded_one;
    ContactCache a = cache;
    const std::size_t warm_one = a.restore(one, bodies, weight, kept_one, &loaded_one);
    if (weight > 1) restored_heavy = one;
    std::vector<Contact> coloured_one = one;
    ColourRanges ranges_one;
    ContactColouring().colour_and_sort(coloured_one, bodies.count, ranges_one, kept_one.data(), &bodies, 0,
                                       loaded_one.data());
    std::size_t loaded = 0;
    ASSERT_EQ(loaded_one.size(), n);
    for (std::size_t t = 0; t < n; ++t) {
      loaded += one[t].normal_impulse > 0 ? 1 : 0;
      // The flags say which contacts start with a load, the islands set cold not among them.
      EXPECT_EQ(loaded_one[t] != 0, one[t].normal_impulse > 0) << "contact " << t << ", weight " << weight;
    }
    loaded_by_weight.push_back(loaded);
    for (const std::size_t split : {std::size_t(0), std::size_t(1), n / 3, n - 1, n}) {
      std::vector<Contact> head(next.begin(), next.begin() + static_cast<std::ptrdiff_t>(split)),
          tail(next.begin() + static_cast<std::ptrdiff_t>(split), next.end());
      std::vector<std::uint8_t> kept, loaded_flags;
      ContactCache b = cache;
      const ContactRuns runs(head.data(), head.size(), tail.data());
      EXPECT_EQ(b.restore(runs, n, bodies, weight, kept, &loaded_flags), warm_one) << "split " << split;
      EXPECT_EQ(kept, kept_one) << "split " << split;
      EXPECT_EQ(loaded_flags, loaded_one) << "split " << split;
      std::vector<Contact> read(head);
      read.insert(read.end(), tail.begin(), tail.end());
      EXPECT_TRUE(same(read, one)) << "restored impulses, split " << split;
      std::vector<Contact> sorted;
      ColourRanges ranges;
      ContactColouring().colour_and_sort(runs, n, sorted, bodies.count, ranges, kept.data(), &bodies, 0,
                                         loaded_flags.data());
      EXPECT_EQ(ranges.begin, ranges_one.begin) << "split " << split;
      EXPECT_EQ(ranges.unloaded, ranges_one.unloaded) << "split " << split;
      EXPECT_EQ(ranges.colours, ranges_one.colours) << "split " << split;
      EXPECT_TRUE(same(sorted, coloured_one)) << "colour-major contacts, split " << split;
    }
    const auto found = static_cast<std::size_t>(
        std::count_if(kept_one.begin(), kept_one.end(), [](std::uint8_t c) { return c != kNoKeptColour; }));
    EXPECT_GT(found, n / 2) << "premise: most contacts find their entry (weight " << weight << ")";
  }
  ASSERT_EQ(loaded_by_weight.size(), 2u);
  EXPECT_LT(loaded_by_weight[1], loaded_by_weight[0]) << "premise: the tiny weight starts some island cold";
  EXPECT_GT(loaded_by_weight[1], 0u) << "premise: and not every island";

  // One cache restoring twice (its lists reused from restore to restore):
  // after a restore with lost loads, one without any sets nothing cold.
  ContactCache twice = cache;
  std::vector<std::uint8_t> kept, loaded_flags;
  std::vector<Contact> light = next, heavy = next;
  twice.restore(light, bodies, real(1e-6), kept, &loaded_flags);
  twice.restore(heavy, bodies, real(1e3), kept, &loaded_flags);
  EXPECT_TRUE(same(heavy, restored_heavy)) << "the second restore as a fresh cache's";
}

namespace {

// Every array of two sets of sweep records, n of them, byte for byte.
bool same_records(const SweepRecords& x, const SweepRecords& y, std::size_t n, bool friction, bool rolling) {
  auto same = [n](const auto* p, const auto* q) {
    return (p == nullptr) == (q == nullptr) && (!p || std::memcmp(p, q, n * sizeof(*p)) == 0);
  };
  return (friction ? same(x.impulse, y.impulse) : same(x.normal, y.normal)) &&
         (!rolling || same(x.rolling, y.rolling)) && same(x.geometry, y.geometry) && same(x.arms, y.arms) &&
         same(x.extra, y.extra) && same(x.bodies, y.bodies);
}

}  // namespace

// The CPU step's contacts as found (FoundContact: the bodies, normal,
// separation and restored impulses; whole_contact makes the arms, the
// coefficients and a wall's surface velocity again as the records are made)
// give the records whole contacts give, bit for bit, through the search,
// the restore (with and without lost loads), the colouring and the records'
// making: a thrown lattice of mixed radii and three materials among walls of
// every kind, moving and spinning, on 1 and 2 threads.
TEST(FoundContacts, RecordsEqualThoseOfWholeContacts) {
  const real r = real(0.01), h = real(1e-3);
  std::mt19937_64 rng(43);
  MovingLattice thrown = MovingLattice::thrown(22, r, rng);
  std::uniform_real_distribution<double> u(0.97, 1.03), c(0.05, 0.9);
  Lattice& l = thrown.lattice;
  for (std::size_t i = 0; i < l.n; ++i) {
    l.radius[i] = real(r * u(rng));
    l.material[i] = static_cast<std::uint32_t>(i % 3);
  }
  std::vector<PairCoefficients> coefficients(9);
  for (PairCoefficients& k : coefficients)
    k = {real(c(rng)), real(c(rng)), real(0.05 * c(rng)), real(0.05 * c(rng))};
  const PairTable table{coefficients.data(), 3};
  const real side = real(2 * r * 1.002 * 21);
  Walls walls;
  walls.planes.push_back({{0, 0, real(0.001 * r)}, {0, 0, 1}, 0, {0, 0, real(0.3)}});
  walls.boxes.push_back({{0, 0, 0}, {side, side, 1}, 1, {real(0.2), real(-0.1), 0}});
  walls.cylinders.push_back({{side / 2, side / 2, 0}, {0, 0, 1}, real(0.64 * side), 1, true, real(3), 2});
  walls.spheres.push_back({{side / 2, side / 2, side + real(0.02)}, real(0.04), 2, {0, 0, real(-0.5)}});
  const std::vector<WallShape> shapes = wall_shapes(walls);
  const BodiesView bodies = thrown.view();
  const std::vector<real> reaches(bodies.count, real(0.1) * r);

  SolverSettings settings;
  settings.friction = settings.rolling = true;
  const int was = thread_count();
  std::size_t cold_seen = 0, walls_seen = 0;
  for (int threads : {1, 2}) {
    set_thread_count(threads);
    // The search both ways, as the CPU step runs it (its runs, walls last).
    std::vector<Contact> first, rest;
    std::vector<FoundContact> found_first, found_rest;
    ContactScratch scratch, found_scratch;
    sphere_contacts(bodies, l.pairs.data(), l.pairs.size(), table, h, reaches.data(), first, rest, scratch);
    wall_contacts(bodies, shapes, table, h, reaches.data(), rest.empty() ? first : rest, &scratch);
    sphere_contacts(bodies, l.pairs.data(), l.pairs.size(), table, h, reaches.data(), found_first, found_rest,
                    found_scratch);
    wall_contacts(bodies, shapes, table, h, reaches.data(), found_rest.empty() ? found_first : found_rest,
                  &found_scratch);
    ASSERT_EQ(found_first.size(), first.size());
    ASSERT_EQ(found_rest.size(), rest.size());
    const std::size_t n = first.size() + rest.size();
    ASSERT_GT(n, l.pairs.size() / 10) << "premise: many contacts";
    std::size_t on_walls = 0;
    for (const std::vector<Contact>* run : {&first, &rest})
      for (const Contact& k : *run) on_walls += is_wall(k.b) ? 1 : 0;
    ASSERT_GT(on_walls, 100u) << "premise: contacts on the walls";
    walls_seen = on_walls;

    // A cache of these contacts with loads; then the contacts again, every
    // 5th of each run gone (its entry unmatched: a lost load under the tiny
    // weight).
    std::vector<Contact> stored(first);
    stored.insert(stored.end(), rest.begin(), rest.end());
    ColourRanges stored_colours;
    ContactColouring().colour_and_sort(stored, bodies.count, stored_colours);
    give_random_loads(stored, rng);
    ContactCache cache;
    cache.store(stored, stored_colours);
    for (const real weight : {real(1e3), real(1e-6)}) {
      std::vector<Contact> f1 = first, r1 = rest;
      std::vector<FoundContact> f2 = found_first, r2 = found_rest;
      auto drop = [](auto& v) {
        std::size_t at = 0;
        for (std::size_t k = 0; k < v.size(); ++k)
          if (k % 5 != 2) v[at++] = v[k];
        v.resize(at);
      };
      drop(f1), drop(r1), drop(f2), drop(r2);
      const std::size_t m = f1.size() + r1.size();
      ContactCache a = cache, b = cache;
      std::vector<std::uint8_t> kept_a, kept_b, loaded_a, loaded_b;
      const std::size_t warm_a =
          a.restore(ContactRuns(f1.data(), f1.size(), r1.data()), m, bodies, weight, kept_a, &loaded_a);
      const std::size_t warm_b =
          b.restore(FoundRuns(f2.data(), f2.size(), r2.data()), m, bodies, weight, kept_b, &loaded_b);
      EXPECT_EQ(warm_a, warm_b) << threads << " thread(s), weight " << weight;
      EXPECT_EQ(kept_a, kept_b);
      EXPECT_EQ(loaded_a, loaded_b);
      for (std::size_t k = 0; k < m; ++k) {
        const Contact& x = k < f1.size() ? f1[k] : r1[k - f1.size()];
        const FoundContact y = k < f2.size() ? f2[k] : r2[k - f2.size()];
        const FoundContact fx = found_of(x);
        ASSERT_EQ(std::memcmp(&fx, &y, sizeof(FoundContact)), 0) << "contact " << k << " as restored";
        if (weight < 1 && x.normal_impulse == 0 && kept_a[k] != kNoKeptColour) ++cold_seen;
      }
      std::vector<std::uint64_t> masks_a, masks_b;
      const std::uint32_t colours_a = a.kept_masks(bodies.count, masks_a);
      const std::uint32_t colours_b = b.kept_masks(bodies.count, masks_b);
      const KeptMasks km_a{masks_a.data(), colours_a}, km_b{masks_b.data(), colours_b};
      ContactColouring colouring_a, colouring_b;
      ColourRanges ranges_a, ranges_b;
      colouring_a.colour_and_place(Runs<const Contact>(ContactRuns(f1.data(), f1.size(), r1.data())), m,
                                   bodies.count, ranges_a, kept_a.data(), loaded_a.data(), &km_a);
      colouring_b.colour_and_place(Runs<const FoundContact>(FoundRuns(f2.data(), f2.size(), r2.data())), m,
                                   bodies.count, ranges_b, kept_b.data(), loaded_b.data(), &km_b);
      ASSERT_EQ(ranges_a.begin, ranges_b.begin);
      ASSERT_EQ(ranges_a.record, ranges_b.record);
      ASSERT_EQ(std::memcmp(colouring_a.places(), colouring_b.places(), m * sizeof(std::uint32_t)), 0);
      ContactSolver solver_a(settings), solver_b(settings);
      solver_a.make_records(Runs<const Contact>(ContactRuns(f1.data(), f1.size(), r1.data())),
                            colouring_a.places(), ranges_a, bodies);
      solver_b.make_records(Runs<const FoundContact>(FoundRuns(f2.data(), f2.size(), r2.data())),
                            colouring_b.places(), ranges_b, bodies, table, shapes);
      ASSERT_NE(solver_a.made_records(), nullptr);
      ASSERT_NE(solver_b.made_records(), nullptr);
      EXPECT_TRUE(same_records(*solver_a.made_records(), *solver_b.made_records(), m, true, true))
          << threads << " thread(s), weight " << weight;
      EXPECT_EQ(ranges_a.fast_approach, ranges_b.fast_approach);
      std::vector<Contact> whole_a, whole_b;
      solver_a.contacts_of_records(ranges_a, bodies, table, shapes, whole_a);
      solver_b.contacts_of_records(ranges_b, bodies, table, shapes, whole_b);
      ASSERT_EQ(whole_a.size(), whole_b.size());
      EXPECT_EQ(std::memcmp(whole_a.data(), whole_b.data(), whole_a.size() * sizeof(Contact)), 0)
          << "the whole contacts of the records";
    }
  }
  set_thread_count(was);
  EXPECT_GT(cold_seen, 0u) << "premise: the island rule set some kept contacts cold";
  EXPECT_GT(walls_seen, 0u);
}
