// Tests of the order study (bench/order_study.hpp): its tiles' machinery
// (one tile holding every contact and swept once a pass issues the plain
// order's updates: the same bits; small tiles do not), and on columns
// in a box, whose static solution is known (every speed 0, the floor under
// the whole weight), more sweeps of the solver's order leave less undone.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <string>

#include <unistd.h>

#include "bench/order_study.hpp"

namespace os = marbles::order_study;

TEST(OrderStudy, OneTileSweptOnceAPassIsTheSolversOrder) {
  for (const bool rolling : {false, true})
  for (const os::PileKind kind : {os::PileKind::cubic, os::PileKind::close_packed}) {
    SCOPED_TRACE(rolling ? "rolling resistance" : "friction");
    os::Pile pile = os::make_pile(kind, 6, 5, rolling);
    ASSERT_GT(pile.contacts.size(), 100u);
    const os::Result solver = os::run({"solver 5", 5, 0, 0}, pile, 4);
    const os::Result one_tile = os::run({"local 5x1, one tile", 5, 1, 1000}, pile, 4);
    EXPECT_EQ(one_tile.tiles, 1u);
    EXPECT_EQ(one_tile.between, 0.0);
    ASSERT_EQ(one_tile.velocity.size(), solver.velocity.size());
    EXPECT_EQ(std::memcmp(one_tile.velocity.data(), solver.velocity.data(),
                          solver.velocity.size() * sizeof(marbles::Vec3)),
              0)
        << "the same updates in the same order";
    // Small tiles: another order, other bits, contacts between tiles.
    const os::Result tiles = os::run({"local 5x1 tile 2", 5, 1, 2}, pile, 4);
    EXPECT_GT(tiles.tiles, 1u);
    EXPECT_GT(tiles.between, 0.0);
    EXPECT_NE(std::memcmp(tiles.velocity.data(), solver.velocity.data(),
                          solver.velocity.size() * sizeof(marbles::Vec3)),
              0);
  }
}

TEST(OrderStudy, MoreSweepsLeaveLessUndoneOnColumns) {
  os::Pile pile = os::make_pile(os::PileKind::cubic, 8, 12);
  double last_rms = 2, last_floor = -1;
  for (const int sweeps : {1, 3, 10, 30}) {
    const os::Result res = os::run({"solver", sweeps, 0, 0}, pile, 20);
    EXPECT_LT(res.rms, last_rms) << sweeps << " sweeps";
    EXPECT_GT(res.floor_ratio, last_floor) << sweeps << " sweeps";
    EXPECT_LE(res.floor_ratio, 1.001) << sweeps << " sweeps: the floor carries no more than the weight";
    last_rms = res.rms, last_floor = res.floor_ratio;
  }
  EXPECT_LT(last_rms, 0.05) << "thirty sweeps a substep bring twelve layers near rest";
  EXPECT_GT(last_floor, 0.95);
}

// The order by height: one band above the whole pile holds every contact
// in the colouring's colour-major order, so it sweeps as the solver does
// (the same bits); by height alone, or in thin bands, it is another order.
TEST(OrderStudy, OneHeightBandIsTheSolversOrder) {
  for (const os::PileKind kind : {os::PileKind::cubic, os::PileKind::close_packed}) {
    os::Pile pile = os::make_pile(kind, 6, 5);
    const os::Result solver = os::run({"solver 5", 5, 0, 0}, pile, 4);
    const os::Result one_band = os::run({"bands 1000 x 5", 5, 0, 0, 1000}, pile, 4);
    ASSERT_EQ(one_band.velocity.size(), solver.velocity.size());
    EXPECT_EQ(std::memcmp(one_band.velocity.data(), solver.velocity.data(),
                          solver.velocity.size() * sizeof(marbles::Vec3)),
              0)
        << "the same updates in the same order";
    for (const int band : {0, 1}) {
      const os::Result other = os::run({"height", 5, 0, 0, band}, pile, 4);
      EXPECT_NE(std::memcmp(other.velocity.data(), solver.velocity.data(),
                            solver.velocity.size() * sizeof(marbles::Vec3)),
                0)
          << "band " << band;
      EXPECT_LE(other.floor_ratio, 1.001) << "band " << band;
    }
  }
}

// Over-relaxation: the relaxed masses with omega 1 are the solver's, bit
// for bit (the same steps, times 1); with another omega, other bits.
TEST(OrderStudy, RelaxedByOneIsTheSolversUpdate) {
  for (const bool rolling : {false, true}) {
    os::Pile pile = os::make_pile(os::PileKind::close_packed, 6, 5, rolling);
    const os::Result solver = os::run({"solver 5", 5, 0, 0}, pile, 4);
    os::Order relaxed{"relaxed", 5, 0, 0, -1, 1.0};
    const os::Result same = os::run(relaxed, pile, 4);
    EXPECT_EQ(std::memcmp(same.velocity.data(), solver.velocity.data(), solver.velocity.size() * sizeof(marbles::Vec3)),
              0);
    relaxed.omega = 1.5;
    const os::Result other = os::run(relaxed, pile, 4);
    EXPECT_NE(std::memcmp(other.velocity.data(), solver.velocity.data(), solver.velocity.size() * sizeof(marbles::Vec3)),
              0);
  }
}

