// sim/cuda_step.cu — the substep's verbs on device arrays (StepBackend).
//
// The world lives on the device (DeviceWorld) for the whole run; the host
// copy is refreshed only when world() is asked for (output, tests), and an
// edit of it is sent back before the next step. Each verb is one or a few
// launches over the stage twins (*_cuda.cuh), which call the per-element
// functions the CPU loops call, in the CPU's coloured order: CudaStep and
// CpuStep give the same bits.
//
// A contact is found as its body pair (8 bytes) and made whole once, in
// colour-major order, straight into the sweep's records and its approach
// speed, with impact candidates its impact words too (narrowphase/
// solver_math.hpp: ImpactRecords): the device
// holds no 112-byte Contact array. contacts() makes whole contacts from the
// records when the host asks.
//
// Host waits (docs/architecture.md "Fewer waits", "Fewer launches", "The
// pair count read with the contacts'", "The contact count read with the
// colours", "The grid chosen on the device"), per substep: the colouring's
// colour ranges and rounds run, read with the contact count, the broad
// phase's pair count and whether any contact is an impact candidate and
// whether the radii differ (one read); per step, the flags. The broad
// phase chooses its grid on the device, for the plan its last read of the
// bounds made; a grid past the plan leaves the pair count kNoPairCount,
// and the substep is found again with the waits of a first one; a plan the
// device finds outsized for its grid (read with the pair count) is made again
// at the next substep, which waits for its bounds. The pairs and
// the contacts go into rooms sized from the last substep's counts; a
// substep whose counts outgrow them finds them again (colour_contacts). The
// first substep waits for the counts before the colouring too. The cache's
// entry count, the lost-load count, the impact levels and the flags of the
// impact and projection passes stay on the device: those stages run as one
// launch each (a cooperative grid, or one cluster where they are small).
// Where the last step left rooms and its solve took one launch, a step waits
// once, at its end (MARBLES_CUDA_WAITS; one_wait_possible below): its
// substeps colour without reading the ranges back and check their counts on
// the device, and a substep that outgrew a room is undone and done again
// with waits (then kUndoHold steps wait a substep). Elsewhere (a solve of a
// launch per colour: the piles of 10^5 and up) a step waits once a substep
// and at its end, unless MARBLES_CUDA_WAITS=step (launches by slots of the
// device's plan: slower, solve_in_slots).
#include <cuda_runtime.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>

#include "broadphase/broadphase_cuda.hpp"
#include "core/cuda_check.hpp"
#include "core/device.hpp"
#include "core/environment.hpp"
#include "core/error.hpp"
#include "integrator/integrator_cuda.cuh"
#include "narrowphase/colouring.hpp"
#include "narrowphase/colouring_cuda.cuh"
#include "narrowphase/contact_cache_cuda.cuh"
#include "narrowphase/contacts_cuda.cuh"
#include "narrowphase/solver.hpp"
#include "narrowphase/solver_cuda.cuh"
#include "sim/device_world.cuh"
#include "sim/step_backend.hpp"
#include "sim/watch_math.hpp"

namespace marbles {
namespace {

namespace nc = narrowphase::cuda;
using ::marbles::cuda::DeviceBuffer;

constexpr int kWatchBlock = 256;

// The watchdog's figures (watch_math.hpp): out[0] the kinetic energy (a
// double, summed in no fixed order: it decides a rollback, it never reaches
// the state), out[1] the spheres beyond a wall.
__global__ void watch_kernel(BodiesView b, const narrowphase::WallShape* walls, std::uint32_t wall_count,
                             unsigned long long* out, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  double energy = 0;
  unsigned long long beyond = 0;
  for (std::size_t i = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x; i < b.count;
       i += std::size_t(gridDim.x) * blockDim.x) {
    energy += watch::kinetic_energy(b.velocity[i], b.angular_velocity[i], b.inv_mass[i], b.inv_inertia[i]);
    beyond += watch::beyond_walls(b.position[i], b.radius[i], walls, wall_count) ? 1 : 0;
  }
  for (int d = 16; d > 0; d /= 2) {
    energy += __shfl_down_sync(0xffffffffu, energy, d);
    beyond += __shfl_down_sync(0xffffffffu, beyond, d);
  }
  if ((threadIdx.x & 31) == 0) {
    if (energy != 0) atomicAdd(reinterpret_cast<double*>(out), energy);
    if (beyond != 0) atomicAdd(out + 1, beyond);
  }
}

// The unswept check (watch_math.hpp): the spheres the drift found past
// their reach (past[0] of them, the first `checked` from past[1] on)
// against the first `spheres` spheres (a thread a sphere: all of them, or
// none without collisions) and every wall (a thread a listed sphere, grid-stride); the deepest meeting's bits into *word by atomicMax (a
// maximum: the same whatever the order), or every bit where there were
// more than are checked.
__global__ void unswept_kernel(BodiesView b, std::size_t spheres, const narrowphase::WallShape* walls,
                               std::uint32_t wall_count, const std::uint32_t* past, std::uint32_t checked, real h,
                               unsigned long long* word, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  const std::uint32_t count = past[0];
  if (count == 0) return;
  const std::size_t first = blockIdx.x * std::size_t(blockDim.x) + threadIdx.x;
  if (count > checked) {
    if (first == 0) atomicMax(word, ~0ull);
    return;
  }
  real deepest = 0;
  for (std::size_t j = first; j < spheres; j += std::size_t(gridDim.x) * blockDim.x)
    for (std::uint32_t k = 0; k < count; ++k) {
      const real d = watch::unswept_pair(b, past[1 + k], j, h);
      deepest = d > deepest ? d : deepest;
    }
  for (std::size_t k = first; k < count; k += std::size_t(gridDim.x) * blockDim.x)
    for (std::uint32_t w = 0; w < wall_count; ++w) {
      const std::uint32_t i = past[1 + k];
      const real d = watch::wall_swept_deepening(walls[w], b.position[i], b.velocity[i], b.radius[i], h);
      deepest = d > deepest ? d : deepest;
    }
  ::marbles::cuda::warp_atomic_max(word, bits_of_real(deepest));
}

// The words of a step's one read (CudaStep::end_step), in m_flags: the
// flags of every step, then those a step without a wait a substep adds up
// on the device (check_substep_kernel).
enum StepWord {
  kNonFinite,         // integrate_positions: a state not finite
  kDeepest,           // the deepest overlap's bits (the step's last records)
  kProjectionSweeps,  // summed over substeps
  kKineticEnergy,     // with the watch: a double's bits
  kBeyondWalls,       // with the watch
  kUnswept,           // with the watch: the unswept check's deepest meeting's bits, max over substeps
                      // (every bit: more spheres past their reach than are checked)
  kRedo,              // 1 + the first substep that outgrew a room it was given (0: none), its UndoCause bits
                      // from bit 32 (kCauseShift); see cuda::skipped
  kMostPairs,         // the most candidate pairs of a substep (its room's next size)
  kMostContacts,      // the most contacts of a substep
  kCandidateSeen,     // some contact was an impact candidate
  kMixedSeen,         // some substep's radii were not all the same
  kOutsizedSeen,      // some substep's grid found the broad phase's plan outsized
  kMostColours,       // the most colours of a substep
  kWidest,            // its widest colour
  kOverflowSum,       // contacts of the overflow sets, summed
  kPairSum,           // candidate pairs, summed
  kContactSum,        // contacts, summed
  kGridPast,          // some substep's grid outgrew the broad phase's plan (no pairs)
  kLastContacts,      // the last substep's contacts
  kRadiusSeen,        // sphere 0's radius's bits (the last substep's)
  kSolvedSubsteps,    // substeps with contacts (each solved in one launch)
  kUniformSubsteps,   // of those, whose records held no arms word
  kImpactWordSubsteps,  // of those, whose records kept impact words
  kStepWords
};
constexpr int kFlagWords = kUnswept + 1;  // what a step with waits a substep reads
constexpr int kCauseShift = 32;                 // words[kRedo]: the substep below, its causes above
// After the step's words, where a step without waits launches by slots:
// each colour's most contacts in a substep (its slot's grid next step).
constexpr int kColourWords = static_cast<int>(narrowphase::kMaxColours);

// What a substep that waits for nothing gave, against the rooms and the
// records' form it was given (CudaStep::colour_contacts).
struct SubstepCheck {
  const std::uint32_t* pair_count = nullptr;  // the broad phase's (count, plan outsized); null: host_pairs
  std::uint32_t host_pairs = 0, pair_room = 0;
  const std::uint32_t* contact_count = nullptr;
  std::uint32_t contact_room = 0;
  const unsigned* seen = nullptr;  // [0] an impact candidate, [1] mixed radii, then sphere 0's radius
  bool words_kept = false;         // the records keep impact words
  bool candidates_fit = false;     // an impact candidate fits the records (words kept, or no restitution)
  bool uniform = false;            // the records hold no arms word, for radius (mixed radii outgrow them)
  real radius = 0;
  const narrowphase::ColourPlan* plan = nullptr;
  std::uint32_t slots = 0;  // the colours and the overflow set launched for (0: one launch walks any plan)
  std::uint32_t substep = 0;
};

// One thread: the substep's counts against its rooms; where one outgrew its
// room (or the records' form does not fit its contacts), the first such
// substep is named in words[kRedo], and from there on the kernels that
// write the state do nothing (cuda::skipped) and no figure is added up.
__global__ void check_substep_kernel(SubstepCheck c, unsigned long long* words) {
  if (blockIdx.x != 0 || threadIdx.x != 0 || words[kRedo] != 0) return;
  constexpr std::uint32_t kNoPairs = broadphase::SubdivisionCuda::kNoPairCount;
  const std::uint32_t pairs = c.pair_count ? c.pair_count[0] : c.host_pairs;
  const std::uint32_t contacts = *c.contact_count;
  const bool grid_past = pairs == kNoPairs;
  const bool candidate = c.seen[0] != 0, mixed = c.seen[1] != 0;
  real radius = 0;
  memcpy(&radius, c.seen + 2, sizeof(real));
  const narrowphase::ColourPlan& plan = *c.plan;
  std::uint32_t causes = 0;
  if (grid_past) causes |= kUndoGrid;
  else if (pairs > c.pair_room) causes |= kUndoPairs;
  if (contacts > c.contact_room) causes |= kUndoContacts;
  if (candidate && !c.candidates_fit) causes |= kUndoImpactWords;
  if (c.uniform && (mixed || bits_of_real(radius) != bits_of_real(c.radius))) causes |= kUndoArms;
  if (c.slots > 0 && !narrowphase::slots_hold(plan, c.slots)) causes |= kUndoColours;
  if (!grid_past && pairs > words[kMostPairs]) words[kMostPairs] = pairs;
  if (contacts > words[kMostContacts]) words[kMostContacts] = contacts;
  if (plan.colours > words[kMostColours]) words[kMostColours] = plan.colours;  // also the slots' next bound
  if (causes != 0) {
    words[kRedo] = (c.substep + 1ull) | static_cast<unsigned long long>(causes) << kCauseShift;
    if (grid_past) words[kGridPast] = 1;
    return;
  }
  if (candidate) words[kCandidateSeen] = 1;
  if (mixed) words[kMixedSeen] = 1;
  if (c.pair_count && c.pair_count[1] != 0) words[kOutsizedSeen] = 1;
  if (c.slots > 0) narrowphase::keep_most_per_colour(plan, words + kStepWords);
  const std::uint32_t widest = plan.widest();
  if (widest > words[kWidest]) words[kWidest] = widest;
  words[kOverflowSum] += plan.begin[plan.colours + 1] - plan.begin[plan.colours];
  words[kPairSum] += pairs;
  words[kContactSum] += contacts;
  words[kLastContacts] = contacts;
  words[kRadiusSeen] = bits_of_real(radius);
  if (contacts > 0) {  // as a step with waits counts its layouts: those of substeps with contacts
    ++words[kSolvedSubsteps];
    if (c.uniform) ++words[kUniformSubsteps];
    if (c.words_kept) ++words[kImpactWordSubsteps];
  }
}

// Where a step waits once, at its end, rather than once a substep and at
// its end (MARBLES_CUDA_WAITS): auto (the default) where the solve takes one
// launch (the small scenes: the wait was much of their step), step in every
// step (where the solve takes a launch per colour, a launch per slot of the
// device's plan: measured slower than the wait it saves, docs/architecture.md
// "One wait a step"), substep never (the earlier form, for comparisons).
// The same bits in every form.
enum class Waits { auto_, step, substep };
Waits waits_from_environment() {
  const char* asked = std::getenv("MARBLES_CUDA_WAITS");
  if (asked == nullptr || std::strcmp(asked, "auto") == 0) return Waits::auto_;
  if (std::strcmp(asked, "step") == 0) return Waits::step;
  if (std::strcmp(asked, "substep") == 0) return Waits::substep;
  throw RuntimeFailure(std::string("MARBLES_CUDA_WAITS=") + asked + ": expected auto, step or substep");
}

// How the solve is launched (MARBLES_CUDA_SOLVE): auto (the default), a
// launch per colour (launches; the range at a sweep's turn one launch that
// visits it twice, visit_sweeps), the same with that range launched again
// for the next sweep (apart: the earlier form, for comparisons), or the warm
// start and all sweeps in one launch (one). The same bits either way: a
// choice of speed, and the tests run each.
enum class SolveMode { auto_, launches, apart, one_launch };
SolveMode solve_mode_from_environment() {
  const char* asked = std::getenv("MARBLES_CUDA_SOLVE");
  if (asked == nullptr || std::strcmp(asked, "auto") == 0) return SolveMode::auto_;
  if (std::strcmp(asked, "launches") == 0) return SolveMode::launches;
  if (std::strcmp(asked, "apart") == 0) return SolveMode::apart;
  if (std::strcmp(asked, "one") == 0) return SolveMode::one_launch;
  throw RuntimeFailure(std::string("MARBLES_CUDA_SOLVE=") + asked + ": expected auto, launches, apart or one");
}

// How often (steps) the step's per-contact buffers are trimmed to their
// need (CudaStep::trim_buffers; MARBLES_CUDA_TRIM_EVERY, 0: never; the
// tests trim every step, the most often, against the CPU's bits).
constexpr int kTrimEvery = 16;
int trim_every_from_environment() {
  return static_cast<int>(whole_from_environment("MARBLES_CUDA_TRIM_EVERY", kTrimEvery, 1000000,
                                                 "expected a whole number of steps from 0 (never) to 1000000"));
}

// Room for a count the host reads only after the stages that fill it (the
// broad phase's pairs, the contacts): from the last count, a sixteenth more
// (a quarter after a count that outgrew its room) and twice the last
// growth, never less than it was unless the count fell below half of that.
// A gas let go from a lattice grows its pairs by half or more a step for
// its first dozen steps (the bench's gas: 141, 821, 2137, 5021, 8125,
// 11 539, ... 40 301 in 20 steps of 10^5 spheres): a sixteenth alone was
// outgrown in 9 steps of 20, with twice the growth in 3 (H100). The first
// count has no growth: the buffers it sizes never shrink.
struct Room {
  std::size_t capacity = 0;  // 0: no count yet
  std::size_t last = 0;      // the last count
  void fit(std::size_t count, bool outgrown) {
    const std::size_t growth = capacity > 0 && count > last ? count - last : 0;
    last = count;
    const std::size_t room = count + count / (outgrown ? 4 : 16) + 2 * growth + kSlack;
    if (room > capacity || 2 * room < capacity) capacity = room;
  }
  static constexpr std::size_t kSlack = 64;
};

class CudaStep final : public StepBackend {
 public:
  // Only with a device (make_cuda_step asks first: the members allocate).
  CudaStep(const StepModel& model, World world) : m_model(model), m_host(std::move(world)) {
    m_sm = std::max(1, cuda_device().multiprocessors);
    std::size_t total = 0;
    MARBLES_CUDA_CHECK(cudaMemGetInfo(&m_free_at_start, &total));
    m_stream.create(cudaStreamNonBlocking);
    m_device.upload(m_host, m_stream);
    ::marbles::cuda::upload(m_walls, model.wall_shapes, m_stream);
    ::marbles::cuda::upload(m_pair_table, model.pair_coefficients, m_stream);
    MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
    m_table = {m_pair_table.get_as<narrowphase::PairCoefficients>(), model.material_count};
    m_flags.as<unsigned long long>(kStepWords + kColourWords);
    if (model.collisions) {
      m_broadphase = std::make_unique<broadphase::SubdivisionCuda>(model.algorithm);
      m_broadphase->set_stage_timing(false);  // its events cost a sync per call: profiling only
      m_broadphase->share_scratch(m_record_memory);  // the contact search's temporaries: see m_record_memory
    }
    m_terms = {model.solver.friction, model.solver.rolling};
    m_cache.set_terms(m_terms.friction, m_terms.rolling);
    m_cache.share_scratch(m_scratch);
    m_cache.share_store_memory(m_pairs);  // after the solve: see m_pairs
    m_colouring.share_scratch(m_scratch);
    m_colouring.share_round_memory(m_record_memory);  // dead while contacts are coloured
    nc::cluster_widest();  // MARBLES_CUDA_CLUSTER read (or refused) before any step
  }

