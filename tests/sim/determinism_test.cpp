// Determinism of the whole step on the CPU: the same scene gives the same
// bits on every run and for every thread count (the solver's colours share
// no sphere, and every reduction has a fixed order). The CUDA backend's
// parity with these states is in step_cuda_test.cpp.
#include <gtest/gtest.h>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include <algorithm>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <iterator>
#include <random>
#include <stdexcept>

#include "core/error.hpp"
#include "narrowphase/solver.hpp"
#include "sim/checkpoint.hpp"
#include "tests/sim/test_scenes.hpp"
#include "tests/sim/watchdog_cases.hpp"

using namespace marbles;
using namespace marbles::testing;

namespace {

// OpenMP's thread count set while it lives, then as it was (however the
// scope ends).
class Threads {
 public:
  explicit Threads(int threads) {
#if defined(_OPENMP)
    m_before = omp_get_max_threads();
    omp_set_num_threads(threads);
#else
    (void)threads;
#endif
  }
  ~Threads() {
#if defined(_OPENMP)
    omp_set_num_threads(m_before);
#endif
  }
  Threads(const Threads&) = delete;
  Threads& operator=(const Threads&) = delete;

 private:
  int m_before = 1;
};

std::uint64_t run_pour(int threads, int steps) {
  const Threads team(threads);
  auto [s, g] = pour_scene(400, 3);
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < steps; ++k) sim.step();
  return state_hash(sim.world());
}

// A checkpoint's bytes are its values': two walls equal in every field but
// held in memory with other padding bytes (what a stack or heap left there)
// write the same file, whose padding is zero.
TEST(CheckpointBytes, WallPaddingIsWrittenAsZero) {
  auto wall = [](unsigned char fill) {
    narrowphase::WallShape w;
    std::memset(static_cast<void*>(&w), fill, sizeof w);  // the padding as some memory held it
    w.kind = narrowphase::WallShape::Kind::cylinder_inside;
    w.point = {1, 2, 3};
    w.direction = {0, 0, 1};
    w.radius = 0.5;
    w.length = 2;
    w.velocity = {0, 0, 0};
    w.angular_velocity = 0.25;
    w.material = 1;
    return w;
  };
  Checkpoint zeros, ones;
  zeros.state.walls = {wall(0x00)};
  ones.state.walls = {wall(0xff)};
  const std::string a = checkpoint_bytes(zeros), b = checkpoint_bytes(ones);
  EXPECT_EQ(a, b);
  const char* const first = reinterpret_cast<const char*>(&ones.state.walls[0]);
  const std::size_t at = a.find(std::string(first + offsetof(narrowphase::WallShape, point), sizeof(Vec3)));
  ASSERT_NE(at, std::string::npos);
  const std::size_t record = at - offsetof(narrowphase::WallShape, point);
  for (std::size_t k = 1; k < offsetof(narrowphase::WallShape, point); ++k)
    EXPECT_EQ(a[record + k], '\0') << "padding byte " << k << " after kind";
}

}  // namespace

// A block of 67,200 touching spheres (a cubic lattice, slightly jittered)
// settling in a box: ~200,000 contacts, about 20,000 per colour, so every
// OpenMP path runs in parallel (contact gathering, reach, colours, cache),
// and more than 2^16 spheres, so that the cache's store sorts by groups of
// spheres from three threads on (detail::wide_counting_sort).
std::uint64_t run_block(int threads, int steps) {
  const Threads team(threads);
  using scene::Effect;
  scene::Scene s = make_scene(1e-3, 1,
                              {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                               Effect::friction, Effect::rolling_resistance},
                              0.3, 0.5, 0.05);
  const real r = real(0.01);
  const int nx = 40, ny = 40, nz = 42;
  s.walls.push_back(box({0, 0, 0}, {real(2 * r * nx), real(2 * r * ny), real(4 * r * nz)}));
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> jitter(-0.002, 0.002);
  scene::GeneratedParticles g;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x)
        add_sphere(g, {real(r * (2 * x + 1) * (1 + jitter(rng))), real(r * (2 * y + 1) * (1 + jitter(rng))),
                       real(r * (2 * z + 1))},
                   r);
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < steps; ++k) sim.step();
  EXPECT_GT(sim.last_step().contacts, 100000u) << "the block must be large enough to run the parallel paths";
  return state_hash(sim.world());
}

TEST(Determinism, LargeBlockIsTheSameForEveryThreadCount) {
  const std::uint64_t one = run_block(1, 4);
  for (const int threads : {2, 3, 5, 16}) {
    EXPECT_EQ(run_block(threads, 4), one) << threads << " threads";
  }
}

TEST(Determinism, PourIsTheSameOnEveryRunAndThreadCount) {
  const std::uint64_t one = run_pour(1, 300);
  EXPECT_EQ(run_pour(1, 300), one);
  EXPECT_EQ(run_pour(2, 300), one);
  EXPECT_EQ(run_pour(3, 300), one);
  EXPECT_NE(run_pour(1, 299), one) << "the hash must see the state change";
}

