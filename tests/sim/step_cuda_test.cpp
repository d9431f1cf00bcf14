// The CUDA step against the CPU step, bit for bit: the same scenes through
// both backends give equal states after every step (same per-element
// functions, same coloured order, no FMA contraction). Also: the CUDA step
// repeats itself exactly, edits of the host copy reach the device, and the
// contacts come back in the CPU's order. Label `gpu`; every case skips,
// saying so, without a CUDA device.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>
#include <random>
#include <set>
#include <string>

#include "broadphase/grid.hpp"
#include "core/device.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/colouring_math.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contact_cache_math.hpp"
#include "narrowphase/solver.hpp"
#include "sim/step_backend.hpp"
#include "sim/step_model.hpp"
#include "tests/require_device.hpp"
#include "tests/sim/test_scenes.hpp"
#include "tests/sim/watchdog_cases.hpp"

#if defined(MARBLES_HAVE_CUDA)
#include <cuda_runtime.h>
#endif

using namespace marbles;
using namespace marbles::testing;
using scene::Effect;

namespace {

// The solve's form MARBLES_CUDA_SOLVE asks for (sim/cuda_step.cu): auto
// (unset), launches (a launch per colour, a sweep's turn one launch),
// apart (the same, the turn's range launched for each sweep) or one (one
// launch a substep).
std::string solve_form() {
  const char* asked = std::getenv("MARBLES_CUDA_SOLVE");
  return asked ? asked : "auto";
}

// Whether every sphere has the same radius, bit for bit.
bool one_radius(const World& w) {
  for (std::size_t i = 1; i < w.size(); ++i)
    if (std::memcmp(&w.radius[i], &w.radius[0], sizeof(real)) != 0) return false;
  return true;
}

// The bytes of the part of the step's device memory named `name`
// (StepBackend::device_buffers).
std::size_t part(const std::vector<DeviceBytes>& parts, const std::string& name) {
  for (const DeviceBytes& p : parts)
    if (p.name == name) return p.bytes;
  ADD_FAILURE() << "no part named " << name;
  return 0;
}

// The two states equal bit for bit.
void expect_same_state(const World& a, const World& b, int step) {
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a.position[i], b.position[i]) << "step " << step << " sphere " << i;
    ASSERT_EQ(a.velocity[i], b.velocity[i]) << "step " << step << " sphere " << i;
    ASSERT_EQ(a.angular_velocity[i], b.angular_velocity[i]) << "step " << step << " sphere " << i;
  }
}

// What the GPU's steps did, added up over the steps of expect_same_steps.
struct GpuCounts {
  std::uint64_t one_launch = 0;    // substeps whose solve took one launch
  std::uint64_t cluster = 0;       // one-launch stages run as one cluster
  std::uint64_t turns = 0;         // sweep launches that visited a turn's range twice
  std::uint64_t groups = 0;        // launches that walked a run of small ranges in one block
  std::uint64_t solved = 0;        // steps with contacts (the CPU's count)
  std::uint64_t pair_redos = 0;    // substeps whose broad phase outgrew its pairs' room and ran again
  std::uint64_t grid_replans = 0;  // of those, the grid outgrew the broad phase's plan
  std::uint64_t grid_shrinks = 0;  // substeps whose grid found the plan outsized: the next one plans
  std::uint64_t trims = 0;         // buffers freed at a step's start, held beyond their need
  std::uint64_t unwaited = 0;      // substeps that waited for nothing (one wait a step)
  std::uint64_t undone = 0;        // of those, outgrew a room: put back and done again with waits
  std::uint32_t causes = 0;        // what those outgrew: UndoCause bits, or-ed
};

// The undo causes' names, for messages.
std::string cause_names(std::uint32_t causes) {
  std::string names;
  for (const std::string& name : undo_cause_names(causes)) names += (names.empty() ? "" : ",") + name;
  return names.empty() ? "none" : names;
}

// Where a step waits once (MARBLES_CUDA_WAITS): auto (unset: where the
// solve takes one launch), step (every step) or substep (none).
std::string waits_form() {
  const char* asked = std::getenv("MARBLES_CUDA_WAITS");
  return asked ? asked : "auto";
}

// Steps both backends side by side; the first step whose states differ
// fails. The GPU's records leave the arms word out exactly where every
// contact has the same (one radius and uniform pairs: UniformArms).
void expect_same_steps(Simulation& cpu, Simulation& gpu, int steps, GpuCounts& counts) {
  const std::string form = solve_form();
  const bool uniform_arms = gpu.model().uniform_pairs && one_radius(cpu.world());
  for (int k = 0; k < steps; ++k) {
    cpu.step();
    gpu.step();
    counts.one_launch += gpu.last_step().one_launch_solves;
    counts.cluster += gpu.last_step().cluster_stages;
    counts.turns += gpu.last_step().turn_launches;
    counts.groups += gpu.last_step().range_groups;
    counts.pair_redos += gpu.last_step().pair_redos;
    counts.grid_replans += gpu.last_step().grid_replans;
    counts.grid_shrinks += gpu.last_step().grid_shrinks;
    counts.trims += gpu.last_step().buffer_trims;
    counts.unwaited += gpu.last_step().unwaited_substeps;
    counts.undone += gpu.last_step().undone_substeps;
    counts.causes |= gpu.last_step().undo_causes;
    ASSERT_EQ(gpu.last_step().undo_causes != 0, gpu.last_step().undone_substeps > 0)
        << "step " << k << ": an undo names what its substep outgrew, and only an undo ("
        << cause_names(gpu.last_step().undo_causes) << ")";
    // (a step the watchdog split ran its substeps 2^rollbacks times over)
    ASSERT_LE(gpu.last_step().unwaited_substeps,
              static_cast<std::uint64_t>(gpu.substeps()) << gpu.last_rollbacks().size())
        << "step " << k;
    if (cpu.last_step().contacts > 0) counts.solved += 1;
    if (form == "one") {
      ASSERT_EQ(gpu.last_step().one_launch_solves > 0, cpu.last_step().contacts > 0) << "step " << k;
    }
    ASSERT_EQ(gpu.last_step().uniform_arms > 0, uniform_arms && cpu.last_step().contacts > 0) << "step " << k;
    ASSERT_EQ(gpu.last_step().candidate_pairs, cpu.last_step().candidate_pairs) << "step " << k;
    ASSERT_EQ(gpu.last_step().contacts, cpu.last_step().contacts) << "step " << k;
    ASSERT_EQ(gpu.last_step().colours, cpu.last_step().colours) << "step " << k;
    ASSERT_EQ(gpu.last_step().overflow, cpu.last_step().overflow) << "step " << k;
    ASSERT_EQ(gpu.last_step().projection_sweeps, cpu.last_step().projection_sweeps) << "step " << k;
    ASSERT_EQ(gpu.last_step().max_overlap, cpu.last_step().max_overlap) << "step " << k;
    ASSERT_EQ(gpu.last_step().unswept_depth, cpu.last_step().unswept_depth) << "step " << k;
    ASSERT_EQ(gpu.last_step().unswept_unchecked, cpu.last_step().unswept_unchecked) << "step " << k;
    ASSERT_EQ(gpu.last_rollbacks(), cpu.last_rollbacks()) << "step " << k;
    ASSERT_EQ(gpu.last_kept(), cpu.last_kept()) << "step " << k;
    if (k % 10 == 9 || k + 1 == steps) {
      expect_same_state(cpu.world(), gpu.world(), k);
      if (::testing::Test::HasFatalFailure()) return;
    }
  }
}

// Whether MARBLES_CUDA_GROUP=0 asks for no group of small ranges.
bool groups_off() {
  const char* asked = std::getenv("MARBLES_CUDA_GROUP");
  return asked && std::strcmp(asked, "0") == 0;
}

// Whether a run of `steps` steps of a small scene (every scene here: its
// solve takes one launch unless MARBLES_CUDA_SOLVE asks for a launch per
// colour) runs substeps without a wait: every step after the first, where a
// step waits once in every step (MARBLES_CUDA_WAITS=step: a launch per slot
// of the device's plan under launches or apart) or where the solve takes one
// launch (auto).
bool unwaits(int steps) {
  const std::string form = solve_form(), waits = waits_form();
  if (waits == "substep" || steps < 2) return false;
  return waits == "step" || (form != "launches" && form != "apart");
}

