// The GPU contact cache (contact_cache_cuda.cu) against the CPU's
// (contact_cache.cpp) on random and adversarial contact sets: a store gives
// the same entries (keys, impulses, colours) bit for bit, and a restore,
// from a store or from an upload of the CPU's entries, gives every contact
// the same impulses and kept colour, lost loads and cold islands included.
// Label `gpu`; every case skips, saying so, without a CUDA device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "narrowphase/colouring.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contact_cache_cuda.cuh"
#include "narrowphase/contact_cache_math.hpp"
#include "narrowphase/solver_math.hpp"
#include "tests/narrowphase/random_pairs.hpp"
#include "tests/require_device.hpp"

using namespace marbles;
using namespace marbles::narrowphase;
using marbles::narrowphase::cuda::ContactCacheCuda;
using marbles::narrowphase::cuda::kNoEntry;

namespace {

using ::marbles::cuda::DeviceBuffer;

using test::random_pairs;  // a wall one time in ten

// Impulses (a share `loaded` with load, the rest none) and colours: the
// contacts in colour-major order, `colours` colours and an overflow set
// (colour kNoKeptColour), a share `coloured` of the unloaded ones coloured.
struct Stored {
  std::vector<Contact> contacts;
  ColourRanges ranges;
  std::vector<std::uint8_t> colour;  // per contact, as the GPU's colouring gives it
};

Stored with_impulses(std::mt19937_64& rng, std::vector<Contact> contacts, double loaded, double coloured,
                     std::uint32_t colours) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<std::uint32_t> of(contacts.size());
  for (std::size_t k = 0; k < contacts.size(); ++k) {
    Contact& c = contacts[k];
    c.normal = {0, 0, 1};
    const bool load = u(rng) < loaded;
    c.normal_impulse = load ? real(u(rng)) : real(0);
    c.tangent_impulse = {real(u(rng) - 0.5), real(u(rng) - 0.5), 0};
    c.rolling_impulse = {real(u(rng)), real(u(rng)), real(u(rng))};
    of[k] = load || u(rng) < coloured ? static_cast<std::uint32_t>(u(rng) * colours) : colours;  // colours: overflow
  }
  Stored s;
  s.ranges.colours = colours;
  s.ranges.begin.assign(colours + 2, 0);
  for (std::uint32_t c = 0; c <= colours; ++c) {
    s.ranges.begin[c + 1] = s.ranges.begin[c];
    for (std::size_t k = 0; k < contacts.size(); ++k)
      if (of[k] == c) {
        s.contacts.push_back(contacts[k]);
        s.colour.push_back(c < colours ? static_cast<std::uint8_t>(c) : kNoKeptColour);
        ++s.ranges.begin[c + 1];
      }
  }
  return s;
}

