// The lanes sweep (solver_lanes.hpp) against its oracle, solve_one of
// solver_math.hpp, which the CUDA sweep runs: W contacts of one colour
// solved side by side must leave the contacts and the bodies bit for bit as
// solve_one leaves them contact by contact, for every effect set, on random
// contacts and on the edge cases of the branches the lanes turn into
// selects (a slip exactly at the friction limit, no slip, no load, walls,
// static bodies, signed zeros, subnormal values, gaps open and closed).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <type_traits>
#include <vector>

#include <signal.h>
#include <sys/mman.h>
#include <unistd.h>

#include "narrowphase/solver_lanes.hpp"

namespace marbles::narrowphase {
namespace {

constexpr std::uint32_t W = lanes::W;

bool same_bits(const void* a, const void* b, std::size_t n) { return std::memcmp(a, b, n) == 0; }

struct Case {
  std::vector<Contact> contacts;  // W of them, no sphere twice
  std::vector<SolverBody> bodies;
};

Vec3 unit(std::mt19937& rng) {
  std::normal_distribution<real> g(0, 1);
  for (;;) {
    const Vec3 v(g(rng), g(rng), g(rng));
    const real len = length(v);
    if (len > real(1e-3)) return v / len;
  }
}

// `count` contacts (W unless asked) on 2 count distinct spheres (some b
// walls); `edge` picks values from the branch boundaries instead of the bulk.
// `uniform` (not null): every contact takes its arms and friction
// coefficients from it, as contacts of one radius and one pair table entry
// have them (a wall's arm +0).
Case make_case(std::mt19937& rng, bool edge, std::uint32_t count = W, const UniformArms* uniform = nullptr) {
  std::uniform_real_distribution<real> u(-1, 1);
  std::uniform_int_distribution<int> pick(0, 7);
  Case out;
  const std::uint32_t spheres = 2 * count + 3;
  out.bodies.resize(spheres);
  for (SolverBody& b : out.bodies) {
    b.v = Vec3(u(rng), u(rng), u(rng));
    b.w = Vec3(u(rng), u(rng), u(rng)) * real(20);
    b.inv_mass = real(0.5) + u(rng) * real(0.4);
    b.inv_inertia = real(800) + u(rng) * real(300);
    if (edge) {
      switch (pick(rng)) {
        case 0: b.inv_mass = 0, b.inv_inertia = 0; break;  // static
        case 1: b.v = Vec3(-real(0), real(0), -real(0)), b.w = Vec3(real(0), -real(0), real(0)); break;
        case 2: b.v = Vec3(real(1e-39), -real(1e-40), real(0)); break;  // subnormal in float
        default: break;
      }
    }
  }
  std::vector<std::uint32_t> ids(spheres);
  std::iota(ids.begin(), ids.end(), 0u);
  std::shuffle(ids.begin(), ids.end(), rng);
  for (std::uint32_t l = 0; l < count; ++l) {
    Contact c;
    c.a = ids[2 * l];
    const bool wall = pick(rng) < 2;
    c.b = wall ? (kWallFlag | static_cast<std::uint32_t>(pick(rng))) : ids[2 * l + 1];
    c.normal = unit(rng);
    c.ra = real(0.01) + real(0.005) * u(rng);
    c.rb = wall ? real(0) : real(0.01) + real(0.005) * u(rng);
    c.wall_velocity = wall && pick(rng) < 4 ? Vec3(u(rng), 0, u(rng)) : Vec3{};
    c.separation = real(1e-3) * u(rng);
    c.normal_impulse = std::max(real(0), u(rng)) * real(1e-2);
    c.tangent_impulse = Vec3(u(rng), u(rng), u(rng)) * real(1e-3);
    c.rolling_impulse = Vec3(u(rng), u(rng), u(rng)) * real(1e-6);
    c.impact_impulse = u(rng);
    c.approach_speed = u(rng);
    u(rng);  // a draw kept where the contact had a per-contact impact word: the same cases as before
    c.coeff = {real(0.3), real(0.5) + real(0.4) * u(rng), real(0.05), real(0.02)};
    if (edge) {
      switch (pick(rng)) {
        case 0: c.separation = 0; break;
        case 1: c.normal_impulse = 0, c.tangent_impulse = {}, c.rolling_impulse = {}; break;  // no load: limits 0
        case 2: c.coeff.friction = 0, c.coeff.rolling_friction = 0, c.coeff.twisting_friction = 0; break;
        case 3: c.separation = -real(0); break;
        case 4: c.coeff.friction = real(1e6); break;  // never at the limit
        default: break;
      }
    }
    if (uniform) {
      c.ra = uniform->radius, c.rb = wall ? real(0) : uniform->radius;
      c.coeff.friction = uniform->friction, c.coeff.rolling_friction = uniform->rolling_friction;
    }
    prepare_one(c, out.bodies.data());
    out.contacts.push_back(c);
  }
  return out;
}

// Records of `count` contacts (W unless asked) in 64-byte-aligned host
// memory; without the arms array where `uniform` gives the arms.
struct RecordsMemory {
  std::uint32_t count;
  std::vector<unsigned char> bytes;
  explicit RecordsMemory(std::uint32_t n = W) : count(n), bytes(SweepRecords::bytes_for(n) + 64) {}
  SweepRecords records(const UniformArms* uniform = nullptr) {
    void* aligned = bytes.data() + (64 - reinterpret_cast<std::uintptr_t>(bytes.data()) % 64);
    return SweepRecords::in(aligned, count, true, uniform == nullptr, uniform ? *uniform : UniformArms{});
  }
};

// The arms of a uniform case: a radius, and coefficients from the friction
// limit's edges where `edge` (none, or never reached) or from the bulk.
UniformArms uniform_arms_of(std::mt19937& rng, bool edge) {
  std::uniform_real_distribution<real> u(-1, 1);
  const real friction[3] = {real(0.5) + real(0.4) * u(rng), real(0), real(1e6)};
  return {real(0.01) + real(0.005) * u(rng), friction[edge ? rng() % 3 : 0], real(0.02) + real(0.01) * u(rng)};
}

// A case twice: whole contacts, and the same packed into records (with
// `uniform`, contacts of one radius and one pair of coefficients, their
// records without arms).
struct PackedCase {
  Case whole, packed;
  RecordsMemory memory;
  SweepRecords records;
  PackedCase(std::uint32_t seed, bool edge, std::uint32_t count = W, bool uniform = false) : memory(count) {
    std::mt19937 rng(seed);
    const UniformArms arms = uniform ? uniform_arms_of(rng, edge) : UniformArms{};  // the other cases' draws as before
    whole = make_case(rng, edge, count, uniform ? &arms : nullptr);
    packed = whole;
    records = memory.records(uniform ? &arms : nullptr);
    for (std::uint32_t k = 0; k < count; ++k) pack_sweep_record(packed.contacts[k], records, k);
  }
};

// The 32-byte lanes (two L blocks joined; solver.cpp runs them compiled for
// AVX2 or AVX-512), compiled here for AVX2: called only where the CPU has it.
constexpr std::uint32_t WW = lanes::width<lanes::Wide>;
template <bool Friction, bool Rolling>
[[gnu::target("avx2")]] void solve_wide_block(const SweepRecords& s, SolverBody* bodies, real inv_h) {
  lanes::solve_block<Friction, Rolling, lanes::Wide>(s, 0, bodies, inv_h);
}

template <bool Friction, bool Rolling>
[[gnu::target("avx2")]] bool wide_all_idle(const SweepRecords& s, const SolverBody* bodies, real inv_h) {
  using V = lanes::Wide;
  return lanes::all_idle<Friction, Rolling>(lanes::load_records_of<Friction || Rolling, Rolling, V>(s, 0),
                                            lanes::load_bodies_of<V>(bodies, s, 0, false),
                                            lanes::load_bodies_of<V>(bodies, s, 0, true), inv_h);
}

// One block (W records, or WW with Wide) solved side by side against
// solve_one contact by contact on the whole contacts, over three sweeps:
// the impulses unpacked from the records and the bodies bit for bit.
template <bool Friction, bool Rolling, bool Wide = false>
void expect_lanes_equal_scalar(std::uint32_t seed, bool edge, bool uniform = false) {
  constexpr std::uint32_t count = Wide ? WW : W;
  PackedCase p(seed, edge, count, uniform);
  ASSERT_EQ(p.records.arms == nullptr, uniform);
  Case &scalar = p.whole, &block = p.packed;
  const real inv_h = real(1000);
  for (int sweep = 0; sweep < 3; ++sweep) {  // later sweeps start from clamped impulses
    for (Contact& c : scalar.contacts) solve_one<Friction, Rolling>(c, scalar.bodies.data(), inv_h);
    if constexpr (Wide) solve_wide_block<Friction, Rolling>(p.records, block.bodies.data(), inv_h);
    else lanes::solve_block<Friction, Rolling>(p.records, 0, block.bodies.data(), inv_h);
    for (std::uint32_t k = 0; k < count; ++k) unpack_sweep_impulses(p.records, k, block.contacts[k]);
    ASSERT_TRUE(same_bits(scalar.contacts.data(), block.contacts.data(), sizeof(Contact) * count))
        << "seed " << seed << " sweep " << sweep << (edge ? " (edge)" : "");
    ASSERT_TRUE(same_bits(scalar.bodies.data(), block.bodies.data(), sizeof(SolverBody) * scalar.bodies.size()))
        << "seed " << seed << " sweep " << sweep << (edge ? " (edge)" : "");
  }
}

// check.template operator()<Friction, Rolling>(seed, edge) for seeds
// 1..seeds, plain and edge cases, every combination of the two terms.
template <class Check>
void over_cases(std::uint32_t seeds, Check&& check) {
  for (std::uint32_t seed = 1; seed <= seeds; ++seed)
    for (bool edge : {false, true}) {
      check.template operator()<true, true>(seed, edge);
      check.template operator()<true, false>(seed, edge);
      check.template operator()<false, true>(seed, edge);
      check.template operator()<false, false>(seed, edge);
    }
}

TEST(SolverLanes, EqualSolveOneBitForBit) {
  over_cases(400, []<bool F, bool R>(std::uint32_t seed, bool edge) { expect_lanes_equal_scalar<F, R>(seed, edge); });
}

// The test above can fail: a lane that differs from its scalar twin in one
// operation (here one bit of an impulse) is seen.
TEST(SolverLanes, TheComparisonSeesOneBit) {
  PackedCase p(7, false);
  p.records.impulse[W - 1].x = std::nextafter(p.records.impulse[W - 1].x, real(1));
  for (Contact& c : p.whole.contacts) solve_one<true, true>(c, p.whole.bodies.data(), real(1000));
  lanes::solve_block<true, true>(p.records, 0, p.packed.bodies.data(), real(1000));
  for (std::uint32_t k = 0; k < W; ++k) unpack_sweep_impulses(p.records, k, p.packed.contacts[k]);
  EXPECT_FALSE(same_bits(p.whole.contacts.data(), p.packed.contacts.data(), sizeof(Contact) * W));
}

TEST(SolverLanes, WideLanesEqualSolveOneBitForBit) {
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "skipped: this CPU has no AVX2";
  static_assert(WW == 2 * W);
  over_cases(400, []<bool F, bool R>(std::uint32_t seed, bool edge) { expect_lanes_equal_scalar<F, R, true>(seed, edge); });
}

// It can fail: one bit of the high half's first contact is seen.
TEST(SolverLanes, TheWideComparisonSeesOneBit) {
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "skipped: this CPU has no AVX2";
  PackedCase p(5, false, WW);
  p.records.impulse[W].x = std::nextafter(p.records.impulse[W].x, real(1));
  for (Contact& c : p.whole.contacts) solve_one<true, true>(c, p.whole.bodies.data(), real(1000));
  solve_wide_block<true, true>(p.records, p.packed.bodies.data(), real(1000));
  for (std::uint32_t k = 0; k < WW; ++k) unpack_sweep_impulses(p.records, k, p.packed.contacts[k]);
  EXPECT_FALSE(same_bits(p.whole.contacts.data(), p.packed.contacts.data(), sizeof(Contact) * WW));
}

// Records without arms (every contact of one radius and one pair of
// coefficients: SweepRecords::uniform, as the CPU step and the GPU make
// them where that holds) solve as the whole contacts do, in both widths;
// a wall's lane takes the arm +0.
TEST(SolverLanes, UniformArmsEqualSolveOneBitForBit) {
  over_cases(200, []<bool F, bool R>(std::uint32_t seed, bool edge) { expect_lanes_equal_scalar<F, R>(seed, edge, true); });
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "skipped: this CPU has no AVX2";
  over_cases(200, []<bool F, bool R>(std::uint32_t seed, bool edge) {
    expect_lanes_equal_scalar<F, R, true>(seed, edge, true);
  });
}

// It can fail: the uniform radius a millionth off, or a wall's arm taken
// as a sphere's, is seen in either width.
TEST(SolverLanes, UniformArmsComparisonSeesOneBit) {
  auto differs = [](std::uint32_t count, auto&& change) {
    // The first case with a wall among its contacts.
    std::uint32_t seed = 1;
    auto has_wall = [&] {
      const PackedCase p(seed, false, count, true);
      return std::any_of(p.whole.contacts.begin(), p.whole.contacts.end(), [](const Contact& c) { return is_wall(c.b); });
    };
    while (!has_wall()) ++seed;
    PackedCase p(seed, false, count, true);
    change(p);
    for (Contact& c : p.whole.contacts) solve_one<true, true>(c, p.whole.bodies.data(), real(1000));
    if (count == W) lanes::solve_block<true, true>(p.records, 0, p.packed.bodies.data(), real(1000));
    else solve_wide_block<true, true>(p.records, p.packed.bodies.data(), real(1000));
    for (std::uint32_t k = 0; k < count; ++k) unpack_sweep_impulses(p.records, k, p.packed.contacts[k]);
    return !same_bits(p.whole.contacts.data(), p.packed.contacts.data(), sizeof(Contact) * count) ||
           !same_bits(p.whole.bodies.data(), p.packed.bodies.data(), sizeof(SolverBody) * p.whole.bodies.size());
  };
  auto radius_off = [](PackedCase& p) { p.records.uniform.radius *= real(1 + 1e-6); };
  // The oracle's walls given a sphere's arm (the rolling resistance's
  // radius then differs): the lanes, which give them +0, part from it.
  auto walls_as_spheres = [](PackedCase& p) {
    int walls = 0;
    for (Contact& c : p.whole.contacts)
      if (is_wall(c.b)) c.rb = p.records.uniform.radius, ++walls;
    ASSERT_GT(walls, 0);
  };
  EXPECT_TRUE(differs(W, radius_off));
  EXPECT_TRUE(differs(W, walls_as_spheres));
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "skipped: this CPU has no AVX2";
  EXPECT_TRUE(differs(WW, radius_off));
  EXPECT_TRUE(differs(WW, walls_as_spheres));
}

// The grouped moves (float: 4 x 4 transposes of record words and body
// records) move the same fields as the field-by-field forms, both ways.
TEST(SolverLanes, GroupedMovesEqualFieldByField) {
  int stored = 0;  // cases whose stores changed some body (not every lane of a side b is a wall)
  for (std::uint32_t seed = 1; seed <= 50; ++seed) {
    PackedCase p(seed, seed % 2 == 0);
    const SweepRecords& s = p.records;
    const lanes::ContactLanes grouped = lanes::load_records<true, true>(s, 0);
    const lanes::ContactLanes each = lanes::load_records_each<true, true>(s, 0);
    ASSERT_TRUE(same_bits(&grouped, &each, sizeof grouped)) << seed;
    for (bool side_b : {false, true}) {
      const lanes::BodyLanes g = lanes::load_bodies(p.packed.bodies.data(), s, 0, side_b);
      const lanes::BodyLanes e = lanes::load_bodies_each(p.packed.bodies.data(), s, 0, side_b);
      ASSERT_TRUE(same_bits(&g, &e, sizeof g)) << seed << " side " << side_b;
      // Stored back through either form, changed: the same bodies.
      lanes::BodyLanes changed = g;
      changed.v.x = changed.v.x + real(1), changed.w.z = changed.w.z - real(2);
      std::vector<SolverBody> by_group = p.packed.bodies, by_field = p.packed.bodies;
      lanes::store_bodies(by_group.data(), s, 0, side_b, changed);
      lanes::store_bodies_each(by_field.data(), s, 0, side_b, changed);
      ASSERT_TRUE(same_bits(by_group.data(), by_field.data(), sizeof(SolverBody) * by_group.size())) << seed;
      stored += same_bits(by_group.data(), p.packed.bodies.data(), sizeof(SolverBody) * by_group.size()) ? 0 : 1;
    }
    RecordsMemory other;
    const SweepRecords t = other.records();
    lanes::ContactLanes changed = grouped;
    changed.normal_impulse = changed.normal_impulse + real(1);
    lanes::store_record_impulses<true>(changed, s, 0);
    lanes::store_record_impulses_each<true>(changed, t, 0);
    ASSERT_TRUE(same_bits(s.impulse, t.impulse, sizeof(Real4) * W)) << seed;
    ASSERT_TRUE(same_bits(s.rolling, t.rolling, sizeof(Real4) * W)) << seed;
  }
  EXPECT_GT(stored, 75);  // of 100
}

#if !defined(MARBLES_DOUBLE)
// The wide moves (eight contacts a 32-byte vector, transposed within
// halves: lane i holds contact kWideLane[i]) move the same fields as the
// field-by-field forms of the baseline, lane for contact, both ways; and
// every contact of a block lands in one lane.
// Each vector of a structure of lanes moved from kWideLane's order to the
// contacts' (to_contacts), or back.
template <class Lanes>
Lanes reordered(const Lanes& from, bool to_contacts) {
  constexpr std::size_t fields = sizeof(Lanes) / sizeof(lanes::Wide);
  lanes::Wide in[fields], out[fields];
  std::memcpy(in, &from, sizeof from);
  for (std::size_t f = 0; f < fields; ++f)
    for (std::uint32_t l = 0; l < WW; ++l) {
      const std::uint32_t c = lanes::kWideLane[l];
      if (to_contacts) out[f][c] = in[f][l];
      else out[f][l] = in[f][c];
    }
  Lanes to;
  std::memcpy(&to, out, sizeof to);
  return to;
}
template <class Lanes>
Lanes lane_to_contact_order(const Lanes& wide) {
  return reordered(wide, true);
}
template <class Lanes>
Lanes contact_to_lane_order(const Lanes& ordered) {
  return reordered(ordered, false);
}
// Two L blocks' fields (contacts 0-3, then 4-7) joined, in the contacts' order.
template <class Wide, class Half>
Wide joined(const Half& lo, const Half& hi) {
  constexpr std::size_t fields = sizeof(Half) / sizeof(lanes::L);
  lanes::L a[fields], b[fields];
  lanes::Wide out[fields];
  std::memcpy(a, &lo, sizeof lo);
  std::memcpy(b, &hi, sizeof hi);
  for (std::size_t f = 0; f < fields; ++f)
    for (std::uint32_t l = 0; l < W; ++l) out[f][l] = a[f][l], out[f][W + l] = b[f][l];
  Wide w;
  std::memcpy(&w, out, sizeof w);
  return w;
}
[[gnu::target("avx2")]] lanes::ContactLanes<lanes::Wide> wide_records(const SweepRecords& s) {
  return lanes::load_records_of<true, true, lanes::Wide>(s, 0);
}
[[gnu::target("avx2")]] lanes::BodyLanes<lanes::Wide> wide_bodies(const SolverBody* b, const SweepRecords& s,
                                                                   bool side_b) {
  return lanes::load_bodies_of<lanes::Wide>(b, s, 0, side_b);
}
[[gnu::target("avx2")]] void store_wide(SolverBody* b, const SweepRecords& s, bool side_b,
                                        const lanes::BodyLanes<lanes::Wide>& lanes_in) {
  lanes::store_bodies_of<lanes::Wide>(b, s, 0, side_b, lanes_in);
}
[[gnu::target("avx2")]] void store_wide_impulses(const lanes::ContactLanes<lanes::Wide>& c, const SweepRecords& s) {
  lanes::store_record_impulses_of<true, lanes::Wide>(c, s, 0);
}

TEST(SolverLanes, WideMovesEqualFieldByField) {
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "skipped: this CPU has no AVX2";
  static_assert(sizeof(lanes::kWideLane) / sizeof(lanes::kWideLane[0]) == WW);
  std::uint32_t seen = 0;  // every contact in some lane
  for (std::uint32_t l = 0; l < WW; ++l) seen |= 1u << lanes::kWideLane[l];
  ASSERT_EQ(seen, (1u << WW) - 1);
  using CW = lanes::ContactLanes<lanes::Wide>;
  using BW = lanes::BodyLanes<lanes::Wide>;
  int stored = 0;
  for (std::uint32_t seed = 1; seed <= 50; ++seed) {
    PackedCase p(seed, seed % 2 == 0, WW);
    const SweepRecords& s = p.records;
    const CW each = joined<CW>(lanes::load_records_each<true, true>(s, 0), lanes::load_records_each<true, true>(s, W));
    const CW wide = lane_to_contact_order(wide_records(s));
    ASSERT_TRUE(same_bits(&wide, &each, sizeof wide)) << seed;
    for (bool side_b : {false, true}) {
      const SolverBody* bodies = p.packed.bodies.data();
      const BW e =
          joined<BW>(lanes::load_bodies_each(bodies, s, 0, side_b), lanes::load_bodies_each(bodies, s, W, side_b));
      const BW g = lane_to_contact_order(wide_bodies(bodies, s, side_b));
      ASSERT_TRUE(same_bits(&g, &e, sizeof g)) << seed << " side " << side_b;
      // Changed and stored back through either form: the same bodies.
      BW changed = e;
      changed.v.x = changed.v.x + real(1), changed.w.z = changed.w.z - real(2);
      changed.inv_mass = changed.inv_mass * real(3);
      std::vector<SolverBody> by_wide = p.packed.bodies, by_field = p.packed.bodies;
      store_wide(by_wide.data(), s, side_b, contact_to_lane_order(changed));
      const lanes::BodyLanes<lanes::L> lo{lanes::low(changed.v), lanes::low(changed.w), lanes::low(changed.inv_mass),
                                          lanes::low(changed.inv_inertia)};
      const lanes::BodyLanes<lanes::L> hi{lanes::high(changed.v), lanes::high(changed.w),
                                          lanes::high(changed.inv_mass), lanes::high(changed.inv_inertia)};
      lanes::store_bodies_each(by_field.data(), s, 0, side_b, lo);
      lanes::store_bodies_each(by_field.data(), s, W, side_b, hi);
      ASSERT_TRUE(same_bits(by_wide.data(), by_field.data(), sizeof(SolverBody) * by_wide.size())) << seed;
      stored += same_bits(by_wide.data(), p.packed.bodies.data(), sizeof(SolverBody) * by_wide.size()) ? 0 : 1;
    }
    RecordsMemory other(WW);
    const SweepRecords t = other.records();
    CW changed = each;
    changed.normal_impulse = changed.normal_impulse + real(1);
    changed.twisting_friction = changed.twisting_friction * real(2);
    store_wide_impulses(contact_to_lane_order(changed), s);
    lanes::ContactLanes<lanes::L> lo{}, hi{};
    lo.normal_impulse = lanes::low(changed.normal_impulse), hi.normal_impulse = lanes::high(changed.normal_impulse);
    lo.tangent_impulse = lanes::low(changed.tangent_impulse), hi.tangent_impulse = lanes::high(changed.tangent_impulse);
    lo.rolling_impulse = lanes::low(changed.rolling_impulse), hi.rolling_impulse = lanes::high(changed.rolling_impulse);
    lo.twisting_friction = lanes::low(changed.twisting_friction);
    hi.twisting_friction = lanes::high(changed.twisting_friction);
    lanes::store_record_impulses_each<true>(lo, t, 0);
    lanes::store_record_impulses_each<true>(hi, t, W);
    ASSERT_TRUE(same_bits(s.impulse, t.impulse, sizeof(Real4) * WW)) << seed;
    ASSERT_TRUE(same_bits(s.rolling, t.rolling, sizeof(Real4) * WW)) << seed;
  }
  EXPECT_GT(stored, 75);  // of 100
}
#endif  // the wide moves are float's (in double a Wide block is two L blocks joined)

// The GPU's sweep on the sweep's records (solver_math.hpp): the contacts
// packed, swept through solve_record (the effective masses computed from the
// bodies, not read), and unpacked must equal solve_one on the whole prepared
// contacts, contacts and bodies bit for bit (the fields it leaves out are the
// ones no sweep reads).
template <bool Friction, bool Rolling>
void expect_records_equal_contacts(std::uint32_t seed, bool edge) {
  PackedCase p(seed, edge);
  Case &whole = p.whole, &packed = p.packed;
  const SweepRecords& records = p.records;
  const real inv_h = real(1000);
  for (int sweep = 0; sweep < 3; ++sweep)
    for (std::uint32_t k = 0; k < W; ++k) {
      solve_one<Friction, Rolling>(whole.contacts[k], whole.bodies.data(), inv_h);
      solve_record<Friction, Rolling>(records, k, packed.bodies.data(), inv_h);
    }
  for (std::uint32_t k = 0; k < W; ++k) unpack_sweep_impulses(records, k, packed.contacts[k]);
  ASSERT_TRUE(same_bits(whole.contacts.data(), packed.contacts.data(), sizeof(Contact) * W))
      << "seed " << seed << (edge ? " (edge)" : "");
  ASSERT_TRUE(same_bits(whole.bodies.data(), packed.bodies.data(), sizeof(SolverBody) * whole.bodies.size()))
      << "seed " << seed << (edge ? " (edge)" : "");
}

TEST(SweepRecords, SweepOnTheRecordsEqualsSolveOneBitForBit) {
  over_cases(200, []<bool F, bool R>(std::uint32_t seed, bool edge) { expect_records_equal_contacts<F, R>(seed, edge); });
}

// Contacts that carry no impulse (+0), their gaps open and their spheres
// moving at random: about half are given none by their update (idle), the
// rest approach faster than their gap allows. `zeros`: some velocity
// components are +0 or -0.
Case unloaded_case(std::mt19937& rng, bool zeros) {
  std::uniform_real_distribution<real> u(-1, 1);
  std::uniform_int_distribution<int> pick(0, 5);
  Case c = make_case(rng, false);
  for (SolverBody& b : c.bodies)
    for (real* x : {&b.v.x, &b.v.y, &b.v.z, &b.w.x, &b.w.y, &b.w.z})
      if (zeros && pick(rng) == 0) *x = pick(rng) < 3 ? real(0) : -real(0);
  for (Contact& k : c.contacts) {
    k.normal_impulse = 0, k.tangent_impulse = {}, k.rolling_impulse = {};
    k.separation = real(2e-4) + real(2e-4) * u(rng);  // allows 0.2-0.6 m/s of approach at h = 1 ms
    prepare_one(k, c.bodies.data());
  }
  return c;
}

// What solve_loaded leaves unwritten is what an update changed no bit of:
// the impulses, where they were and are +0 (impulses_clear: the same bits by
// its definition), and a body loaded without a -0 velocity component
// (has_minus_zero), compared with the update written back, on random and
// signed-zero cases, every effect set. Not a vacuous pass: most updates of
// these unloaded contacts are clear, which takes clamp_length's +0 (without
// it the tangential impulse of an idle contact is a -0 about every other
// time, and it is no longer clear).
template <bool Friction, bool Rolling>
void expect_unwritten_means_unchanged(int& clear_updates, int& kept_bodies) {
  for (std::uint32_t seed = 1; seed <= 300; ++seed)
    for (bool zeros : {false, true}) {
      std::mt19937 rng(seed);
      Case start = unloaded_case(rng, zeros);
      for (Contact c : start.contacts) {
        BodyState A = load_body(start.bodies.data(), c.a, c), B = load_body(start.bodies.data(), c.b, c);
        const BodyState A0 = A, B0 = B;
        const bool was_clear = impulses_clear<Friction, Rolling>(c);
        set_masses<Friction, Rolling>(c, A, B);
        solve_states<Friction, Rolling>(c, A, B, real(1000));
        const bool clear = was_clear && impulses_clear<Friction, Rolling>(c);
        clear_updates += clear ? 1 : 0;
        for (auto [now, before] : {std::pair{&A, &A0}, std::pair{&B, &B0}}) {
          if (!clear || has_minus_zero(*before)) continue;
          ++kept_bodies;
          ASSERT_TRUE(same_bits(&now->v, &before->v, sizeof(Vec3)) && same_bits(&now->w, &before->w, sizeof(Vec3)))
              << "seed " << seed << (zeros ? " (zeros)" : "");
        }
      }
    }
}

TEST(SweepRecords, WhatIsNotWrittenBackIsUnchanged) {
  int clear = 0, kept = 0;
  expect_unwritten_means_unchanged<true, true>(clear, kept);
  expect_unwritten_means_unchanged<true, false>(clear, kept);
  expect_unwritten_means_unchanged<false, true>(clear, kept);
  expect_unwritten_means_unchanged<false, false>(clear, kept);
  const int updates = 4 * 300 * 2 * static_cast<int>(W);
  EXPECT_GT(clear, updates / 2) << "of " << updates;  // 61 %; 24 % with the clamps' -0 left in
  EXPECT_GT(kept, clear / 2) << clear << " clear updates";
}

// Velocities so small that a tangential impulse made of them has a squared
// length that underflows to 0 (clamp_length must still clamp it to +0
// under a zero limit): about half the square root of the smallest real.
real underflowing_speed() { return real(0.5) * std::sqrt(std::numeric_limits<real>::denorm_min()); }
void make_tiny(std::vector<SolverBody>& bodies) {
  for (SolverBody& b : bodies) b.v = b.v * underflowing_speed(), b.w = b.w * underflowing_speed();
}

// The idle rule of lanes::all_idle (solver_lanes.hpp) for one contact, the
// scalar oracle its lanes are held to: impulses +0, no -0 velocity
// component in either body, a normal slack >= 0.
template <bool Friction, bool Rolling>
bool known_idle(const Contact& c, const BodyState& A, const BodyState& B, real inv_h) {
  return impulses_clear<Friction, Rolling>(c) && !has_minus_zero(A) && !has_minus_zero(B) &&
         normal_slack(c, A, B, inv_h) >= 0;
}

// known_idle against the whole update: where it says idle, the effective
// masses and the three terms change no bit of the impulses or of either body.
// Cases: unloaded contacts (gaps open, spheres moving at random, with and
// without signed-zero velocity components, and moving so slowly that their
// tangential impulses' squared lengths underflow) and make_case's edge cases
// (static bodies, walls, subnormal and signed-zero velocities, gaps of +0 and
// -0, friction 0 and 10^6). Counts the updates it calls idle, and for each of
// its conditions the updates where that one alone fails and the update does
// change a bit (the condition is needed: without it the test would fail).
struct IdleCounts {
  int updates = 0, idle = 0, needs_clear = 0, needs_no_minus_zero = 0, needs_slack = 0;
};
bool update_changes_a_bit(Contact c, BodyState A, BodyState B, real inv_h, bool friction, bool rolling) {
  const Contact c0 = c;
  const BodyState A0 = A, B0 = B;
  auto solve = [&]<bool F, bool R>() {
    set_masses<F, R>(c, A, B);
    solve_states<F, R>(c, A, B, inv_h);
  };
  if (friction && rolling) solve.template operator()<true, true>();
  else if (friction) solve.template operator()<true, false>();
  else if (rolling) solve.template operator()<false, true>();
  else solve.template operator()<false, false>();
  return !same_bits(&A.v, &A0.v, sizeof(Vec3)) || !same_bits(&A.w, &A0.w, sizeof(Vec3)) ||
         !same_bits(&B.v, &B0.v, sizeof(Vec3)) || !same_bits(&B.w, &B0.w, sizeof(Vec3)) ||
         !same_bits(&c.normal_impulse, &c0.normal_impulse, sizeof(real)) ||
         (friction && !same_bits(&c.tangent_impulse, &c0.tangent_impulse, sizeof(Vec3))) ||
         (rolling && !same_bits(&c.rolling_impulse, &c0.rolling_impulse, sizeof(Vec3)));
}
template <bool Friction, bool Rolling>
void expect_known_idle_changes_nothing(IdleCounts& n) {
  const real inv_h = real(1000);
  for (std::uint32_t seed = 1; seed <= 300; ++seed)
    for (int kind = 0; kind < 4; ++kind) {
      std::mt19937 rng(seed);
      Case start = kind == 2 ? make_case(rng, true) : unloaded_case(rng, kind == 1);
      if (kind == 3) make_tiny(start.bodies);
      for (Contact c : start.contacts) {
        const BodyState A = load_body(start.bodies.data(), c.a, c), B = load_body(start.bodies.data(), c.b, c);
        const bool changes = update_changes_a_bit(c, A, B, inv_h, Friction, Rolling);
        ++n.updates;
        const bool clear = impulses_clear<Friction, Rolling>(c);
        const bool no_minus_zero = !has_minus_zero(A) && !has_minus_zero(B);
        const bool slack = normal_slack(c, A, B, inv_h) >= 0;
        if (known_idle<Friction, Rolling>(c, A, B, inv_h)) {
          ++n.idle;
          ASSERT_FALSE(changes) << "seed " << seed << " kind " << kind;
        }
        n.needs_clear += !clear && no_minus_zero && slack && changes;
        n.needs_no_minus_zero += clear && !no_minus_zero && slack && changes;
        n.needs_slack += clear && no_minus_zero && !slack && changes;
      }
    }
}

TEST(SweepRecords, AnUpdateKnownIdleChangesNoBit) {
  IdleCounts n;
  expect_known_idle_changes_nothing<true, true>(n);
  expect_known_idle_changes_nothing<true, false>(n);
  expect_known_idle_changes_nothing<false, true>(n);
  expect_known_idle_changes_nothing<false, false>(n);
  EXPECT_GT(n.idle, n.updates / 4) << "of " << n.updates;
  EXPECT_GT(n.needs_clear, 0);
  EXPECT_GT(n.needs_no_minus_zero, 0);
  EXPECT_GT(n.needs_slack, 0);
}

// A block of `count` unloaded contacts whose gaps allow more approach than
// their spheres can have (|v| <= 1.8 m/s, a gap of 4 mm at h = 1 ms): every
// update idle, unless a body has a -0 velocity component (`zeros`). With
// `tiny` the spheres move at underflowing_speed's scale.
Case idle_case(std::mt19937& rng, bool zeros, std::uint32_t count, bool tiny = false) {
  std::uniform_int_distribution<int> pick(0, 7);
  Case c = make_case(rng, false, count);
  if (tiny) make_tiny(c.bodies);
  for (SolverBody& b : c.bodies)
    if (zeros && pick(rng) == 0) b.w.y = -real(0);
  for (Contact& k : c.contacts) {
    k.normal_impulse = 0, k.tangent_impulse = {}, k.rolling_impulse = {};
    k.separation = real(4e-3);
    prepare_one(k, c.bodies.data());
  }
  return c;
}

// Whole idle blocks (all_idle: the block returns before its arithmetic and
// writes nothing) against solve_one contact by contact, over three sweeps,
// for every effect set and both widths; blocks with a -0 go the whole way.
// Counts the blocks all_idle passes (the return is taken) and those it
// refuses.
template <bool Friction, bool Rolling, bool Wide>
void expect_idle_blocks_equal_scalar(std::uint32_t seed, bool zeros, int& skipped, int& solved) {
  constexpr std::uint32_t count = Wide ? WW : W;
  std::mt19937 rng(seed);
  Case scalar = idle_case(rng, zeros, count, seed % 2 == 0), block = scalar;
  RecordsMemory memory(count);
  const SweepRecords records = memory.records();
  for (std::uint32_t k = 0; k < count; ++k) pack_sweep_record(block.contacts[k], records, k);
  const real inv_h = real(1000);
  for (int sweep = 0; sweep < 3; ++sweep) {
    using V = std::conditional_t<Wide, lanes::Wide, lanes::L>;
    bool idle = false;
    if constexpr (Wide) idle = wide_all_idle<Friction, Rolling>(records, block.bodies.data(), inv_h);
    else
      idle = lanes::all_idle<Friction, Rolling>(lanes::load_records_of<Friction || Rolling, Rolling, V>(records, 0),
                                                lanes::load_bodies_of<V>(block.bodies.data(), records, 0, false),
                                                lanes::load_bodies_of<V>(block.bodies.data(), records, 0, true), inv_h);
    (idle ? skipped : solved) += 1;
    bool every_lane = true;  // the scalar rule on each lane's contact, as the block holds it now
    for (const Contact& c : scalar.contacts)
      every_lane = every_lane && known_idle<Friction, Rolling>(c, load_body(scalar.bodies.data(), c.a, c),
                                                               load_body(scalar.bodies.data(), c.b, c), inv_h);
    ASSERT_EQ(idle, every_lane) << "seed " << seed << " sweep " << sweep;
    for (Contact& c : scalar.contacts) solve_one<Friction, Rolling>(c, scalar.bodies.data(), inv_h);
    if constexpr (Wide) solve_wide_block<Friction, Rolling>(records, block.bodies.data(), inv_h);
    else lanes::solve_block<Friction, Rolling>(records, 0, block.bodies.data(), inv_h);
    for (std::uint32_t k = 0; k < count; ++k) unpack_sweep_impulses(records, k, block.contacts[k]);
    ASSERT_TRUE(same_bits(scalar.contacts.data(), block.contacts.data(), sizeof(Contact) * count))
        << "seed " << seed << " sweep " << sweep;
    ASSERT_TRUE(same_bits(scalar.bodies.data(), block.bodies.data(), sizeof(SolverBody) * scalar.bodies.size()))
        << "seed " << seed << " sweep " << sweep;
  }
}

template <bool Wide>
void expect_idle_blocks(int& skipped, int& solved) {
  for (std::uint32_t seed = 1; seed <= 100; ++seed)
    for (bool zeros : {false, true}) {
      expect_idle_blocks_equal_scalar<true, true, Wide>(seed, zeros, skipped, solved);
      expect_idle_blocks_equal_scalar<true, false, Wide>(seed, zeros, skipped, solved);
      expect_idle_blocks_equal_scalar<false, true, Wide>(seed, zeros, skipped, solved);
      expect_idle_blocks_equal_scalar<false, false, Wide>(seed, zeros, skipped, solved);
    }
}

TEST(SolverLanes, IdleBlocksEqualSolveOneBitForBit) {
  int skipped = 0, solved = 0;
  expect_idle_blocks<false>(skipped, solved);
  EXPECT_GT(skipped, 600) << solved << " solved";  // of 2400: every block without a -0 is idle
  EXPECT_GT(solved, 300) << skipped << " skipped";
}

TEST(SolverLanes, WideIdleBlocksEqualSolveOneBitForBit) {
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "skipped: this CPU has no AVX2";
  int skipped = 0, solved = 0;
  expect_idle_blocks<true>(skipped, solved);
  EXPECT_GT(skipped, 600) << solved << " solved";
  EXPECT_GT(solved, 300) << skipped << " skipped";
}

// A contact's records and bodies in pages of their own, read-only once
// packed: a sweep that writes to them dies of SIGSEGV.
struct ReadOnlyCase {
  std::size_t bytes = 0;
  void* memory = nullptr;
  SweepRecords records;
  SolverBody* bodies = nullptr;
  explicit ReadOnlyCase(const Case& c) {
    const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
    const std::size_t record_bytes = (SweepRecords::bytes_for(W) + page - 1) / page * page;
    bytes = record_bytes + (sizeof(SolverBody) * c.bodies.size() + page - 1) / page * page;
    memory = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (memory == MAP_FAILED) std::abort();
    records = SweepRecords::in(memory, W);
    bodies = reinterpret_cast<SolverBody*>(static_cast<char*>(memory) + record_bytes);
    std::copy(c.bodies.begin(), c.bodies.end(), bodies);
    for (std::uint32_t k = 0; k < W; ++k) pack_sweep_record(c.contacts[k], records, k);
    mprotect(memory, bytes, PROT_READ);
  }
  ~ReadOnlyCase() { munmap(memory, bytes); }
};

// Contact k of c swept in read-only memory, then exit(0).
[[noreturn]] void sweep_read_only(const Case& c, std::uint32_t k) {
  ReadOnlyCase ro(c);
  solve_record<true, true>(ro.records, k, ro.bodies, real(1000));
  std::exit(0);
}

// The records' sweep writes nothing for an idle contact whose bodies have
// no -0 velocity component, and writes for one that takes a load (the
// memory is read-only: it dies, which shows the protection holds).
TEST(SweepRecords, AnUpdateThatChangesNothingWritesNothing) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  Case c;
  int idle = -1, loaded = -1;
  for (std::uint32_t seed = 1; seed <= 100 && (idle < 0 || loaded < 0); ++seed) {
    std::mt19937 rng(seed);
    c = unloaded_case(rng, false);
    idle = loaded = -1;
    for (std::uint32_t k = 0; k < W; ++k) {
      Contact probe = c.contacts[k];
      BodyState A = load_body(c.bodies.data(), probe.a, probe), B = load_body(c.bodies.data(), probe.b, probe);
      const bool no_minus_zero = !has_minus_zero(A) && !has_minus_zero(B);
      set_masses<true, true>(probe, A, B);
      solve_states<true, true>(probe, A, B, real(1000));
      if (impulses_clear<true, true>(probe) && no_minus_zero)
        idle = static_cast<int>(k);
      else if (probe.normal_impulse > 0)
        loaded = static_cast<int>(k);
    }
  }
  ASSERT_GE(idle, 0) << "the case has an idle contact";
  ASSERT_GE(loaded, 0) << "the case has a contact that takes a load";
  EXPECT_EXIT(sweep_read_only(c, static_cast<std::uint32_t>(idle)), ::testing::ExitedWithCode(0), "");
  EXPECT_EXIT(sweep_read_only(c, static_cast<std::uint32_t>(loaded)), ::testing::KilledBySignal(SIGSEGV), "");
}

// The GPU's warm start on the records (warm_start_record: the impulses
// first, the rest only with a load) equals warm_start_one on the whole
// contacts, bodies bit for bit; make_case's edge cases carry unloaded
// contacts and walls.
template <bool Friction, bool Rolling>
void expect_warm_start_records_equal(std::uint32_t seed, bool edge) {
  PackedCase p(seed, edge);
  Case &whole = p.whole, &packed = p.packed;
  const SweepRecords& records = p.records;
  for (std::uint32_t k = 0; k < W; ++k) {
    warm_start_one<Friction, Rolling>(whole.contacts[k], whole.bodies.data());
    warm_start_record<Friction, Rolling>(records, k, packed.bodies.data());
  }
  ASSERT_TRUE(same_bits(whole.bodies.data(), packed.bodies.data(), sizeof(SolverBody) * whole.bodies.size()))
      << "seed " << seed << (edge ? " (edge)" : "");
}

TEST(SweepRecords, WarmStartOnTheRecordsEqualsTheContacts) {
  over_cases(200,
             []<bool F, bool R>(std::uint32_t seed, bool edge) { expect_warm_start_records_equal<F, R>(seed, edge); });
  int moved = 0;
  for (std::uint32_t seed = 1; seed <= 200; ++seed)
    for (bool edge : {false, true}) {
      std::mt19937 rng(seed);
      Case c = make_case(rng, edge);
      const std::vector<SolverBody> before = c.bodies;
      for (const Contact& k : c.contacts) warm_start_one<true, true>(k, c.bodies.data());
      if (!same_bits(before.data(), c.bodies.data(), sizeof(SolverBody) * before.size())) ++moved;
    }
  EXPECT_GT(moved, 200);  // in most of the 400 cases the warm start moved the bodies: not untouched states compared
}

// The records hold what they were given: a field left out of the packing
// (here the wall's velocity of a wall contact) changes the sweep's result.
TEST(SweepRecords, AFieldLeftOutIsSeen) {
  std::mt19937 rng(7);
  Case c = make_case(rng, false);
  RecordsMemory memory;
  const SweepRecords records = memory.records();
  Contact wall;
  wall.a = 0, wall.b = kWallFlag | 1u, wall.normal = {0, 0, 1}, wall.ra = real(0.01), wall.normal_mass = 1;
  wall.tangent_mass = 1, wall.coeff.friction = 1, wall.normal_impulse = 1, wall.wall_velocity = {1, 0, 0};
  pack_sweep_record(wall, records, 0);
  Contact loaded = load_sweep_contact<true, false>(records, 0);
  EXPECT_EQ(loaded.wall_velocity.x, real(1));
  std::vector<SolverBody> a = c.bodies, b = c.bodies;
  solve_record<true, false>(records, 0, a.data(), real(1000));
  const Real4 with = records.impulse[0];
  pack_sweep_record(wall, records, 0);
  records.extra[0] = {};
  solve_record<true, false>(records, 0, b.data(), real(1000));
  const Real4 without = records.impulse[0];
  EXPECT_FALSE(same_bits(&with, &without, sizeof(Real4)));
}

// The masses a record's sweep computes are the prepared ones: a contact whose
// stored masses disagree with its bodies (here prepared from other bodies)
// gives another result on the whole contact than on its record.
TEST(SweepRecords, TheMassesComeFromTheBodies) {
  std::mt19937 rng(11);
  Case c = make_case(rng, false);
  RecordsMemory memory;
  const SweepRecords records = memory.records();
  int differ = 0;
  for (std::uint32_t k = 0; k < W; ++k) {
    Contact stale = c.contacts[k];
    stale.normal_mass *= real(2), stale.tangent_mass *= real(2);
    pack_sweep_record(stale, records, k);
    std::vector<SolverBody> a = c.bodies, b = c.bodies;
    solve_one<true, false>(stale, a.data(), real(1000));
    solve_record<true, false>(records, k, b.data(), real(1000));
    Contact fresh = c.contacts[k];
    std::vector<SolverBody> f = c.bodies;
    solve_one<true, false>(fresh, f.data(), real(1000));
    EXPECT_TRUE(same_bits(f.data(), b.data(), sizeof(SolverBody) * f.size())) << k;
    if (!same_bits(a.data(), b.data(), sizeof(SolverBody) * a.size())) ++differ;
  }
  EXPECT_GT(differ, 0);
}

// The position stages on the records: project_one and overlap_ratio of
// the contact load_position_contact gives must move the spheres and
// measure the overlap exactly as on the whole contact.
TEST(SweepRecords, PositionStagesOnTheRecordsEqualTheContacts) {
  int moved = 0;
  for (std::uint32_t seed = 1; seed <= 100; ++seed) {
    std::mt19937 rng(seed);
    Case cs = make_case(rng, seed % 2 == 0);
    std::uniform_real_distribution<real> u(-1, 1);
    const std::size_t n = cs.bodies.size();
    std::vector<Vec3> position(n);
    std::vector<real> radius(n), inv_mass(n);
    for (std::size_t i = 0; i < n; ++i) {
      position[i] = Vec3(u(rng), u(rng), u(rng)) * real(0.015);
      radius[i] = real(0.01) + real(0.003) * u(rng);
      inv_mass[i] = cs.bodies[i].inv_mass;
    }
    std::vector<WallShape> walls(8);
    for (WallShape& w : walls) w.point = Vec3(u(rng), u(rng), u(rng)) * real(0.01), w.direction = unit(rng);
    RecordsMemory memory;
    const SweepRecords records = memory.records();
    for (std::uint32_t k = 0; k < W; ++k) pack_sweep_record(cs.contacts[k], records, k);
    std::vector<Vec3> whole = position, packed = position;
    const BodiesView bw{whole.data(), nullptr, nullptr, radius.data(), inv_mass.data(), nullptr, nullptr, n};
    const BodiesView bp{packed.data(), nullptr, nullptr, radius.data(), inv_mass.data(), nullptr, nullptr, n};
    const SolverSettings settings;
    for (std::uint32_t k = 0; k < W; ++k) {
      project_one(cs.contacts[k], bw, walls.data(), settings);
      project_one(load_position_contact(records, k), bp, walls.data(), settings);
      const real o1 = overlap_ratio(cs.contacts[k], bw, walls.data());
      const real o2 = overlap_ratio(load_position_contact(records, k), bp, walls.data());
      ASSERT_TRUE(same_bits(&o1, &o2, sizeof o1)) << "seed " << seed << " contact " << k;
    }
    ASSERT_TRUE(same_bits(whole.data(), packed.data(), sizeof(Vec3) * n)) << "seed " << seed;
    moved += same_bits(whole.data(), position.data(), sizeof(Vec3) * n) ? 0 : 1;
  }
  EXPECT_GT(moved, 80);  // the cases reach the stages' arithmetic
}

}  // namespace
}  // namespace marbles::narrowphase