// The kept colours are part of the state a checkpoint carries: saved and
// restored, the run goes on with the same bits; a restored state without
// colours (a format-1 checkpoint) or with an improper colouring colours
// afresh, and the run still goes on, properly coloured.
// Where every sphere has one radius and every material pair the same
// friction and rolling friction, the CPU's records leave the arms word out
// (narrowphase::UniformArms, as the GPU's do) and the sweeps take the arms
// from the one word: the same bits as the records with arms, which the same
// pour takes when a material no sphere uses has another friction (the pair
// table no longer uniform). A pour of one radius, with walls at rest and
// spinning (a wall's arm is +0) and two materials of one friction.
TEST(Determinism, UniformArmsGiveTheBitsOfTheArmsWords) {
  auto [s, g] = pour_scene(300, 5);
  std::fill(g.radius.begin(), g.radius.end(), real(0.011));
  scene::Scene apart = s;
  scene::Material unused = s.materials[0];
  unused.name = "unused";
  unused.friction = 0.9;
  apart.materials.push_back(unused);
  Simulation uniform(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation arms(apart, make_world(apart, g), broadphase::Backend::cpu);
  std::uint64_t uniform_substeps = 0, contacts = 0, substeps_with_contacts = 0;
  for (int k = 0; k < 400; ++k) {
    uniform.step();
    arms.step();
    ASSERT_EQ(uniform.last_step().contacts, arms.last_step().contacts) << "step " << k;
    ASSERT_EQ(arms.last_step().uniform_arms, 0u) << "step " << k;
    uniform_substeps += uniform.last_step().uniform_arms;
    contacts += uniform.last_step().contacts;
    substeps_with_contacts += uniform.last_step().contacts > 0 ? 1 : 0;
    if (k % 10 == 9) {
      ASSERT_EQ(state_hash(uniform.world()), state_hash(arms.world())) << "step " << k;
    }
  }
  EXPECT_GT(contacts, 100000u);  // the pour reaches the floor and piles there
  EXPECT_GE(uniform_substeps, substeps_with_contacts);  // every step with contacts solved records without arms
  EXPECT_EQ(state_hash(uniform.world()), state_hash(arms.world()));
}

// The records' form follows the radii: after an edit gives one sphere
// another radius the step keeps the arms words, and after it gives that
// radius back it leaves them out again.
TEST(Determinism, UniformArmsFollowTheRadiiAfterAnEdit) {
  auto [s, g] = pour_scene(300, 5);
  std::fill(g.radius.begin(), g.radius.end(), real(0.011));
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  auto step_with_contacts = [&] {
    do sim.step();
    while (sim.last_step().contacts == 0);
    return sim.last_step().uniform_arms;
  };
  for (int k = 0; k < 250; ++k) sim.step();
  EXPECT_GT(step_with_contacts(), 0u);
  sim.edit_world().radius[7] = real(0.0105);
  EXPECT_EQ(step_with_contacts(), 0u);
  EXPECT_EQ(step_with_contacts(), 0u);
  sim.edit_world().radius[7] = real(0.011);
  EXPECT_GT(step_with_contacts(), 0u);
}

TEST(Determinism, KeptColoursTravelWithTheState) {
  auto [s, g] = pour_scene(400, 3);
  Simulation whole(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < 60; ++k) whole.step();
  const World at60 = whole.world();
  const StepState state = whole.save_state();
  ASSERT_EQ(state.cache.colour.size(), state.cache.size());
  ASSERT_GT(std::count_if(state.cache.colour.begin(), state.cache.colour.end(),
                          [](std::uint8_t c) { return c != narrowphase::kNoKeptColour; }),
            0);
  for (int k = 0; k < 40; ++k) whole.step();

  Simulation resumed(s, make_world(s, g), broadphase::Backend::cpu);
  resumed.restore(at60, state, 60);
  for (int k = 0; k < 40; ++k) resumed.step();
  EXPECT_EQ(state_hash(resumed.world()), state_hash(whole.world()));

  // Without colours: coloured afresh, so another order and other bits; the
  // cache then keeps colours again.
  StepState plain = state;
  plain.cache.colour.clear();
  Simulation fresh(s, make_world(s, g), broadphase::Backend::cpu);
  fresh.restore(at60, plain, 60);
  EXPECT_EQ(fresh.save_state().cache.colour,
            std::vector<std::uint8_t>(state.cache.size(), narrowphase::kNoKeptColour));
  for (int k = 0; k < 40; ++k) fresh.step();
  EXPECT_NE(state_hash(fresh.world()), state_hash(whole.world())) << "the colours must reach the result";
  EXPECT_EQ(fresh.save_state().cache.colour.size(), fresh.save_state().cache.size());

  // Two entries of one sphere with one colour: not a proper colouring, dropped.
  StepState bad = state;
  std::size_t first = 0;  // an entry with a colour, followed by another entry of its sphere a
  while (first + 1 < bad.cache.size() && (bad.cache.colour[first] == narrowphase::kNoKeptColour ||
                                          (bad.cache.key[first + 1] >> 32) != (bad.cache.key[first] >> 32)))
    ++first;
  ASSERT_LT(first + 1, bad.cache.size());
  bad.cache.colour[first + 1] = bad.cache.colour[first];
  Simulation guarded(s, make_world(s, g), broadphase::Backend::cpu);
  guarded.restore(at60, bad, 60);
  EXPECT_EQ(guarded.save_state().cache.colour,
            std::vector<std::uint8_t>(state.cache.size(), narrowphase::kNoKeptColour));
  for (int k = 0; k < 5; ++k) guarded.step();
  EXPECT_EQ(guarded.world().first_non_finite(), guarded.world().size());
}

// The checkpoint of a pour of 300 after 30 steps (scene hash 42).
static Checkpoint pour_checkpoint() {
  auto [s, g] = pour_scene(300, 3);
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < 30; ++k) sim.step();
  Checkpoint c;
  c.scene_hash = 42;
  c.steps = 30;
  c.world = sim.world();
  c.state = sim.save_state();
  return c;
}

