#include <algorithm>

#include <cooperative_groups.h>

#include "core/counting_sort_cuda.cuh"
#include "core/cuda_check.hpp"
#include "narrowphase/colouring_cuda.cuh"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {
namespace {

using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;
namespace cg = cooperative_groups;

// What colour_and_sort reads back: the firsts of the kMaxColours colours'
// keys, of the overflow's and of the inactive's, the rounds run and the
// contact count (where it was on the device).
constexpr std::uint32_t kRounds = kMaxColours + 2, kCount = kRounds + 1, kRead = kCount + 1;

// A contact as a round sees it: its spheres and its rank.
struct ColourEntry {
  std::uint32_t a, b;
  std::uint64_t rank;
};

// The rounds' lists hold contact indices (4 bytes, not a 16-byte entry: the
// colouring's lists set the size of the step's scratch memory), and a round
// makes each contact's entry again from its index, the same way every time.
// colour_and_sort's: the body pair and contact_rank.
struct ContactEntries {
  const BodyPair* pairs;
  __device__ ColourEntry operator()(std::uint32_t k) const {
    const BodyPair ab = pairs[k];
    return {ab.a, ab.b, contact_rank(ab.a, ab.b, k)};
  }
};
// impact_levels': the record's body pair and the impact_rank of its time of
// impact.
struct ImpactEntries {
  SweepRecords records;
  const real* approach;
  __device__ ColourEntry operator()(std::uint32_t k) const {
    const BodyPair ab = records.bodies[k];
    return {ab.a, ab.b, impact_rank(time_of_impact(load_approach(records, approach, k)), k)};
  }
};

// Appends contact k to list when `want`, one atomic per warp (a single
// counter taken by every thread would serialise). The order within the list
// is free: a round's result does not depend on the order it visits its
// contacts.
__device__ void append(std::uint32_t* list, std::uint32_t* count, std::uint32_t k, bool want) {
  const unsigned active = __activemask();
  const unsigned wanting = __ballot_sync(active, want);
  if (wanting == 0) return;
  const int lane = threadIdx.x & 31;
  const int leader = __ffs(wanting) - 1;
  std::uint32_t base = 0;
  if (lane == leader) base = atomicAdd(count, static_cast<std::uint32_t>(__popc(wanting)));
  base = __shfl_sync(active, base, leader);
  if (want) list[base + __popc(wanting & ((1u << lane) - 1u))] = k;
}

// Round 0's list: every contact without a kept colour (in any order); a
// contact with one takes it and marks it at its spheres (an atomic or: the
// masks do not depend on the order). count[0] and body_used start at 0.
// Items past the contacts (count_within) are inactive: sorted last.
__global__ void contact_ranks_kernel(const BodyPair* pairs, std::uint32_t items, const std::uint32_t* count_on_device,
                                     const std::uint8_t* kept, std::uint32_t* colour, std::uint32_t* active,
                                     std::uint32_t* count, unsigned long long* body_used) {
  const std::size_t n = ::marbles::cuda::count_within(items, count_on_device);
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < items; k += gridDim.x * blockDim.x) {
    if (k >= n) {
      colour[k] = kNotActive;
      continue;
    }
    const BodyPair ab = pairs[k];
    const std::uint32_t a = ab.a, b = ab.b;
    const std::uint32_t c = kept ? kept[k] : kNoKeptColour;
    const bool keeps = c < kMaxColours;
    if (keeps) {
      const unsigned long long bit = 1ull << c;
      atomicOr(&body_used[a], bit);
      if (!is_wall(b)) atomicOr(&body_used[b], bit);
    }
    colour[k] = keeps ? c : kUncoloured;
    append(active, count, k, !keeps);
  }
}

// The impact candidates join the active list (in any order: a round's
// result does not depend on the order it visits its contacts).
__global__ void impact_candidates_kernel(SweepRecords records, const real* approach, std::uint32_t n,
                                         const std::uint32_t* count_on_device, real rest_speed, std::uint32_t* colour,
                                         std::uint32_t* active, std::uint32_t* count) {
  const std::size_t contacts = ::marbles::cuda::count_within(n, count_on_device);
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x) {
    const bool candidate = k < contacts && is_impact_candidate(load_approach(records, approach, k), rest_speed);
    colour[k] = candidate ? kUncoloured : kNotActive;
    append(active, count, k, candidate);
  }
}