// The benchmark's settled pile rests under the solver: held still in its
// box, enough sweeps bring every sphere near rest (its walls and floor are
// there: without them the side spheres would keep falling at g h), and more
// sweeps leave less undone.
TEST(OrderStudy, TheSettledPileComesToRest) {
  const std::filesystem::path cache =
      std::filesystem::temp_directory_path() / ("marbles-order-study-" + std::to_string(::getpid()));
  os::Pile pile = os::settled_pile(600, cache.string());
  std::filesystem::remove_all(cache);
  ASSERT_EQ(pile.world.size(), 600u);
  EXPECT_GT(pile.contacts.size(), 600u);
  double last_rms = 2;
  for (const int sweeps : {3, 10, 40}) {
    const os::Result res = os::run({"solver", sweeps, 0, 0}, pile, 60);
    EXPECT_LT(res.rms, last_rms) << sweeps << " sweeps";
    last_rms = res.rms;
  }
  // (Speeds in units of g h. Piles settled with 4 and 16 impact passes
  // left 0.019 and 0.023 after forty sweeps, 0.020 after eighty.)
  EXPECT_LT(last_rms, 0.03) << "forty sweeps a substep bring the settled pile to rest";
}

// Conjugate gradients over the solver's sweeps take no step after the last
// sweep, nor before two sweeps have given a ratio: with one or two sweeps
// (three where the step is taken within the sweeps) they are the solver's
// sweeps bit for bit; with one sweep more they step, and other bits follow.
TEST(OrderStudy, ConjugateGradientsStepOnlyBetweenSweeps) {
  os::Pile pile = os::make_pile(os::PileKind::cubic, 6, 8);
  auto same = [](const os::Result& a, const os::Result& b) {
    return a.velocity.size() == b.velocity.size() &&
           std::memcmp(a.velocity.data(), b.velocity.data(), a.velocity.size() * sizeof(marbles::Vec3)) == 0;
  };
  for (const int form : {1, 2, 3}) {
    SCOPED_TRACE(form == 1 ? "a pass of its own" : form == 2 ? "within the sweeps" : "the bodies by their own direction");
    const int plain = form == 2 ? 3 : 2;
    for (int passes = 1; passes <= plain; ++passes) {
      os::Order o{"nncg", passes, 0, 0};
      o.nncg = form;
      EXPECT_TRUE(same(os::run(o, pile, 6), os::run({"solver", passes, 0, 0}, pile, 6))) << passes << " sweeps";
    }
    os::Order o{"nncg", plain + 1, 0, 0};
    o.nncg = form;
    const os::Result stepped = os::run(o, pile, 6);
    EXPECT_FALSE(same(stepped, os::run({"solver", plain + 1, 0, 0}, pile, 6)));
    EXPECT_LE(stepped.floor_ratio, 1.001);
  }
}

// The step taken on the bodies by a direction of their own (the sum of
// their velocities' changes, as the impulses' direction sums the impulses')
// is the step taken through each contact's impulses, up to rounding: the
// same speeds left where the two are the same maths (no rolling resistance,
// whose impulses only the bodies' form steps). A cap of 0 never steps (the
// solver's bits) and a cap of 1 is no cap; a tail of plain sweeps as long
// as the solve never steps either.
TEST(OrderStudy, TheBodiesOwnDirectionStepsThemAsTheImpulsesDo) {
  os::Pile pile = os::make_pile(os::PileKind::cubic, 8, 12);
  os::Order through{"nncg", 6, 0, 0}, own{"nncg by bodies", 6, 0, 0};
  through.nncg = 1, own.nncg = 3;
  const os::Result a = os::run(through, pile, 20), b = os::run(own, pile, 20);
  const os::Result plain = os::run({"solver", 6, 0, 0}, pile, 20);
  ASSERT_EQ(a.velocity.size(), b.velocity.size());
  double most = 0, apart = 0;
  for (std::size_t i = 0; i < a.velocity.size(); ++i) {
    most = std::max(most, double(length(a.velocity[i] - b.velocity[i])));
    apart = std::max(apart, double(length(a.velocity[i] - plain.velocity[i])));
  }
  const double gh = 9.81 * 1e-3;  // the study's g h (kGravity, kSubstep)
  EXPECT_LT(most, 1e-3 * gh) << "the two forms of the step";
  EXPECT_GT(apart, 100 * most) << "both step, far from the solver's own sweeps";
  EXPECT_NEAR(a.rms, b.rms, 1e-3 * a.rms);
  for (const int form : {1, 3}) {
    os::Order capped{"nncg", 6, 0, 0};
    capped.nncg = form;
    capped.beta_cap = 0;
    const os::Result none = os::run(capped, pile, 20);
    EXPECT_EQ(0, std::memcmp(none.velocity.data(), plain.velocity.data(), plain.velocity.size() * sizeof(marbles::Vec3)))
        << "form " << form << " capped at 0";
    capped.beta_cap = 1;
    capped.tail = 6;
    const os::Result tail = os::run(capped, pile, 20);
    EXPECT_EQ(0, std::memcmp(tail.velocity.data(), plain.velocity.data(), plain.velocity.size() * sizeof(marbles::Vec3)))
        << "form " << form << " with no step before its last 6 sweeps";
    capped.tail = 1;
    const os::Result open = os::run(capped, pile, 20), uncapped = form == 1 ? a : b;
    EXPECT_EQ(0, std::memcmp(open.velocity.data(), uncapped.velocity.data(), open.velocity.size() * sizeof(marbles::Vec3)))
        << "form " << form << " capped at 1";
  }
}