// A run of both backends from the same scene (expect_same_steps). The GPU's
// solve takes the form asked for: never one launch when a launch per colour
// is asked, every substep with contacts in one when one is, and under auto
// one launch at least once (every scene here has small colours).
// `pair_redos` (if given) adds up the substeps whose broad phase outgrew
// its pairs' room and ran again; `grid_replans` those whose grid outgrew
// the broad phase's plan; `trims` the buffers trimmed to their need;
// `undone` the substeps that waited for nothing and outgrew a room. Some
// substep runs without a wait exactly where unwaits() says.
void expect_same_run(const scene::Scene& s, const scene::GeneratedParticles& g, int steps,
                     std::uint64_t* pair_redos = nullptr, std::uint64_t* grid_replans = nullptr,
                     std::uint64_t* trims = nullptr, std::uint64_t* undone = nullptr,
                     std::uint32_t* causes = nullptr, std::uint64_t* groups = nullptr) {
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  ASSERT_EQ(gpu.backend_name(), "cuda");
  GpuCounts counts;
  expect_same_steps(cpu, gpu, steps, counts);
  if (::testing::Test::HasFatalFailure()) return;
  if (pair_redos) *pair_redos += counts.pair_redos;
  if (grid_replans) *grid_replans += counts.grid_replans;
  if (trims) *trims += counts.trims;
  if (undone) *undone += counts.undone;
  if (causes) *causes |= counts.causes;
  if (groups) *groups += counts.groups;
  const std::string form = solve_form();
  // Runs of small ranges go as one launch only where the solve takes a
  // launch per range (never under MARBLES_CUDA_SOLVE=one), and never with
  // MARBLES_CUDA_GROUP=0.
  if (form == "one" || groups_off()) {
    EXPECT_EQ(counts.groups, 0u) << "MARBLES_CUDA_SOLVE=" << form << ", MARBLES_CUDA_GROUP=0: " << groups_off();
  }
  EXPECT_EQ(counts.unwaited > 0, unwaits(steps))
      << counts.unwaited << " substeps without a wait; MARBLES_CUDA_WAITS=" << waits_form() << ", solve " << form;
  // A walk of two sweeps or more turns on a range it then visits twice in
  // one launch (visit_sweeps), unless the turns are asked apart.
  const bool turns = gpu.model().solver.iterations > 1 && counts.solved > 0;
  if (form == "launches" || form == "apart") {
    EXPECT_EQ(counts.one_launch, 0u);
    // Merged with a wait a substep or without (by the device plan's slots).
    EXPECT_EQ(counts.turns > 0, form == "launches" && turns) << "MARBLES_CUDA_SOLVE=" << form;
  } else if (counts.solved > 0) {
    EXPECT_GT(counts.one_launch, 0u) << "MARBLES_CUDA_SOLVE=" << form;
  }
  // The one-launch stages (the projection at least: every scene here
  // projects) take one cluster where the device and the build's code allow
  // clusters of 16 blocks (an H100 or H200 with this build's default sm_90
  // code: these scenes' colours are all narrower than 16 blocks' threads)
  // under MARBLES_CUDA_CLUSTER's default; never where clusters are not
  // allowed (code for another architecture: -DCMAKE_CUDA_ARCHITECTURES=80)
  // or where it is 0. Smaller clusters, or another width, ask nothing here.
  const char* widest = std::getenv("MARBLES_CUDA_CLUSTER");
  const int blocks = cuda_cluster_blocks();
  if (counts.solved > 0 && (!widest || std::strtol(widest, nullptr, 10) == 0) && (blocks == 0 || blocks >= 16)) {
    EXPECT_EQ(counts.cluster > 0, !widest && blocks > 0)
        << counts.cluster << " stages as one cluster; MARBLES_CUDA_CLUSTER=" << (widest ? widest : "unset")
        << ", clusters of " << blocks << " blocks here";
  }
}

// Touching spheres of radius r on an nx x ny x nz lattice, one radius in
// from the walls at x = y = 0, the lowest layer's bottom at height z0.
scene::GeneratedParticles dense_block(int nx, int ny, int nz, real r, real z0) {
  scene::GeneratedParticles g;
  for (int x = 0; x < nx; ++x)
    for (int y = 0; y < ny; ++y)
      for (int z = 0; z < nz; ++z) add_sphere(g, {r * (2 * x + 2), r * (2 * y + 2), z0 + r * (2 * z + 1)}, r);
  return g;
}

// Both backends under the order MARBLES_SOLVE_ORDER (or SolveOrder) asks
// for, step by step; the GPU's positions at the end. A local order runs its
// own launches, never the one-launch solve.
std::vector<Vec3> run_in_order(const scene::Scene& s, const scene::GeneratedParticles& g, int steps) {
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  EXPECT_EQ(gpu.backend_name(), "cuda");
  GpuCounts counts;
  expect_same_steps(cpu, gpu, steps, counts);
  if (narrowphase::local_order_from_environment()) {
    EXPECT_EQ(counts.one_launch, 0u) << "the local order runs its own launches";
  }
  return gpu.world().position;
}

// The last substep's contacts as the host gets them: the CPU's, every field
// bit for bit (the GPU makes them from its records: contact_of_record); the
// first contact that differs fails.
void expect_same_contacts(Simulation& cpu, Simulation& gpu) {
  const auto& cc = cpu.contacts();
  const auto& gc = gpu.contacts();
  ASSERT_EQ(gc.size(), cc.size());
  for (std::size_t k = 0; k < cc.size(); ++k)
    ASSERT_EQ(std::memcmp(&gc[k], &cc[k], sizeof(narrowphase::Contact)), 0) << "contact " << k;
}

// Every contact term on (restitution, friction, rolling and twisting
// resistance), one material, in a small box at rest.
scene::Scene every_term_box() {
  scene::Scene s = make_scene(1e-3, 2, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction, Effect::rolling_resistance},
                              0.3, 0.5, 0.02, 0.01);
  s.walls.push_back(box({0, 0, 0}, {real(0.2), real(0.2), real(0.5)}));
  return s;
}

// A bed of 20 x 20 spheres of radius r on a floor (friction, no
// restitution), `spacing` radii apart, their centres `height` radii up.
std::pair<scene::Scene, scene::GeneratedParticles> bed_on_a_floor(real spacing, real height, real r) {
  scene::Scene s = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::friction}, 0, 0.5);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::GeneratedParticles g;
  for (int x = 0; x < 20; ++x)
    for (int y = 0; y < 20; ++y) add_sphere(g, {spacing * r * (x + 1), spacing * r * (y + 1), height * r}, r);
  return {s, g};
}

// A large sphere on a floor with small ones on its upper half, each touching
// it: more contacts on one sphere than there are colours, so the overflow
// set (solved one by one, in order, forwards and backwards) is never empty.
std::pair<scene::Scene, scene::GeneratedParticles> overflow_scene() {
  scene::Scene s = make_scene(1e-3, 2, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction}, 0.4, 0.5);
  s.walls.push_back(box({0, 0, 0}, {real(0.6), real(0.6), real(1)}));
  const real big = real(0.1), r = real(0.01);
  const Vec3 centre{real(0.3), real(0.3), big};
  scene::GeneratedParticles g;
  add_sphere(g, centre, big);
  const int small = 150;  // on a Fibonacci spiral over the upper half, about 2.2 r apart
  for (int k = 0; k < small; ++k) {
    const double z = 1 - (k + 0.5) / small, ring = std::sqrt(1 - z * z), phi = 2.399963229728653 * k;
    const Vec3 n{real(ring * std::cos(phi)), real(ring * std::sin(phi)), real(z)};
    add_sphere(g, centre + n * (big + r * real(0.98)), r);
  }
  return {s, g};
}

}  // namespace

// Without a device the CUDA step is refused with a message that says so,
// before it touches the CUDA runtime (where a device is present, the rest of
// this file runs instead).
TEST(StepCuda, RefusedWithoutADevice) {
  if (marbles::cuda_device().available) GTEST_SKIP() << "a CUDA device is present";
  auto [s, g] = pour_scene(50, 1);
  try {
    Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
    FAIL() << "the CUDA step was made without a device";
  } catch (const RuntimeFailure& e) {
    const std::string what = e.what();
    EXPECT_TRUE(what.find("no CUDA device") != std::string::npos || what.find("no CUDA backend") != std::string::npos)
        << what;
  }
}

// The velocity sweep, which waits on its bodies' loads, in its form for
// wide ranges keeps at least three blocks of 256 threads a multiprocessor in
// float (its launch bound: unbounded, the sweep with friction and rolling
// takes 94 registers and two blocks), and no instance of either form uses
// local memory (spills).
TEST(StepCuda, WideSweepKeepsThreeBlocksASmAndNoSweepSpills) {
  REQUIRE_DEVICE();
  const std::vector<KernelFit> fits = cuda_sweep_kernel_fits();
  ASSERT_EQ(fits.size(), 16u);
  for (std::size_t i = 0; i < fits.size(); ++i) {
    const bool wide = i >= 8;
    const std::string which = std::string(wide ? "wide" : "narrow") + ", friction " + (i & 4 ? "on" : "off") +
                              ", rolling " + (i & 2 ? "on" : "off") + (i & 1 ? ", twice" : "");
    std::printf("sweep, %s: %d registers, %zu local bytes, %d blocks a SM\n", which.c_str(), fits[i].registers,
                fits[i].local_bytes, fits[i].blocks_per_sm);
    EXPECT_EQ(fits[i].local_bytes, 0u) << which;
    if (wide && sizeof(real) == 4) {
      EXPECT_GE(fits[i].blocks_per_sm, 3) << which;
    }
  }
}

// Values written into the step's own arrays from outside (as Python's views
// do, on the device with CUDA) are checked where they live: a NaN, or a
// speed finite but past float's range once squared (its energy inf), makes
// state_finite() false on both backends alike; back in range, true again.
TEST(StepCuda, StateWrittenFromOutsideIsCheckedWhereItLives) {
  REQUIRE_DEVICE();
#if defined(MARBLES_HAVE_CUDA)
  auto [s, g] = pour_scene(100, 3);
  const real big = real(2) * std::sqrt(std::numeric_limits<real>::max());
  for (const broadphase::Backend backend : {broadphase::Backend::cpu, broadphase::Backend::cuda}) {
    SCOPED_TRACE(backend == broadphase::Backend::cuda ? "cuda" : "cpu");
    Simulation sim(s, make_world(s, g), backend);
    sim.step();
    const Vec3 good = sim.world().velocity[5];
    const BodiesView v = sim.state_in_place();
    const auto write = [&](Vec3* at, const Vec3& value) {
      if (backend == broadphase::Backend::cuda)
        ASSERT_EQ(cudaMemcpy(at, &value, sizeof value, cudaMemcpyHostToDevice), cudaSuccess);
      else
        *at = value;
      sim.state_written();
    };
    EXPECT_TRUE(sim.state_finite());
    write(v.velocity + 5, Vec3(big, 0, 0));
    EXPECT_FALSE(sim.state_finite());
    write(v.velocity + 5, good);
    EXPECT_TRUE(sim.state_finite());
    write(v.angular_velocity + 7, Vec3(0, std::numeric_limits<real>::quiet_NaN(), 0));
    EXPECT_FALSE(sim.state_finite());
    write(v.angular_velocity + 7, Vec3{});
    write(v.position + 9, Vec3(0, 0, big));
    EXPECT_FALSE(sim.state_finite());
  }
#endif
}