// Step 1 of round r over its active list (n long): offers, an atomic max
// whose result does not depend on order.
template <class Entries>
__device__ void offer(const Entries& entries, const std::uint32_t* active, std::uint32_t n, std::uint32_t round,
                      unsigned long long* body_word, std::uint32_t first, std::uint32_t stride) {
  for (std::uint32_t t = first; t < n; t += stride) {
    const ColourEntry e = entries(active[t]);
    const unsigned long long word = round_word(round, e.rank);
    atomicMax(&body_word[e.a], word);
    if (!is_wall(e.b)) atomicMax(&body_word[e.b], word);
  }
}

// Step 2: the contacts holding both offers take a colour (they share no
// sphere); the others go on to round r + 1's list (count[r + 1] long).
template <class Entries>
__device__ void select(const Entries& entries, const std::uint32_t* active, std::uint32_t n, std::uint32_t* next,
                       std::uint32_t* count, std::uint32_t* colour, std::uint32_t round, ColourRule rule,
                       const unsigned long long* body_word, unsigned long long* body_used, std::uint32_t first,
                       std::uint32_t stride) {
  for (std::uint32_t t = first; t < n; t += stride) {
    const std::uint32_t k = active[t];
    const ColourEntry e = entries(k);
    const bool wall = is_wall(e.b);
    const std::uint64_t word = round_word(round, e.rank);
    const bool coloured = holds_both(word, body_word[e.a], wall ? 0 : body_word[e.b], wall);
    if (coloured)
      colour[k] = rule == ColourRule::by_round ? round
                                               : take_lowest_free(body_used[e.a], wall ? nullptr : &body_used[e.b]);
    append(next, &count[round + 1], k, !coloured);
  }
}

// Every round in one cooperative launch, the lists alternating, a
// grid-wide barrier after each step; it ends after a round that leaves no
// contact (every block reads the same list size) or after the last round,
// and writes the rounds it ran to count[kMaxColourRounds + 1].
template <class Entries>
__global__ void rounds_kernel(Entries entries, std::uint32_t* list0, std::uint32_t* list1, std::uint32_t* count,
                              std::uint32_t* colour, ColourRule rule, unsigned long long* body_word,
                              unsigned long long* body_used) {
  const cg::grid_group grid = cg::this_grid();
  const std::uint32_t first = blockIdx.x * blockDim.x + threadIdx.x, stride = gridDim.x * blockDim.x;
  std::uint32_t r = 0;
  for (; r < kMaxColourRounds; ++r) {
    const std::uint32_t n = ::marbles::cuda::read_volatile(count + r);
    if (n == 0) break;
    std::uint32_t* list = r % 2 == 0 ? list0 : list1;
    offer(entries, list, n, r, body_word, first, stride);
    grid.sync();
    select(entries, list, n, r % 2 == 0 ? list1 : list0, count, colour, r, rule, body_word, body_used, first,
           stride);
    grid.sync();
  }
  if (first == 0) count[kMaxColourRounds + 1] = r;
}

// A contact's bucket in colour-major order: its colour, the overflow's key
// after every colour, the inactive ones last.
struct ColourKey {
  const std::uint32_t* colour;
  std::uint32_t overflow_key;
  __device__ std::uint32_t operator()(std::uint32_t k) const {
    const std::uint32_t c = colour[k];
    return c == kNotActive ? overflow_key + 1 : (c == kUncoloured || c == kOverflowColour) ? overflow_key : c;
  }
};

// colour_and_sort's: each contact's place in colour-major order, written
// over its colour (its own, read just before), and each placed contact's
// colour as the cache keeps it (sorted_colour may be null).
struct PlaceOverColour {
  std::uint32_t* position;
  std::uint8_t* sorted_colour;
  __device__ void operator()(std::uint32_t k, std::uint32_t place, std::uint32_t key) const {
    position[k] = place;
    if (sorted_colour) sorted_colour[place] = key < kMaxColours ? static_cast<std::uint8_t>(key) : kNoKeptColour;
  }
};

// impact_levels': the contact at each place.
struct PlaceInOrder {
  std::uint32_t* order;
  __device__ void operator()(std::uint32_t k, std::uint32_t place, std::uint32_t) const { order[place] = k; }
};

}  // namespace

// A call's temporaries: the colours and, never live at once, the rounds'
// lists and body words (body_used only for the rule lowest_free), or the
// counting sort's (core/counting_sort_cuda.cuh) and the impact levels'
// order.
struct ColouringArrays {
  std::uint32_t* colour = nullptr;
  std::uint32_t *active = nullptr, *next = nullptr;
  unsigned long long *body_word = nullptr, *body_used = nullptr;
  std::uint32_t* order = nullptr;
  ::marbles::cuda::CountingSortArrays sort;
};