  void apply_body_forces(real h) override {
    if (m_one_wait) keep_substep_start();
    ++m_substep_index;
    const BodiesView bodies = m_device.view();
    // With drag, gravity's kick is taken in drag's launch (as on the CPU).
    if (m_model.drag)
      integrator::cuda::launch_apply_drag(
          bodies, m_model.drag_linear, m_model.drag_quadratic, m_model.first_kick(h),
          m_model.verlet ? integrator::DragKick::verlet_first : integrator::DragKick::whole,
          m_model.gravity ? &m_model.g : nullptr, m_sm, m_stream);
    else if (m_model.gravity)
      integrator::cuda::launch_apply_gravity(bodies, m_model.g, m_model.first_kick(h), m_sm, m_stream);
  }

  // Swept bounds -> broad phase -> sphere contacts (in pair order), then wall
  // contacts (by sphere, then wall): flag, scan, write. Where the last
  // substep left rooms (Room), nothing here waits: the broad phase writes
  // its pairs and the contacts their body pairs where they fit their rooms,
  // and both counts stay on the device, where the restore and the colouring
  // read them (count_within), until the colouring reads them with its ranges
  // (colour_contacts). The first substep waits for both counts here.
  void find_contacts(real substep) override {
    m_substep = substep;
    find_contacts_within(substep, m_contact_room.capacity == 0);
  }