// A checkpoint carries the cache's colours (format 2); one of format 1 (the
// same file without them) still loads, with no colours.
TEST(Determinism, CheckpointsOfBothFormatsLoad) {
  const Checkpoint c = pour_checkpoint();
  ASSERT_GT(c.state.cache.size(), 0u);
  const std::string path = ::testing::TempDir() + "/marbles_formats.mck";
  write_checkpoint(path, c);
  const Checkpoint back = read_checkpoint(path, 42);
  EXPECT_EQ(back.state.cache.colour, c.state.cache.colour);
  EXPECT_EQ(back.state.cache.key, c.state.cache.key);

  // The same file as format 1: the colour array cut out, the format word 1,
  // the checksum made anew.
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::size_t at = 8 + 4 + 16 + 4 + 4 + 8 + 8;  // magic, format, version, real and wall sizes, scene hash, steps
  auto skip = [&](std::size_t element) {
    std::uint64_t n = 0;
    std::memcpy(&n, bytes.data() + at, 8);
    at += 8 + n * element;
  };
  for (std::size_t element : {sizeof(Vec3), sizeof(Vec3), sizeof(Vec3), sizeof(real), sizeof(real), sizeof(real),
                              sizeof(std::uint32_t), sizeof(std::uint64_t), sizeof(real), sizeof(Vec3), sizeof(Vec3)})
    skip(element);
  const std::size_t colour_at = at;
  skip(1);
  bytes.erase(colour_at, at - colour_at);
  const std::uint32_t one = 1;
  std::memcpy(bytes.data() + 8, &one, 4);
  std::uint64_t h = 14695981039346656037ull;  // FNV-1a of all before the checksum
  for (std::size_t i = 0; i + 8 < bytes.size(); ++i) h = (h ^ static_cast<unsigned char>(bytes[i])) * 1099511628211ull;
  std::memcpy(bytes.data() + bytes.size() - 8, &h, 8);
  const std::string old_path = ::testing::TempDir() + "/marbles_format1.mck";
  std::ofstream(old_path, std::ios::binary) << bytes;
  const Checkpoint old = read_checkpoint(old_path, 42);
  EXPECT_TRUE(old.state.cache.colour.empty());
  EXPECT_EQ(old.state.cache.key, c.state.cache.key);
  EXPECT_EQ(old.state.cache.normal_impulse, c.state.cache.normal_impulse);
  EXPECT_EQ(old.totals.contact_sum, c.totals.contact_sum);
  EXPECT_EQ(state_hash(old.world), state_hash(c.world));
  std::remove(path.c_str());
  std::remove(old_path.c_str());
}

// The steps kept unswept (format 4) travel with the totals; a run without
// them writes format 2, as before, which earlier builds read.
TEST(Determinism, CheckpointsKeepTheStepsKeptUnswept) {
  Checkpoint c = pour_checkpoint();
  const std::string path = ::testing::TempDir() + "/marbles_unswept.mck";
  const auto format_of = [&] {
    std::ifstream in(path, std::ios::binary);
    char head[12] = {};
    in.read(head, sizeof head);
    std::uint32_t format = 0;
    std::memcpy(&format, head + 8, 4);
    return format;
  };
  write_checkpoint(path, c);
  EXPECT_EQ(format_of(), 2u);
  EXPECT_EQ(read_checkpoint(path, 42).totals.unswept, 0.0);
  c.totals.unswept = 3;
  write_checkpoint(path, c);
  EXPECT_EQ(format_of(), 4u);
  const Checkpoint back = read_checkpoint(path, 42);
  EXPECT_EQ(back.totals.unswept, 3.0);
  EXPECT_EQ(back.totals.rollbacks, c.totals.rollbacks);
  EXPECT_EQ(back.totals.contact_sum, c.totals.contact_sum);
  EXPECT_EQ(state_hash(back.world), state_hash(c.world));
  c.totals.unswept = 2.5;
  write_checkpoint(path, c);
  EXPECT_THROW(read_checkpoint(path, 42), InputError);
  std::remove(path.c_str());
}

// A checkpoint whose cache's entries are out of key order, or name one pair
// twice, is refused as damaged: the restore's runs by sphere and the kept
// colours' split between threads read them in key order.
TEST(Determinism, CheckpointsWithTheCacheOutOfKeyOrderAreRefused) {
  const Checkpoint c = pour_checkpoint();
  ASSERT_GT(c.state.cache.size(), 3u);
  const std::string path = ::testing::TempDir() + "/marbles_key_order.mck";
  write_checkpoint(path, c);
  EXPECT_NO_THROW(read_checkpoint(path, 42)) << "premise: the file as written loads";
  for (const bool repeat : {false, true}) {
    Checkpoint bad = c;
    std::vector<std::uint64_t>& key = bad.state.cache.key;
    if (repeat) key[2] = key[1];
    else std::swap(key[1], key[2]);
    write_checkpoint(path, bad);
    try {
      read_checkpoint(path, 42);
      ADD_FAILURE() << (repeat ? "a repeated key" : "two keys swapped") << " loaded";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("not in key order"), std::string::npos) << e.what();
    }
  }
  std::remove(path.c_str());
}

