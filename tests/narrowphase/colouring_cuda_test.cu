// The GPU colouring (Jones–Plassmann rounds, colouring_cuda.cu) against the
// CPU colouring on random and adversarial contact sets: the same colour
// ranges and the same colour-major order, contact for contact; and the
// impact levels against the CPU's by_round colouring. Label `gpu`; every case
// skips, saying so, without a CUDA device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#include "core/device.hpp"
#include "narrowphase/colouring.hpp"
#include "narrowphase/colouring_cuda.cuh"
#include "narrowphase/solver_math.hpp"
#include "tests/narrowphase/random_pairs.hpp"
#include "tests/require_device.hpp"

using namespace marbles;
using namespace marbles::narrowphase;

namespace {

// Distinct pairs, a wall one time in ten (test::random_pairs), each with a
// separation, an approach speed and its index as a tag.
std::vector<Contact> random_contacts(std::mt19937_64& rng, std::uint32_t bodies, std::size_t count) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Contact> out = test::random_pairs(rng, 0, bodies, count);
  for (std::size_t k = 0; k < out.size(); ++k) {
    Contact& c = out[k];
    c.separation = real(1e-3 * u(rng));
    c.approach_speed = real(u(rng) < 0.5 ? -2 * u(rng) : u(rng));  // about half are impacts
    c.normal_impulse = real(k);                                   // a tag
  }
  return out;
}

// The contacts as the GPU step holds them: their body pairs before the
// colouring, the sweep's records and approach speeds after it (records in
// input order here: the impact levels read them by contact index).
struct DeviceContacts {
  ::marbles::cuda::DeviceBuffer pairs_memory, records_memory;  // freed however the test ends
  BodyPair* pairs = nullptr;
  real* approach = nullptr;
  SweepRecords records;
  explicit DeviceContacts(const std::vector<Contact>& c) {
    const std::size_t n = c.size();
    std::vector<BodyPair> pairs_h(n);
    const std::size_t bytes = SweepRecords::bytes_for(n);
    std::vector<Real4> words((bytes + 15) / 16 + SweepRecords::real_words(n));
    const SweepRecords host = SweepRecords::in(words.data(), n);
    auto* approach_h = reinterpret_cast<real*>(words.data() + (bytes + 15) / 16);
    for (std::size_t k = 0; k < n; ++k) {
      pairs_h[k] = {c[k].a, c[k].b};
      pack_sweep_record(c[k], host, static_cast<std::uint32_t>(k));
      approach_h[k] = c[k].approach_speed;
    }
    pairs = pairs_memory.as<BodyPair>(n + 1);
    Real4* memory = records_memory.as<Real4>(words.size());
    EXPECT_EQ(cudaMemcpy(pairs, pairs_h.data(), n * sizeof(BodyPair), cudaMemcpyHostToDevice), cudaSuccess);
    EXPECT_EQ(cudaMemcpy(memory, words.data(), words.size() * sizeof(Real4), cudaMemcpyHostToDevice), cudaSuccess);
    records = SweepRecords::in(memory, n);
    approach = reinterpret_cast<real*>(memory + (bytes + 15) / 16);
  }
};

// Poisons the plan the colouring keeps in device memory (before a call).
void poison_device_plan(const narrowphase::cuda::ColouringCuda& gpu) {
  ASSERT_EQ(cudaMemset(const_cast<ColourPlan*>(gpu.device_plan()), 0xab, sizeof(ColourPlan)), cudaSuccess);
}

// A plan's ranges as ColourRanges::begin holds them (colours + 2 words).
std::vector<std::uint32_t> ranges_of(const ColourPlan& plan) {
  return std::vector<std::uint32_t>(plan.begin, plan.begin + plan.colours + 2);
}