template <class T>
std::vector<T> to_host(const T* d, std::size_t n) {
  std::vector<T> h(n);
  if (n > 0) EXPECT_EQ(cudaMemcpy(h.data(), d, n * sizeof(T), cudaMemcpyDeviceToHost), cudaSuccess);
  return h;
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

// Two downloads hold the same entries, bit for bit.
void expect_same_entries(const CacheEntries& got, const CacheEntries& want, const std::string& what) {
  EXPECT_EQ(got.size(), want.size()) << what;
  EXPECT_TRUE(same_bits(got.key, want.key)) << what;
  EXPECT_TRUE(same_bits(got.normal_impulse, want.normal_impulse)) << what;
  EXPECT_TRUE(same_bits(got.tangent_impulse, want.tangent_impulse)) << what;
  EXPECT_TRUE(same_bits(got.rolling_impulse, want.rolling_impulse)) << what;
  EXPECT_TRUE(same_bits(got.colour, want.colour)) << what;
}

// The records of `s` on the host and on the device, with the colours.
struct Records {
  std::vector<Real4> host_words;
  SweepRecords host;
  DeviceBuffer words, colours;
  SweepRecords device;
  std::uint8_t* colour = nullptr;
  explicit Records(const Stored& s) {
    const std::size_t n = s.contacts.size();
    host_words.resize((SweepRecords::bytes_for(n) + 15) / 16 + 1);
    host = SweepRecords::in(host_words.data(), n);
    for (std::size_t k = 0; k < n; ++k) pack_sweep_record(s.contacts[k], host, static_cast<std::uint32_t>(k));
    device = SweepRecords::in(::marbles::cuda::upload(words, host_words, nullptr), n);
    colour = ::marbles::cuda::upload(colours, s.colour, nullptr);
  }
};

// What a restore did: contacts warm-started, and contacts whose entry
// carried a load but which start cold (the island rule).
struct Restored {
  std::size_t warm = 0, cold = 0;
};

// Restores `next` (contacts of spheres [0, spheres)) on both caches and
// compares each contact's impulses and kept colour. weight: the weight
// impulse (inverse masses 1: loads above 4 weight are lost loads). The GPU
// restores twice: the n contacts alone, then in a room half as large again
// whose pairs past n are the cache's own keys (each would find its entry,
// and the lost loads and islands would change) with the count n on the
// device: the same.
Restored expect_same_restore(ContactCache& cpu, ContactCacheCuda& gpu, const std::vector<Contact>& next,
                         std::uint32_t spheres, real weight, const std::string& what) {
  const std::size_t n = next.size();
  std::vector<real> inv_mass(spheres, real(1));
  DeviceBuffer mass_memory, pair_memory, kept_memory, match_memory, count_memory;
  BodiesView bodies;
  bodies.count = spheres;
  bodies.inv_mass = inv_mass.data();
  std::vector<Contact> restored = next;
  std::vector<std::uint8_t> kept;
  const CacheEntries& entries = cpu.entries();
  cpu.restore(restored, bodies, weight, kept);

  BodiesView device_bodies = bodies;
  device_bodies.inv_mass = ::marbles::cuda::upload(mass_memory, inv_mass, nullptr);
  Restored r;
  for (const bool room : {false, true}) {
    const std::string how = what + (room ? " (in a room)" : "");
    std::vector<BodyPair> pairs(n);
    for (std::size_t k = 0; k < n; ++k) pairs[k] = {next[k].a, next[k].b};
    const std::uint32_t* count_d = nullptr;
    if (room) {
      std::vector<BodyPair> poison;
      for (const std::uint64_t key : entries.key) {
        const BodyPair ab{static_cast<std::uint32_t>(key >> 32), static_cast<std::uint32_t>(key)};
        if (ab.a < spheres && (is_wall(ab.b) || ab.b < spheres)) poison.push_back(ab);
      }
      if (poison.empty()) poison.push_back({0, kWallFlag});
      for (std::size_t k = 0; k < n / 2 + 3; ++k) pairs.push_back(poison[k % poison.size()]);
      count_d = ::marbles::cuda::upload(count_memory, std::vector<std::uint32_t>{static_cast<std::uint32_t>(n)},
                                        nullptr);
    }
    const std::size_t items = pairs.size();
    auto* kept_d = kept_memory.as<std::uint8_t>(items + 1);
    auto* match_d = match_memory.as<std::uint32_t>(items + 1);
    const BodyPair* pairs_d = ::marbles::cuda::upload(pair_memory, pairs, nullptr);
    const bool any = gpu.restore(pairs_d, static_cast<std::uint32_t>(items), count_d, device_bodies, weight, kept_d,
                                 match_d, 4, nullptr);
    EXPECT_EQ(cudaDeviceSynchronize(), cudaSuccess) << how;
    std::vector<std::uint8_t> kept_g(n, kNoKeptColour);
    std::vector<std::uint32_t> match(n, kNoEntry);
    if (any && n > 0) kept_g = to_host(kept_d, n), match = to_host(match_d, n);
    r = {};
    for (std::size_t k = 0; k < n; ++k) {
      const real p = match[k] != kNoEntry ? entries.normal_impulse.at(match[k]) : real(0);
      EXPECT_EQ(p, restored[k].normal_impulse) << how << ": contact " << k;
      EXPECT_EQ(kept_g[k], kept[k]) << how << ": contact " << k;
      const std::uint64_t key = cache_key(next[k].a, next[k].b);
      if (match[k] != kNoEntry) EXPECT_EQ(entries.key.at(match[k]), key) << how << ": contact " << k;
      const auto e = std::lower_bound(entries.key.begin(), entries.key.end(), key);
      const bool loaded = e != entries.key.end() && *e == key && entries.normal_impulse[e - entries.key.begin()] > 0;
      r.warm += p > 0;
      r.cold += loaded && !(p > 0);
    }
  }
  return r;
}

// Stores `s` on both caches, compares the entries, then restores `next`
// from the GPU's store and from an upload of the CPU's entries.
Restored expect_same_as_cpu(const Stored& s, std::uint32_t spheres, const std::vector<Contact>& next,
                            std::uint32_t restore_spheres, real weight, const std::string& what) {
  const std::size_t n = s.contacts.size();
  Records records(s);
  ContactCache cpu;
  cpu.store(records.host, static_cast<std::uint32_t>(n), true, s.ranges, spheres);
  ContactCacheCuda gpu;
  DeviceBuffer poison;  // the scratch full of ones: the store must write all it reads
  const std::size_t poison_bytes = 64 * (n + spheres) + (1 << 20);
  EXPECT_EQ(cudaMemset(poison.reserve(poison_bytes), 0xff, poison_bytes), cudaSuccess);
  gpu.share_scratch(poison);
  gpu.store(records.device, records.colour, static_cast<std::uint32_t>(n), spheres, 4, nullptr);
  const CacheEntries& want = cpu.entries();
  expect_same_entries(gpu.download(nullptr), want, what);
  const Restored r = expect_same_restore(cpu, gpu, next, restore_spheres, weight, what + " (stored)");
  ContactCacheCuda uploaded;
  uploaded.upload(want, restore_spheres, nullptr);
  const CacheEntries back = uploaded.download(nullptr);  // every entry, runs made on the host, keys made again
  EXPECT_EQ(back.size(), want.size()) << what;
  EXPECT_TRUE(same_bits(back.key, want.key)) << what << " (uploaded)";
  EXPECT_TRUE(same_bits(back.normal_impulse, want.normal_impulse)) << what << " (uploaded)";
  EXPECT_TRUE(same_bits(back.colour, want.colour)) << what << " (uploaded)";
  expect_same_restore(cpu, uploaded, next, restore_spheres, weight, what + " (uploaded)");
  return r;
}

// The next substep's contacts: a share `kept` of `s`'s pairs (a lost load
// among those left out), and `fresh` new ones of spheres below `spheres`.
std::vector<Contact> next_contacts(std::mt19937_64& rng, const Stored& s, double kept, std::size_t fresh,
                                   std::uint32_t spheres) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Contact> next;
  std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
  for (const Contact& c : s.contacts)
    if (c.a < spheres && (is_wall(c.b) || c.b < spheres) && u(rng) < kept) {
      Contact d;
      d.a = c.a, d.b = c.b, d.normal = c.normal;
      next.push_back(d);
      seen.insert({c.a, c.b});
    }
  for (const Contact& c : random_pairs(rng, 0, spheres, fresh))
    if (seen.insert({c.a, c.b}).second) next.push_back(c);
  std::shuffle(next.begin(), next.end(), rng);
  return next;
}