// A checkpoint whose checksum holds but whose values no run could have
// written (a radius not above zero, a mass, state, impulse or total not
// finite, a negative inverse mass, masses a sphere of its radius could not
// have (masses_as_made), a precision word of neither type) is
// refused as damaged; one that names a material the scene lacks, or holds
// another number of spheres, does not fit the scene.
TEST(Determinism, CheckpointsWithImpossibleValuesAreRefused) {
  const Checkpoint c = pour_checkpoint();
  ASSERT_GT(c.world.size(), 3u);
  ASSERT_GT(c.state.cache.size(), 0u);
  const std::string path = ::testing::TempDir() + "/marbles_values.mck";
  write_checkpoint(path, c);
  EXPECT_NO_THROW(read_checkpoint(path, 42)) << "premise: the file as written loads";
  {  // as many as its steps make: every step redone four times, and kept unswept
    ASSERT_GT(c.steps, 0u);
    Checkpoint most = c;
    most.totals.rollbacks = double(c.steps) * 4;
    most.totals.unswept = double(c.steps);
    write_checkpoint(path, most);
    EXPECT_NO_THROW(read_checkpoint(path, 42));
  }
  const real nan = std::numeric_limits<real>::quiet_NaN(), inf = std::numeric_limits<real>::infinity();
  const real beyond_square = real(2) * std::sqrt(std::numeric_limits<real>::max());  // finite, its square not
  const std::vector<std::pair<std::string, std::function<void(Checkpoint&)>>> damages{
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.radius[2] = 0; }},
      {"radius, mass or inertia", [&](Checkpoint& k) { k.world.radius[1] = -k.world.radius[1]; }},
      {"radius, mass or inertia", [&](Checkpoint& k) { k.world.radius[3] = nan; }},
      {"radius, mass or inertia", [&](Checkpoint& k) { k.world.inv_mass[0] = nan; }},
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.inv_mass[2] = -1; }},
      {"radius, mass or inertia", [&](Checkpoint& k) { k.world.inv_inertia[1] = inf; }},
      // Finite, but no world make_world builds: a radius past the masses it
      // came with, an inertia gone where the mass stays, a mass past the
      // precision's usable range, a fixed sphere that still turns.
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.radius[3] = real(3e37); }},
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.radius[0] *= real(2); }},
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.radius[2] = std::numeric_limits<real>::denorm_min(); }},
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.inv_inertia[3] = 0; }},
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.inv_mass[1] = std::numeric_limits<real>::max() / 4; }},
      {"radius, mass or inertia", [](Checkpoint& k) { k.world.inv_mass[0] = 0; }},
      {"state is not finite", [&](Checkpoint& k) { k.world.position[2].y = inf; }},
      {"state is not finite", [&](Checkpoint& k) { k.world.velocity[0].z = nan; }},
      {"state is not finite", [&](Checkpoint& k) { k.world.angular_velocity[3].x = -inf; }},
      {"impulse is not finite", [&](Checkpoint& k) { k.state.cache.normal_impulse[0] = nan; }},
      {"impulse is not finite", [&](Checkpoint& k) { k.state.cache.tangent_impulse[0].x = inf; }},
      {"running totals", [](Checkpoint& k) { k.totals.energy_start = std::numeric_limits<double>::quiet_NaN(); }},
      {"running totals", [](Checkpoint& k) { k.totals.contact_sum = -1; }},
      {"running totals", [](Checkpoint& k) { k.totals.deepest = 1e308; }},  // "inf %" once printed
      {"running totals", [](Checkpoint& k) { k.totals.rollbacks = 0.5; }},
      // More than its steps make (2^64 and more read as 0 in the summary).
      {"running totals", [](Checkpoint& k) { k.totals.rollbacks = 18446744073709551616.0; }},
      {"running totals", [](Checkpoint& k) { k.totals.unswept = 1e299; }},
      {"running totals", [](Checkpoint& k) { k.totals.rollbacks = double(k.steps) * 4 + 1; }},
      {"running totals", [](Checkpoint& k) { k.totals.unswept = double(k.steps) + 1; }},
      {"step count", [](Checkpoint& k) { k.steps = ~std::uint64_t{0}; }},  // a Python restart wrapped it to 1
      {"step count", [](Checkpoint& k) { k.steps = (std::uint64_t{1} << 53) + 1; }},
      {"range once squared", [&](Checkpoint& k) { k.world.velocity[1].x = beyond_square; }},
      {"range once squared", [&](Checkpoint& k) { k.world.angular_velocity[2].z = -beyond_square; }},
      {"range once squared", [&](Checkpoint& k) { k.world.position[0].y = beyond_square; }},
      {"cache's array lengths differ", [](Checkpoint& k) { k.state.cache.normal_impulse.pop_back(); }},
      {"cache's array lengths differ", [](Checkpoint& k) { k.state.cache.rolling_impulse.pop_back(); }},
  };
  for (const auto& [why, damage] : damages) {
    Checkpoint bad = c;
    damage(bad);
    write_checkpoint(path, bad);
    try {
      read_checkpoint(path, 42);
      ADD_FAILURE() << "a checkpoint damaged in its " << why << " loaded";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  }
  // The precision word (after the magic, the format and the version) of
  // neither type, with the checksum made anew.
  write_checkpoint(path, c);
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const std::uint32_t zero = 0;
  std::memcpy(bytes.data() + 8 + 4 + 16, &zero, 4);
  std::uint64_t h = 14695981039346656037ull;  // FNV-1a of all before the checksum
  for (std::size_t i = 0; i + 8 < bytes.size(); ++i) h = (h ^ static_cast<unsigned char>(bytes[i])) * 1099511628211ull;
  std::memcpy(bytes.data() + bytes.size() - 8, &h, 8);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  try {
    read_checkpoint(path, 42);
    ADD_FAILURE() << "a precision word of 0 loaded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("neither float nor double"), std::string::npos) << e.what();
  }
  // Fitting the scene: the materials it has, the spheres it makes, its walls.
  std::uint32_t materials = 0;
  for (std::uint32_t m : c.world.material) materials = std::max(materials, m + 1);
  auto [s, g] = pour_scene(300, 3);
  const std::vector<narrowphase::WallShape> walls =
      Simulation(s, make_world(s, g), broadphase::Backend::cpu).model().wall_shapes;
  ASSERT_FALSE(walls.empty());
  ASSERT_EQ(c.state.walls.size(), walls.size());
  EXPECT_NO_THROW(check_checkpoint_fits(c, path, "--restart", c.world, c.ids, materials, walls));
  try {
    check_checkpoint_fits(c, path, "--restart", c.world, c.ids, materials - 1, walls);
    ADD_FAILURE() << "a checkpoint naming a material past the scene's fitted it";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("names material " + std::to_string(materials - 1)), std::string::npos)
        << e.what();
  }
  World more = c.world;  // the scene makes one sphere more
  for (auto* v : {&more.position, &more.velocity, &more.angular_velocity}) v->push_back(Vec3{});
  more.radius.push_back(1), more.inv_mass.push_back(1), more.inv_inertia.push_back(1), more.material.push_back(0);
  EXPECT_THROW(check_checkpoint_fits(c, path, "--restart", more, c.ids, materials, walls), InputError);
  // Each sphere of its sphere's material, fixed where that one is (a forged
  // checkpoint's sphere of zero masses ran as a fixed one), by the scene's
  // numbering: a checkpoint in another numbering fits through its ids.
  ASSERT_TRUE(c.ids.empty());
  ASSERT_GT(c.world.inv_mass[1], 0);
  const auto fits_or_why = [&](const Checkpoint& k, const World& scene, std::size_t with_materials) -> std::string {
    try {
      check_checkpoint_fits(k, path, "--restart", scene, {}, with_materials, walls);
      return "";
    } catch (const InputError& e) {
      return e.what();
    }
  };
  Checkpoint held = c;
  held.world.inv_mass[1] = 0, held.world.inv_inertia[1] = 0;
  EXPECT_NE(fits_or_why(held, c.world, materials).find("(sphere 1 is not the scene's: fixed where the scene's moves)"),
            std::string::npos);
  EXPECT_NE(fits_or_why(c, held.world, materials).find("(sphere 1 is not the scene's: it moves where the scene's is fixed)"),
            std::string::npos);
  World other = c.world;
  other.material[2] = c.world.material[2] + 1;
  EXPECT_NE(fits_or_why(c, other, materials + 1).find("(sphere 2 is not the scene's: another material)"),
            std::string::npos);
  std::vector<std::uint32_t> reversed(c.world.size());
  for (std::size_t i = 0; i < reversed.size(); ++i) reversed[i] = static_cast<std::uint32_t>(reversed.size() - 1 - i);
  Checkpoint renumbered = c;
  renumbered.world = permuted(held.world, reversed);
  renumbered.ids = reversed;
  EXPECT_EQ(fits_or_why(renumbered, held.world, materials), "");
  renumbered.ids = {};  // the same arrays read in the scene's numbering: sphere 1 is another's
  EXPECT_NE(fits_or_why(renumbered, held.world, materials).find("is not the scene's"), std::string::npos);
  // A moving wall moved along (its point) fits; a wall at rest moved, one
  // whose point is not finite, whose shape is another, or a wall more or
  // fewer, does not (a NaN point had made the floor vanish).
  std::vector<narrowphase::WallShape> moving = walls;
  moving[0].velocity = Vec3(0, 0, real(0.5));
  Checkpoint moved = c;
  moved.state.walls[0].velocity = moving[0].velocity;
  moved.state.walls[0].point += Vec3(0, 0, real(0.25));
  EXPECT_NO_THROW(check_checkpoint_fits(moved, path, "--restart", c.world, c.ids, materials, moving));
  const std::vector<std::function<void(Checkpoint&)>> wall_damages{
      [&](Checkpoint& k) { k.state.walls[0].point.z += real(0.25); },  // a wall at rest moved
      [&](Checkpoint& k) { k.state.walls[0].point.x = nan; },
      [&](Checkpoint& k) { k.state.walls.back().direction.z = -k.state.walls.back().direction.z + real(0.5); },
      [&](Checkpoint& k) { k.state.walls[0].velocity.y = real(1); },
      [&](Checkpoint& k) { k.state.walls[0].material += 1; },
      [](Checkpoint& k) { k.state.walls.pop_back(); },
  };
  for (const auto& damage : wall_damages) {
    Checkpoint bad = c;
    damage(bad);
    try {
      check_checkpoint_fits(bad, path, "--restart", c.world, c.ids, materials, walls);
      ADD_FAILURE() << "a checkpoint with a damaged wall fitted the scene";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("wall shape"), std::string::npos) << e.what();
    }
  }
  std::remove(path.c_str());
}

