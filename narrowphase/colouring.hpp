// narrowphase/colouring.hpp — contacts into colours (colouring_math.hpp has
// the method), on the CPU.
//
// The solver colouring puts the contacts in colour-major order: colour 0's
// contacts first, each colour in contact-index order, the overflow set last.
// Cost: a few passes over a shrinking list of uncoloured contacts (each round
// colours a large share of what is left).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "core/parallel.hpp"
#include "core/spheres.hpp"
#include "narrowphase/colouring_math.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

// Contacts [begin[c], begin[c + 1]) have colour c; the last range
// [begin[colours], begin[colours + 1]) is the overflow set. With kept colours
// a colour may be empty (its contacts all gone).
struct ColourRanges {
  std::vector<std::uint32_t> begin{0, 0};
  // The CPU solver's records, where the colouring was told the loads the
  // contacts carry in (else both empty: contact k is record k): contact k
  // is record[k], and colour c's records are its contacts' places,
  // [begin[c], begin[c + 1]), those that carried a load first,
  // [begin[c], unloaded[c]), the others after, each in index order; the
  // overflow set's are its own places. No bit of a colour's sweep depends
  // on the order of its records (its contacts share no sphere); the parts
  // put a settled pile's unloaded contacts side by side, whose updates are
  // mostly known idle (solver_lanes.hpp all_idle), so that the sweep's
  // lanes meet whole blocks of them.
  std::vector<std::uint32_t> record;
  std::vector<std::uint32_t> unloaded;
  std::uint32_t colours = 0;
  std::uint32_t rounds = 0;  // colouring rounds it took
  // Whether a contact may approach faster than the rest speed given to
  // colour_and_sort: false only when it prepared every contact and saw none
  // (the impact stage then skips its scan for candidates: a pile at rest).
  bool fast_approach = true;
  std::size_t overflow() const { return begin[colours + 1] - begin[colours]; }
  // Where colour c's unloaded records start (its end where not told).
  std::uint32_t unloaded_from(std::uint32_t c) const { return unloaded.empty() ? begin[c + 1] : unloaded[c]; }
  // Contact k's record.
  std::uint32_t record_of(std::uint32_t k) const { return record.empty() ? k : record[k]; }
  std::size_t size() const { return begin[colours + 1]; }
};

// The body pairs of colour-major contacts read from the solver's records:
// place k's pair is bodies[places.record_of(k)]. What the impact stage
// colours.
struct PlacedPairs {
  const BodyPair* bodies = nullptr;
  const ColourRanges* places = nullptr;
  const BodyPair& operator[](std::size_t k) const { return bodies[places->record_of(static_cast<std::uint32_t>(k))]; }
};

// How far ahead a walk over colour-major places asks for the contact it
// will read (and, half as far, for that contact's bodies' velocities): each
// place reads a 112-byte contact in random order from a list far past the
// caches, where the search left it, and prepares it. Settle scene of 10^5,
// 2 threads, colour verb, six runs alternated: 16 ahead 9.1-10.6 ms (median
// 9.4), 32 ahead 7.5-9.8, 64 ahead 6.9-10.4 (median 7.6), 128 ahead
// 8.0-11.2; then three pairs, 16 against 64: 8.7-9.3 against 6.5-6.9 ms.
inline constexpr std::ptrdiff_t kPlaceAhead = 64;

// The hints of such a walk at place p of n (places[p]: the contact at place
// p): the contact kPlaceAhead places ahead; and the velocities of the bodies
// of the one half as far ahead. Each branch-free (GCC drops a prefetch under
// a condition, even inside the callee: the records' making took 68 ms a step
// instead of 51 with the second behind a test of its world); hints only,
// the result is the same. The colouring's gather (colour_and_sort) and the
// solver's records (ContactSolver::make_records).
template <class C>  // Contact or FoundContact
inline void hint_place_ahead(Runs<const C> found, const std::uint32_t* places, std::ptrdiff_t p, std::ptrdiff_t n) {
  const auto* next = reinterpret_cast<const char*>(&found[places[p + kPlaceAhead < n ? p + kPlaceAhead : n - 1]]);
  __builtin_prefetch(next), __builtin_prefetch(next + sizeof(C) - 1);
  if constexpr (sizeof(C) > 64) __builtin_prefetch(next + 64);
}
template <class C>
inline void hint_bodies_ahead(Runs<const C> found, const std::uint32_t* places, std::ptrdiff_t p, std::ptrdiff_t n,
                              const BodiesView& world) {
  const C& ahead = found[places[p + kPlaceAhead / 2 < n ? p + kPlaceAhead / 2 : n - 1]];
  const std::uint32_t b = ahead.b & ~kWallFlag;  // a wall's: some sphere's words, harmless
  __builtin_prefetch(world.velocity + ahead.a), __builtin_prefetch(world.velocity + b);
  __builtin_prefetch(world.angular_velocity + ahead.a), __builtin_prefetch(world.angular_velocity + b);
}