TEST(ContactCacheCuda, RandomContactsAsOnTheCpu) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(41);
  std::size_t cold = 0;
  for (int trial = 0; trial < 4; ++trial) {
    const std::uint32_t spheres = 500u << (2 * trial);  // 500 to 32 000
    // Sparse (0.3 contacts a sphere, a few new ones): many small islands,
    // some of which lose a load and start cold while the others start warm.
    const Stored s = with_impulses(rng, random_pairs(rng, 0, spheres, 3 * spheres / 10), 0.6, 0.5, 14);
    const std::vector<Contact> next = next_contacts(rng, s, 0.9, spheres / 20, spheres);
    const Restored r = expect_same_as_cpu(s, spheres, next, spheres, real(0.1), "trial " + std::to_string(trial));
    EXPECT_GT(r.warm, next.size() / 4) << "trial " << trial;  // the comparison saw impulses restored
    cold += r.cold;
  }
  EXPECT_GT(cold, 0u);  // and islands started cold
}

// Adversarial: one sphere in a third of the contacts (a run of thousands,
// the insertion sort's worst), contacts among the middle spheres only (runs
// empty at both ends), every contact dropped (no load, no colour), one
// contact, no lost load at all (weight large), and a restore after spheres
// were removed (entries of spheres past the count never found).
TEST(ContactCacheCuda, AdversarialContactsAsOnTheCpu) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(43);
  {
    const Stored s = with_impulses(rng, random_pairs(rng, 0, 3000, 6000, 0.1, 0.33, 17), 0.7, 0.3, 9);
    expect_same_as_cpu(s, 3000, next_contacts(rng, s, 0.8, 500, 3000), 3000, real(0.1), "hub");
  }
  {
    const Stored s = with_impulses(rng, random_pairs(rng, 400, 600, 900), 0.6, 0.5, 12);
    expect_same_as_cpu(s, 1000, next_contacts(rng, s, 0.9, 100, 1000), 1000, real(0.1), "middle");
  }
  {
    const Stored s = with_impulses(rng, random_pairs(rng, 0, 800, 2000), 0.0, 0.0, 10);
    ASSERT_EQ(s.ranges.overflow(), s.contacts.size());
    expect_same_as_cpu(s, 800, next_contacts(rng, s, 0.9, 100, 800), 800, real(0.1), "dropped");
  }
  {
    const Stored s = with_impulses(rng, random_pairs(rng, 0, 2, 1), 1.0, 0.0, 3);
    expect_same_as_cpu(s, 2, next_contacts(rng, s, 1.0, 0, 2), 2, real(0.1), "one");
  }
  {
    const Stored s = with_impulses(rng, random_pairs(rng, 0, 2000, 6000), 0.6, 0.5, 14);
    const Restored r =
        expect_same_as_cpu(s, 2000, next_contacts(rng, s, 0.7, 300, 2000), 2000, real(100), "no lost load");
    EXPECT_EQ(r.cold, 0u);
  }
  {
    const Stored s = with_impulses(rng, random_pairs(rng, 0, 2000, 6000), 0.6, 0.5, 14);
    expect_same_as_cpu(s, 2000, next_contacts(rng, s, 0.9, 300, 1200), 1200, real(0.1), "fewer spheres");
  }
}