TEST(StepCuda, PourMatchesTheCpuBitForBit) {
  REQUIRE_DEVICE();
  auto [s, g] = pour_scene(400, 3);
  std::uint64_t trims = 0, undone = 0, groups = 0;
  expect_same_run(s, g, 400, nullptr, nullptr, &trims, &undone, nullptr, &groups);
  std::printf("substeps undone in the pour: %llu\n", static_cast<unsigned long long>(undone));
  // A launch per colour with a wait a substep (MARBLES_CUDA_SOLVE=launches
  // or apart): the pour's colours, all small, go as groups of ranges
  // (RangeGroup), the same bits as above.
  const std::string form = solve_form();
  if ((form == "launches" || form == "apart") && waits_form() != "step" && !groups_off()) {
    EXPECT_GT(groups, 0u);
  }
  std::printf("launches of grouped ranges in the pour: %llu\n", static_cast<unsigned long long>(groups));
  // Trimmed every step (ctest step_cuda_test.trim_every_step), the pour's
  // falling need (a substep's impact words gone) frees buffers: the bits
  // above held across them. Not where a step waits once: it lays its records
  // out for the rooms and keeps impact words while the pour lands, so its
  // need does not fall within these steps (TrimmedBuffers* below trim so).
  const char* every = std::getenv("MARBLES_CUDA_TRIM_EVERY");
  if (every && std::strcmp(every, "1") == 0 && !unwaits(400)) {
    EXPECT_GT(trims, 0u);
  }
  std::printf("buffers trimmed in the pour: %llu\n", static_cast<unsigned long long>(trims));
}

// The watchdog on both backends (marbles run's default): the cache's
// entries kept at each step's start without a copy (ContactCacheCuda::keep,
// two sets written in turn), the pour's steps the CPU's bit for bit. Then
// the highest sphere is sent down at 10 m/s mid-pour (on both: an edit),
// so every sphere's speculative reach grows tenfold and the candidate pairs
// jump in the next step's first substep: without a wait that substep is
// undone, its store skipped in the set it moved to (back_to_kept), and the
// redone step must warm-start from the kept entries, which differ from
// the other set's (the pour's impulses change from step to step). Then a
// try rolled back and redone on both alike; and a step that fails every
// try leaves the world and the cache as they were at its start.
TEST(StepCuda, WatchdogKeepsTheCacheWithoutACopy) {
  REQUIRE_DEVICE();
  auto [s, g] = pour_scene(400, 3);
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  cpu.set_watchdog(true);
  gpu.set_watchdog(true);
  GpuCounts counts;
  expect_same_steps(cpu, gpu, 120, counts);
  ASSERT_FALSE(HasFatalFailure());
  const std::uint64_t undone_before = counts.undone;
  for (Simulation* sim : {&cpu, &gpu}) {
    World& w = sim->edit_world();
    const auto top = std::max_element(w.position.begin(), w.position.end(),
                                      [](const Vec3& a, const Vec3& b) { return a.z < b.z; }) -
                     w.position.begin();
    w.velocity[top] = {0, 0, -10};
  }
  expect_same_steps(cpu, gpu, 30, counts);
  ASSERT_FALSE(HasFatalFailure());
  std::printf("substeps undone in the watched pour: %llu, after the kick %llu\n",
              static_cast<unsigned long long>(undone_before),
              static_cast<unsigned long long>(counts.undone - undone_before));
  EXPECT_EQ(counts.undone > undone_before, unwaits(150)) << "the kick's pairs outgrow their room without a wait";
  cpu.inject_fault_at(cpu.steps() + 1);
  gpu.inject_fault_at(gpu.steps() + 1);
  expect_same_steps(cpu, gpu, 1, counts);
  ASSERT_FALSE(HasFatalFailure());
  ASSERT_EQ(gpu.last_rollbacks().size(), 1u);
  EXPECT_EQ(gpu.last_rollbacks(), cpu.last_rollbacks());
  expect_same_steps(cpu, gpu, 20, counts);
  ASSERT_FALSE(HasFatalFailure());
  expect_a_failed_step_leaves_its_start(gpu);
}

// The unswept check (sim/watch_math.hpp) on the device as on the CPU: a
// row struck into a wall within a substep (found, the step split), 70 such
// rows (each checked: found, split), 480 (more spheres past their reach
// than are checked at 2 400 spheres: split unchecked),
// and a sphere struck at 100 m/s with dt = 1/60 s (past even the finest
// substep: kept and counted). The same rollbacks, reasons and bits.
TEST(StepCuda, UnsweptMotionIsCheckedAsOnTheCpu) {
  REQUIRE_DEVICE();
  GpuCounts counts;
  for (const int copies : {1, 70, 480}) {
    auto [s, g] = struck_row_scene(copies);
    Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
    Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
    cpu.set_watchdog(true);
    gpu.set_watchdog(true);
    cpu.step();
    gpu.step();
    ASSERT_FALSE(cpu.last_rollbacks().empty()) << "the case this test is about: the row's first step is split";
    EXPECT_EQ(gpu.last_rollbacks(), cpu.last_rollbacks());
    expect_same_state(cpu.world(), gpu.world(), 0);
    expect_same_steps(cpu, gpu, 20, counts);
    ASSERT_FALSE(HasFatalFailure());
    EXPECT_EQ(gpu.rollbacks(), cpu.rollbacks());
  }
  auto [s, g] = struck_through_scene();
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  cpu.set_watchdog(true);
  gpu.set_watchdog(true);
  expect_same_steps(cpu, gpu, 3, counts);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_GE(cpu.unswept_kept(), 1u);
  EXPECT_EQ(gpu.unswept_kept(), cpu.unswept_kept());
}

// The accuracy knobs: velocity Verlet (its half kicks and its wall impacts at
// the accelerated time of impact) and speculative contacts off.
TEST(StepCuda, VerletAndNoSpeculativePoursMatchTheCpuBitForBit) {
  REQUIRE_DEVICE();
  for (const bool speculative : {true, false}) {
    auto [s, g] = pour_scene(400, 3);
    s.solver.integrator = "velocity_verlet";
    s.solver.speculative = speculative;
    expect_same_run(s, g, 300);
  }
}

// Drag on both integrators: symplectic Euler's implicit kick, and velocity
// Verlet's two halves (gravity and drag in one kick, then each after the
// drift), linear and quadratic.
TEST(StepCuda, DragPoursMatchTheCpuBitForBit) {
  REQUIRE_DEVICE();
  for (const char* integrator : {"symplectic_euler", "velocity_verlet"}) {
    auto [s, g] = pour_scene(400, 5);
    s.effects.push_back(scene::Effect::drag);
    s.drag = 0.8;
    s.drag_quadratic = 0.5;
    s.solver.integrator = integrator;
    expect_same_run(s, g, 300);
  }
}

// solver.renumber: both backends number the spheres again at the same steps
// from the same host copies (Simulation::renumber), the GPU's world and
// cache sent up again: the same bits, seen in the scene's numbering.
TEST(StepCuda, RenumberedPourMatchesTheCpuBitForBit) {
  REQUIRE_DEVICE();
  auto [s, g] = pour_scene(1000, 7);
  s.solver.renumber = 3;
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  GpuCounts counts;
  expect_same_steps(cpu, gpu, 120, counts);
  EXPECT_FALSE(gpu.ids().empty());
  EXPECT_EQ(gpu.ids(), cpu.ids());
}

// Whether two arrays hold the same bits.
template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