// The colours kept at each sphere: bit c of used[i] is set where a contact
// of sphere i keeps colour c; `colours` is one more than the largest kept
// colour (0: none). What the colouring's kept contacts hold at their spheres
// before it colours the others, made where the kept contacts' spheres are
// cheaper to read than the contacts themselves (ContactCache::kept_masks,
// from its matched entries).
struct KeptMasks {
  const std::uint64_t* used = nullptr;
  std::uint32_t colours = 0;
};

// One item of or_kept_colours: a contact's spheres and the colour it keeps.
struct KeptItem {
  std::uint32_t a, b;
  std::uint8_t colour;
};

// Ors the kept colours of items [0, n) into used[0, body_count) (which the
// caller has cleared; walls hold no colour): item(t) gives {a, b, colour}
// (colour kNoKeptColour: none kept). In parallel from 16384 items: an or
// of bits gives the same masks in any order. With a few threads each ors
// into masks of its own (the first into `used`, the others into
// `thread_used`), joined after; with more, into `used` by atomics (settle
// scene of 10^5, 2 threads: the colouring 3.3 -> 2.4 % of the step's
// samples with masks of their own). Returns one more than the largest
// colour kept (0: none).
template <class Item>
std::uint32_t or_kept_colours(std::size_t n, std::size_t body_count, Item&& item, std::uint64_t* used,
                              std::vector<std::uint64_t>& thread_used) {
  constexpr int kMostOwnMasks = 4;
  const auto m = static_cast<std::ptrdiff_t>(n);
  const int threads = m >= 16384 ? thread_count() : 1;
  const bool own_masks = threads > 1 && threads <= kMostOwnMasks, atomics = threads > kMostOwnMasks;
  if (own_masks) thread_used.resize(static_cast<std::size_t>(threads - 1) * body_count);
  std::uint64_t* others = thread_used.data();
  std::uint32_t top = 0;
#pragma omp parallel num_threads(threads) reduction(max : top) if (threads > 1)
  {
    const int me = thread_index();
    std::uint64_t* mine = own_masks && me > 0 ? others + static_cast<std::size_t>(me - 1) * body_count : used;
    if (mine != used) std::fill(mine, mine + body_count, std::uint64_t(0));  // each thread its own
#pragma omp for schedule(static)
    for (std::ptrdiff_t t = 0; t < m; ++t) {
      const KeptItem k = item(static_cast<std::uint32_t>(t));
      if (k.colour >= kMaxColours) continue;
      const std::uint64_t bit = std::uint64_t(1) << k.colour;
      if (atomics) {
#pragma omp atomic update
        used[k.a] |= bit;
        if (!is_wall(k.b)) {
#pragma omp atomic update
          used[k.b] |= bit;
        }
      } else {
        mine[k.a] |= bit;
        if (!is_wall(k.b)) mine[k.b] |= bit;
      }
      top = std::max<std::uint32_t>(top, k.colour + 1u);
    }
    if (own_masks) {
#pragma omp for schedule(static)
      for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(body_count); ++i)
        for (int o = 0; o < threads - 1; ++o) used[i] |= others[static_cast<std::size_t>(o) * body_count + i];
    }
  }
  return top;
}