ColouringArrays ColouringCuda::lay_out(std::uint32_t n, std::size_t body_count, std::uint32_t buckets, bool ordered,
                                       ColourRule rule, DeviceBuffer* rounds_memory, DeviceBuffer* word_memory,
                                       DeviceBuffer* part_memory) {
  namespace dev = ::marbles::cuda;
  ColouringArrays at;
  at.sort = dev::CountingSortArrays::for_items(n, buckets);
  auto take_words = [&](dev::Carve& words) {
    at.body_word = words.take<unsigned long long>(body_count);
    if (rule == ColourRule::lowest_free) at.body_used = words.take<unsigned long long>(body_count);
  };
  // The words go to word_memory only where it holds them as it is (a pile's
  // matches): grown for them it would hold more than the scratch saves (a
  // gas's matches are a byte or two a sphere).
  dev::Carve words_need;
  take_words(words_need);
  const bool words_apart = word_memory != nullptr && word_memory != m_scratch && word_memory != rounds_memory &&
                           word_memory != part_memory && word_memory->bytes() >= words_need.used();
  auto take_rounds = [&](dev::Carve& rounds) {
    at.active = rounds.take<std::uint32_t>(n);
    at.next = rounds.take<std::uint32_t>(n);
    if (!words_apart) take_words(rounds);
  };
  const bool apart = rounds_memory != nullptr && rounds_memory != m_scratch && rounds_memory != part_memory;
  auto take_part = [&](dev::Carve& c) {
    at.colour = c.take<std::uint32_t>(n);
    dev::Carve rounds = c;
    if (!apart) take_rounds(rounds);
    at.order = ordered ? c.take<std::uint32_t>(n) : nullptr;
    at.sort.take(c);
    c.merge(rounds);
  };
  // The colours, sort and order (with the lists unless apart) go to
  // part_memory only where it holds them as it is, else to the scratch.
  dev::Carve part_need;
  take_part(part_need);
  DeviceBuffer* part = part_memory != nullptr && part_memory->bytes() >= part_need.used() ? part_memory : m_scratch;
  // Each buffer carved before the scratch's: several buffers, any order.
  if (words_apart) dev::carve_counted(*word_memory, take_words, words_need);
  if (apart) dev::carve(*rounds_memory, take_rounds);
  dev::carve_counted(*part, take_part, part_need);
  return at;
}

// The firsts sized once for the larger use (the impact levels'): no
// allocation inside a stage that does not wait.
ColouringCuda::ColouringCuda() : m_host(kRead) {
  m_count.as<std::uint32_t>(kMaxColourRounds + 2);
  m_first_of_key.as<std::uint32_t>(kMaxColourRounds + 2);
  m_plan.as<ColourPlan>(1);
}
ColouringCuda::~ColouringCuda() = default;

// Every round over the active lists, from a clear start (no body offers, no
// list size yet: count[0] is set by the caller, body_used holds the kept
// colours), in one launch that ends at the first round to find its list
// empty and writes the rounds it ran to count[kMaxColourRounds + 1].
template <class Entries>
void ColouringCuda::launch_rounds(const Entries& entries, const ColouringArrays& at, std::uint32_t n,
                                  std::size_t body_count, ColourRule rule, int sm_count, cudaStream_t s) {
  auto* count = m_count.get_as<std::uint32_t>();
  MARBLES_CUDA_CHECK(cudaMemsetAsync(at.body_word, 0, body_count * sizeof(unsigned long long), s));
  MARBLES_CUDA_CHECK(cudaMemsetAsync(count + 1, 0, (kMaxColourRounds + 1) * sizeof(std::uint32_t), s));
  ::marbles::cuda::launch_cooperative<rounds_kernel<Entries>>(n, sm_count, s, entries, at.active, at.next, count,
                                                              at.colour, rule, at.body_word, at.body_used);
}

// The plan in device memory, from the firsts the sort left there: the
// ranges the host reads back, for the stages that walk every colour in one
// launch. n: the contacts, or with count_on_device a room (count_within).
__global__ void plan_kernel(const std::uint32_t* first, std::uint32_t n, const std::uint32_t* count_on_device,
                            ColourPlan* plan) {
  if (blockIdx.x == 0 && threadIdx.x == 0)
    plan_of_firsts(first, static_cast<std::uint32_t>(::marbles::cuda::count_within(n, count_on_device)), *plan);
}