// The watchdog's entries kept without a copy (keep, back_to_kept): after a
// keep, stores (a trim between them) write the other set, each the CPU's
// entries, and back_to_kept gives the kept ones back bit for bit, again
// after more stores; a store skipped right after a keep (a step without
// waits whose first substep outgrew a room) writes nothing, and
// back_to_kept undoes its move; without a keep a skipped store leaves the
// entries as they were, and after an upload none is kept.
TEST(ContactCacheCuda, KeptEntriesComeBackWhateverWasStoredSince) {
  REQUIRE_DEVICE();
  std::mt19937_64 rng(47);
  const std::uint32_t spheres = 2000;
  const Stored a = with_impulses(rng, random_pairs(rng, 0, spheres, 6000), 0.6, 0.5, 14);
  const Stored b = with_impulses(rng, random_pairs(rng, 0, spheres, 7000), 0.7, 0.4, 15);
  const Stored c = with_impulses(rng, random_pairs(rng, 0, spheres, 5000), 0.5, 0.5, 13);
  Records ra(a), rb(b), rc(c);
  auto count = [](const Stored& s) { return static_cast<std::uint32_t>(s.contacts.size()); };
  auto cpu_entries = [&](const Stored& s, const Records& r) {
    ContactCache cpu;
    cpu.store(r.host, count(s), true, s.ranges, spheres);
    return cpu.entries();
  };
  const CacheEntries want_a = cpu_entries(a, ra), want_b = cpu_entries(b, rb), want_c = cpu_entries(c, rc);
  ASSERT_NE(want_a.size(), want_b.size());  // premise: the sets differ
  DeviceBuffer skip_word;
  auto* skip = skip_word.as<unsigned long long>(1);
  const unsigned long long skipped = 1;
  ASSERT_EQ(cudaMemcpy(skip, &skipped, sizeof skipped, cudaMemcpyHostToDevice), cudaSuccess);

  ContactCacheCuda gpu;
  gpu.back_to_kept();  // none kept: nothing changes
  gpu.store(ra.device, ra.colour, count(a), spheres, 4, nullptr);
  expect_same_entries(gpu.download(nullptr), want_a, "a");
  gpu.keep();
  EXPECT_EQ(gpu.kept_bytes(), 0u) << "the other set holds nothing before a store after a keep";
  gpu.store(rb.device, rb.colour, count(b), spheres, 4, nullptr);
  expect_same_entries(gpu.download(nullptr), want_b, "b after a keep");
  EXPECT_GT(gpu.kept_bytes(), 0u) << "the kept entries are a set of their own";
  gpu.trim_entries();
  gpu.store(rc.device, rc.colour, count(c), spheres, 4, nullptr);
  expect_same_entries(gpu.download(nullptr), want_c, "c after b");
  gpu.back_to_kept();
  expect_same_entries(gpu.download(nullptr), want_a, "back to the kept a");
  gpu.store(rb.device, rb.colour, count(b), spheres, 4, nullptr);
  expect_same_entries(gpu.download(nullptr), want_b, "b after the undo");
  gpu.back_to_kept();
  expect_same_entries(gpu.download(nullptr), want_a, "back to the kept a again");

  gpu.store(rc.device, rc.colour, count(c), spheres, 4, nullptr);  // in the other set: a stays kept
  gpu.keep();                                                       // c kept now
  gpu.store(rb.device, rb.colour, count(b), spheres, 4, nullptr, nullptr, skip);
  gpu.back_to_kept();
  expect_same_entries(gpu.download(nullptr), want_c, "a store skipped after the keep, then back");
  gpu.stores_kept();
  expect_same_entries(gpu.download(nullptr), want_c, "and its bound the last store's");

  ContactCacheCuda plain;  // no keep: a skipped store leaves the entries in place
  plain.store(ra.device, ra.colour, count(a), spheres, 4, nullptr);
  plain.store(rb.device, rb.colour, count(b), spheres, 4, nullptr, nullptr, skip);
  plain.back_to_kept();
  expect_same_entries(plain.download(nullptr), want_a, "a skipped store without a keep");

  gpu.keep();
  gpu.upload(want_b, spheres, nullptr);  // an edit in place: nothing kept from here on
  gpu.back_to_kept();
  expect_same_entries(gpu.download(nullptr), want_b, "an upload keeps none");
}

}  // namespace