// The same for items sorted by their sphere a, each b a wall or a sphere
// above a (the cache's entries, in key order), on all threads without
// atomics for almost every item: the items are split between the threads
// at changes of a, so each thread's spheres a are its own, and so is every
// b below the next thread's first a; only the items whose b lies past that
// (across a split) are ored after a barrier, by atomics, in a second pass
// over the thread's items. Masks of each
// thread's own, joined after, cost memory in proportion to the threads,
// and atomics for every item ~40 cycles each: on 16 threads the kept masks
// of the settle scene of 10^5 took 1.2 ms a step by atomics (12 at 10^6).
template <class Item>
std::uint32_t or_kept_colours_by_a(std::size_t n, Item&& item, std::uint64_t* used) {
  const int threads = n >= 16384 ? thread_count() : 1;
  std::uint32_t top = 0;
#pragma omp parallel num_threads(threads) reduction(max : top) if (threads > 1)
  {
    const int t = thread_index(), team = team_size();
    // This thread's items: from the first whose a differs from the item
    // before's, at or after its even share's start, to the next thread's.
    auto split = [&](int u) {
      std::size_t k = n * static_cast<std::size_t>(u) / static_cast<std::size_t>(team);
      while (k > 0 && k < n && item(static_cast<std::uint32_t>(k)).a == item(static_cast<std::uint32_t>(k - 1)).a) ++k;
      return k;
    };
    const std::size_t lo = split(t), hi = split(t + 1);
    const std::uint32_t a_next = hi < n ? item(static_cast<std::uint32_t>(hi)).a : ~std::uint32_t(0);
    std::size_t first_across = hi;
    for (std::size_t k = lo; k < hi; ++k) {
      const KeptItem i = item(static_cast<std::uint32_t>(k));
      if (i.colour >= kMaxColours) continue;
      const std::uint64_t bit = std::uint64_t(1) << i.colour;
      used[i.a] |= bit;
      if (!is_wall(i.b)) {
        if (i.b < a_next) used[i.b] |= bit;
        else first_across = std::min(first_across, k);
      }
      top = std::max<std::uint32_t>(top, i.colour + 1u);
    }
#pragma omp barrier
    // The items across: the thread's own items again from the first of them
    // (no list to allocate inside the region; in a pile they lie near the
    // end of its range), those whose b lies past its spheres.
    for (std::size_t k = first_across; k < hi; ++k) {
      const KeptItem i = item(static_cast<std::uint32_t>(k));
      if (i.colour >= kMaxColours || is_wall(i.b) || i.b < a_next) continue;
#pragma omp atomic update
      used[i.b] |= std::uint64_t(1) << i.colour;
    }
  }
  return top;
}

class ContactColouring {
 public:
  // Colours `active` (indices into contacts, ascending) by `rank` (one per
  // contact index, ending in 0xffffffff - index as contact_rank and
  // impact_rank do) under `rule`; writes colour[k] for each active k and
  // returns the number of colours (lowest_free) or rounds (by_round) used,
  // overflow not counted.
  // `body_count`: spheres (contacts' a and b are below it, or walls).
  // `kept` (lowest_free only): contacts whose colour[k] is already set (a
  // proper colouring among themselves); they hold their colours at their
  // spheres and take no part in the rounds.
  // `masks` (with `kept`): the kept contacts' colours at their spheres,
  // made elsewhere, used instead of reading the kept contacts.
  // `contacts[k]` has the contact's a and b: the contacts, or the records'
  // pairs by place (PlacedPairs).
  std::uint32_t colour(Runs<const Contact> contacts, const std::vector<std::uint32_t>& active,
                       const std::uint64_t* rank, std::size_t body_count, ColourRule rule,
                       std::vector<std::uint32_t>& colour, std::uint32_t* rounds = nullptr,
                       const std::vector<std::uint32_t>* kept = nullptr, const KeptMasks* masks = nullptr) {
    return colour_from<Runs<const Contact>>(contacts, active, rank, body_count, rule, colour, rounds, kept, masks);
  }
  std::uint32_t colour(const PlacedPairs& contacts, const std::vector<std::uint32_t>& active,
                       const std::uint64_t* rank, std::size_t body_count, ColourRule rule,
                       std::vector<std::uint32_t>& colour, std::uint32_t* rounds = nullptr,
                       const std::vector<std::uint32_t>* kept = nullptr) {
    return colour_from<PlacedPairs>(contacts, active, rank, body_count, rule, colour, rounds, kept);
  }

