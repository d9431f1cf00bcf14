// narrowphase/colouring_math.hpp — per-contact steps of the contact
// colouring, host and device.
//
// A colour is a set of contacts of which no two share a sphere (walls take no
// colour), so the contacts of one colour can be solved at once, in any order,
// with the same result bit for bit. The colouring is Jones–Plassmann with
// fixed ranks, in rounds:
//   1. every uncoloured contact offers its rank to both its spheres
//      (body_word = max of the offers: an atomic max, whose result does not
//      depend on the order of the offers);
//   2. a contact that holds the largest offer at both its spheres is coloured
//      in this round: with the lowest colour that no coloured contact of its
//      spheres has (rule lowest_free), or with the round number (by_round).
// No two contacts coloured in one round share a sphere, so step 2 has no
// conflicts. A contact is coloured exactly when all its higher-ranked
// neighbours are, so `lowest_free` gives the colouring of the sequential
// greedy rule in rank order, and `by_round` orders every two contacts that
// share a sphere by rank (the impact stage uses it for time-of-impact order).
// The result depends on the ranks only: the CPU and the GPU agree bit for bit.
//
// Kept colours: a contact that persists from the last substep keeps the
// colour it had there (any subset of a proper colouring is proper), marked in
// its spheres' masks before the rounds; only the new contacts take part in
// the rounds, taking the lowest colour free at both spheres around the kept
// ones. In a settled pile nearly every contact persists, so the rounds run
// over a few percent of the contacts. The result is a function of the
// contact list and the kept colours: both backends give the same.
#pragma once

#include <cstdint>

#include "core/bits.hpp"
#include "core/config.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

inline constexpr std::uint32_t kUncoloured = 0xffffffffu;
inline constexpr std::uint32_t kOverflowColour = 0xfffffffeu;  // solved one by one, after the colours
inline constexpr std::uint32_t kMaxColours = 64;               // one bit each in a 64-bit body mask
inline constexpr std::uint32_t kMaxColourRounds = 250;     // left uncoloured after these: overflow
// A contact's colour kept from the last substep (ContactCache: the colour its
// key had), or none. A kept colour is < kMaxColours.
inline constexpr std::uint8_t kNoKeptColour = 0xff;

enum class ColourRule : std::uint8_t { lowest_free, by_round };

// The solver's order over colour-major contacts, the same on every backend
// and on the host and the device: forwards, colours 0, 1, ... then the
// overflow set; backwards, the overflow set then the colours down to 0.
// visit(begin, end, serial, backwards): a colour's range (serial false: any
// order within, so in parallel) or the overflow set (serial true: one by
// one, reversed when backwards). `begin` as ColourRanges::begin (a vector on
// the host, an array in a kernel's parameters).
#if defined(__CUDACC__)
#pragma nv_exec_check_disable
#endif
template <class Begin, class Visit>
MARBLES_HD_INLINE void visit_colours(const Begin& begin, std::uint32_t colours, bool backwards, Visit&& visit) {
  if (backwards) {
    visit(begin[colours], begin[colours + 1], true, true);
    for (std::uint32_t c = colours; c-- > 0;) visit(begin[c], begin[c + 1], false, true);
  } else {
    for (std::uint32_t c = 0; c < colours; ++c) visit(begin[c], begin[c + 1], false, false);
    visit(begin[colours], begin[colours + 1], true, false);
  }
}

// The impact levels' ranges from the firsts their sort left (first[key]:
// the first sorted position holding key, kNoFirst where none): the levels'
// keys are 0, 1, ... contiguous (a level-l contact has a neighbour of level
// l - 1), the overflow's kMaxColourRounds, the other contacts'
// kMaxColourRounds + 1, n sorted in all. visit(begin, end, serial) for each
// level in order, then the overflow set (serial: one by one, in order).
inline constexpr std::uint32_t kNoFirst = 0xffffffffu;
#if defined(__CUDACC__)
#pragma nv_exec_check_disable
#endif
template <class Visit>
MARBLES_HD_INLINE void visit_levels(const std::uint32_t* first, std::uint32_t n, Visit&& visit) {
  const std::uint32_t overflow = first[kMaxColourRounds], others = first[kMaxColourRounds + 1];
  const std::uint32_t levels_end = overflow != kNoFirst ? overflow : others != kNoFirst ? others : n;
  for (std::uint32_t l = 0; l < kMaxColourRounds && first[l] != kNoFirst; ++l)
    visit(first[l], l + 1 < kMaxColourRounds && first[l + 1] != kNoFirst ? first[l + 1] : levels_end, false);
  if (overflow != kNoFirst) visit(overflow, others != kNoFirst ? others : n, true);
}

// The colour ranges of colour-major contacts as a whole stage walks them:
// colour c is [begin[c], begin[c + 1]), the overflow set [begin[colours],
// begin[colours + 1]). The same words on the host and in device memory.
struct ColourPlan {
  std::uint32_t begin[kMaxColours + 2] = {};
  std::uint32_t colours = 0;

  // The largest colour (the overflow set is one thread's).
  MARBLES_HD_INLINE std::uint32_t widest() const {
    std::uint32_t w = 0;
    for (std::uint32_t c = 0; c < colours; ++c) w = begin[c + 1] - begin[c] > w ? begin[c + 1] - begin[c] : w;
    return w;
  }
  MARBLES_HD_INLINE bool empty() const { return begin[colours + 1] == begin[0]; }
};