namespace {

// A world of n random spheres (polydisperse, a few a cell, so the sort's
// stability counts), random velocities and spins.
World random_world(const scene::Scene& s, std::uint32_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  scene::GeneratedParticles g;
  for (std::uint32_t i = 0; i < n; ++i)
    add_sphere(g, {real(0.3 * u(rng)), real(0.3 * u(rng)), real(u(rng))}, real(0.004 + 0.008 * u(rng)),
               {real(u(rng) - 0.5), real(u(rng) - 0.5), real(u(rng) - 0.5)}, static_cast<std::uint32_t>(rng() % 2));
  World world = make_world(s, g);
  for (Vec3& w : world.angular_velocity) w = {real(u(rng) - 0.5), real(u(rng) - 0.5), real(u(rng) - 0.5)};
  return world;
}

// Random cache keys of spheres below n: 0 to 4 a sphere, a quarter of them
// walls, the rest pairs that the numbering may turn round.
std::set<std::uint64_t> random_keys(std::uint32_t n, std::mt19937_64& rng) {
  std::set<std::uint64_t> keys;
  for (std::uint32_t a = 0; a + 1 < n; ++a)
    for (std::uint64_t k = rng() % 5; k > 0; --k) {
      const std::uint32_t b = rng() % 4 == 0 ? narrowphase::kWallFlag | static_cast<std::uint32_t>(rng() % 3)
                                             : a + 1 + static_cast<std::uint32_t>(rng() % (n - a - 1));
      keys.insert(narrowphase::cache_key(a, b));
    }
  return keys;
}

// Entries of `keys` with random impulses (idle ones, +0 and -0 among the
// components) and colours (some none).
narrowphase::CacheEntries random_cache(const std::set<std::uint64_t>& keys, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  narrowphase::CacheEntries cache;
  cache.resize(keys.size());
  const real signed_zero[] = {real(0), -real(0)};
  auto component = [&] { return rng() % 4 == 0 ? signed_zero[rng() % 2] : real(u(rng) - 0.5); };
  std::size_t k = 0;
  for (std::uint64_t key : keys) {
    cache.key[k] = key;
    cache.normal_impulse[k] = rng() % 3 == 0 ? real(0) : real(u(rng));
    cache.tangent_impulse[k] = {component(), component(), component()};
    cache.rolling_impulse[k] = {component(), component(), component()};
    cache.colour[k] = rng() % 5 == 0 ? narrowphase::kNoKeptColour : static_cast<std::uint8_t>(rng() % 24);
    ++k;
  }
  return cache;
}

// Both backends number their spheres again: the same order, the same bits
// of every array and of every cache entry. Returns the CPU's order and
// cache after.
struct Numbered {
  std::vector<std::uint32_t> order;
  narrowphase::CacheEntries cache;
};
Numbered expect_same_numbering(StepBackend& cpu, StepBackend& gpu) {
  const SphereOrder cpu_order = cpu.renumber(), gpu_order = gpu.renumber();
  std::vector<std::uint32_t> order(cpu_order.begin(), cpu_order.end());
  EXPECT_FALSE(order.empty()) << "a random world must be numbered again";
  EXPECT_EQ(std::vector<std::uint32_t>(gpu_order.begin(), gpu_order.end()), order);
  const World& c = cpu.world();
  const World& d = gpu.world();
  EXPECT_TRUE(same_bits(d.position, c.position));
  EXPECT_TRUE(same_bits(d.velocity, c.velocity));
  EXPECT_TRUE(same_bits(d.angular_velocity, c.angular_velocity));
  EXPECT_TRUE(same_bits(d.radius, c.radius));
  EXPECT_TRUE(same_bits(d.inv_mass, c.inv_mass));
  EXPECT_TRUE(same_bits(d.inv_inertia, c.inv_inertia));
  EXPECT_TRUE(same_bits(d.material, c.material));
  narrowphase::CacheEntries hc = cpu.save_state().cache, dc = gpu.save_state().cache;
  EXPECT_EQ(dc.key, hc.key);
  EXPECT_TRUE(same_bits(dc.normal_impulse, hc.normal_impulse));
  EXPECT_TRUE(same_bits(dc.tangent_impulse, hc.tangent_impulse));
  EXPECT_TRUE(same_bits(dc.rolling_impulse, hc.rolling_impulse));
  EXPECT_EQ(dc.colour, hc.colour);
  return {std::move(order), std::move(hc)};
}

}  // namespace

// A renumbering on the device (StepBackend::renumber: home keys sorted,
// arrays gathered, the cache's entries renamed and counted into their new
// runs on the GPU) against the CPU's (cell_order, permuted, renumbered on
// host arrays): the same order and the same bits, on a random world with a
// random cache (pairs that turn round, walls, idle entries, -0 and +0,
// colours, and three entries of spheres past the world, which both drop).
// A host edit just before it reaches both; a second numbering changes
// nothing.
TEST(StepCuda, RenumberOnTheDeviceIsTheCpusBitForBit) {
  REQUIRE_DEVICE();
  auto [s, ignored] = pour_scene(1, 1);
  std::mt19937_64 rng(20261127);
  const std::uint32_t n = 6000;
  const World world = random_world(s, n, rng);
  std::set<std::uint64_t> keys = random_keys(n, rng);
  const std::size_t in_the_world = keys.size();
  keys.insert(narrowphase::cache_key(5, n + 2));
  keys.insert(narrowphase::cache_key(n + 1, n + 4));
  keys.insert(narrowphase::cache_key(n + 3, narrowphase::kWallFlag | 1));
  const narrowphase::CacheEntries cache = random_cache(keys, rng);
  const StepModel model = compile_step_model(s, broadphase::kDefaultCpuAlgorithm);
  ASSERT_TRUE(model.solver.friction && model.solver.rolling) << "the cache must keep both impulses";
  auto cpu = make_cpu_step(model, world);
  auto gpu = make_cuda_step(model, world);
  const StepState state{cache, model.wall_shapes};
  cpu->load_state(state);
  gpu->load_state(state);
  cpu->edit_world().velocity[17] = {1, 2, 3};
  gpu->edit_world().velocity[17] = {1, 2, 3};
  (void)gpu->world();  // a host copy read before: the numbering must leave it stale

  const auto [order, hc] = expect_same_numbering(*cpu, *gpu);
  EXPECT_EQ(cpu->world().velocity[inverse_of(order)[17]], Vec3(1, 2, 3));
  ASSERT_EQ(hc.size(), in_the_world);
  std::size_t turned = 0;
  for (std::size_t e = 0; e < hc.size(); ++e) turned += hc.key[e] != cache.key[e] ? 1 : 0;
  EXPECT_GT(turned, hc.size() / 2) << "the numbering must rename most entries";

  EXPECT_TRUE(cpu->renumber().empty());
  EXPECT_TRUE(gpu->renumber().empty());
}

// A world that gained spheres since its cache was stored (an edit between
// steps, half as many again): the device reads its old runs before their
// room grows for the new spheres. The same order and bits as the CPU's,
// with friction and rolling resistance and without either (the device's
// cache then keeps neither impulse: a frictionless store leaves them zero).
TEST(StepCuda, RenumberAfterTheWorldGrewIsTheCpus) {
  REQUIRE_DEVICE();
  for (const bool frictionless : {false, true}) {
    SCOPED_TRACE(frictionless ? "frictionless" : "friction and rolling resistance");
    auto [s, ignored] = pour_scene(1, 1);
    if (frictionless)
      std::erase_if(s.effects, [](Effect e) { return e == Effect::friction || e == Effect::rolling_resistance; });
    std::mt19937_64 rng(20261128);
    const std::uint32_t n = 4000, added = 2000;
    const World all = random_world(s, n + added, rng);
    World first = all;
    for (auto* v : {&first.position, &first.velocity, &first.angular_velocity}) v->resize(n);
    for (auto* v : {&first.radius, &first.inv_mass, &first.inv_inertia}) v->resize(n);
    first.material.resize(n);
    narrowphase::CacheEntries cache = random_cache(random_keys(n, rng), rng);
    const StepModel model = compile_step_model(s, broadphase::kDefaultCpuAlgorithm);
    ASSERT_EQ(model.solver.friction, !frictionless);
    if (frictionless) {
      std::fill(cache.tangent_impulse.begin(), cache.tangent_impulse.end(), Vec3{});
      std::fill(cache.rolling_impulse.begin(), cache.rolling_impulse.end(), Vec3{});
    }
    auto cpu = make_cpu_step(model, first);
    auto gpu = make_cuda_step(model, first);
    const StepState state{cache, model.wall_shapes};
    cpu->load_state(state);
    gpu->load_state(state);
    cpu->edit_world() = all;
    gpu->edit_world() = all;
    const narrowphase::CacheEntries hc = expect_same_numbering(*cpu, *gpu).cache;
    EXPECT_EQ(hc.size(), cache.size()) << "every entry names spheres of the grown world";
  }
}

// The same without rolling resistance (the cache keeps no rolling
// impulses: the device's numbering skips them) and numbered every other
// step, so each numbering renames a cache the last step stored (its room
// past the entries included).
TEST(StepCuda, RenumberedPourWithoutRollingMatchesTheCpu) {
  REQUIRE_DEVICE();
  auto [s, g] = pour_scene(800, 11);
  s.effects.erase(std::remove(s.effects.begin(), s.effects.end(), Effect::rolling_resistance), s.effects.end());
  s.solver.renumber = 2;
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  ASSERT_FALSE(gpu.model().solver.rolling);
  GpuCounts counts;
  expect_same_steps(cpu, gpu, 80, counts);
  EXPECT_FALSE(gpu.ids().empty());
  EXPECT_EQ(gpu.ids(), cpu.ids());
}

// Without friction or rolling resistance the device's records keep the
// normal impulse alone (SweepRecords::normal): a pour, impacts and a
// settling heap, the CPU's bits every step and every field of every contact
// at the end, in the solve's form MARBLES_CUDA_SOLVE asks for (ctest runs
// both).
TEST(StepCuda, PourWithoutFrictionMatchesTheCpu) {
  REQUIRE_DEVICE();
  auto [s, g] = pour_scene(800, 13);
  std::erase_if(s.effects, [](Effect e) { return e == Effect::friction || e == Effect::rolling_resistance; });
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  ASSERT_FALSE(gpu.model().solver.friction);
  ASSERT_FALSE(gpu.model().solver.rolling);
  GpuCounts counts;
  expect_same_steps(cpu, gpu, 150, counts);
  if (::testing::Test::HasFatalFailure()) return;
  EXPECT_GT(counts.solved, 0u);
  expect_same_contacts(cpu, gpu);
}

TEST(StepCuda, LargerPourMatchesTheCpuBitForBit) {
  REQUIRE_DEVICE();
  auto [s, g] = pour_scene(3000, 5);
  expect_same_run(s, g, 150);
}

// A dense block (touching spheres on a lattice) dropped onto a floor: the
// contact count jumps from the block's own to thousands more in one step;
// every contact is kept (the CPU's, one for one).
TEST(StepCuda, DroppedDenseBlockKeepsEveryContact) {
  REQUIRE_DEVICE();
  scene::Scene s = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction}, 0.2, 0.5);
  const real r = real(0.01);
  s.walls.push_back(box({0, 0, 0}, {real(0.5), real(0.5), real(1)}));
  expect_same_run(s, dense_block(24, 24, 12, r, real(0.02)), 120);
}