// The plan the colouring left in device memory, as the stages that walk
// every colour in one launch read it: the host's ranges, and past them the
// last range's end.
void expect_device_plan(const narrowphase::cuda::ColouringCuda& gpu, const std::vector<std::uint32_t>& begin) {
  ColourPlan plan;
  ASSERT_EQ(cudaMemcpy(&plan, gpu.device_plan(), sizeof plan, cudaMemcpyDeviceToHost), cudaSuccess);
  ASSERT_EQ(plan.colours + 2, begin.size());
  EXPECT_EQ(ranges_of(plan), begin);
  for (std::uint32_t c = plan.colours + 2; c < kMaxColours + 2; ++c) EXPECT_EQ(plan.begin[c], begin.back()) << c;
}

// kept: colours kept from the last substep (colour_and_sort), or empty;
// scratch: the temporaries' memory, shared with other users (null: the
// colouring's own); rounds: the round lists' memory apart from it (null:
// in the scratch).
void expect_same_as_cpu(const std::vector<Contact>& input, std::uint32_t bodies,
                        const std::vector<std::uint8_t>& kept = {},
                        ::marbles::cuda::DeviceBuffer* scratch = nullptr,
                        ::marbles::cuda::DeviceBuffer* rounds = nullptr) {
  std::vector<Contact> cpu = input;
  ColourRanges ranges;
  ContactColouring().colour_and_sort(cpu, bodies, ranges, kept.empty() ? nullptr : kept.data());

  DeviceContacts d(input);
  narrowphase::cuda::ColouringCuda gpu;
  if (scratch) gpu.share_scratch(*scratch);
  if (rounds) gpu.share_round_memory(*rounds);
  ColourPlan plan;
  const auto n = static_cast<std::uint32_t>(input.size());
  ::marbles::cuda::DeviceBuffer kept_memory, sorted_memory;  // freed however the test ends
  auto* kept_d = kept_memory.as<std::uint8_t>(n + 1);
  auto* sorted_colour = sorted_memory.as<std::uint8_t>(n + 1);
  ASSERT_EQ(cudaMemset(sorted_colour, 0xab, n + 1), cudaSuccess);  // poisoned
  if (!kept.empty()) ASSERT_EQ(cudaMemcpy(kept_d, kept.data(), n, cudaMemcpyHostToDevice), cudaSuccess);
  const std::uint32_t* position_d = nullptr;
  poison_device_plan(gpu);
  const std::uint32_t colours = gpu.colour_and_sort(d.pairs, n, nullptr, bodies, position_d, plan, 8, nullptr,
                                                    kept.empty() ? nullptr : kept_d, sorted_colour);
  ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  const std::vector<std::uint32_t> begin = ranges_of(plan);
  EXPECT_EQ(colours, ranges.colours);
  EXPECT_EQ(begin, ranges.begin);
  expect_device_plan(gpu, ranges.begin);
  EXPECT_EQ(gpu.rounds(), ranges.rounds);
  std::vector<std::uint32_t> position(n), sorted(n, 0xffffffffu);
  std::vector<std::uint8_t> gpu_colour(n), cpu_colour(n, 0xcd);
  if (n > 0) ASSERT_EQ(cudaMemcpy(position.data(), position_d, n * 4, cudaMemcpyDeviceToHost), cudaSuccess);
  for (std::uint32_t i = 0; i < n; ++i) {
    ASSERT_LT(position[i], n) << "contact " << i;
    ASSERT_EQ(sorted[position[i]], 0xffffffffu) << "two contacts at position " << position[i];
    sorted[position[i]] = i;
  }
  if (n > 0) ASSERT_EQ(cudaMemcpy(gpu_colour.data(), sorted_colour, n, cudaMemcpyDeviceToHost), cudaSuccess);
  // The CPU's sorted contacts carry their input index as a tag.
  for (std::uint32_t k = 0; k < n; ++k) ASSERT_EQ(real(sorted[k]), cpu[k].normal_impulse) << "position " << k;
  for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) { cpu_colour[k] = c; });
  EXPECT_EQ(gpu_colour, cpu_colour);
  EXPECT_EQ(gpu.last_count(), n);

  // The same contacts as the first n of a room half as large again, their
  // count on the device: the pairs past them repeat the contacts' own (they
  // would take offers and colours from them), with kept colour 0 (it would
  // mark their spheres). The same ranges, places and colours; past the room
  // (the count one more than it), no colour and the count told.
  if (n > 0) {
    const std::uint32_t items = n + n / 2 + 3;
    std::vector<BodyPair> pairs(items);
    std::vector<std::uint8_t> kept_room(items, 0);
    for (std::uint32_t k = 0; k < items; ++k) pairs[k] = {input[k % n].a, input[k % n].b};
    if (!kept.empty()) std::copy(kept.begin(), kept.end(), kept_room.begin());
    ::marbles::cuda::DeviceBuffer room_pairs, room_kept, room_sorted, count_memory;
    const BodyPair* pairs_d = ::marbles::cuda::upload(room_pairs, pairs, nullptr);
    const std::uint8_t* kept_room_d = ::marbles::cuda::upload(room_kept, kept_room, nullptr);
    auto* sorted_d = room_sorted.as<std::uint8_t>(items);
    for (const std::uint32_t count : {n, items + 1}) {
      const std::uint32_t* count_d =
          ::marbles::cuda::upload(count_memory, std::vector<std::uint32_t>{count}, nullptr);
      ASSERT_EQ(cudaMemset(sorted_d, 0xab, items), cudaSuccess);
      ColourPlan room_plan;
      poison_device_plan(gpu);
      const std::uint32_t room_colours =
          gpu.colour_and_sort(pairs_d, items, count_d, bodies, position_d, room_plan, 8, nullptr,
                              kept.empty() ? nullptr : kept_room_d, sorted_d);
      ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
      const std::vector<std::uint32_t> room_begin = ranges_of(room_plan);
      EXPECT_EQ(gpu.last_count(), count);
      expect_device_plan(gpu, room_begin);
      if (count > items) {
        EXPECT_EQ(room_colours, 0u);
        EXPECT_EQ(room_begin, (std::vector<std::uint32_t>{0, 0}));
        continue;
      }
      EXPECT_EQ(room_colours, colours);
      EXPECT_EQ(room_begin, begin);
      EXPECT_EQ(gpu.rounds(), ranges.rounds);
      std::vector<std::uint32_t> room_position(n);
      std::vector<std::uint8_t> room_colour(n);
      ASSERT_EQ(cudaMemcpy(room_position.data(), position_d, n * 4, cudaMemcpyDeviceToHost), cudaSuccess);
      ASSERT_EQ(cudaMemcpy(room_colour.data(), sorted_d, n, cudaMemcpyDeviceToHost), cudaSuccess);
      EXPECT_EQ(room_position, position);
      EXPECT_EQ(room_colour, cpu_colour);
    }
  }

  // Impact levels: the candidates of each level, in index order, as the CPU's.
  const real rest = real(0.1);
  std::vector<std::uint32_t> candidates, level(n, kUncoloured);
  std::vector<std::uint64_t> rank(n);
  for (std::uint32_t k = 0; k < n; ++k)
    if (is_impact_candidate(input[k], rest)) {
      candidates.push_back(k);
      rank[k] = impact_rank(time_of_impact(input[k]), k);
    }
  std::uint32_t cpu_levels = 0;
  ContactColouring().colour(input.data(), candidates, rank.data(), bodies, ColourRule::by_round, level, &cpu_levels);
  std::uint32_t* order = nullptr;
  const std::uint32_t* first_d = nullptr;
  gpu.impact_levels(d.records, d.approach, n, bodies, rest, order, first_d, 8, nullptr);
  ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  if (n == 0) {
    EXPECT_EQ(order, nullptr);
    EXPECT_EQ(first_d, nullptr);
    return;
  }
  // The ranges as the impact stage reads them (visit_levels on the firsts).
  std::vector<std::uint32_t> first(kMaxColourRounds + 2);
  ASSERT_EQ(cudaMemcpy(first.data(), first_d, first.size() * 4, cudaMemcpyDeviceToHost), cudaSuccess);
  std::vector<std::uint32_t> level_begin{0};
  std::uint32_t levels = 0, overflow = 0;
  visit_levels(first.data(), n, [&](std::uint32_t b, std::uint32_t e, bool serial) {
    ASSERT_EQ(b, level_begin.back()) << "ranges in order, without gaps";
    ASSERT_LT(b, e) << "no empty range";
    level_begin.push_back(e);
    if (serial) overflow = e - b;
    else ++levels;
  });
  EXPECT_EQ(level_begin.back(), candidates.size());
  if (candidates.empty()) {
    EXPECT_EQ(levels, 0u);
    return;
  }
  ASSERT_EQ(levels, cpu_levels);
  std::vector<std::uint32_t> gpu_order(candidates.size());
  ASSERT_EQ(cudaMemcpy(gpu_order.data(), order, gpu_order.size() * 4, cudaMemcpyDeviceToHost), cudaSuccess);
  // Level by level, then the overflow (beyond kMaxColourRounds levels), each in index order.
  std::vector<std::uint32_t> expect;
  for (std::uint32_t l = 0; l <= levels; ++l)
    for (std::uint32_t k : candidates)
      if (level[k] == (l < levels ? l : kOverflowColour)) expect.push_back(k);
  ASSERT_EQ(expect.size(), candidates.size());
  for (std::uint32_t l = 0; l < levels; ++l)
    EXPECT_EQ(level_begin[l + 1] - level_begin[l],
              std::count_if(candidates.begin(), candidates.end(), [&](std::uint32_t k) { return level[k] == l; }))
        << "level " << l;
  EXPECT_EQ(overflow, std::count_if(candidates.begin(), candidates.end(),
                                    [&](std::uint32_t k) { return level[k] == kOverflowColour; }));
  EXPECT_EQ(gpu_order, expect);
}

}  // namespace