  // One try of find_contacts; `wait`: for the counts (then every later stage
  // has them on the host).
  void find_contacts_within(real substep, bool wait) {
    const real h = m_model.lookahead(substep);  // 0 without speculative contacts: touching pairs only
    m_lookahead = h;
    m_reach_fresh = false;
    m_count = 0;
    m_count_on_device = nullptr;
    m_pair_items = 0;
    m_pair_count_on_device = false;
    m_impact_candidates = false;
    m_uniform_arms = false;
    if (!m_model.collisions && !m_model.wall_contacts) return;
    const BodiesView bodies = m_device.view();
    const std::size_t n = bodies.count;
    // The candidate pairs the flag pass walks (their count, or their room
    // when the count stays on the device: pair_count_on_device).
    std::size_t pair_items = 0, wall_items = 0;
    const std::uint32_t* pair_count_on_device = nullptr;
    std::uint32_t *pair_offsets = nullptr, *wall_offsets = nullptr;
    const IndexPair* pairs = nullptr;
    // The fastest speed, then the words read with the counts: [0]
    // any contact an impact candidate (a substep without one skips the
    // impact stage), [1] the radii not all the same (the records then keep
    // their arms word), [2..] sphere 0's radius (UniformArms'); then the
    // contact count (the pair writes'). One set clears the first three.
    auto* words = m_found_words.as<unsigned long long>(4);
    auto* max_speed = words;
    auto* seen = reinterpret_cast<unsigned*>(words + 1);
    auto* contact_count = reinterpret_cast<std::uint32_t*>(words + 3);
    real* reach = m_reach.as<real>(n);
    real* bound = m_model.collisions ? m_bound.as<real>(n) : nullptr;
    MARBLES_CUDA_CHECK(cudaMemsetAsync(words, 0, 3 * sizeof(unsigned long long), m_stream));
    unsigned* mixed_radii = m_model.uniform_pairs ? seen + 1 : nullptr;
    auto* radius = reinterpret_cast<real*>(seen + 2);
    nc::launch_contact_reaches(bodies, h, max_speed, reach, bound, mixed_radii, radius, m_sm, m_stream);
    m_reach_fresh = true;
    const auto wall_count = static_cast<std::uint32_t>(m_model.wall_shapes.size());
    if (m_model.wall_contacts) wall_items = n;  // a count of walls touched a sphere
    // The flags and their offsets (and the scans' temporaries) in the
    // records' memory (no record is live until the colouring makes them),
    // live only until the contacts are written; behind the broad phase's
    // pairs where it left them there (a call within a room: the pairs' room
    // first, as it took it). That memory is grown for the layout before the
    // broad phase runs, so that the flags' carve does not move the pairs.
    namespace dev = ::marbles::cuda;
    std::uint32_t *pair_flags = nullptr, *wall_flags = nullptr;
    void *pair_temp = nullptr, *wall_temp = nullptr;
    const IndexPair* front = nullptr;
    std::size_t pair_temp_bytes = 0, wall_temp_bytes = 0;
    // The layout for a room of `front_pairs` pairs first (or none) and flags
    // for `items` candidates; the scans' temporary bytes set for it.
    auto layout = [&](std::size_t front_pairs, std::size_t items) {
      pair_temp_bytes = m_model.collisions ? dev::exclusive_sum_bytes<std::uint32_t>(items + 1) : 0;
      wall_temp_bytes = m_model.wall_contacts ? dev::exclusive_sum_bytes<std::uint32_t>(wall_items + 1) : 0;
      return [&, front_pairs, items](dev::Carve& c) {
        front = front_pairs > 0 ? c.take<IndexPair>(front_pairs) : nullptr;
        pair_flags = c.take<std::uint32_t>(items + 1);
        pair_offsets = c.take<std::uint32_t>(items + 1);
        pair_temp = c.take<char>(pair_temp_bytes);
        wall_flags = c.take<std::uint32_t>(wall_items + 1);
        wall_offsets = c.take<std::uint32_t>(wall_items + 1);
        wall_temp = c.take<char>(wall_temp_bytes);
      };
    };
    // The layout a call within a room leaves (the seed algorithm keeps its
    // pairs: no room for them here), made once: it is the one carved below
    // when the pairs are there.
    std::optional<decltype(layout(0, 0))> within;
    if (m_model.collisions && m_pair_room.capacity > 0 && m_broadphase->algorithm() == broadphase::Algorithm::home) {
      within.emplace(layout(m_pair_room.capacity, m_pair_room.capacity));
      dev::Carve need;
      (*within)(need);
      m_record_memory.reserve(need.used());
    }
    if (m_model.collisions) {
      const SpheresIn spheres{bodies.position, bound, n};
      try {
        pair_items = m_pair_room.capacity == 0
                         ? m_broadphase->find_pairs_device(spheres, 0, m_stream)
                         : m_broadphase->find_pairs_device_within(spheres, 0, m_pair_room.capacity, m_stream);
      } catch (const broadphase::NonFiniteInput&) {
        m_non_finite_seen = true;  // an earlier substep went non-finite: the step ends with that flag
        return;
      }
      if (pair_items == broadphase::SubdivisionCuda::kCountOnDevice) {
        pair_items = m_pair_room.capacity;
        pair_count_on_device = m_broadphase->device_pair_count();
      }
      pairs = m_broadphase->device_pairs();
      m_counters.broadphase_ms += m_broadphase->last_stats().ms_total;
    }
    m_pair_items = pair_items;
    m_pair_count_on_device = pair_count_on_device != nullptr;
    const bool pairs_in_front = m_model.collisions && m_broadphase->pairs_in_scratch();
    const std::size_t memory_bytes = m_record_memory.bytes();
    if (pairs_in_front && within) dev::carve(m_record_memory, *within);  // pair_items is the room's
    else dev::carve(m_record_memory, layout(0, pair_items));
    if (pairs_in_front && (front != pairs || m_record_memory.bytes() != memory_bytes))
      throw std::logic_error("the CUDA step: the broad phase's pairs are not at the front of the records' memory");
    nc::ImpactWatch watch;
    if (m_model.solver.restitution) watch = {seen, m_model.solver.rest_speed};
    // Copied for the read (here where it waits, else the colouring's).
    auto read = [&](FoundWord word, const void* from, std::size_t bytes) {
      if (m_one_wait) return;  // check_substep_kernel reads them on the device
      MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_pinned + word, from, bytes, cudaMemcpyDeviceToHost, m_stream));
      m_bytes += bytes;
    };
    if (m_model.collisions) {
      nc::launch_sphere_contact_flags(bodies, pairs, pair_items, pair_count_on_device, m_table, h, reach, pair_flags,
                                      watch, m_sm, m_stream);
      dev::device_exclusive_sum(pair_flags, pair_offsets, pair_items + 1, pair_temp, pair_temp_bytes, m_stream);
      if (wait) read(kSphereContacts, pair_offsets + pair_items, 4);
      if (pair_count_on_device)  // the count and the plan outsized
        read(kPairCount, pair_count_on_device, 4 * broadphase::SubdivisionCuda::kPairCountWords);
    }
    if (m_model.wall_contacts) {
      nc::launch_wall_contact_flags(bodies, walls(), wall_count, m_table, h, reach, wall_flags, watch, m_sm,
                                    m_stream);
      dev::device_exclusive_sum(wall_flags, wall_offsets, wall_items + 1, wall_temp, wall_temp_bytes, m_stream);
      if (wait) read(kWallContacts, wall_offsets + wall_items, 4);
    }
    if (watch.any || mixed_radii) read(kCandidates, seen, mixed_radii ? 8 + sizeof(real) : 4);
    std::size_t room = m_contact_room.capacity;
    if (wait) {
      MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
      room = (m_model.collisions ? m_pinned[kSphereContacts] : 0) + (m_model.wall_contacts ? m_pinned[kWallContacts] : 0);
    }
    // The body pairs, where they fit the room, and their count.
    auto* found = m_pairs.as_room<narrowphase::BodyPair>(room);
    const auto fits = static_cast<std::uint32_t>(room);
    if (m_model.collisions)
      nc::launch_sphere_pair_write(pairs, pair_items, pair_offsets, fits, found,
                                   m_model.wall_contacts ? nullptr : contact_count, m_sm, m_stream);
    if (m_model.wall_contacts)
      nc::launch_wall_pair_write(bodies, walls(), wall_count, m_table, h, reach, wall_offsets,
                                 m_model.collisions ? pair_offsets + pair_items : nullptr, fits, found, contact_count,
                                 m_sm, m_stream);
    m_count = fits;
    if (wait) take_counts(pair_items, room, false);
    else m_count_on_device = contact_count;
  }

  // The next substep's rooms from a substep's counts (or a step's most):
  // false where the pairs or the contacts outgrew theirs (`again`: a second
  // try). Pairs that outgrew theirs made no contact, so the contacts' room
  // then holds one for each.
  bool fit_rooms(std::size_t pairs, std::size_t contacts, bool again) {
    const bool pairs_fit = pairs <= m_pair_items, contacts_fit = contacts <= m_count;
    if (m_model.collisions) m_pair_room.fit(pairs, again || !pairs_fit);
    m_contact_room.fit(pairs_fit ? contacts : contacts + pairs, again || !pairs_fit || !contacts_fit);
    return pairs_fit && contacts_fit;
  }
  // The grid the device chose outgrew the broad phase's plan (no pairs): the
  // next search reads its bounds and plans, waiting.
  void plan_again() {
    m_broadphase->replan();
    m_pair_room = Room{};
    ++m_counters.grid_replans;
  }
  // The grid fit a plan larger than it asks (a far sphere come back): the
  // next substep reads its bounds and plans smaller, one wait.
  void plan_smaller() {
    m_broadphase->replan();
    ++m_counters.grid_shrinks;
  }

  // After the read of the counts (find_contacts' where it waited, else the
  // colouring's): the next substep's rooms from them, and the words read
  // with them. False where a count outgrew its room: the pairs or contacts
  // past it were not written, and the substep finds them again (`again`:
  // the second try). Pairs that outgrew theirs made no contact, so the
  // contacts' room then holds one for each.
  bool take_counts(std::size_t pair_count, std::size_t contacts, bool again) {
    if (m_pair_count_on_device && pair_count == broadphase::SubdivisionCuda::kNoPairCount) {
      // The substep finds them again as the first one does, waiting for the
      // bounds and the counts.
      plan_again();
      m_replanned = true;
      return false;
    }
    if (m_pair_count_on_device && m_pinned[kPlanOutsized] != 0) plan_smaller();
    if (!fit_rooms(pair_count, contacts, again)) return false;
    m_count = static_cast<std::uint32_t>(contacts);
    m_count_on_device = nullptr;
    m_counters.candidate_pairs += pair_count;
    m_counters.contacts += m_count;
    m_impact_candidates = m_model.solver.restitution && m_pinned[kCandidates] != 0;
    m_uniform_arms = m_model.uniform_pairs && m_pinned[kMixedRadii] == 0;
    if (m_uniform_arms) std::memcpy(&m_radius, m_pinned + kRadius, sizeof(real));
    m_step_candidates = m_step_candidates || m_impact_candidates;
    m_expect_uniform = m_uniform_arms;  // the next step without waits lays its records out so
    return true;
  }

  // Colours the contacts, then makes them in colour-major order as the
  // sweep's records: nothing moves the bodies before the solve, so each is
  // made as it was found, restored from its cache entry and prepared. Where
  // the counts were left on the device, they are read with the colours; a
  // substep whose pairs or contacts outgrew their rooms finds them again in
  // rooms grown past them, without a wait (but for the bounds' read where
  // the broad phase plans again: a grid past its plan, or a plan outsized):
  // nothing has moved, so the same pairs, contacts and bits.
  void colour_contacts() override {
    if (m_one_wait) {
      colour_without_a_wait();
      return;
    }
    const std::uint32_t* position = nullptr;
    std::uint32_t colours = colour_and_sort(position);
    if (m_count_on_device && !take_counts(pair_count_read(), m_colouring.last_count(), false)) {
      ++m_counters.pair_redos;
      find_contacts_within(m_substep, m_replanned);  // waits where the grid was planned again
      m_replanned = false;
      warm_start();
      colours = colour_and_sort(position);
      if (m_count_on_device && !take_counts(pair_count_read(), m_colouring.last_count(), true))
        throw RuntimeFailure("the CUDA step: the contacts outgrew their room on the same spheres a second time");
    }
    if (m_count > 0) {
      lay_out_records();
      const nc::ContactInputs in{m_device.view(), walls(), m_table, m_lookahead, m_reach.get_as<real>()};
      nc::launch_sorted_records(in, pairs_d(), m_kept_valid ? m_match.get_as<std::uint32_t>() : nullptr,
                                m_cache.entries(), position, m_count, nullptr, m_records, m_impacts, m_sm, m_stream);
    }
    m_last_widest = m_plan.widest();
    m_last_colours = colours;
    for (std::uint32_t k = 0; k < narrowphase::kMaxColours; ++k)
      m_last_sizes[k] = k < colours ? m_plan.begin[k + 1] - m_plan.begin[k] : 0;
    m_counters.colours = std::max(m_counters.colours, colours);
    m_counters.overflow += m_plan.begin[colours + 1] - m_plan.begin[colours];
  }