// A block of spheres on a cubic lattice, each overlapping its neighbours a
// little and moving at random (up to 5 cm/s an axis), in free space (no
// walls, no gravity): every contact is between two spheres, about 10 000 a
// colour, so the colour loops run in parallel, and the velocity solve has
// work to do.
std::uint64_t run_free_block(int threads, int steps, int* iterations = nullptr) {
  const Threads team(threads);
  using scene::Effect;
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::friction}, 0, 0.5);
  if (iterations) *iterations = s.solver.iterations;
  const real r = real(0.01);
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> speed(-0.05, 0.05);
  auto v = [&] { return real(speed(rng)); };
  scene::GeneratedParticles g;
  for (int z = 0; z < 30; ++z)
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < 30; ++x)
        add_sphere(g, {real(1.98 * r * x), real(1.98 * r * y), real(1.98 * r * z)}, r, {v(), v(), v()});
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < steps; ++k) sim.step();
  EXPECT_GT(sim.last_step().contacts, 60000u) << "the colours must be large enough to run in parallel";
  return state_hash(sim.world());
}

// The local order of the CPU study (narrowphase/solver.hpp, LocalOrder)
// against the solver's, where the two must agree bit for bit: one cube
// around everything swept once a pass (the same updates in the same order),
// and cubes smaller than a sphere in a scene without walls (every contact
// between cubes, walked colour by colour as the solver walks them, in
// parallel within a colour), as many passes as the scene's iterations.
// Cubes of a few diameters give another state, the same for every thread
// count (cubes share no sphere).
TEST(Determinism, LocalOrderStudy) {
  int iterations = 0;
  const std::uint64_t block = run_free_block(2, 4, &iterations);
  const std::string passes = std::to_string(iterations);
  {
    SolveOrder between("tiles:0.01:" + passes + ":3");
    EXPECT_EQ(run_free_block(2, 4), block) << "every contact between cubes: the solver's order";
  }
  {
    SolveOrder cubes("tiles:3:3:4");
    const std::uint64_t one = run_free_block(1, 4);
    EXPECT_EQ(run_free_block(2, 4), one);
    EXPECT_EQ(run_free_block(3, 4), one);
    EXPECT_NE(one, block) << "another order, other bits";
  }
  auto [s, g] = pour_scene(400, 3);
  const std::uint64_t pour = run_pour(2, 150);
  {
    // The pour's box starts at the origin: one cube of a million diameters holds it.
    SolveOrder one_cube("tiles:1e6:" + std::to_string(s.solver.iterations) + ":1");
    EXPECT_EQ(run_pour(2, 150), pour) << "one cube, one sweep a pass: the solver's order";
  }
  {
    SolveOrder cubes("tiles:3:3:4");
    const std::uint64_t one = run_pour(1, 150);
    EXPECT_EQ(run_pour(2, 150), one);
    EXPECT_NE(one, pour) << "another order, other bits";
  }
  EXPECT_EQ(run_pour(2, 150), pour) << "restored: the solver's order again";
}