TEST(ColouringCuda, EqualsTheCpuColouringOnRandomSets) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(21);
  for (int trial = 0; trial < 30; ++trial) {
    const std::uint32_t bodies = 2 + static_cast<std::uint32_t>(rng() % 20000);
    const std::size_t count = std::min<std::size_t>(std::size_t(bodies) * (bodies - 1) / 2, rng() % 60000);
    expect_same_as_cpu(random_contacts(rng, bodies, count), bodies);
  }
}

// Substep after substep: a share of the contacts persists (shuffled) with
// the colours the last colouring gave them, new ones join; the GPU keeps and
// colours them as the CPU does.
TEST(ColouringCuda, EqualsTheCpuWithKeptColours) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(27);
  for (int trial = 0; trial < 10; ++trial) {
    const std::uint32_t bodies = 100 + static_cast<std::uint32_t>(rng() % 20000);
    std::vector<Contact> contacts = random_contacts(rng, bodies, std::min<std::size_t>(5 * bodies, 60000));
    ColourRanges ranges;
    std::vector<std::uint8_t> kept;
    for (int substep = 0; substep < 3; ++substep) {
      ContactColouring().colour_and_sort(contacts, bodies, ranges, kept.empty() ? nullptr : kept.data());
      std::vector<std::pair<Contact, std::uint8_t>> next;
      std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
      for_each_colour(ranges, [&](std::uint32_t k, std::uint8_t c) {
        if (rng() % 10 < 8) next.push_back({contacts[k], rng() % 10 < 9 ? c : kNoKeptColour});
        seen.insert({contacts[k].a, contacts[k].b});
      });
      for (const Contact& c : random_contacts(rng, bodies, bodies / 3))
        if (seen.insert({c.a, c.b}).second) next.push_back({c, kNoKeptColour});
      std::shuffle(next.begin(), next.end(), rng);
      contacts.clear();
      kept.clear();
      for (auto& [c, colour] : next) {
        c.normal_impulse = real(contacts.size());  // the tag
        contacts.push_back(c);
        kept.push_back(colour);
      }
      expect_same_as_cpu(contacts, bodies, kept);
    }
  }
}