  // The solver colouring of all contacts: contact k keeps kept_colour[k] when
  // it is not kNoKeptColour (kept_colour null: none kept), the others are
  // coloured by contact_rank around them; then puts `contacts` in
  // colour-major order. With `loaded` (loaded[k] not 0: contact k carries a
  // load in) it also places the solver's records, each colour's loaded ones
  // first (out.record, out.unloaded). With `prepare` (the world's bodies)
  // each contact is also prepared on its way (prepare_from_world,
  // solver_math.hpp): the solver is then told the contacts are prepared.
  // `rest_speed`: with `prepare`, out.fast_approach tells whether a contact
  // approaches faster (is_impact_candidate).
  void colour_and_sort(std::vector<Contact>& contacts, std::size_t body_count, ColourRanges& out,
                       const std::uint8_t* kept_colour = nullptr, const BodiesView* prepare = nullptr,
                       real rest_speed = 0, const std::uint8_t* loaded = nullptr);
  // The same for `count` contacts held in runs (Runs), gathered in
  // colour-major order into `sorted` (whose contents go; it holds none of
  // the runs).
  void colour_and_sort(ContactRuns contacts, std::size_t count, std::vector<Contact>& sorted, std::size_t body_count,
                       ColourRanges& out, const std::uint8_t* kept_colour = nullptr,
                       const BodiesView* prepare = nullptr, real rest_speed = 0, const std::uint8_t* loaded = nullptr);
  // The colouring alone: `out` as colour_and_sort gives it (fast_approach
  // left as it was), the contacts left where they are; places() then names
  // the contact at each colour-major place, which the CPU step's records
  // are made from (ContactSolver::make_records).
  // `masks` (with `kept_colour`): the kept contacts' colours at their
  // spheres (KeptMasks), the same colouring without a read of them.
  void colour_and_place(Runs<const Contact> contacts, std::size_t count, std::size_t body_count, ColourRanges& out,
                        const std::uint8_t* kept_colour = nullptr, const std::uint8_t* loaded = nullptr,
                        const KeptMasks* masks = nullptr);
  // The same for the contacts as found (the CPU step's).
  void colour_and_place(Runs<const FoundContact> contacts, std::size_t count, std::size_t body_count,
                        ColourRanges& out, const std::uint8_t* kept_colour = nullptr,
                        const std::uint8_t* loaded = nullptr, const KeptMasks* masks = nullptr);
  // places()[p]: the index of the contact at place p of the last
  // colour_and_place (or colour_and_sort).
  const std::uint32_t* places() const { return m_source.data(); }

 private:
  template <class Pairs>
  std::uint32_t colour_from(const Pairs& contacts, const std::vector<std::uint32_t>& active, const std::uint64_t* rank,
                          std::size_t body_count, ColourRule rule, std::vector<std::uint32_t>& colour,
                          std::uint32_t* rounds, const std::vector<std::uint32_t>* kept,
                          const KeptMasks* masks = nullptr);
  template <class Pairs>
  void prefetch_ahead(const Pairs& contacts, std::size_t t, std::size_t count) const;
  template <class C>
  void place_runs(Runs<const C> contacts, std::size_t count, std::size_t body_count, ColourRanges& out,
                  const std::uint8_t* kept_colour, const std::uint8_t* loaded, const KeptMasks* masks);
  std::vector<std::uint64_t> m_body_used, m_rank, m_by_rank, m_sort_keys;
  std::vector<std::uint64_t> m_thread_used;  // or_kept_colours' masks of the threads after the first
  std::vector<std::uint32_t> m_body_next_round;
  std::vector<std::uint32_t> m_all, m_kept, m_colour, m_bucket_count, m_order, m_sort_values, m_high, m_sort_high,
      m_source;
  std::vector<Contact> m_sorted;
  std::vector<std::vector<std::uint32_t>> m_all_parts;  // colour_and_place's new contacts, by thread
};

// The records the launch just before wrote, [begin, end), so that the next
// one knows whether its own are untouched by it and may be loaded before it
// ends (the GPU's dependent launches, solver_cuda.cu): whatever ran before
// the solve's first launch (the records made, the impacts) counts as having
// written every record, a warm start writes none, a sweep its own range. Where a forward sweep
// ends and a backward one starts the same range comes twice in a row (the
// last colour, or the overflow set) unless merged into one launch
// (visit_sweeps), and the second may not load early.
class LastWrites {
 public:
  explicit LastWrites(std::uint32_t all) : m_end(all) {}
  // The next launch, over [begin, end) (not empty), writing its records or
  // not: true when the launch before wrote none of them.
  bool next(std::uint32_t begin, std::uint32_t end, bool writes) {
    const bool untouched = end <= m_begin || begin >= m_end;
    m_begin = writes ? begin : 0, m_end = writes ? end : 0;
    return untouched;
  }

 private:
  std::uint32_t m_begin = 0, m_end;
};