TEST(Determinism, LocalOrderStudyRefusesWhatItCannotRead) {
  for (const char* bad : {"tiles:0:3:4", "tiles:8:0:4", "tiles:8:3:0", "tiles:8:3", "tiles:8:3:4x", "tiles:nan:3:4",
                          "cubes", "tiles:inf:3:4"}) {
    SolveOrder order(bad);
    EXPECT_THROW(narrowphase::local_order_from_environment(), RuntimeFailure) << bad;
  }
  for (const char* none : {"", "colours"}) {
    SolveOrder order(none);
    EXPECT_FALSE(narrowphase::local_order_from_environment().has_value()) << "'" << none << "'";
  }
  SolveOrder order("tiles:12:2:6");
  const auto o = narrowphase::local_order_from_environment();
  ASSERT_TRUE(o.has_value());
  EXPECT_EQ(o->tile_diameters, 12.0);
  EXPECT_EQ(o->passes, 2);
  EXPECT_EQ(o->local, 6);
  EXPECT_EQ(o->threads, 256) << "a cube's block on the GPU, unset";
}

// MARBLES_LOCAL_THREADS (a cube's block on the GPU) is read with the order,
// and refused, with or without the order, where it is no multiple of 32
// from 32 to 1024.
TEST(Determinism, LocalOrderThreadsRefusedWhereTheGpuCannotTakeThem) {
  for (const char* bad : {"0", "16", "33", "100", "1056", "2048", "-32", "64x", "", "sixty-four"}) {
    for (const char* order : {"tiles:8:2:6", "colours"}) {
      SolveOrder o(order);
      ScopedEnvironment threads("MARBLES_LOCAL_THREADS", bad);
      EXPECT_THROW(narrowphase::local_order_from_environment(), RuntimeFailure) << bad << " with " << order;
    }
  }
  for (const int good : {32, 64, 128, 96, 992, 1024}) {
    SolveOrder o("tiles:8:2:6");
    ScopedEnvironment threads("MARBLES_LOCAL_THREADS", std::to_string(good));
    const auto read = narrowphase::local_order_from_environment();
    ASSERT_TRUE(read.has_value());
    EXPECT_EQ(read->threads, good);
  }
}