// A bed of spheres kept apart (gaps of 0.8 radii) and a ball falling
// towards it from far above: once the ball passes 4 m/s, every sphere's
// speculative reach (the fastest sphere's travel in a substep) closes the
// bed's gaps, and the candidate pairs jump from none to every neighbour in
// one substep, past the room the last substep's count left them. The step
// finds them again with room for them: no pair and no bit is lost.
TEST(StepCuda, PairCountJumpRedoesTheBroadPhase) {
  REQUIRE_DEVICE();
  const real r = real(0.01);
  auto [s, g] = bed_on_a_floor(real(2.8), 1, r);
  add_sphere(g, {real(0.3), real(0.3), real(0.3)}, r, {0, 0, real(-3.95)});
  Simulation probe(s, make_world(s, g), broadphase::Backend::cpu);
  probe.step();
  const std::uint64_t pairs_before = probe.last_step().candidate_pairs;
  for (int k = 0; k < 20; ++k) probe.step();
  ASSERT_GT(probe.last_step().candidate_pairs, 8 * (pairs_before + 64)) << "the scene must make the pairs jump";
  std::uint64_t redos = 0, undone = 0;
  std::uint32_t causes = 0;
  expect_same_run(s, g, 20, &redos, nullptr, nullptr, &undone, &causes);
  EXPECT_GT(redos, 0u) << "the jump must outgrow the pairs' room";
  EXPECT_EQ(undone > 0, unwaits(20)) << "without a wait, the substep that outgrew it is undone and done again";
  if (undone > 0) {
    EXPECT_TRUE(causes & kUndoPairs) << "undone for " << cause_names(causes);
  }
}

// A ball shot up and away from a bed at 112 m/s: the centres' bounds, and with
// them the broad phase's grid (chosen on the device from bounds the host
// does not read), grow by three cells a step, past the plan the host laid the
// broad phase's buffers out for (dense lower bounds a quarter larger than
// the grid it read last) every few steps. Each time the substep finds its
// pairs again, waiting for the bounds and planning from them: no pair and
// no bit is lost.
TEST(StepCuda, GridOutgrowingItsPlanIsPlannedAgain) {
  REQUIRE_DEVICE();
  const real r = real(0.01);
  auto [s, g] = bed_on_a_floor(real(2.8), 1, r);
  add_sphere(g, {real(0.3), real(0.3), real(0.05)}, r, {real(100), real(0), real(50)});
  std::uint64_t redos = 0, replans = 0, undone = 0;
  std::uint32_t causes = 0;
  expect_same_run(s, g, 80, &redos, &replans, nullptr, &undone, &causes);
  EXPECT_EQ(undone > 0, unwaits(80)) << "without a wait, a substep whose grid outgrew the plan is undone";
  if (undone > 0) {
    EXPECT_TRUE(causes & kUndoGrid) << "undone for " << cause_names(causes);
  }
  // Each plan holds a quarter more cells (and 1024) than the grid it was
  // made from, so the ball's flight outgrows it at shorter and shorter
  // intervals of its growing grid: four in these 80 steps by grid.hpp's
  // plan_of and plan_fits over the CPU's states (shot at 20 m/s up for 40
  // steps, as this test had it, the ball outgrew it once since contacts take
  // the normal of the moment of touch, twice before: the start's line of
  // centres to the bed spheres it flies over had acted on it).
  EXPECT_GE(replans, 2u) << "the growing grid must outgrow the plan, and again";
  EXPECT_GE(redos, replans) << "a replan is a redo";
}

// The study of a local order (MARBLES_SOLVE_ORDER) on the CUDA step: the
// CPU's bits (LocalSweepsCuda). Cubes of a few diameters split the pour
// into many, with contacts between them. The order reaches the GPU: its
// bits differ from the solver's order's.
TEST(StepCuda, LocalOrderStudyMatchesTheCpu) {
  REQUIRE_DEVICE();
  auto [pour, grains] = pour_scene(400, 3);
  const std::vector<Vec3> solver_order = run_in_order(pour, grains, 150);
  if (HasFatalFailure()) return;
  {
    SolveOrder order("tiles:3:3:4");
    EXPECT_NE(run_in_order(pour, grains, 150), solver_order) << "another order, other bits";
    if (HasFatalFailure()) return;
  }
  SolveOrder order("tiles:2:2:3");
  run_in_order(pour, grains, 100);
}

// The local order's small cases (short enough for the sanitizers): the
// dense block with every term in cubes of three diameters, and the
// overflow scene in cubes of half the large sphere's diameter, which keep
// its overflow set in its own cube (one thread's walk, forwards and
// backwards) and put others between cubes.
TEST(StepCuda, LocalOrderSmallCasesMatchTheCpu) {
  REQUIRE_DEVICE();
  {
    SolveOrder order("tiles:3:3:4");
    run_in_order(every_term_box(), dense_block(7, 5, 3, real(0.01), real(0.005)), 30);
    if (HasFatalFailure()) return;
  }
  SolveOrder order("tiles:0.5:2:3");
  auto [s, g] = overflow_scene();
  Simulation probe(s, make_world(s, g), broadphase::Backend::cpu);
  probe.step();
  ASSERT_GT(probe.last_step().overflow, 0u) << "the scene must fill every colour";
  run_in_order(s, g, 60);
}

// A free ball moved far out along x, then back above the bed (the same
// edit on both backends): far out, the grid outgrows the broad phase's plan
// once (27 key bits against 15: four sort digits against two, and binary
// search); back, the grid fits that plan but finds it outsized (the premise
// from the host's grids), and the next substep plans from its bounds, once.
// The CPU's bits throughout.
TEST(StepCuda, PlanShrinksWithItsGrid) {
  REQUIRE_DEVICE();
  const real r = real(0.01);
  auto [s, g] = bed_on_a_floor(real(2.8), 1, r);
  add_sphere(g, {real(0.3), real(0.3), real(0.3)}, r);
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  const std::size_t ball = cpu.world().size() - 1;
  auto move_ball = [&](real x) {
    for (Simulation* sim : {&cpu, &gpu}) {
      World& w = sim->edit_world();
      w.position[ball] = {x, real(0.3), real(0.3)};
      w.velocity[ball] = {0, 0, 0};
    }
  };
  // The home grid of the world's radii (the broad phase's are a little
  // larger, swept: the premise is about sort digits, a dozen key bits apart).
  auto grid_of = [&] {
    const World& w = cpu.world();
    return broadphase::choose_home_grid(broadphase::bounds_of({w.position.data(), w.radius.data(), w.size()}), 0);
  };
  GpuCounts counts;
  expect_same_steps(cpu, gpu, 5, counts);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(counts.grid_shrinks, 0u) << "the first plan is the bed's own";
  move_ball(real(3000));
  expect_same_steps(cpu, gpu, 5, counts);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(counts.grid_replans, 1u) << "far out, the grid outgrows the bed's plan, once";
  const broadphase::HomeGridChoice far = grid_of();
  move_ball(real(0.3));
  const broadphase::HomeGridChoice near = grid_of();
  const std::size_t n = cpu.world().size();
  ASSERT_TRUE(broadphase::plan_outsized(broadphase::plan_of(far.grid, far.width, n), near.grid, n)) << "premise";
  const std::uint64_t shrinks_far = counts.grid_shrinks;
  expect_same_steps(cpu, gpu, 5, counts);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(shrinks_far, 0u) << "far out, the plan is the far grid's own";
  EXPECT_EQ(counts.grid_shrinks, 1u) << "back, the plan is found outsized once, then planned from the bed";
  EXPECT_EQ(counts.grid_replans, 1u) << "back, the bed's grid fits the far plan: no grid outgrows one";
}

// A layer of spheres kept far apart (4 radii) hovering 0.3 radii above a
// floor: they fall together, and in one substep every sphere's speculative
// reach meets the floor, so the contacts jump from none to 400, past the
// room the last substep's count left them. The step finds them again with
// room for them: no contact and no bit is lost.
TEST(StepCuda, ContactCountJumpFindsTheContactsAgain) {
  REQUIRE_DEVICE();
  auto [s, g] = bed_on_a_floor(4, real(1.3), real(0.01));
  Simulation probe(s, make_world(s, g), broadphase::Backend::cpu);
  probe.step();
  ASSERT_EQ(probe.last_step().contacts, 0u) << "the layer must start clear of the floor";
  for (int k = 0; k < 40; ++k) probe.step();
  ASSERT_EQ(probe.last_step().contacts, 400u) << "the scene must make the contacts jump";
  std::uint64_t redos = 0, undone = 0;
  std::uint32_t causes = 0;
  expect_same_run(s, g, 40, &redos, nullptr, nullptr, &undone, &causes);
  EXPECT_GT(redos, 0u) << "the jump must outgrow the contacts' room";
  EXPECT_EQ(undone > 0, unwaits(40)) << "without a wait, the substep that outgrew it is undone and done again";
  if (undone > 0) {
    EXPECT_TRUE(causes & kUndoContacts) << "undone for " << cause_names(causes);
  }
}