// The sweeps' walk as launches: `sweeps` walks of visit_colours, forwards
// and backwards in turn, empty ranges left out. With `merge_turns`, a range
// that ends one sweep and begins the next (the turn: the last colour, or the
// overflow set, after a forwards sweep; colour 0 after a backwards one)
// comes once, visited twice: visit(begin, end, serial, reversed, twice),
// twice meaning the range again at once the other way (serial: one by one
// back; in parallel: each contact solved again right after itself, which
// nothing else can tell apart, as no other contact of its colour shares a
// sphere). Without, every range comes once a sweep (twice false).
template <class Begin, class Visit>
void visit_sweeps(const Begin& begin, std::uint32_t colours, int sweeps, bool merge_turns, Visit&& visit) {
  struct Held {
    std::uint32_t begin = 0, end = 0;
    bool serial = false, reversed = false, held = false;
  } held;
  auto flush = [&](bool twice) {
    if (held.held) visit(held.begin, held.end, held.serial, held.reversed, twice);
    held.held = false;
  };
  for (int it = 0; it < sweeps; ++it)
    visit_colours(begin, colours, it % 2 == 1, [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
      if (e <= b) return;
      if (merge_turns && held.held && held.begin == b && held.end == e) return flush(true);
      flush(false);
      held = {b, e, serial, reversed, true};
    });
  flush(false);
}

// The sweeps' walk by the slots of a plan the host does not read (a step
// that waits once, CudaStep::solve_in_slots): `sweeps` walks of `slots`
// slots, forwards and backwards in turn; a launch reads its slot's range
// on the device (slot < colours: that colour; slot == colours: the overflow
// set, serial; past it: nothing). It is visit_sweeps over slots as ranges
// of one (the last in the overflow set's place), each distinct: with
// `merge_turns` a slot that ends one sweep and begins the next comes once,
// visited twice (with one slot, each launch but maybe the last takes two
// sweeps). visit(slot, backwards, twice).
template <class Visit>
void visit_slot_sweeps(std::uint32_t slots, int sweeps, bool merge_turns, Visit&& visit) {
  if (slots == 0) return;
  struct Slots {  // slot k as the range [k, k + 1)
    std::uint32_t operator[](std::uint32_t k) const { return k; }
  };
  visit_sweeps(Slots{}, slots - 1, sweeps, merge_turns,
               [&](std::uint32_t slot, std::uint32_t, bool, bool backwards, bool twice) { visit(slot, backwards, twice); });
}

// A launch of the solve's walk (visit_colours, visit_sweeps): its range,
// and whether it visits it twice (a turn merged).
struct WalkRange {
  std::uint32_t begin = 0, end = 0;
  bool serial = false, reversed = false, twice = false;
};

// The most ranges one group walks (SmallRangeGroups).
inline constexpr std::size_t kMostInGroup = 16;

// The walk's launches with each run of small ones made one launch (the
// GPU walks a group in one block, a barrier between its ranges, in the
// walk's order: solver_cuda.cuh RangeGroup; the same bits, as the order of
// the ranges is the walk's and within a range no two contacts share a
// sphere). A range of at most `widest` contacts is held; a run of held
// ranges ends at a wider range, at kMostInGroup ranges or at flush(), and
// goes to group(first, n) where it has two or more, else to single(r), as
// every wider range does, in the walk's order. widest 0: no group.
template <class Single, class Group>
class SmallRangeGroups {
 public:
  SmallRangeGroups(std::uint32_t widest, Single single, Group group)
      : m_widest(widest), m_single(std::move(single)), m_group(std::move(group)) {}
  void add(const WalkRange& r) {
    if (r.end - r.begin > m_widest) {
      flush();
      m_single(r);
      return;
    }
    m_held[m_count++] = r;
    if (m_count == kMostInGroup) flush();
  }
  void flush() {
    if (m_count == 1) m_single(m_held[0]);
    else if (m_count > 1) m_group(static_cast<const WalkRange*>(m_held.data()), m_count);
    m_count = 0;
  }

 private:
  std::uint32_t m_widest;
  Single m_single;
  Group m_group;
  std::array<WalkRange, kMostInGroup> m_held{};
  std::size_t m_count = 0;
};

// True when no two contacts of one colour share a sphere (tests, checks).
bool colouring_is_proper(const std::vector<Contact>& contacts, const ColourRanges& ranges, std::size_t body_count);

// The colour of each contact of colour-major `ranges` as the cache keeps it:
// its colour, or kNoKeptColour in the overflow set.
template <class F>
void for_each_colour(const ColourRanges& ranges, F&& f) {
  for (std::uint32_t c = 0; c <= ranges.colours; ++c)
    for (std::uint32_t k = ranges.begin[c]; k < ranges.begin[c + 1]; ++k)
      f(k, c < ranges.colours ? static_cast<std::uint8_t>(c) : kNoKeptColour);
}

}  // namespace marbles::narrowphase