// inverse_of (the step's numbering and the scene's): a random permutation
// long enough for its parallel loops, against its definition; an index past
// the length is refused.
TEST(Renumber, InverseOfAPermutation) {
  std::vector<std::uint32_t> order(200000);
  for (std::uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::mt19937 rng(5);
  std::shuffle(order.begin(), order.end(), rng);
  const std::vector<std::uint32_t> inverse = inverse_of(order);
  ASSERT_EQ(inverse.size(), order.size());
  for (std::uint32_t i = 0; i < order.size(); ++i) ASSERT_EQ(inverse[order[i]], i) << i;
  EXPECT_TRUE(is_identity(inverse_of(std::vector<std::uint32_t>{0, 1, 2})));
  order[123] = static_cast<std::uint32_t>(order.size());
  EXPECT_THROW(inverse_of(order), std::out_of_range);
}

// inverse_into (renumber's, into kept memory): the inverse of a random
// permutation whatever the target held before (longer, shorter, stale
// values), as inverse_of gives it.
TEST(Renumber, InverseIntoKeptMemory) {
  std::vector<std::uint32_t> order(100000);
  for (std::uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), std::mt19937(11));
  for (const std::size_t held : {std::size_t(0), order.size() / 3, order.size() * 2}) {
    std::vector<std::uint32_t> inverse(held, 7u);
    inverse_into(order, inverse);
    EXPECT_EQ(inverse, inverse_of(order)) << held << " held before";
  }
}

// A numbering that brings the spheres back to the scene's order is
// dropped: ids() empty again, as before the first. A row of spheres at
// rest along x is in the broad phase's order; two of them swap places (an
// edit), the step numbers them so, and swapped back, numbers them back.
TEST(Renumber, BackInTheScenesOrderDropsTheNumbering) {
  using scene::Effect;
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions}, 0, 0.5);
  s.solver.renumber = 1;
  const real r = real(0.01);
  scene::GeneratedParticles g;
  for (int x = 0; x < 12; ++x) add_sphere(g, {r * (6 * x + 1), r, r}, r);
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  sim.step();
  ASSERT_TRUE(sim.ids().empty()) << "the row is in the broad phase's order";
  const World start = sim.world();
  auto swap_places = [&] {
    World& w = sim.edit_world();
    std::swap(w.position[2], w.position[9]);
  };
  swap_places();
  sim.step();
  ASSERT_FALSE(sim.ids().empty());
  EXPECT_EQ(sim.ids()[2], 9u) << "the step's sphere 2 is the scene's 9";
  EXPECT_EQ(sim.ids()[9], 2u);
  EXPECT_EQ(sim.world().position[9], start.position[2]);
  swap_places();
  sim.step();
  EXPECT_TRUE(sim.ids().empty());
  EXPECT_EQ(state_hash(sim.world()), state_hash(start));
}

// solver.renumber: the step numbers the spheres again in the broad phase's
// order every few steps, and hides it. The pour seen through world() keeps
// the scene's numbering (each sphere its radius, material and mass; once
// free of the post, spheres move less than a radius a step, so each keeps
// its place too), contacts()
// name touching spheres in that numbering, a checkpoint's state with its
// numbering restores bit for bit (its cache translated to the scene's
// numbering and back), and the arrays in place are refused.
TEST(Renumber, HiddenFromWorldContactsAndRestarts) {
  auto [s, g] = pour_scene(400, 5);
  s.solver.renumber = 4;
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  EXPECT_THROW(sim.state_in_place(), RuntimeFailure) << "refused from the start: a numbering replaces the arrays";
  const World start = sim.world();
  bool renumbered = false;
  World before = start;
  for (int k = 1; k <= 60; ++k) {
    sim.step();
    renumbered = renumbered || !sim.ids().empty();
    const World& w = sim.world();
    ASSERT_EQ(w.size(), start.size());
    EXPECT_EQ(w.radius, start.radius) << k;
    EXPECT_EQ(w.material, start.material) << k;
    EXPECT_EQ(w.inv_mass, start.inv_mass) << k;
    if (k > 3) {  // after the first steps' push out of the spinning post the spheres start on
      for (std::size_t i = 0; i < w.size(); ++i)
        ASSERT_LT(length(w.position[i] - before.position[i]), w.radius[i]) << "step " << k << ", sphere " << i;
    }
    before = w;
    for (const narrowphase::Contact& c : sim.contacts()) {
      if (narrowphase::is_wall(c.b)) continue;
      const real gap = length(w.position[c.b] - w.position[c.a]) - w.radius[c.a] - w.radius[c.b];
      ASSERT_LT(gap, real(0.5) * std::min(w.radius[c.a], w.radius[c.b])) << "step " << k << ", " << c.a << "-" << c.b;
    }
  }
  ASSERT_TRUE(renumbered) << "the pour is made in layers, not in the broad phase's rows";
  EXPECT_THROW(sim.state_in_place(), RuntimeFailure);

  // A checkpoint at step 62 (between two numberings: at the start of steps
  // 61 and 65), restored into a fresh run.
  sim.step();
  sim.step();
  const World at62 = sim.world();
  const StepState state = sim.save_state();
  const std::vector<std::uint32_t> ids = sim.ids();
  for (int k = 0; k < 30; ++k) sim.step();
  Simulation resumed(s, make_world(s, g), broadphase::Backend::cpu);
  resumed.restore(at62, state, 62, ids);
  for (int k = 0; k < 30; ++k) resumed.step();
  EXPECT_EQ(state_hash(resumed.world()), state_hash(sim.world()));
  EXPECT_EQ(resumed.ids(), sim.ids());
}

// An edit between steps is in the scene's numbering, as the world it edits.
TEST(Renumber, EditsAreInTheScenesNumbering) {
  auto [s, g] = pour_scene(200, 6);
  s.solver.renumber = 1;
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < 5; ++k) sim.step();
  ASSERT_FALSE(sim.ids().empty());
  const std::size_t top = 199;  // the pour's last sphere: in its top layer, free
  const Vec3 was = sim.world().position[top];
  sim.edit_world().velocity[top] = {0, 0, real(2)};
  sim.step();
  EXPECT_GT(sim.world().position[top].z, was.z + real(1e-3)) << "sphere " << top << " was sent up";
  for (std::size_t i = 0; i < 190; ++i)
    EXPECT_LT(sim.world().velocity[i].z, real(1)) << "sphere " << i << " was not";
}