// The same layer with four substeps a step: its contacts jump in a later
// substep of a step (the premise, from the CPU's count: 400 a substep once
// they touch), so the substeps before it stand, the one that outgrew the
// room is put back to its own start (not the step's) and it and the rest
// are done again with waits: the CPU's bits every step. Where the jump's
// step ran without waits, its undo came after a substep without one.
TEST(StepCuda, ContactCountJumpInALaterSubstepIsUndoneThere) {
  REQUIRE_DEVICE();
  auto [s, g] = bed_on_a_floor(4, real(1.3), real(0.01));
  s.time.substeps = 4;
  Simulation probe(s, make_world(s, g), broadphase::Backend::cpu);
  int first = -1;
  std::uint64_t touching = 0;
  for (int k = 0; k < 80 && first < 0; ++k) {
    probe.step();
    if (probe.last_step().contacts > 0) first = k, touching = probe.last_step().contacts;
  }
  ASSERT_GE(first, 1) << "the layer must start clear of the floor";
  ASSERT_EQ(touching % 400, 0u) << "premise: all 400 touch at once";
  ASSERT_LT(touching, 4u * 400u) << "premise: the contacts jump after the step's first substep";
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  GpuCounts counts;
  for (int k = 0; k <= first + 2; ++k) {
    const std::uint64_t undone = counts.undone;
    expect_same_steps(cpu, gpu, 1, counts);  // every step's counts and state
    ASSERT_FALSE(HasFatalFailure()) << "step " << k;
    if (k == first && counts.undone > undone) {
      EXPECT_GT(gpu.last_step().unwaited_substeps, 0u) << "the substeps before the jump stand";
    }
  }
  EXPECT_EQ(counts.undone > 0, unwaits(first + 3)) << "without a wait, the substep that outgrew it is undone";
  if (counts.undone > 0) {
    EXPECT_TRUE(counts.causes & kUndoContacts) << "undone for " << cause_names(counts.causes);
  }
}

// Forty pairs of touching spheres at rest, far apart (one colour), and six
// spheres closing on a seventh along the axes, all six the same distance
// away (exact binary coordinates: they meet it in the same step): in one
// step the seventh takes six contacts, so the colours jump from one to six
// or more, while the contacts grow by six, within their room. Where a step
// waits once and launches a sweep per slot of the device's plan (the last
// step's colours and one more, for a new colour or the overflow set:
// MARBLES_CUDA_WAITS=step with a launch per colour), the colours outgrow the
// slots and that substep is undone and done again with waits; in every other
// form nothing outgrows a room. The CPU's bits every step.
TEST(StepCuda, ColourCountJumpPastTheSlotsIsUndone) {
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::friction}, 0, 0.5);
  const real r = real(1.0 / 128), v = 1, h = real(1e-3);
  scene::GeneratedParticles g;
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 5; ++y) {
      const Vec3 p{real(x) / 16, real(y) / 16, 0};
      add_sphere(g, p, r);
      add_sphere(g, p + Vec3{2 * r, 0, 0}, r);
    }
  const Vec3 centre{real(0.25), real(0.5), real(0.25)};
  add_sphere(g, centre, r);
  const real from = 2 * r + real(8.5) * v * h;  // 8.5 substeps of travel from the centre: meets it in step 7
  for (const Vec3 n : {Vec3{1, 0, 0}, Vec3{-1, 0, 0}, Vec3{0, 1, 0}, Vec3{0, -1, 0}, Vec3{0, 0, 1}, Vec3{0, 0, -1}})
    add_sphere(g, centre + n * from, r, n * -v);
  constexpr int kSteps = 14;
  Simulation probe(s, make_world(s, g), broadphase::Backend::cpu);
  std::uint32_t colours = 0;
  std::uint64_t contacts = 0;
  int jump = -1;
  for (int k = 0; k < kSteps; ++k) {
    probe.step();
    if (jump < 0 && probe.last_step().colours >= colours + 2) {
      jump = k;
      EXPECT_LE(probe.last_step().contacts, contacts + 6) << "premise: the contacts grow by the six alone";
    }
    colours = probe.last_step().colours, contacts = probe.last_step().contacts;
  }
  ASSERT_GE(jump, 2) << "premise: the colours jump by two or more in a step after the first two";
  ASSERT_LT(jump, kSteps - 1);
  REQUIRE_DEVICE();
  std::uint64_t redos = 0, undone = 0;
  std::uint32_t causes = 0;
  expect_same_run(s, g, kSteps, &redos, nullptr, nullptr, &undone, &causes);
  const std::string form = solve_form();
  const bool slots = waits_form() == "step" && (form == "launches" || form == "apart");
  EXPECT_EQ(undone > 0, slots) << "MARBLES_CUDA_WAITS=" << waits_form() << ", solve " << form;
  EXPECT_EQ(redos, 0u) << "the pairs fit their room";
  if (undone > 0) {
    EXPECT_TRUE(causes & kUndoColours) << "undone for " << cause_names(causes);
    EXPECT_FALSE(causes & (kUndoPairs | kUndoContacts | kUndoGrid)) << "undone for " << cause_names(causes);
  }
}

// A layer of 40 000 spheres kept apart falls onto a floor. Its first steps
// have no contacts, so under auto the solve takes one launch and the steps
// run without waits, keeping each substep's start. Once the layer lands,
// its wall contacts take one colour (walls take none), wider than one
// launch takes (32 768), so the steps wait a substep, and a few steps later
// the start is let go: the device memory's "substep's start" part is 0 at
// the end. Where every step waits once (MARBLES_CUDA_WAITS=step) or the
// solve always takes one launch (MARBLES_CUDA_SOLVE=one) it is held; where
// no step runs without waits it is never there. Where it goes, it goes
// within a few steps of the landing. Where it is held, it is the velocities
// alone (nothing else of the state is written before a substep's check).
// The CPU's bits at the end.
TEST(StepCuda, SubstepStartLetGoWhereTheSolveOutgrowsOneLaunch) {
  scene::Scene s = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::friction}, 0, 0.5);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  const real r = real(0.01);
  scene::GeneratedParticles g;
  for (int x = 0; x < 200; ++x)
    for (int y = 0; y < 200; ++y) add_sphere(g, {real(3) * r * (x + 1), real(3) * r * (y + 1), real(1.3) * r}, r);
  constexpr int kSteps = 60;
  REQUIRE_DEVICE();
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  std::size_t held_most = 0, held_last = 0;
  std::uint64_t first_contacts = 0;
  int landed = -1, let_go = -1;  // the first step with contacts; the first after it holding no start
  for (int k = 0; k < kSteps; ++k) {
    cpu.step(), gpu.step();
    if (k == 0) first_contacts = cpu.last_step().contacts;
    if (landed < 0 && cpu.last_step().contacts > 0) landed = k;
    held_last = part(gpu.device_buffers(), "substep's start");
    held_most = std::max(held_most, held_last);
    if (landed >= 0 && let_go < 0 && held_last == 0) let_go = k;
  }
  ASSERT_EQ(first_contacts, 0u) << "premise: the layer starts clear of the floor";
  ASSERT_EQ(cpu.last_step().contacts, g.position.size()) << "premise: every sphere has landed";
  const std::string form = solve_form(), waits = waits_form();
  if (form == "auto") {
    EXPECT_EQ(gpu.last_step().one_launch_solves, 0u) << "premise: the landed layer's colour outgrows one launch";
  }
  EXPECT_EQ(held_most > 0, unwaits(kSteps)) << "MARBLES_CUDA_WAITS=" << waits << ", solve " << form;
  EXPECT_EQ(held_last > 0, waits == "step" || (waits == "auto" && form == "one"))
      << "MARBLES_CUDA_WAITS=" << waits << ", solve " << form << ": " << held_last << " bytes held at the end";
  if (held_most > 0) {
    EXPECT_EQ(held_most, g.position.size() * sizeof(Vec3)) << "the substep's start: the velocities alone";
  }
  if (held_most > 0 && held_last == 0) {
    EXPECT_LE(let_go, landed + 8) << "let go within a few steps of the landing (the step that outgrew one launch)";
  }
  EXPECT_EQ(state_hash(gpu.world()), state_hash(cpu.world()));
}

// A small block (105 spheres, 7 x 5 x 3: no kernel's block is full) with
// every contact term on, dropped onto the floor of a box: the partial runs
// of the block-staged contact writes, gathers and record packs. Short enough
// to run under compute-sanitizer (scripts/gpu-check).
TEST(StepCuda, SmallDenseBlockWithEveryTermMatchesTheCpu) {
  REQUIRE_DEVICE();
  expect_same_run(every_term_box(), dense_block(7, 5, 3, real(0.01), real(0.005)), 30);
}

// A large sphere on a floor with small ones on its upper half, each touching
// it: more contacts on one sphere than there are colours, so the overflow
// set (solved one by one, in order, forwards and backwards) is never empty.
TEST(StepCuda, OverflowSetMatchesTheCpu) {
  auto [s, g] = overflow_scene();
  Simulation probe(s, make_world(s, g), broadphase::Backend::cpu);
  probe.step();
  ASSERT_GT(probe.last_step().overflow, 0u) << "the scene must fill every colour";
  REQUIRE_DEVICE();
  expect_same_run(s, g, 100);
}

// A glued floor (fixed spheres overlapping their neighbours by half a
// radius, no contacts among them on either backend) under a block falling
// onto it, with every contact term: the CPU's bits.
TEST(StepCuda, GluedFloorMatchesTheCpu) {
  const real r = real(0.01);
  scene::GeneratedParticles g = dense_block(6, 6, 3, r, real(0.03));
  const std::size_t free = g.size();
  for (int x = 0; x < 12; ++x)
    for (int y = 0; y < 12; ++y) add_sphere(g, {r * (real(1.5) * x + 1), r * (real(1.5) * y + 1), r}, r);
  g.fixed.assign(g.size(), 0);
  for (std::size_t i = free; i < g.size(); ++i) g.fixed[i] = 1;
  const scene::Scene s = every_term_box();
  Simulation probe(s, make_world(s, g), broadphase::Backend::cpu);
  for (int k = 0; k < 30; ++k) probe.step();
  std::size_t on_floor = 0;
  for (const narrowphase::Contact& c : probe.contacts()) {
    ASSERT_FALSE(c.a >= free && !narrowphase::is_wall(c.b) && c.b >= free) << "a contact between two fixed spheres";
    on_floor += (c.a >= free) != (!narrowphase::is_wall(c.b) && c.b >= free);
  }
  ASSERT_GT(on_floor, 0u) << "the block must reach the floor";
  REQUIRE_DEVICE();
  expect_same_run(s, g, 60);
}