  // Before the colouring: the contacts that persist find their cache entry
  // (their impulses, restored as the records are made) and the colour they
  // had (kept by the colouring).
  void warm_start() override {
    const real weight = m_model.gravity ? length(m_model.g) * m_model.substep() : real(0);
    auto* kept_colour = m_kept_colour.as_room<std::uint8_t>(m_count);
    auto* match = m_match.as_room<std::uint32_t>(m_count);
    m_kept_valid = m_cache.restore(pairs_d(), m_count, m_count_on_device, m_device.view(), weight, kept_colour, match,
                                   m_sm, m_stream);
  }

  // The warm start's launches (sweep false) or the sweeps', a range each,
  // or a run of small ones as one group (narrowphase::SmallRangeGroups,
  // nc::group_widest), each launch loading its records early where `last`
  // says the launch before wrote none of them (a group waits first).
  auto walk_in_groups(narrowphase::LastWrites& last, bool sweep, narrowphase::SolverBody* bodies, real inv_h) {
    // Range w as a launch takes it, every other parallel one mirrored.
    auto range_of = [this](const narrowphase::WalkRange& w) {
      nc::ContactRange r{w.begin, w.end, w.serial, w.reversed};
      if (!w.serial) r.mirrored = m_mirror, m_mirror = !m_mirror;
      r.twice = w.twice;
      m_counters.turn_launches += w.twice ? 1 : 0;
      return r;
    };
    auto single = [this, &last, sweep, bodies, inv_h, range_of](const narrowphase::WalkRange& w) {
      nc::ContactRange r = range_of(w);
      r.early = last.next(r.begin, r.end, sweep);
      if (sweep) nc::launch_sweep(m_records, r, bodies, inv_h, m_terms, m_sm, m_stream);
      else nc::launch_warm_start(m_records, r, bodies, m_terms, m_stream);
    };
    auto group = [this, &last, sweep, bodies, inv_h, range_of](const narrowphase::WalkRange* w, std::size_t n) {
      nc::RangeGroup g;
      std::uint32_t low = w[0].begin, high = w[0].end;
      for (std::size_t i = 0; i < n; ++i) {
        g.range[i] = range_of(w[i]);
        low = std::min(low, w[i].begin), high = std::max(high, w[i].end);
      }
      g.count = static_cast<std::uint32_t>(n);
      last.next(low, high, sweep);  // what the group wrote, for the launch after it
      ++m_counters.range_groups;
      if (sweep) nc::launch_sweep_group(m_records, g, bodies, inv_h, m_terms, m_stream);
      else nc::launch_warm_start_group(m_records, g, bodies, m_terms, m_stream);
    };
    return narrowphase::SmallRangeGroups(nc::group_widest(), single, group);
  }

  // The velocity state packed (SolverBody) for the solve, then back.
  void solve_velocities(real h) override {
    if (m_count == 0) return;
    const BodiesView world = m_device.view();
    // The body pairs are read no more; behind the bodies, where restitution
    // is on, the spheres' shifts from the impacts (shift_d), read by the
    // integration before the cache's store takes this memory.
    const std::size_t shift_words = m_model.solver.restitution ? shift_bodies(world.count) : 0;
    auto* bodies = m_pairs.as<narrowphase::SolverBody>(world.count + shift_words);
    nc::launch_gather_bodies(world, bodies, m_sm, m_stream);
    if (m_model.solver.restitution) impacts(bodies, h);
    sweep_bodies(bodies, world, h, m_model.solver.iterations, true);
  }

  // Velocity Verlet's closing solve (narrowphase::close_record): the bodies
  // gathered again into m_pairs, what the records held carved behind them
  // (ClosingKept: each record's impulse word, its rolling word with rolling
  // resistance, its separation) while the records hold their gaps at the
  // substep's end, the warm start and sweeps of the solve, then the
  // separations back and both solves' impulses. The impacts' shifts were
  // read by the integration and the cache's store is done: the pairs'
  // memory is free.
  void close_velocities(real h) override {
    if (m_count == 0) return;
    const BodiesView world = m_device.view();
    const std::size_t n = m_count;
    narrowphase::SolverBody* bodies = nullptr;
    narrowphase::ClosingKept kept;
    ::marbles::cuda::carve(m_pairs, [&](::marbles::cuda::Carve& c) {
      bodies = c.take<narrowphase::SolverBody>(world.count);
      kept.impulse = c.take<narrowphase::Real4>(n);
      if (m_terms.rolling) kept.rolling = c.take<narrowphase::Real4>(n);
      kept.gap = c.take<real>(n);
    });
    nc::launch_gather_bodies(world, bodies, m_sm, m_stream);
    nc::launch_close_records(m_records, m_colouring.device_plan(), m_count, bodies, world, walls(),
                             m_model.solver.rest_speed, kept, m_terms, m_sm, m_stream, skip());
    sweep_bodies(bodies, world, h, m_model.solver.closing_iterations, false);
    nc::launch_reopen_records(m_records, m_colouring.device_plan(), m_count, kept, m_terms, m_sm, m_stream, skip());
  }

  // The solve's warm start (each colour whole: a record that carries no
  // load applies nothing) and `iterations` sweeps (times the watchdog's
  // factor) on the gathered bodies, in the step's form, then the bodies
  // back to the world. `first`: the substep's first solve, the one the
  // counters of one-launch solves count (not the closing solve).
  void sweep_bodies(narrowphase::SolverBody* bodies, const BodiesView& world, real h, int iterations, bool first) {
    const real inv_h = real(1) / h;
    const int sweeps = iterations * m_iteration_factor;
    if (m_local) {  // the local order study: the warm start as always, then its passes
      if (m_model.solver.warm_start) over_colours(false, [&](nc::ContactRange r) {
          nc::launch_warm_start(m_records, r, bodies, m_terms, m_stream);
        });
      m_local_sweeps.run(m_records, m_count, m_plan, world, m_local->tile_diameters, m_local->passes,
                         m_local->local, m_local->threads, bodies, inv_h, m_terms, m_sm, m_stream);
      nc::launch_scatter_bodies(bodies, world, m_sm, m_stream, skip());
      return;
    }
    if (solve_in_one_launch()) {
      // (else counted on the device for substeps with contacts)
      if (!m_one_wait && first) ++m_counters.one_launch_solves;
      if (nc::launch_solve(m_records, device_plan(), bodies, inv_h, m_terms, m_model.solver.warm_start, sweeps, m_sm,
                           m_stream))
        ++m_counters.cluster_stages;
      nc::launch_scatter_bodies(bodies, world, m_sm, m_stream, skip());
      return;
    }
    if (m_one_wait) {
      solve_in_slots(bodies, inv_h, sweeps);
      nc::launch_scatter_bodies(bodies, world, m_sm, m_stream, skip());
      return;
    }
    // A launch loads its records while the launch just before it ends,
    // unless that one wrote them (LastWrites, ContactRange::early). Empty
    // ranges launch nothing. A run of small ranges (the pile's last colours,
    // a turn among them) is one launch of one block (RangeGroup).
    narrowphase::LastWrites last(m_count);  // the records were written before (made, the impacts, the closing gaps)
    if (m_model.solver.warm_start) {
      auto walk = walk_in_groups(last, false, bodies, inv_h);
      narrowphase::visit_colours(m_plan.begin, m_plan.colours, false,
                                 [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
                                   if (e > b) walk.add({b, e, serial, reversed, false});
                                 });
      walk.flush();
    }
    auto walk = walk_in_groups(last, true, bodies, inv_h);
    narrowphase::visit_sweeps(m_plan.begin, m_plan.colours, sweeps, m_solve_mode != SolveMode::apart,
                              [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed, bool twice) {
                                walk.add({b, e, serial, reversed, twice});
                              });
    walk.flush();
    nc::launch_scatter_bodies(bodies, world, m_sm, m_stream, skip());
  }

  void integrate_positions(real h) override {
    // With the watch and speculative contacts, where the reaches were made
    // for this substep: the spheres that moved past theirs, checked
    // (unswept_kernel, before the walls move).
    const BodiesView bodies = m_device.view();
    const bool check = m_watch && m_model.speculative && m_reach_fresh && bodies.count > 0;
    const std::uint32_t checked = watch::unswept_checked(bodies.count);
    std::uint32_t* past = check ? m_past.as<std::uint32_t>(1 + checked) : nullptr;
    if (check) MARBLES_CUDA_CHECK(cudaMemsetAsync(past, 0, sizeof(std::uint32_t), m_stream));
    // The impacts' shifts where the impact stage ran (zeroed there: a sphere
    // no hit moved keeps its bits).
    const Vec3* shift = m_impact_candidates && m_count > 0 ? shift_d() : nullptr;
    integrator::cuda::launch_integrate_positions(bodies, h, m_flags.get_as<unsigned>(), m_sm, m_stream, skip(),
                                                 m_reach.get_as<real>(), past, checked, shift);  // flags[0]
    if (check) {
      const auto wall_count = m_model.wall_contacts ? static_cast<std::uint32_t>(m_model.wall_shapes.size()) : 0u;
      unswept_kernel<<<::marbles::cuda::grid_for(bodies.count, m_sm), kWatchBlock, 0, m_stream>>>(
          bodies, m_model.collisions ? bodies.count : 0, walls(), wall_count, past, checked, h, flag(kUnswept), skip());
      MARBLES_CUDA_CHECK_LAUNCH();
    }
    if (m_model.verlet && m_model.drag)
      integrator::cuda::launch_apply_drag(m_device.view(), m_model.drag_linear, m_model.drag_quadratic,
                                          m_model.second_kick(h), integrator::DragKick::verlet_second,
                                          m_model.gravity ? &m_model.g : nullptr, m_sm, m_stream);
    else if (m_model.verlet && m_model.gravity)
      integrator::cuda::launch_apply_gravity(m_device.view(), m_model.g, m_model.second_kick(h), m_sm, m_stream);
    nc::launch_advance_walls(walls(), static_cast<std::uint32_t>(m_model.wall_shapes.size()), h, m_stream, skip());
  }

  // The CPU's projection sweeps until one moves nothing beyond
  // settled_move: one launch, no read-back.
  void project_positions() override {
    if (m_count == 0) return;
    const int sweeps = narrowphase::projection_limit(m_model.solver);
    auto* moved = m_moved.as<unsigned>(static_cast<std::size_t>(std::max(sweeps, 1)));
    if (sweeps > 0) MARBLES_CUDA_CHECK(cudaMemsetAsync(moved, 0, sweeps * sizeof(unsigned), m_stream));
    if (nc::launch_projection(m_records, device_plan(), m_device.view(), walls(), m_model.solver, sweeps, moved,
                              flag(kProjectionSweeps), m_sm, m_stream, skip()))
      ++m_counters.cluster_stages;
  }