// The temporaries in memory shared with other stages, which leave it dirty
// (poisoned here) and grow it or find it larger between calls: the same
// colouring and impact levels as the CPU's, whatever the memory held.
TEST(ColouringCuda, SharedScratchLeftDirtyBetweenCalls) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(33);
  ::marbles::cuda::DeviceBuffer scratch;
  for (const std::size_t count : {20000, 300, 60000, 1000, 45000}) {
    if (scratch.bytes() > 0) ASSERT_EQ(cudaMemset(scratch.get(), 0xa5, scratch.bytes()), cudaSuccess);
    const auto bodies = static_cast<std::uint32_t>(count / 3 + 10);
    expect_same_as_cpu(random_contacts(rng, bodies, count), bodies, {}, &scratch);
  }
}

// The round lists in memory of their own (the CUDA step's records', dead
// while contacts are coloured), as dirty as the scratch, with and without
// kept colours: the same colouring as the CPU's.
TEST(ColouringCuda, RoundListsApartFromTheScratch) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(34);
  ::marbles::cuda::DeviceBuffer scratch, rounds;
  for (const std::size_t count : {45000, 300, 60000, 1000}) {
    for (auto* memory : {&scratch, &rounds})
      if (memory->bytes() > 0) ASSERT_EQ(cudaMemset(memory->get(), 0xa5, memory->bytes()), cudaSuccess);
    const auto bodies = static_cast<std::uint32_t>(count / 3 + 10);
    const std::vector<Contact> contacts = random_contacts(rng, bodies, count);
    std::vector<std::uint8_t> kept(count);
    for (std::uint8_t& c : kept) c = rng() % 3 == 0 ? kNoKeptColour : static_cast<std::uint8_t>(rng() % 12);
    expect_same_as_cpu(contacts, bodies, {}, &scratch, &rounds);
    expect_same_as_cpu(contacts, bodies, kept, &scratch, &rounds);
  }
}