TEST(StepCuda, NewtonsCradleMatchesTheCpu) {
  REQUIRE_DEVICE();
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::restitution}, 1.0);
  const real r = real(0.05);
  scene::GeneratedParticles g;
  add_sphere(g, {real(-0.2), 0, 0}, r, {1, 0, 0});
  for (int k = 1; k < 5; ++k) add_sphere(g, {real(2 * r * (k - 1)), 0, 0}, r);
  expect_same_run(s, g, 300);
}

// A block of one radius and one material (records without the arms word),
// then one sphere made a little smaller on both backends (the arms word
// again, found on the device from the radii), then its radius put back:
// the CPU's bits throughout, the records' form following the radii, and
// the contacts the host gets the CPU's, from impact words and from
// approach speeds alone.
TEST(StepCuda, RecordsFollowAnEditedRadius) {
  REQUIRE_DEVICE();
  const scene::Scene s = every_term_box();
  const real r = real(0.01);
  const scene::GeneratedParticles g = dense_block(6, 5, 4, r, real(0.002));
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  ASSERT_TRUE(gpu.model().uniform_pairs);
  const real radii[3] = {r, real(0.97) * r, r};
  std::uint64_t calm = 0, hit = 0;  // steps whose substeps kept approach speeds only, or impact words
  for (int phase = 0; phase < 3; ++phase) {
    for (Simulation* sim : {&cpu, &gpu}) sim->edit_world().radius[17] = radii[phase];
    for (int k = 0; k < 25; ++k) {
      cpu.step(), gpu.step();
      ASSERT_GT(cpu.last_step().contacts, 0u);
      // A step that waits once lays its records out as the last step's
      // contacts asked: the arms word one step longer once the radii agree
      // again (an edit that makes them differ is found and the step done
      // again with it).
      const bool lag = phase == 2 && k == 0 && unwaits(2);
      ASSERT_EQ(gpu.last_step().uniform_arms > 0, phase != 1 && !lag) << "phase " << phase << " step " << k;
      ASSERT_EQ(state_hash(gpu.world()), state_hash(cpu.world())) << "phase " << phase << " step " << k;
      calm += gpu.last_step().impact_words == 0 ? 1 : 0;
      hit += gpu.last_step().impact_words > 0 ? 1 : 0;
      if (k % 8 == 7) expect_same_contacts(cpu, gpu);
    }
  }
  EXPECT_GT(calm, 0u);  // both forms of the impact stage's words were made and read back
  EXPECT_GT(hit, 0u);
}

TEST(StepCuda, RepeatsItselfAndTakesEdits) {
  REQUIRE_DEVICE();
  auto [s, g] = pour_scene(400, 8);
  auto run = [&](bool edit) {
    Simulation sim(s, make_world(s, g), broadphase::Backend::cuda);
    for (int k = 0; k < 100; ++k) sim.step();
    if (edit) sim.edit_world().velocity[7] = {0, 0, 3};
    for (int k = 0; k < 100; ++k) sim.step();
    return state_hash(sim.world());
  };
  const std::uint64_t first = run(false);
  EXPECT_EQ(run(false), first);
  EXPECT_NE(run(true), first) << "an edit of the host copy must reach the device";

  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  for (int k = 0; k < 100; ++k) cpu.step(), gpu.step();
  cpu.edit_world().velocity[7] = {0, 0, 3};
  gpu.edit_world().velocity[7] = {0, 0, 3};
  for (int k = 0; k < 100; ++k) cpu.step(), gpu.step();
  EXPECT_EQ(state_hash(gpu.world()), state_hash(cpu.world()));
  expect_same_contacts(cpu, gpu);
}

// The island rule (a lost load cold-starts its island) runs on the device
// (min-label propagation): lifting the heavy top off a stack gives the CPU's
// state, and the stack below does not jump (it would, at ~0.2 m/s, without
// the rule: Stability.RemovingTheHeavyTopDoesNotLaunchTheStack).
TEST(StepCuda, LostLoadMatchesTheCpu) {
  REQUIRE_DEVICE();
  scene::Scene s = make_scene(2e-3, 2, {Effect::gravity, Effect::collisions, Effect::walls, Effect::friction}, 0.3, 0.5);
  scene::Material heavy = s.materials[0];
  heavy.name = "heavy";
  heavy.density = 100 * s.materials[0].density;
  s.materials.push_back(heavy);
  const real r = real(0.02);
  scene::WallSpec tube;
  tube.kind = scene::WallSpec::Kind::cylinder;
  tube.radius = 1.02 * r;
  s.walls.push_back(tube);
  s.walls.push_back(plane({0, 0, 0}, {0, 0, 1}));
  scene::GeneratedParticles g;
  for (int k = 0; k < 6; ++k) add_sphere(g, {0, 0, r + 2 * r * k}, r, {}, k == 5 ? 1 : 0);
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  for (int k = 0; k < 300; ++k) cpu.step(), gpu.step();
  for (Simulation* sim : {&cpu, &gpu}) {
    sim->edit_world().position[5] = {10, 10, 10};
    sim->edit_world().velocity[5] = {};
  }
  for (int k = 0; k < 100; ++k) {
    cpu.step(), gpu.step();
    ASSERT_EQ(state_hash(gpu.world()), state_hash(cpu.world())) << "step " << k;
    for (int i = 0; i < 5; ++i) EXPECT_LT(gpu.world().velocity[i].z, 0.01) << "sphere " << i << " step " << k;
  }
}

// The device memory by part (what `marbles bench step` prints): each part
// at least what its arrays need for the step's spheres and contacts, the
// watchdog's copy there only once the watchdog keeps a step's start, and
// "runtime" last. Not held to device_bytes(): that is the device's free
// memory, which other processes move (the gpu tests run side by side).
TEST(StepCuda, DeviceBuffersAccountForTheStepsMemory) {
  REQUIRE_DEVICE();
  scene::Scene s = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction, Effect::rolling_resistance}, 0.2, 0.5, 0.02);
  const real r = real(0.01);
  s.walls.push_back(box({0, 0, 0}, {real(1.25), real(1.25), real(1)}));
  Simulation gpu(s, make_world(s, dense_block(60, 60, 30, r, real(0.02))), broadphase::Backend::cuda);
  const std::size_t n = gpu.world().size();
  for (int k = 0; k < 40; ++k) gpu.step();
  const std::uint64_t contacts = gpu.last_step().contacts;
  ASSERT_GT(contacts, n);  // a block resting in layers: several contacts a sphere
  const std::size_t entries = gpu.save_state().cache.size();
  ASSERT_GT(entries, n);  // the contacts, but for unloaded ones of the overflow set
  std::vector<DeviceBytes> parts = gpu.device_buffers();
  EXPECT_GE(part(parts, "world"), n * (3 * sizeof(Vec3) + 3 * sizeof(real)));
  // Impulse, rolling and geometry words and the body pair, at least.
  EXPECT_GE(part(parts, "records"), contacts * (3 * sizeof(narrowphase::Real4) + sizeof(narrowphase::BodyPair)));
  // One memory for what is live in turn: every contact's body pair (found,
  // read until the records are made), the solver bodies (the solve), the
  // store's temporaries (a count a sphere, a rank and an index a contact).
  const std::size_t pairs = contacts * sizeof(narrowphase::BodyPair);
  const std::size_t solver = n * sizeof(narrowphase::SolverBody);
  const std::size_t store = (n + 1) * sizeof(std::uint32_t) + contacts * 2 * sizeof(std::uint32_t);
  EXPECT_GE(part(parts, "contact pairs and solver bodies"), std::max({pairs, solver, store}));
  EXPECT_LT(part(parts, "contact pairs and solver bodies"), pairs + solver) << "not shared?";
  // The runs' firsts, then each entry's b, impulses and colour.
  EXPECT_GE(part(parts, "cache"), (n + 1) * sizeof(std::uint32_t) +
                                      entries * (sizeof(std::uint32_t) + 7 * sizeof(real) + sizeof(std::uint8_t)));
  // The broad phase's candidate pairs (at least the sphere contacts) at the
  // front of the records' memory (dead while contacts are searched), with a
  // flag and an offset each behind them; the broad phase holds none of its
  // own.
  const std::size_t candidates = contacts - n;
  EXPECT_GE(part(parts, "records"), candidates * (sizeof(broadphase::Pair) + 2 * sizeof(std::uint32_t)));
  EXPECT_LT(part(parts, "broad phase"), candidates * sizeof(broadphase::Pair));
  // The scratch holds only the colouring's temporaries and the restore's,
  // the largest of: the colouring's colours with either the impact levels'
  // round lists (8 bytes a contact) and a word a body (in the matches'
  // memory instead where it holds them; the colouring's lists and words are
  // in the records') or its counting sort (a word a contact for the order,
  // two a bucket and tile of 1024 contacts, at most 252 buckets: the impact
  // levels'); the restore's byte a contact and 13 a body. With the carve's
  // 256-byte alignment, its scans' storage and the buffer's headroom (a
  // sixteenth).
  // The arrays are sized for the contacts' room, not their count: a quarter
  // more at most (Room, after a count that outgrew its room).
  const std::size_t bodies = n + s.walls.size() + 1, room = contacts + contacts / 4 + 64;
  const std::size_t colouring = 4 * room + std::max(8 * room + 8 * bodies,
                                                    4 * room + 2 * 4 * (252 * (room / 1024 + 1) + 1));
  const std::size_t restore = room + 13 * bodies;
  const std::size_t largest = std::max(colouring, restore) + 64 * 1024;
  const std::size_t scratch = part(parts, "scratch");
  EXPECT_LE(scratch, largest + largest / 16 + 256) << "the contact search's temporaries in the scratch?";
  std::printf("device bytes a sphere: records %.1f, scratch %.1f (its bound %.1f); %.2f contacts a sphere\n",
              double(part(parts, "records")) / n, double(scratch) / n, double(largest) / n, double(contacts) / n);
  EXPECT_EQ(part(parts, "watchdog's copy"), 0u);
  if (!narrowphase::local_order_from_environment()) {
    EXPECT_EQ(part(parts, "local order"), 0u);
  }
  EXPECT_EQ(parts.back().name, "runtime");

  gpu.set_watchdog(true);
  gpu.step();
  parts = gpu.device_buffers();
  EXPECT_GE(part(parts, "watchdog's copy"), n * 3 * sizeof(Vec3));  // positions, velocities, angular velocities
}