  void store_impulses() override {
    // trim_buffers' step: the entries were read (restore, records), now
    // rewritten; not in a step without waits, whose store a substep that
    // outgrew a room skips (the entries then stay the warm start's)
    if (m_cache_trim_due && !m_one_wait) {
      m_counters.buffer_trims += m_cache.trim_entries();
      m_cache_trim_due = false;
    }
    m_cache.store(m_records, m_kept_colour.get_as<std::uint8_t>(), m_count,
                  static_cast<std::uint32_t>(m_device.size()), m_sm, m_stream, m_count_on_device, skip());
  }

  void begin_step() override {
    send_host_edits();
    m_counters = {};
    trim_buffers();
    MARBLES_CUDA_CHECK(
        cudaMemsetAsync(m_flags.get(), 0, (kStepWords + kColourWords) * sizeof(unsigned long long), m_stream));
    m_substep_index = 0;
    m_redo_from = -1;
    m_counters_at.clear();
    m_one_wait = one_wait_possible();
    // The substep's start is kept for steps without waits; where the solve
    // has outgrown one launch (auto then waits a substep: a gas whose first
    // steps ran without waits, then its colours grew), it is let go after
    // kStartHold such steps, not held for the run (12 bytes a sphere: the
    // velocities, keep_substep_start).
    if (m_waits != Waits::auto_ || solve_in_one_launch()) m_steps_past_one_launch = 0;
    else if ((m_steps_past_one_launch = std::min(m_steps_past_one_launch + 1, kStartHold)) == kStartHold)
      m_start_velocity.release();  // nothing where it holds none
    m_step_candidates = false;
  }