std::uint32_t ColouringCuda::colour_and_sort(const BodyPair* pairs, std::uint32_t n,
                                             const std::uint32_t* count_on_device, std::size_t body_count,
                                             const std::uint32_t*& position, ColourPlan& plan, int sm_count,
                                             cudaStream_t s, const std::uint8_t* kept_colour,
                                             std::uint8_t* sorted_colour, bool read_back) {
  position = nullptr;
  m_rounds = 0;
  m_last_count = n;
  if (n == 0) {
    plan = ColourPlan{};
    MARBLES_CUDA_CHECK(cudaMemsetAsync(m_plan.get(), 0, sizeof(ColourPlan), s));
    return 0;
  }
  // Buckets: the colours (< kMaxColours), the overflow's and the inactive's.
  const ColouringArrays at = lay_out(n, body_count, kMaxColours + 2, false, ColourRule::lowest_free, m_round_memory);
  auto* count = m_count.get_as<std::uint32_t>();
  MARBLES_CUDA_CHECK(cudaMemsetAsync(at.body_used, 0, body_count * sizeof(unsigned long long), s));
  MARBLES_CUDA_CHECK(cudaMemsetAsync(count, 0, sizeof(std::uint32_t), s));
  contact_ranks_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(pairs, n, count_on_device, kept_colour, at.colour,
                                                                at.active, count, at.body_used);
  MARBLES_CUDA_CHECK_LAUNCH();
  launch_rounds(ContactEntries{pairs}, at, n, body_count, ColourRule::lowest_free, sm_count, s);
  ::marbles::cuda::counting_sort(at.sort, n, ColourKey{at.colour, kMaxColours},
                                 PlaceOverColour{at.colour, sorted_colour},
                                 m_first_of_key.get_as<std::uint32_t>(), kNoFirst, s);
  plan_kernel<<<1, 32, 0, s>>>(m_first_of_key.get_as<std::uint32_t>(), n, count_on_device,
                               m_plan.get_as<ColourPlan>());
  MARBLES_CUDA_CHECK_LAUNCH();
  position = at.colour;
  if (!read_back) return 0;
  // One read: the firsts of every key, the rounds run and the count.
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_host, m_first_of_key.get_as<std::uint32_t>(),
                                     (kMaxColours + 2) * sizeof(std::uint32_t), cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_host + kRounds, count + kMaxColourRounds + 1, sizeof(std::uint32_t),
                                     cudaMemcpyDeviceToHost, s));
  if (count_on_device)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(m_host + kCount, count_on_device, sizeof(std::uint32_t), cudaMemcpyDeviceToHost, s));
  m_bytes += (count_on_device ? kRead : kCount) * sizeof(std::uint32_t);
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  m_rounds = m_host[kRounds];
  if (count_on_device) m_last_count = m_host[kCount];
  plan_of_firsts(m_host, m_last_count <= n ? m_last_count : 0, plan);  // as plan_kernel makes it
  return plan.colours;
}

void ColouringCuda::impact_levels(const SweepRecords& records, const real* approach, std::uint32_t n,
                                  std::size_t body_count, real rest_speed, std::uint32_t*& order,
                                  const std::uint32_t*& first, int sm_count, cudaStream_t s,
                                  const std::uint32_t* count_on_device, DeviceBuffer* word_memory,
                                  DeviceBuffer* level_memory) {
  order = nullptr;
  first = nullptr;
  if (n == 0) return;
  // Buckets: the levels (< kMaxColourRounds), the overflow's and the others'.
  const ColouringArrays at = lay_out(n, body_count, kMaxColourRounds + 2, true, ColourRule::by_round, nullptr, word_memory,
                                             level_memory);
  MARBLES_CUDA_CHECK(cudaMemsetAsync(m_count.get_as<std::uint32_t>(), 0, sizeof(std::uint32_t), s));
  impact_candidates_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(records, approach, n, count_on_device, rest_speed,
                                                                    at.colour, at.active,
                                                                    m_count.get_as<std::uint32_t>());
  MARBLES_CUDA_CHECK_LAUNCH();
  // A level is the round that coloured it. Nothing is read on the host.
  launch_rounds(ImpactEntries{records, approach}, at, n, body_count, ColourRule::by_round, sm_count, s);
  auto* firsts = m_first_of_key.get_as<std::uint32_t>();
  ::marbles::cuda::counting_sort(at.sort, n, ColourKey{at.colour, kMaxColourRounds}, PlaceInOrder{at.order}, firsts,
                                 kNoFirst, s);
  order = at.order;
  first = firsts;
}

}  // namespace marbles::narrowphase::cuda