namespace {

// One scene on the GPU twice: its buffers trimmed every step, and never.
struct TrimmedAndNot {
  TrimmedAndNot(const scene::Scene& s, const scene::GeneratedParticles& g) {
    {
      ScopedEnvironment every("MARBLES_CUDA_TRIM_EVERY", "1");
      trimmed.emplace(s, make_world(s, g), broadphase::Backend::cuda);
    }
    ScopedEnvironment never("MARBLES_CUDA_TRIM_EVERY", "0");
    untrimmed.emplace(s, make_world(s, g), broadphase::Backend::cuda);
  }
  std::optional<Simulation> trimmed, untrimmed;
};

}  // namespace

// A dense block dropped onto the floor of a box: its first substeps have
// impact candidates (impact words in the records, the impact levels'
// lists in the scratch), the later ones not. A step that trims its buffers
// every step gives the bits of one that never does, and once two steps in
// a row had no impact word, holds less: the records and scratch of its
// present need, where the untrimmed one still holds the landing's.
TEST(StepCuda, TrimmedBuffersFollowTheNeedWithTheSameBits) {
  REQUIRE_DEVICE();
  scene::Scene s = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction}, 0.2, 0.5);
  s.walls.push_back(box({0, 0, 0}, {real(0.5), real(0.5), real(1)}));
  TrimmedAndNot runs(s, dense_block(24, 24, 12, real(0.01), real(0.02)));
  Simulation& trimmed = *runs.trimmed;
  Simulation& untrimmed = *runs.untrimmed;
  std::uint64_t trims = 0, untrimmed_trims = 0, impact_steps = 0;
  bool quiet_before = false, found = false;
  for (int k = 0; k < 400 && !found; ++k) {
    trimmed.step();
    untrimmed.step();
    trims += trimmed.last_step().buffer_trims;
    untrimmed_trims += untrimmed.last_step().buffer_trims;
    ASSERT_EQ(trimmed.last_step().impact_words, untrimmed.last_step().impact_words) << "step " << k;
    const bool quiet = trimmed.last_step().impact_words == 0;
    impact_steps += quiet ? 0 : 1;
    found = impact_steps > 0 && quiet && quiet_before;  // the trim at this step's start saw a quiet step
    quiet_before = quiet;
    if (k % 10 == 9 || found) {
      expect_same_state(trimmed.world(), untrimmed.world(), k);
      if (::testing::Test::HasFatalFailure()) return;
    }
  }
  ASSERT_GT(impact_steps, 0u) << "the landing must have impact candidates";
  ASSERT_TRUE(found) << "the block must come to two steps in a row without impact candidates";
  EXPECT_GT(trims, 0u);
  EXPECT_EQ(untrimmed_trims, 0u);
  const std::vector<DeviceBytes> a = trimmed.device_buffers(), b = untrimmed.device_buffers();
  const std::size_t records = part(a, "records"), scratch = part(a, "scratch");
  std::printf("records %zu bytes trimmed, %zu untrimmed; scratch %zu, %zu; %zu spheres, %llu contacts\n", records,
              part(b, "records"), scratch, part(b, "scratch"), trimmed.world().size(),
              static_cast<unsigned long long>(trimmed.last_step().contacts));
  EXPECT_LE(records, part(b, "records"));
  EXPECT_LT(records + scratch, part(b, "records") + part(b, "scratch"));
  // What the step needs stays: the records of every contact at least.
  EXPECT_GE(records, trimmed.last_step().contacts * (2 * sizeof(narrowphase::Real4) + sizeof(narrowphase::BodyPair)));
}

// A dense block with every term dropped onto the floor of a box, a wait a
// substep: while it lands, the impact levels' colours, lists and order (12
// bytes a contact of the room at least, with their body words in the
// matches) take the cache's entries, dead from the records' making to the
// store, wherever those hold them (the room no larger than the last
// store's), so a step with impact words keeps a scratch below that (the
// colouring's colours and sort, the restore's), trimmed to its need every
// step. The CPU's bits all along.
TEST(StepCuda, ImpactLevelsTakeTheCachesDeadEntriesInAStepThatWaits) {
  REQUIRE_DEVICE();
  ScopedEnvironment waits("MARBLES_CUDA_WAITS", "substep");
  ScopedEnvironment every("MARBLES_CUDA_TRIM_EVERY", "1");
  scene::Scene s = make_scene(1e-3, 1, {Effect::gravity, Effect::collisions, Effect::walls, Effect::restitution,
                                        Effect::friction, Effect::rolling_resistance}, 0.2, 0.5, 0.02);
  s.walls.push_back(box({0, 0, 0}, {real(0.5), real(0.5), real(1)}));
  const scene::GeneratedParticles g = dense_block(24, 24, 12, real(0.01), real(0.02));
  Simulation cpu(s, make_world(s, g), broadphase::Backend::cpu);
  Simulation gpu(s, make_world(s, g), broadphase::Backend::cuda);
  std::uint64_t impact_steps = 0, within = 0;
  for (int k = 0; k < 120; ++k) {
    cpu.step();
    gpu.step();
    if (gpu.last_step().impact_words == 0) continue;
    ++impact_steps;
    const std::size_t scratch = part(gpu.device_buffers(), "scratch");
    const std::uint64_t contacts = gpu.last_step().contacts;
    if (scratch < 12 * contacts) ++within;
    if (impact_steps <= 3 || scratch < 12 * contacts)
      std::printf("step %d: scratch %zu bytes, %llu contacts (%.2f bytes a contact)\n", k, scratch,
                  static_cast<unsigned long long>(contacts), double(scratch) / double(contacts));
  }
  expect_same_state(cpu.world(), gpu.world(), 120);
  ASSERT_GT(impact_steps, 0u) << "the landing must have impact candidates";
  EXPECT_GT(within, 0u) << "no step with impact words kept the impact levels out of the scratch";
}

// A block of touching spheres flying apart in empty space (no gravity, each
// sphere moving away from the centre): contacts at first, none once the
// gaps outgrow the contacts' reach. Trimmed every step, the step then holds
// less for its contacts (records, cache, the watchdog's copy of the cache)
// than one that never trims, with the same bits.
TEST(StepCuda, TrimmedBuffersFallWithTheContacts) {
  REQUIRE_DEVICE();
  scene::Scene s = make_scene(1e-3, 1, {Effect::collisions, Effect::restitution, Effect::friction,
                                        Effect::rolling_resistance}, 0.5, 0.5, 0.05);
  const real r = real(0.01);
  scene::GeneratedParticles g = dense_block(16, 16, 8, r, 0);
  Vec3 centre{};
  for (const Vec3& p : g.position) centre = centre + p;
  centre = centre / static_cast<real>(g.position.size());
  for (std::size_t i = 0; i < g.position.size(); ++i) g.velocity[i] = (g.position[i] - centre) * real(20);
  TrimmedAndNot runs(s, g);
  Simulation& trimmed = *runs.trimmed;
  Simulation& untrimmed = *runs.untrimmed;
  trimmed.set_watchdog(true);
  untrimmed.set_watchdog(true);
  trimmed.step();
  untrimmed.step();
  ASSERT_GT(trimmed.last_step().contacts, g.position.size()) << "the block must start touching";
  std::uint64_t trims = trimmed.last_step().buffer_trims;
  for (int k = 1; k < 60; ++k) {
    trimmed.step();
    untrimmed.step();
    trims += trimmed.last_step().buffer_trims;
    ASSERT_EQ(untrimmed.last_step().buffer_trims, 0u);
    ASSERT_EQ(trimmed.last_step().contacts, untrimmed.last_step().contacts) << "step " << k;
  }
  ASSERT_EQ(trimmed.last_step().contacts, 0u) << "the block must have flown apart";
  expect_same_state(trimmed.world(), untrimmed.world(), 60);
  if (::testing::Test::HasFatalFailure()) return;
  EXPECT_GT(trims, 0u);
  const std::vector<DeviceBytes> pa = trimmed.device_buffers(), pb = untrimmed.device_buffers();
  std::printf("records %zu bytes trimmed, %zu untrimmed; cache %zu, %zu; matches and colours %zu, %zu; "
              "watchdog's copy %zu, %zu\n",
              part(pa, "records"), part(pb, "records"), part(pa, "cache"), part(pb, "cache"),
              part(pa, "matches and colours"), part(pb, "matches and colours"), part(pa, "watchdog's copy"),
              part(pb, "watchdog's copy"));
  EXPECT_LT(part(pa, "watchdog's copy"), part(pb, "watchdog's copy"));
  EXPECT_LT(part(pa, "records"), part(pb, "records"));
  EXPECT_LT(part(pa, "cache"), part(pb, "cache"));
  EXPECT_LT(part(pa, "matches and colours"), part(pb, "matches and colours"));
}