// Sets around the block and warp sizes (the staged gathers' partial runs)
// and the counting sort's tiles (1024 contacts a warp, 8 a block), with and
// without kept colours. Small enough for compute-sanitizer.
TEST(ColouringCuda, SetsAroundTheBlockSizes) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(35);
  for (const std::size_t count : {1, 2, 31, 32, 33, 127, 128, 129, 255, 256, 257, 1000, 1023, 1024, 1025, 8193}) {
    const auto bodies = static_cast<std::uint32_t>(8 + count / 2);
    const std::vector<Contact> contacts = random_contacts(rng, bodies, count);
    expect_same_as_cpu(contacts, bodies);
    std::vector<std::uint8_t> kept(count);
    for (auto& c : kept) c = rng() % 4 == 0 ? kNoKeptColour : static_cast<std::uint8_t>(rng() % 3);
    // Kept colours must be a proper colouring: keep a colour only where no
    // earlier contact of either body kept the same one.
    std::set<std::pair<std::uint32_t, std::uint8_t>> used;
    for (std::size_t k = 0; k < count; ++k) {
      if (kept[k] == kNoKeptColour) continue;
      const std::uint32_t a = contacts[k].a, b = contacts[k].b;
      if (used.count({a, kept[k]}) || (!is_wall(b) && used.count({b, kept[k]}))) {
        kept[k] = kNoKeptColour;
        continue;
      }
      used.insert({a, kept[k]});
      if (!is_wall(b)) used.insert({b, kept[k]});
    }
    expect_same_as_cpu(contacts, bodies, kept);
  }
}

TEST(ColouringCuda, LargeSetAndAStarBeyondSixtyFourColours) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(4);
  expect_same_as_cpu(random_contacts(rng, 300000, 1000000), 300000);
  std::vector<Contact> star;
  for (std::uint32_t k = 1; k <= 300; ++k) {
    Contact c;
    c.a = 0;
    c.b = k;
    c.approach_speed = -1;
    c.normal_impulse = real(star.size());
    star.push_back(c);
  }
  expect_same_as_cpu(star, 301);
  expect_same_as_cpu({}, 10);
}