// A pile at rest, its spheres numbered at random, stepped on with the
// numbering changed at every step: the warm start goes with the spheres
// (each cached impulse to its pair, turned round where the pair swaps).
// Here every cell of the broad phase holds one sphere, so the order of
// the pairs, the colours and every sum do not depend on the numbering: the
// renumbered run gives the plain run's bits (an impulse not turned round
// would not), and the pile stays at rest.
TEST(Renumber, APileAtRestStaysAtRest) {
  using scene::Effect;
  scene::Scene s = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::friction}, 0, 0.5);
  const real r = real(0.01);
  const int side = 8, layers = 6;
  s.walls.push_back(box({0, 0, 0}, {2 * r * side, 2 * r * side, 2 * r * (layers + 2)}));
  scene::GeneratedParticles g;
  std::vector<Vec3> at;
  for (int z = 0; z < layers; ++z)
    for (int y = 0; y < side; ++y)
      for (int x = 0; x < side; ++x) at.push_back({r * (2 * x + 1), r * (2 * y + 1), r * (2 * z + 1)});
  std::shuffle(at.begin(), at.end(), std::mt19937_64(3));
  for (const Vec3& p : at) add_sphere(g, p, r);
  Simulation settle(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < 200; ++k) settle.step();
  const World rest = settle.world();
  const StepState state = settle.save_state();

  std::uint64_t hash[2] = {0, 0};
  auto fastest = [&](int renumber) {
    scene::Scene sr = s;
    sr.solver.renumber = renumber;
    Simulation sim(sr, make_world(sr, g), broadphase::Backend::cpu);
    sim.restore(rest, state, 200);
    real top = 0;
    for (int k = 0; k < 100; ++k) {
      sim.step();
      top = std::max(top, sim.world().max_speed());
    }
    EXPECT_EQ(sim.ids().empty(), renumber == 0);
    hash[renumber] = state_hash(sim.world());
    return top;
  };
  const real still = fastest(0), renumbered = fastest(1);
  const real g_dt = real(9.81e-3);
  std::printf("fastest sphere over 100 steps: %.3g m/s without renumbering, %.3g with (g dt = %.3g)\n",
              double(still), double(renumbered), double(g_dt));
  EXPECT_LT(still, g_dt);
  EXPECT_LT(renumbered, g_dt);
  EXPECT_EQ(hash[1], hash[0]);
}

// A speed whose travel in a substep is past the precision's range (the
// contact search's reach), the state itself still finite, ends the step as
// a state gone non-finite does: the watchdog's to repair, else to report
// with the step, not a broad-phase error (it was "broad phase: a centre or
// radius is not finite" with two spheres or more, exit 1 without a
// checkpoint).
TEST(Determinism, AReachPastThePrecisionIsANonFiniteState) {
  auto [s, g] = pour_scene(300, 8);
  s.time.dt = 4;  // a reach of |v| h: past the range for a speed of half of it
  World w = make_world(s, g);
  w.velocity[5] = Vec3{std::numeric_limits<real>::max() / 2, 0, 0};
  ASSERT_EQ(w.first_non_finite(), w.size()) << "premise: the state is finite";
  Simulation sim(s, w, broadphase::Backend::cpu);
  sim.set_watchdog(true);
  try {
    sim.step();
    ADD_FAILURE() << "the step went on";
  } catch (const WatchdogFailure& e) {
    EXPECT_NE(std::string(e.what()).find("step 1: non-finite state"), std::string::npos) << e.what();
  }
}

// The watchdog in a renumbering scene: a try that went non-finite is rolled
// back, and world() shows the redone step, not the failed try; the fault and
// the watchdog's message name the scene's sphere 0; a step that fails every
// try leaves world() at the step's start.
TEST(Renumber, TheWatchdogsRollbackIsWhatTheWorldShows) {
  auto [s, g] = pour_scene(300, 8);
  s.solver.renumber = 2;
  auto swap_first_and_last = [](auto& v) {  // sphere 0 on top (arrays left empty stay so)
    if (!v.empty()) std::swap(v.front(), v.back());
  };
  swap_first_and_last(g.position);
  swap_first_and_last(g.velocity);
  swap_first_and_last(g.radius);
  swap_first_and_last(g.angular_velocity);
  swap_first_and_last(g.material);
  swap_first_and_last(g.fixed);
  Simulation sim(s, make_world(s, g), broadphase::Backend::cpu);
  sim.set_watchdog(true);
  for (int k = 0; k < 6; ++k) sim.step();
  const std::vector<std::uint32_t>& ids = sim.ids();
  ASSERT_FALSE(ids.empty());
  ASSERT_NE(std::find(ids.begin(), ids.end(), 0u) - ids.begin(), 0) << "the scene's sphere 0 elsewhere in the step";
  sim.inject_fault_at(sim.steps() + 1);
  sim.step();
  ASSERT_EQ(sim.last_rollbacks().size(), 1u);
  EXPECT_EQ(sim.last_rollbacks()[0], "non-finite state (sphere 0)");
  EXPECT_EQ(sim.world().first_non_finite(), sim.world().size());
  expect_a_failed_step_leaves_its_start(sim);
}