// Each colour's most contacts over the plans it is given (a step's
// substeps: the CUDA step's slots are sized by them), most[c] for the
// plan's colours c; the overflow set and the words past the colours are
// left as they are.
template <class Word>
MARBLES_HD_INLINE void keep_most_per_colour(const ColourPlan& plan, Word* most) {
  for (std::uint32_t c = 0; c < plan.colours; ++c) {
    const std::uint32_t size = plan.begin[c + 1] - plan.begin[c];
    if (size > most[c]) most[c] = size;
  }
}

// Whether launches by `slots` slots of a plan (slot s < colours: colour s;
// s == colours: the overflow set, serial; past it: nothing; the CUDA step's
// solve without waits) walk all of it: every colour has its slot (even an
// empty one: the step reads each slot's colour's size), and the overflow
// set one too unless it is empty.
MARBLES_HD_INLINE bool slots_hold(const ColourPlan& plan, std::uint32_t slots) {
  return plan.colours < slots || (plan.colours == slots && plan.begin[plan.colours + 1] == plan.begin[plan.colours]);
}

// The plan of n contacts from the firsts their counting sort by colour left
// (first[key]: the first sorted position holding key, kNoFirst where none;
// keys: the colours below kMaxColours, the overflow's kMaxColours, the
// inactive's kMaxColours + 1). Colours may have gaps (a kept colour whose
// other contacts are gone): an empty colour's range is empty. The host reads
// the firsts back and makes it so; the device makes it in place.
MARBLES_HD_INLINE void plan_of_firsts(const std::uint32_t* first, std::uint32_t n, ColourPlan& plan) {
  std::uint32_t colours = kMaxColours;
  while (colours > 0 && first[colours - 1] == kNoFirst) --colours;
  const std::uint32_t overflow_first = first[kMaxColours], inactive_first = first[kMaxColours + 1];
  const std::uint32_t coloured_end =
      overflow_first != kNoFirst ? overflow_first : inactive_first != kNoFirst ? inactive_first : n;
  const std::uint32_t overflow_end = inactive_first != kNoFirst ? inactive_first : n;
  plan.colours = colours;
  plan.begin[0] = 0;
  plan.begin[colours] = coloured_end;
  for (std::uint32_t c = colours; c-- > 1;) plan.begin[c] = first[c] != kNoFirst ? first[c] : plan.begin[c + 1];
  plan.begin[colours + 1] = overflow_first != kNoFirst ? overflow_end : coloured_end;
  for (std::uint32_t c = colours + 2; c < kMaxColours + 2; ++c) plan.begin[c] = plan.begin[colours + 1];
}

// A 32-bit integer hash (lowbias32): spreads ranks so that colouring rounds
// stay few (index order would make long chains of dependent contacts).
MARBLES_HD_INLINE std::uint32_t mix32(std::uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

// Rank of contact k for the solver colouring: a hash of its body pair (stable
// while the contact persists), ties broken towards the lower index. 56 bits.
MARBLES_HD_INLINE std::uint64_t contact_rank(std::uint32_t a, std::uint32_t b, std::uint32_t k) {
  const std::uint32_t h = mix32(a * 0x9e3779b1u ^ mix32(b)) & 0xffffffu;
  return (std::uint64_t(h) << 32) | (0xffffffffu - k);
}

// Rank of an impact: earlier time of impact first, then the lower index (the
// order of the sequential impact stage). toi >= 0 (s).
MARBLES_HD_INLINE std::uint64_t impact_rank(real toi, std::uint32_t k) {
  const std::uint32_t bits = bits_of_float(static_cast<float>(toi));
  const std::uint32_t earlier = (0x7fffffffu - (bits & 0x7fffffffu)) >> 7;  // 24 bits, larger = earlier
  return (std::uint64_t(earlier) << 32) | (0xffffffffu - k);
}

// The offer of a contact in round r: the round in the top byte, so an offer
// of this round beats every stale offer of an earlier one (no reset needed).
MARBLES_HD_INLINE std::uint64_t round_word(std::uint32_t round, std::uint64_t rank) {
  return (std::uint64_t(round + 1) << 56) | rank;
}

// Step 2 for one contact: true if it is coloured in this round.
MARBLES_HD_INLINE bool holds_both(std::uint64_t word, std::uint64_t word_a, std::uint64_t word_b, bool b_is_wall) {
  return word == word_a && (b_is_wall || word == word_b);
}

// The lowest colour free at both spheres, or kOverflowColour.
MARBLES_HD_INLINE std::uint32_t lowest_free_colour(std::uint64_t used) {
  if (used == ~std::uint64_t(0)) return kOverflowColour;
  const std::uint64_t free = ~used;
  std::uint32_t c = 0;
  while (!((free >> c) & 1u)) ++c;
  return c;
}

// Gives a contact the lowest colour free at both its spheres and marks it
// used there (used_b null for a wall); kOverflowColour, marking nothing,
// when every colour is taken. Word: a 64-bit unsigned integer type.
template <class Word>
MARBLES_HD_INLINE std::uint32_t take_lowest_free(Word& used_a, Word* used_b) {
  const std::uint32_t col = lowest_free_colour(used_a | (used_b ? *used_b : Word(0)));
  if (col == kOverflowColour) return col;
  used_a |= Word(1) << col;
  if (used_b) *used_b |= Word(1) << col;
  return col;
}

}  // namespace marbles::narrowphase
