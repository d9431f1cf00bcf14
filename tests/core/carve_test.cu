// core/device_buffer.cuh's Carve: the layouts the stages' temporaries take
// in a shared scratch buffer, laid out over host memory (no device needed).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "core/device_buffer.cuh"

using marbles::cuda::Carve;

namespace {

struct Taken {
  char* at;
  std::size_t bytes;
};

bool overlap(const Taken& x, const Taken& y) { return x.at < y.at + y.bytes && y.at < x.at + x.bytes; }

}  // namespace

// Random layouts of a trunk and two branches (the pattern of the colouring
// and the cache's store): every array 256-byte aligned and inside the
// counted bytes; the trunk's arrays overlap nothing; the two branches, both
// taken after the same point, overlap each other and nothing of the trunk;
// the same layout run on no memory and on memory gives the same offsets.
TEST(Carve, TrunkAndBranchesWithinTheCountedBytes) {
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::size_t> trunk(1 + rng() % 3), first(rng() % 4), second(1 + rng() % 4);
    for (auto* v : {&trunk, &first, &second})
      for (std::size_t& n : *v) n = rng() % 5000;
    std::vector<Taken> t, a, b;
    // The layout: trunk, then the first branch from a copy, the second on
    // the carve itself, merged.
    const auto run = [&](Carve& c, char* base) {
      t.clear(), a.clear(), b.clear();
      const auto put = [&](std::vector<Taken>& to, Carve& from, std::size_t n) {
        auto* p = from.take<std::uint64_t>(n);
        to.push_back({base ? reinterpret_cast<char*>(p) : nullptr, n * sizeof(std::uint64_t)});
      };
      for (std::size_t n : trunk) put(t, c, n);
      Carve branch = c;
      for (std::size_t n : first) put(a, branch, n);
      for (std::size_t n : second) put(b, c, n);
      c.merge(branch);
    };
    Carve count;
    run(count, nullptr);
    std::vector<char> memory(count.used() + 256);
    char* base = memory.data() + (256 - reinterpret_cast<std::uintptr_t>(memory.data()) % 256) % 256;
    Carve at(base);
    run(at, base);
    ASSERT_EQ(at.used(), count.used());
    std::size_t first_end = 0, second_end = 0, trunk_end = 0;
    for (const Taken& x : t) trunk_end = std::max(trunk_end, std::size_t(x.at - base) + x.bytes);
    for (const auto* list : {&t, &a, &b})
      for (const Taken& x : *list) {
        ASSERT_EQ((x.at - base) % 256, 0);
        ASSERT_LE(std::size_t(x.at - base) + x.bytes, count.used());
      }
    for (const Taken& x : a) first_end = std::max(first_end, std::size_t(x.at - base) + x.bytes);
    for (const Taken& x : b) second_end = std::max(second_end, std::size_t(x.at - base) + x.bytes);
    for (const auto* list : {&t, &a, &b})
      for (std::size_t i = 0; i < list->size(); ++i)
        for (std::size_t j = i + 1; j < list->size(); ++j)
          if ((*list)[i].bytes && (*list)[j].bytes) ASSERT_FALSE(overlap((*list)[i], (*list)[j]));
    for (const Taken& x : t)
      for (const auto* branch : {&a, &b})
        for (const Taken& y : *branch)
          if (x.bytes && y.bytes) ASSERT_FALSE(overlap(x, y));
    // The branches start at the same place, and the count covers the longer.
    if (!a.empty() && !b.empty()) ASSERT_EQ(a.front().at, b.front().at);
    ASSERT_GE(count.used(), std::max({trunk_end, first_end, second_end}));
  }
}