  // The one read of flags at the end of a step (StepWord): non_finite, the
  // deepest overlap, the projection's sweeps, with the watch on the
  // watchdog's figures, and after substeps without waits their words (an
  // undo, the step's figures, the next step's rooms).
  void end_step(StepCounters& counters) override {
    auto* flags = m_flags.get_as<unsigned long long>();
    nc::launch_max_overlap(m_records, m_count, m_device.view(), walls(), flags + kDeepest, m_sm, m_stream,
                           m_count_on_device, skip());
    // (a step by slots: its colours' sizes too, one a slot, as many as
    // there are colour words: check_substep_kernel)
    const int words = !m_one_wait           ? (m_watch ? kFlagWords : kKineticEnergy)
                      : solve_in_one_launch() ? kStepWords
                                              : kStepWords + std::min(static_cast<int>(slot_count()), kColourWords);
    if (m_watch && m_device.view().count > 0) {
      const auto wall_count = m_model.wall_contacts ? static_cast<std::uint32_t>(m_model.wall_shapes.size()) : 0u;
      watch_kernel<<<::marbles::cuda::grid_for(m_device.view().count, m_sm), kWatchBlock, 0, m_stream>>>(
          m_device.view(), walls(), wall_count, flags + kKineticEnergy, skip());
      MARBLES_CUDA_CHECK_LAUNCH();
    }
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_end_flags, flags, words * sizeof(unsigned long long), cudaMemcpyDeviceToHost,
                                       m_stream));
    MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
    m_bytes += words * sizeof(unsigned long long);
    if (m_one_wait && m_end_flags[kRedo] != 0) {
      undo_outgrown_substep();
      return;
    }
    if (m_one_wait) take_step_words();
    m_quiet_steps = m_step_candidates ? 0 : m_quiet_steps + 1;
    ++m_steps_since_undo;
    if (m_watch) {
      std::memcpy(&m_counters.kinetic_energy, &m_end_flags[kKineticEnergy], sizeof(double));
      m_counters.beyond_walls = m_end_flags[kBeyondWalls];
      if (m_end_flags[kUnswept] == ~0ull) m_counters.unswept_unchecked = watch::unswept_checked(m_device.size());
      else m_counters.unswept_depth = real_of_bits(m_end_flags[kUnswept]);
    }
    m_counters.projection_sweeps = m_end_flags[kProjectionSweeps];
    const std::uint64_t bytes =
        m_bytes + m_colouring.bytes_copied() + (m_broadphase ? m_broadphase->bytes_copied() : 0);
    m_counters.bytes_copied = bytes - m_bytes_at_step_start;
    m_bytes_at_step_start = bytes;
    m_non_finite = m_end_flags[kNonFinite] != 0 || m_non_finite_seen;
    m_non_finite_seen = false;
    m_counters.max_overlap = real_of_bits(m_end_flags[kDeepest]);
    m_host_stale = true;
    m_contacts_stale = true;
    counters = m_counters;
  }
  bool non_finite() const override { return m_non_finite; }
  int substep_to_redo() override { return std::exchange(m_redo_from, -1); }
  void set_watch(bool on) override { m_watch = on; }
  void set_iteration_factor(int factor) override { m_iteration_factor = factor; }
  void synchronize() override { MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream)); }
  void set_profiling(bool on) override {
    if (m_broadphase) m_broadphase->set_stage_timing(on);
  }
  // What the device lost in free memory since before this step was built:
  // the world, every buffer of every stage and the broad phase's (and
  // anything else allocated on the device meanwhile: a benchmark's figure,
  // with one simulation on the device).
  std::size_t device_bytes() const override {
    std::size_t free = 0, total = 0;
    MARBLES_CUDA_CHECK(cudaMemGetInfo(&free, &total));
    return m_free_at_start > free ? m_free_at_start - free : 0;
  }
  std::vector<DeviceBytes> device_buffers() const override {
    using ::marbles::cuda::bytes_of;
    std::vector<DeviceBytes> parts{
        {"world", m_device.device_bytes()},
        {"contact pairs and solver bodies", m_pairs.bytes()},
        {"broad phase", m_broadphase ? m_broadphase->device_bytes() : 0},
        {"records", m_record_memory.bytes()},
        {"matches and colours", bytes_of(m_match, m_kept_colour)},
        {"cache", m_cache.device_bytes()},
        {"colouring", m_colouring.device_bytes()},
        {"scratch", m_scratch.bytes()},
        {"watchdog's copy", m_kept.device_bytes() + m_cache.kept_bytes() + m_kept_walls.bytes()},
        {"substep's start", m_start_velocity.bytes()},
        {"local order", m_local_sweeps.device_bytes()},
        {"small", bytes_of(m_walls, m_pair_table, m_found_words, m_reach, m_bound, m_flags, m_hit, m_moved,
                           m_contact_chunk, m_check, m_past)},
    };
    std::size_t named = 0;
    for (const DeviceBytes& p : parts) named += p.bytes;
    const std::size_t total = device_bytes();
    parts.push_back({"runtime", total > named ? total - named : 0});
    return parts;
  }

  const World& world() override {
    if (m_host_renumbered) {
      m_device.download(m_host, m_stream);
      m_host_renumbered = m_host_stale = false;
    } else if (m_host_stale) {
      m_device.download_state(m_host, m_stream);
      m_host_stale = false;
    }
    return m_host;
  }
  World& edit_world() override {
    world();
    m_host_edited = true;
    return m_host;
  }
  BodiesView state_in_place() override {
    send_host_edits();  // first, so that the device arrays hold every change
    MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
    return m_device.view();
  }
  void state_written() override {
    // Writes may come from any stream (CuPy's, PyTorch's): wait for all of
    // them. The device arrays win over unsent host edits.
    MARBLES_CUDA_CHECK(cudaDeviceSynchronize());
    m_host_stale = true;
  }
  bool state_finite() override {
    const BodiesView bodies = state_in_place();
    auto* bad = m_check.as<unsigned>(1);
    MARBLES_CUDA_CHECK(cudaMemsetAsync(bad, 0, sizeof(unsigned), m_stream));
    integrator::cuda::launch_check_finite(bodies, bad, m_sm, m_stream);
    unsigned found = 0;
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(&found, bad, sizeof found, cudaMemcpyDeviceToHost, m_stream));
    MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
    return found == 0;
  }
  // The whole contacts, made from the records a chunk at a time (the device
  // holds no Contact array): the masses from the world's inverse masses and
  // inertias, which a step leaves as they were.
  const std::vector<narrowphase::Contact>& contacts() override {
    if (m_contacts_stale) {
      const std::uint32_t n = m_count;  // the records of a step's last substep hold them all
      m_host_contacts.resize(n);
      constexpr std::uint32_t kChunk = 1u << 16;
      auto* chunk = m_contact_chunk.as<narrowphase::Contact>(std::min(n, kChunk));
      for (std::uint32_t first = 0; first < n; first += kChunk) {
        const std::uint32_t count = std::min(kChunk, n - first);
        nc::launch_contacts_of_records(m_records, m_impacts, first, count, m_device.view(), m_table, walls(), chunk,
                                       m_sm, m_stream);
        MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_host_contacts.data() + first, chunk, count * sizeof(narrowphase::Contact),
                                           cudaMemcpyDeviceToHost, m_stream));
      }
      MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
      m_contacts_stale = false;
    }
    return m_host_contacts;
  }
  const broadphase::BroadPhase* broad_phase() const override { return m_broadphase.get(); }
  std::string name() const override { return "cuda"; }
  StepState save_state() override { return {m_cache.download(m_stream), wall_shapes()}; }
  std::vector<narrowphase::WallShape> wall_shapes() override {
    std::vector<narrowphase::WallShape> shapes(m_model.wall_shapes.size());
    if (!shapes.empty()) {
      MARBLES_CUDA_CHECK(cudaMemcpyAsync(shapes.data(), walls(), shapes.size() * sizeof(narrowphase::WallShape),
                                         cudaMemcpyDeviceToHost, m_stream));
      MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
    }
    return shapes;
  }
  void keep_step_start() override {
    send_host_edits();  // edits between steps belong to the step's start
    // The cache's other set of entries (the last step's start) is dead until
    // the step's first store writes it: trimmed after a step that trimmed
    // the step's buffers (trim_buffers). The entries now are kept in place.
    if (m_kept_trim_due) {
      m_cache.trim_spare();
      m_kept_trim_due = false;
    }
    m_device.copy_state_to(m_kept, m_stream);
    m_cache.keep();
    const std::size_t wall_bytes = m_model.wall_shapes.size() * sizeof(narrowphase::WallShape);
    if (wall_bytes > 0)
      MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_kept_walls.as<char>(wall_bytes), m_walls.get(), wall_bytes,
                                         cudaMemcpyDeviceToDevice, m_stream));
  }
  void undo_step() override {
    m_kept.copy_state_to(m_device, m_stream);
    m_cache.back_to_kept();
    const std::size_t wall_bytes = m_model.wall_shapes.size() * sizeof(narrowphase::WallShape);
    if (wall_bytes > 0)
      MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_walls.get(), m_kept_walls.get(), wall_bytes, cudaMemcpyDeviceToDevice,
                                         m_stream));
    m_host_stale = true;
    m_host_edited = false;
    m_contacts_stale = true;
    m_non_finite = false;
  }
  // On the device: the home keys sorted, every array gathered, the cache's
  // entries renamed and sorted; the order read back (only where a sphere
  // moves) for the host copy's fixed arrays and the caller's numbering.
  SphereOrder renumber() override {
    send_host_edits();  // edits between steps first
    const std::size_t n = m_device.size();
    DeviceBuffer orders(m_stream);  // the stream's: no wait where it goes
    std::uint32_t* order = orders.as<std::uint32_t>(2 * n);
    if (!m_device.cell_order(order, m_bytes, m_sm, m_stream)) return {};
    if (!m_order_host || m_order_host->size() < n) {  // grown a sixteenth past the world, as the device's rooms
      m_order_host.reset();  // empty until the allocation has succeeded
      m_order_host.emplace(n + n / 16);
    }
    std::uint32_t* host = *m_order_host;
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(host, order, n * sizeof(std::uint32_t), cudaMemcpyDeviceToHost, m_stream));
    MARBLES_CUDA_CHECK(cudaStreamSynchronize(m_stream));
    m_bytes += n * sizeof(std::uint32_t);
    std::uint32_t* new_index = order + n;
    invert_order(order, n, new_index, m_sm, m_stream);
    m_device.permute(order, m_sm, m_stream);
    m_cache.renumber(new_index, static_cast<std::uint32_t>(n), m_sm, m_stream);
    m_host_stale = m_host_renumbered = true;  // the next world() downloads every array
    m_contacts_stale = true;
    return {host, n};
  }
  void load_state(const StepState& state) override {
    m_cache.upload(state.cache, static_cast<std::uint32_t>(m_host.size()), m_stream);  // the world as restored
    if (!state.walls.empty()) ::marbles::cuda::upload(m_walls, state.walls, m_stream);
  }

 private:
  narrowphase::BodyPair* pairs_d() const { return m_pairs.get_as<narrowphase::BodyPair>(); }
  // The spheres' shifts from the impacts: n words behind the solver bodies
  // (solve_velocities sized m_pairs for both), as many bodies' room as they take.
  static std::size_t shift_bodies(std::size_t n) {
    return (n * sizeof(Vec3) + sizeof(narrowphase::SolverBody) - 1) / sizeof(narrowphase::SolverBody);
  }
  Vec3* shift_d() const {
    return reinterpret_cast<Vec3*>(m_pairs.get_as<narrowphase::SolverBody>() + m_device.size());
  }
  // The substep's plan as the one-launch stages read it: the colouring's in
  // device memory, shaped for the widest colour the host read (without
  // waits, the last step's).
  nc::DevicePlan device_plan() const {
    return {m_colouring.device_plan(), m_last_widest};
  }
  unsigned long long* flag(StepWord w) const { return m_flags.get_as<unsigned long long>() + w; }
  // A real from its bits in a step word (bits_of_real's: a float's in the low half).
  static real real_of_bits(unsigned long long word) {
    real x = 0;
    if constexpr (sizeof(real) == 4) {
      const auto bits = static_cast<std::uint32_t>(word);
      std::memcpy(&x, &bits, sizeof(real));
    } else {
      std::memcpy(&x, &word, sizeof(real));
    }
    return x;
  }
  // The word the state's kernels skip on (cuda::skipped) in a step without
  // waits; none otherwise.
  const unsigned long long* skip() const { return m_one_wait ? flag(kRedo) : nullptr; }

  // --- one wait a step ------------------------------------------------------
  // A step waits once, at its end, where the last step left rooms for its
  // pairs and contacts (one_wait_possible; MARBLES_CUDA_WAITS=auto: where
  // its solve takes one launch, as the one-launch stages walk a plan in
  // device memory whatever its widths; step: also where it takes a launch
  // per colour, solve_in_slots). Each substep then keeps its start
  // (keep_substep_start), colours without reading the ranges back, lays its
  // records out for the contacts' room (with impact words and arms as the
  // last step needed them), and checks on the device what it found against
  // what it was given (check_substep_kernel). A substep that outgrew a room
  // is named in the step's read; from it on, the kernels that write the
  // state do nothing, and end_step puts the state back to that substep's
  // start, grows the rooms and has the substeps from there done again with a
  // wait each (substep_to_redo). The same bits as a wait a substep.

  // The warm start and sweeps of a step without waits where the solve takes
  // a launch per colour: a launch per slot of the device's plan, for the
  // last step's colours and one more, for a new colour or the overflow set
  // (slot_count; a substep whose plan they do not hold, more colours or a
  // new one with an overflow set, is undone: slots_hold,
  // check_substep_kernel), each with a grid for its colour's last size and
  // an eighth more (a wider colour is strided over). A slot past the
  // colours launches and does nothing. The turns merge as with waits. A
  // launch loads its records early where the launch before wrote another
  // slot's (ContactRange::early; every slot's range is its own).
  std::uint32_t slot_count() const { return std::min(m_last_colours + 1, narrowphase::kMaxColours + 1); }
  void solve_in_slots(narrowphase::SolverBody* bodies, real inv_h, int sweeps) {
    const std::uint32_t slots = slot_count();
    // Which slot the launch before wrote, each slot's range its own: the
    // slots as ranges of one (the records made, the impacts, wrote all).
    narrowphase::LastWrites last(slots);
    // A grid for the slot's colour's last size and an eighth; the slot past
    // the last step's colours (a new colour, which comes last and small as
    // the tail's colours do, or the overflow set's one thread) the last
    // colour's. A wider colour is strided over.
    const std::uint32_t tail = m_last_colours > 0 ? m_last_sizes[m_last_colours - 1] : m_last_widest / 8;
    auto slot = [&](std::uint32_t s, bool backwards, bool writes) {
      nc::ContactRange r;
      r.plan = m_colouring.device_plan();
      r.slot = s;
      const std::uint32_t size = s < m_last_colours ? m_last_sizes[s] : tail;
      r.width = size + size / 8 + 1;
      r.backwards = backwards;
      r.mirrored = m_mirror, m_mirror = !m_mirror;
      r.early = last.next(s, s + 1, writes);
      return r;
    };
    if (m_model.solver.warm_start)
      for (std::uint32_t s = 0; s < slots; ++s)
        nc::launch_warm_start(m_records, slot(s, false, false), bodies, m_terms, m_stream);
    // The turns merged as with waits (not under `apart`): a slot that is
    // the overflow set walked back, a colour's contacts each solved again
    // at once.
    narrowphase::visit_slot_sweeps(slots, sweeps, m_solve_mode != SolveMode::apart,
                                   [&](std::uint32_t s, bool backwards, bool twice) {
                                     nc::ContactRange r = slot(s, backwards, true);
                                     r.twice = twice;
                                     m_counters.turn_launches += twice ? 1 : 0;
                                     nc::launch_sweep(m_records, r, bodies, inv_h, m_terms, m_sm, m_stream);
                                   });
  }

  bool one_wait_possible() const {
    if (m_waits == Waits::substep || m_local || m_replanned || m_steps_since_undo < kUndoHold) return false;
    if (!m_model.collisions && !m_model.wall_contacts) return false;
    if (m_contact_room.capacity == 0 || (m_model.collisions && m_pair_room.capacity == 0)) return false;
    return m_waits == Waits::step || solve_in_one_launch();  // with the last step's widest colour
  }

  // The velocities at a substep's start, unless an earlier substep of the
  // step outgrew a room (the copy then still holds that substep's start).
  // The rest of the moving state needs no copy: before the substep's check
  // only the body forces write the state (the velocities), and from a
  // substep that outgrew a room on the kernels that write positions and
  // spins do nothing (the scatter of the solver's bodies, the drift, the
  // position stages), as the walls' advance does.
  void keep_substep_start() {
    m_counters_at.push_back(m_counters);
    m_device.copy_velocities_to(m_start_velocity, m_stream, skip(), m_sm);
  }

  // colour_contacts without a wait: the colouring leaves its plan on the
  // device, the substep's counts are checked there, and the records are
  // made for the room.
  void colour_without_a_wait() {
    // No contact search ran (the broad phase met a non-finite centre: the
    // step ends non-finite), so nothing to check or make.
    if (!m_count_on_device) return;
    const std::uint32_t* position = nullptr;
    colour_and_sort(position, false);
    m_impact_candidates = m_model.solver.restitution && m_quiet_steps < kImpactHold;
    m_uniform_arms = m_model.uniform_pairs && m_expect_uniform;
    SubstepCheck c;
    if (m_pair_count_on_device) c.pair_count = m_broadphase->device_pair_count();
    else c.host_pairs = static_cast<std::uint32_t>(m_pair_items);
    c.pair_room = static_cast<std::uint32_t>(m_pair_items);
    c.contact_count = m_count_on_device;
    c.contact_room = m_count;
    c.seen = reinterpret_cast<const unsigned*>(m_found_words.get_as<unsigned long long>() + 1);
    c.words_kept = m_impact_candidates;
    c.candidates_fit = m_impact_candidates || !m_model.solver.restitution;
    c.uniform = m_uniform_arms;
    c.radius = m_radius;
    c.plan = m_colouring.device_plan();
    c.slots = solve_in_one_launch() ? 0 : slot_count();
    c.substep = static_cast<std::uint32_t>(m_substep_index - 1);
    check_substep_kernel<<<1, 32, 0, m_stream>>>(c, m_flags.get_as<unsigned long long>());
    MARBLES_CUDA_CHECK_LAUNCH();
    lay_out_records();
    const nc::ContactInputs in{m_device.view(), walls(), m_table, m_lookahead, m_reach.get_as<real>()};
    nc::launch_sorted_records(in, pairs_d(), m_kept_valid ? m_match.get_as<std::uint32_t>() : nullptr,
                              m_cache.entries(), position, m_count, m_count_on_device, m_records, m_impacts, m_sm,
                              m_stream);
  }

  // A step without waits whose substep outgrew a room: the moving state put
  // back to that substep's start (the cache's store, the walls' advance and
  // every later kernel that writes what lasts skipped it), the rooms
  // grown past what the step found, and the substeps from there on done
  // again with a wait each. The figures of the substeps before it stand.
  void undo_outgrown_substep() {
    const auto from = static_cast<int>((m_end_flags[kRedo] & 0xffffffffull) - 1);
    m_counters = m_counters_at.at(static_cast<std::size_t>(from));
    add_step_figures();
    m_device.take_velocities(m_start_velocity, m_stream);
    // Its store and every later one were skipped: where the step's first
    // store was that one, it wrote nothing into the set it moved to, and the
    // entries are the kept ones of the step's start (none kept: in place).
    if (from == 0) m_cache.back_to_kept();
    m_last_colours = std::max(m_last_colours, static_cast<std::uint32_t>(m_end_flags[kMostColours]));
    const bool rooms_fit = fit_rooms(m_end_flags[kMostPairs], m_end_flags[kMostContacts], false);
    const bool grid_past = m_broadphase && m_end_flags[kGridPast] != 0;
    if (grid_past) plan_again();
    if (!rooms_fit || grid_past) ++m_counters.pair_redos;
    ++m_counters.undone_substeps;
    m_counters.undo_causes |= static_cast<std::uint32_t>(m_end_flags[kRedo] >> kCauseShift);
    m_counters.unwaited_substeps += static_cast<std::uint64_t>(from);
    // The step's words from here are the redone substeps' own (with waits):
    // the non-finite flag of the skipped ones is not theirs, and the words
    // only a step without waits reads are read no more.
    MARBLES_CUDA_CHECK(cudaMemsetAsync(flag(kNonFinite), 0, sizeof(unsigned long long), m_stream));
    MARBLES_CUDA_CHECK(cudaMemsetAsync(flag(kRedo), 0, (kStepWords - kRedo) * sizeof(unsigned long long), m_stream));
    m_step_candidates = m_step_candidates || m_end_flags[kCandidateSeen] != 0;  // the substeps before it
    m_one_wait = false;
    m_steps_since_undo = -1;  // this step's end counts it: kUndoHold steps after this one
    m_redo_from = from;
    m_substep_index = from;
  }

  // The figures a step without waits added up on the device, into the
  // step's counters.
  void add_step_figures() {
    m_counters.candidate_pairs += m_end_flags[kPairSum];
    m_counters.contacts += m_end_flags[kContactSum];
    m_counters.colours = std::max(m_counters.colours, static_cast<std::uint32_t>(m_end_flags[kMostColours]));
    m_counters.overflow += m_end_flags[kOverflowSum];
    if (solve_in_one_launch()) m_counters.one_launch_solves += m_end_flags[kSolvedSubsteps];  // the step's choice
    m_counters.uniform_arms += m_end_flags[kUniformSubsteps];
    m_counters.impact_words += m_end_flags[kImpactWordSubsteps];
  }

  // The end of a step without waits: its figures, the next step's rooms and
  // records' form, and the last substep's contact count (contacts()).
  void take_step_words() {
    add_step_figures();
    m_cache.stores_kept();
    m_counters.unwaited_substeps += static_cast<std::uint64_t>(m_substep_index);
    fit_rooms(m_end_flags[kMostPairs], m_end_flags[kMostContacts], false);  // all fit: no undo
    if (m_broadphase && m_end_flags[kOutsizedSeen] != 0) plan_smaller();
    const bool slots = !solve_in_one_launch();  // the step's form: its colours' sizes were read
    m_last_widest = static_cast<std::uint32_t>(m_end_flags[kWidest]);
    m_last_colours = static_cast<std::uint32_t>(m_end_flags[kMostColours]);
    for (std::uint32_t k = 0; k < narrowphase::kMaxColours; ++k)  // not read (a step in one launch): the widest
      m_last_sizes[k] = k >= m_last_colours ? 0
                        : slots             ? static_cast<std::uint32_t>(m_end_flags[kStepWords + k])
                                            : m_last_widest;
    m_step_candidates = m_step_candidates || m_end_flags[kCandidateSeen] != 0;
    m_expect_uniform = m_model.uniform_pairs && m_end_flags[kMixedSeen] == 0;
    if (m_expect_uniform) {
      const auto bits = m_end_flags[kRadiusSeen];
      if constexpr (sizeof(real) == 4) {
        const auto low = static_cast<std::uint32_t>(bits);
        std::memcpy(&m_radius, &low, sizeof(real));
      } else {
        std::memcpy(&m_radius, &bits, sizeof(real));
      }
    }
    m_count = static_cast<std::uint32_t>(m_end_flags[kLastContacts]);
    m_count_on_device = nullptr;
  }

  // The host copy's edits (edit_world) to the device, once.
  void send_host_edits() {
    if (!m_host_edited) return;
    m_device.upload(m_host, m_stream);
    m_host_edited = false;
  }

  // The colours of the contacts in colour-major order, as the colouring's
  // sort places them, for the cache's store: in the kept colours' memory
  // (m_kept_colour, a byte a contact of the room). The kept colours are read
  // last by the colouring's first kernel (contact ranks), the sorted ones
  // written first by its sort's last, on the same stream; the warm start
  // writes the kept colours again before each colouring.
  std::uint8_t* sorted_colour() { return m_kept_colour.as_room<std::uint8_t>(m_count); }

  // The colouring of this substep's contacts (m_count, or a room of them
  // with their count on the device); `read_back`: the one wait for its
  // ranges (else the plan stays on the device: colour_without_a_wait). The
  // sorted colours go to the kept colours' memory, as the warm start sized it.
  std::uint32_t colour_and_sort(const std::uint32_t*& position, bool read_back = true) {
    std::uint8_t* sorted = sorted_colour();  // before the kept colours' pointer is read: it may grow the memory
    return m_colouring.colour_and_sort(pairs_d(), m_count, m_count_on_device, m_device.size(), position, m_plan, m_sm,
                                       m_stream, m_kept_valid ? m_kept_colour.get_as<std::uint8_t>() : nullptr, sorted,
                                       read_back);
  }
  // The broad phase's pair count, read with the colouring's ranges where it
  // stayed on the device.
  std::size_t pair_count_read() const { return m_pair_count_on_device ? m_pinned[kPairCount] : m_pair_items; }

  // The records of m_count contacts (the extra word only where a wall
  // moves, the arms word only where contacts' arms differ, the rolling word
  // only with rolling resistance, the normal impulse alone without friction)
  // and their impact words (approach speeds only in a substep without impact
  // candidates), in one buffer.
  void lay_out_records() {
    const bool extra = m_model.moving_walls, arms = !m_uniform_arms;
    const std::size_t words =
        (narrowphase::SweepRecords::bytes_for(m_count, extra, arms, m_terms.rolling, m_terms.friction) + 15) / 16;
    // The approach speeds, and with impact candidates the impact impulses
    // and the separations as found (ImpactRecords; the restitution the pair
    // table's: ImpactParams).
    auto* memory = m_record_memory.as<narrowphase::Real4>(
        words + narrowphase::ImpactRecords::real4_words(m_count, m_impact_candidates));
    const narrowphase::UniformArms uniform = arms ? narrowphase::UniformArms{} : m_model.uniform_arms(m_radius);
    m_records = narrowphase::SweepRecords::in(memory, m_count, extra, arms, uniform, m_terms.rolling, m_terms.friction);
    m_impacts = narrowphase::ImpactRecords::in(memory + words, m_count, m_impact_candidates);
    if (m_one_wait) return;  // counted on the device, for substeps with contacts (check_substep_kernel)
    m_counters.uniform_arms += arms ? 0 : 1;
    m_counters.impact_words += m_impact_candidates ? 1 : 0;
  }
  narrowphase::WallShape* walls() const { return m_walls.get_as<narrowphase::WallShape>(); }

  // Every m_trim_every steps, at a step's start, where the last substep's
  // contacts are no longer asked for: the buffers sized by the substep's
  // contacts or temporaries that hold more than their largest need since
  // the last trim (an eighth and 4 KiB beyond it: DeviceBuffer::trim) are
  // freed, and grow again to fit at their next use. A transient (impact
  // words and levels while a pour lands, a contact count that fell) then
  // holds the device's memory for at most that many steps, not for the
  // run. Their contents are dead here: the contact search, the colouring and
  // the records' making write them before they read them. The cache's
  // entries (the warm start's) are live here: they are trimmed in the
  // first store with waits from here on, which rewrites them (a store
  // without waits may be skipped: store_impulses), and the cache's other
  // set at the next step's start (keep_step_start).
  // A free waits for the device: here it is idle (end_step waited); the
  // store's waits for the substep's work. Only a buffer that is freed
  // costs that wait, in a step that trims.
  void trim_buffers() {
    if (m_trim_every <= 0 || ++m_steps_since_trim < m_trim_every) return;
    m_steps_since_trim = 0;
    for (DeviceBuffer* b : {&m_record_memory, &m_scratch, &m_pairs, &m_match, &m_kept_colour})
      m_counters.buffer_trims += b->trim() ? 1 : 0;
    m_cache_trim_due = m_kept_trim_due = true;
  }

  // One launch per colour range in the solver's order (visit_colours, the
  // CPU solver's too); the overflow set by one thread.
  // Parallel launches take their colour in turn forwards and mirrored (the
  // last contact first): the bodies a colour touched last are still in L2
  // when the next one starts with them (each large colour touches nearly
  // every sphere). Within a colour the order changes no bit.
  template <class F>
  void over_colours(bool backwards, F&& launch) {
    narrowphase::visit_colours(m_plan.begin, m_plan.colours, backwards,
                               [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
                                 nc::ContactRange r{b, e, serial, reversed};
                                 if (!serial) r.mirrored = m_mirror, m_mirror = !m_mirror;
                                 launch(r);
                               });
  }

  // The solve (warm start and sweeps) in one launch: always, never, or
  // (auto) where the widest colour is small enough that a launch per colour
  // would leave the device waiting for the host (MARBLES_CUDA_SOLVE).
  // The widest colour is this substep's where it waited for the colours, else
  // the last step's (m_last_widest).
  bool solve_in_one_launch() const {
    if (m_solve_mode == SolveMode::auto_) return m_last_widest <= kOneLaunchWidest;
    return m_solve_mode == SolveMode::one_launch;
  }

  // The impact stage (ContactSolver::impacts): candidates level by level,
  // then every contact colour by colour while the pass before hit, in one
  // launch after the levels' colouring; nothing is read on the host. A
  // substep without candidates (found with the contacts) skips it.
  void impacts(narrowphase::SolverBody* bodies, real h) {
    if (!m_impact_candidates) return;
    narrowphase::ImpactParams params{m_model.solver.rest_speed, h, m_model.solver.wall_accel};
    params.shift = shift_d();
    params.material = m_device.view().material;
    params.walls = walls();
    params.table = m_table;
    MARBLES_CUDA_CHECK(cudaMemsetAsync(params.shift, 0, m_device.size() * sizeof(Vec3), m_stream));
    std::uint32_t* order = nullptr;
    const std::uint32_t* first = nullptr;
    // The levels' body words in the cache matches' memory where it holds
    // them: read last by the records' making, written again by the next
    // warm start. Their colours, lists and order in the cache's entries
    // where they hold them, in a step that waits: read by the records'
    // making, written by the store (a step without waits may skip its
    // store and do the substep again from them).
    m_colouring.impact_levels(m_records, m_impacts.approach, m_count, m_device.size(), params.rest_speed, order, first,
                              m_sm, m_stream, m_count_on_device, &m_match,
                              m_one_wait ? nullptr : m_cache.dead_entries());
    const int passes = m_model.solver.impact_passes;
    auto* hit = m_hit.as<unsigned>(static_cast<std::size_t>(passes));
    MARBLES_CUDA_CHECK(cudaMemsetAsync(hit, 0, passes * sizeof(unsigned), m_stream));
    if (nc::launch_impact_stage(m_records, m_impacts, order, first, m_count, m_colouring.device_plan(), bodies, params,
                                m_model.solver.friction, passes, hit, m_sm, m_stream))
      ++m_counters.cluster_stages;
  }

  const StepModel& m_model;
  World m_host;  // the host copy: stale after a step until world() is asked for
  DeviceWorld m_device;
  ::marbles::cuda::Stream m_stream;
  int m_sm = 1;
  std::size_t m_free_at_start = 0;
  std::uint64_t m_bytes = 0, m_bytes_at_step_start = 0;  // host<->device bytes copied by this class
  // find_contacts' read, by word: the contact counts (where it waits), the
  // candidate and mixed-radii flags and sphere 0's radius (one or two words;
  // these three in the order of m_found_words, one copy), the broad phase's
  // pair count and whether its plan is outsized (where the count stayed on
  // the device). Read with the contact counts where find_contacts waits,
  // else with the colouring's ranges.
  enum FoundWord {
    kSphereContacts,
    kWallContacts,
    kCandidates,
    kMixedRadii,
    kRadius,
    kPairCount = kRadius + 2,
    kPlanOutsized
  };
  ::marbles::cuda::PinnedBuffer<std::uint32_t> m_pinned{kPlanOutsized + 1};
  ::marbles::cuda::PinnedBuffer<unsigned long long> m_end_flags{kStepWords + kColourWords};  // the end-of-step read
  std::optional<::marbles::cuda::PinnedBuffer<std::uint32_t>> m_order_host;  // renumber's order, read back
  bool m_watch = false;
  int m_iteration_factor = 1;

  // A substep's contacts: their body pairs as found (m_pairs, which then
  // holds in turn the solver bodies for the solve, with the impacts' shifts
  // behind them until the integration, the cache store's temporaries, and
  // under velocity Verlet the closing solve's bodies and what it keeps of
  // the records: the pairs are read last by the records' making), each one's
  // cache entry (m_match; the impact levels' body words while the impact
  // stage runs, where it holds them) and kept colour (from the colouring's
  // sort, in the same memory, the colours in colour-major order for the
  // store: sorted_colour), then in colour-major order the sweep's records
  // and approach speeds, with impact candidates their impact words too
  // (m_record_memory). The records are live from the colouring, which makes them,
  // to their store (under velocity Verlet to the closing solve's end), and
  // a step's last substep's to the end of the step (the deepest overlap,
  // contacts());
  // from the next substep's start until its colouring, their memory holds
  // the contact search's temporaries instead (the broad phase's, its pairs,
  // the contact flags and offsets), which are dead by then.
  DeviceBuffer m_walls, m_pair_table, m_found_words, m_reach, m_bound, m_pairs, m_match, m_kept_colour, m_record_memory,
      m_flags, m_hit, m_moved, m_contact_chunk, m_past;
  // Temporaries of the stages that never run at the same time and must
  // outlive a dead buffer's next use (the colouring's colours and counting
  // sort, the impact levels' lists, the cache's restore): the device holds
  // the largest stage's, not their sum. The search's, the colouring's round
  // lists and the cache store's live in m_record_memory and m_pairs, the
  // impact levels' body words in m_match where it holds them, and their
  // colours, lists and order, in a step that waits, in the cache's entries
  // where they hold them (ContactCacheCuda::dead_entries).
  DeviceBuffer m_scratch;
  narrowphase::PairTable m_table;
  nc::SolverTerms m_terms;
  std::unique_ptr<broadphase::SubdivisionCuda> m_broadphase;
  nc::ColouringCuda m_colouring;
  nc::ContactCacheCuda m_cache;
  DeviceWorld m_kept;                 // the watchdog's copy of the step's start
  DeviceBuffer m_kept_walls;
  DeviceBuffer m_check;  // state_finite()'s flag

  std::uint32_t m_count = 0;          // contacts of this substep (their room where m_count_on_device)
  // One wait a step (one_wait_possible): where (MARBLES_CUDA_WAITS), and
  // whether this attempt's substeps run without waits (then the step's
  // read holds their words).
  Waits m_waits = waits_from_environment();
  bool m_one_wait = false;
  int m_substep_index = 0;            // substeps begun in this attempt
  int m_redo_from = -1;               // substep_to_redo()
  // The widest colour and the colours of the last substep that waited for
  // them, or of the last step without waits (the most of its substeps): the
  // one-launch stages' shape and choice, the slots (solve_in_slots).
  std::uint32_t m_last_widest = 0;
  std::uint32_t m_last_colours = 0;
  // Each of those colours' contacts (0 past them), from the same substep
  // or step: the slots' grids (solve_in_slots). A step without waits reads
  // them only where it launched by slots; after one in one launch each
  // colour takes the widest.
  std::array<std::uint32_t, narrowphase::kMaxColours> m_last_sizes{};
  // Steps since the last with an impact candidate: a step without waits
  // keeps impact words until kImpactHold steps in a row had none (a pour's
  // impacts come and go: an impact candidate in records without them is a
  // substep done again).
  int m_quiet_steps = 1 << 20;
  bool m_step_candidates = false;     // this step's substeps had an impact candidate
  static constexpr int kImpactHold = 8;
  // Steps since a substep without waits was undone: a scene whose counts
  // grow step after step (a gas let go: 6 of its first 10 such substeps at
  // 10^5 on an H200) waits a substep for kUndoHold steps after one, where
  // outgrowing a room costs a contact search again, not a substep.
  int m_steps_since_undo = 1 << 20;
  static constexpr int kUndoHold = 8;
  // Steps in a row whose solve took a launch per colour under auto (no
  // step without waits): after kStartHold of them the substep's start goes.
  int m_steps_past_one_launch = 0;
  static constexpr int kStartHold = 4;
  bool m_expect_uniform = false;      // the last substep's contacts all had m_radius's arms
  DeviceBuffer m_start_velocity;      // the velocities at a substep's start (keep_substep_start)
  std::vector<StepCounters> m_counters_at;  // the counters at each substep's start without waits
  // The rooms of the broad phase's pairs and of the contacts (capacity 0:
  // no count yet, find_contacts waits for the counts).
  Room m_pair_room, m_contact_room;
  real m_substep = 0;                 // find_contacts': a substep that outgrew a room finds them again
  std::size_t m_pair_items = 0;       // the pairs the contact flags walked: their count, or their room
  bool m_pair_count_on_device = false;  // their count was read with the colours (pair_count_read)
  bool m_replanned = false;           // take_counts found the broad phase's grid past its plan: redo waiting
  const std::uint32_t* m_count_on_device = nullptr;  // m_count is a room, and this the count (count_within)
  bool m_impact_candidates = false;   // with restitution: some contact of this substep is an impact candidate
  bool m_uniform_arms = false;        // every contact of this substep has the same arms (UniformArms)
  real m_radius = 0;                  // with m_uniform_arms: every sphere's radius
  bool m_kept_valid = false;          // m_kept_colour holds this substep's kept colours
  bool m_mirror = false;              // the next parallel colour launch runs mirrored (over_colours)
  // The substep's contacts as every stage after the colouring reads them
  // (made by the colouring).
  narrowphase::SweepRecords m_records;
  narrowphase::ImpactRecords m_impacts;  // impact words with impact candidates, else approach speeds
  real m_lookahead = 0;  // find_contacts' h: the colouring makes the contacts again with it
  nc::ColourPlan m_plan;  // the substep's colours as read back with a wait: the launches per colour walk it
  // The solve in one launch (solve_in_one_launch) at most this many
  // contacts a colour in auto mode. The gas of 10^5 (a widest colour
  // between 16 384 and 32 768) then solves in one launch and waits once a
  // step: H200, eight rounds, median 0.704 ms a step against 0.803 with the
  // bound at 16 384 (the device busier, 0.505 against 0.465 ms, 12 bytes a
  // sphere more for the substep's start); the pile of 10^5 (a widest colour
  // past 32 768) keeps a launch a colour, faster there (docs/architecture.md
  // "The gas's solve in one launch, measured again").
  static constexpr std::uint32_t kOneLaunchWidest = 32768;
  SolveMode m_solve_mode = solve_mode_from_environment();
  int m_trim_every = trim_every_from_environment();  // trim_buffers(): steps apart, 0 never
  int m_steps_since_trim = 0;
  bool m_cache_trim_due = false;  // the cache's entries trimmed at the next store (store_impulses)
  bool m_kept_trim_due = false;   // the cache's other set of entries trimmed at the next keep_step_start
  // MARBLES_SOLVE_ORDER's local order (a study; none: the solver's order).
  std::optional<narrowphase::LocalOrder> m_local = narrowphase::local_order_from_environment();
  nc::LocalSweepsCuda m_local_sweeps;
  std::vector<narrowphase::Contact> m_host_contacts;
  StepCounters m_counters;
  bool m_non_finite_seen = false;  // the broad phase met a non-finite centre in this step
  bool m_reach_fresh = false;      // m_reach made by this substep's contact search (integrate_positions' check)
  bool m_non_finite = false, m_host_stale = false, m_host_edited = false, m_contacts_stale = true;
  bool m_host_renumbered = false;  // the host copy's fixed arrays too are stale (renumber)
};

}  // namespace

std::unique_ptr<StepBackend> make_cuda_step(const StepModel& model, World world) {
  const DeviceInfo& dev = cuda_device();
  if (!dev.available) throw RuntimeFailure("the CUDA step: no CUDA device (" + dev.why_not + ")");
  return std::make_unique<CudaStep>(model, std::move(world));
}

int cuda_cluster_blocks() { return cuda_device().available ? nc::cluster_blocks() : 0; }

std::vector<KernelFit> cuda_sweep_kernel_fits() {
  return cuda_device().available ? nc::sweep_kernel_fits() : std::vector<KernelFit>{};
}

}  // namespace marbles
