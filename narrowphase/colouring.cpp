#include "narrowphase/colouring.hpp"

#include <algorithm>
#include <atomic>

#include "core/counting_sort.hpp"
#include "core/parallel.hpp"
#include "core/radix_sort.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase {

constexpr std::uint64_t kRankMask = (std::uint64_t(1) << 56) - 1;  // ranks are below 2^56

// The sequential pass visits the contacts in rank order, which is random in
// memory: each visit would wait for a contact (a 112-byte record of a list
// far larger than the caches) and then for its spheres' words. So it asks
// for the contact 16 visits ahead and for the spheres' words of the contact
// 8 ahead (by then in cache). Branch-free (GCC drops a prefetch under a
// condition); hints only, the result is the same.
template <class Pairs>
void ContactColouring::prefetch_ahead(const Pairs& contacts, std::size_t t, std::size_t count) const {
  const std::size_t last = count - 1;
  __builtin_prefetch(&contacts[m_order[t + 16 < last ? t + 16 : last]].a);
  const auto& c = contacts[m_order[t + 8 < last ? t + 8 : last]];
  const std::uint32_t b = c.b & ~kWallFlag;  // a wall's: some sphere's words, harmless
  __builtin_prefetch(m_body_next_round.data() + c.a);
  __builtin_prefetch(m_body_next_round.data() + b);
  __builtin_prefetch(m_body_used.data() + c.a);
  __builtin_prefetch(m_body_used.data() + b);
}

// The sequential form: in decreasing rank, each contact's round is one more
// than the latest round among its spheres' earlier (higher-ranked) contacts,
// which is the round Jones–Plassmann colours it in; its colour is the lowest
// free one (or its round). The same result as the rounds of the CUDA twin
// (colouring_cuda.cu), in one pass.
template <class Pairs>
std::uint32_t ContactColouring::colour_from(const Pairs& contacts, const std::vector<std::uint32_t>& active,
                                       const std::uint64_t* rank, std::size_t body_count, ColourRule rule,
                                       std::vector<std::uint32_t>& colour, std::uint32_t* rounds_out,
                                       const std::vector<std::uint32_t>* kept, const KeptMasks* masks) {
  // Clear only the spheres these contacts touch, so that the work stays in
  // proportion to the contacts (the impact stage's few candidates); when the
  // contacts outnumber the spheres (a settled pile keeps ~6 per sphere) the
  // whole arrays are cleared instead, which is cheaper than a pass over the
  // contacts. Either way every touched sphere starts at 0.
  m_body_next_round.resize(body_count);
  m_body_used.resize(body_count);
  // With masks made elsewhere every sphere's used word is copied below, so
  // only the rounds are cleared.
  const bool used_copied = kept && masks;
  auto clear = [&](const std::vector<std::uint32_t>& list) {
    for (const std::uint32_t k : list) {
      const auto& c = contacts[k];
      m_body_next_round[c.a] = 0;
      if (!is_wall(c.b)) m_body_next_round[c.b] = 0;
      if (used_copied) continue;
      m_body_used[c.a] = 0;
      if (!is_wall(c.b)) m_body_used[c.b] = 0;
    }
  };
  const bool every_sphere = active.size() + (kept ? kept->size() : 0) >= body_count;
  if (every_sphere) {
    // Every sphere's words on all threads, the masks made elsewhere copied
    // in the same loop.
    std::uint32_t* next_round = m_body_next_round.data();
    std::uint64_t* used = m_body_used.data();
    const std::uint64_t* from = used_copied ? masks->used : nullptr;
    const auto spheres = static_cast<std::ptrdiff_t>(body_count);
#pragma omp parallel for schedule(static) if (spheres >= 20000)
    for (std::ptrdiff_t i = 0; i < spheres; ++i) {
      next_round[i] = 0;
      used[i] = from ? from[i] : 0;
    }
  } else {
    clear(active);
    if (kept) clear(*kept);
  }
  std::uint32_t colours = 0, rounds = 0;
  if (used_copied) {  // made elsewhere: every sphere's word (copied above with every sphere's)
    if (!every_sphere) std::copy(masks->used, masks->used + body_count, m_body_used.begin());
    colours = masks->colours;
  } else if (kept) {  // the kept colours hold their spheres first; they take no round
    const std::uint32_t* kk = kept->data();
    const std::uint32_t* colour_of = colour.data();
    colours = or_kept_colours(
        kept->size(), body_count,
        [&](std::uint32_t t) {
          const auto& c = contacts[kk[t]];
          return KeptItem{c.a, c.b, static_cast<std::uint8_t>(colour_of[kk[t]])};
        },
        m_body_used.data(), m_thread_used);
  }
  // Decreasing rank: an ascending radix sort of (2^56 - 1 - rank) (ranks are
  // 56 bits and unique), carrying the contact index. The ranks of
  // contact_rank and impact_rank keep the index in their low 32 bits, so in
  // index order the keys' low words ascend; then a stable sort of the top 24
  // bits alone (3 passes instead of 7) gives the same order.
  const std::size_t count = active.size();
  m_by_rank.resize(count);
  m_order.resize(count);
  bool low_ascending = true;
  for (std::size_t t = 0; t < count; ++t) {
    m_by_rank[t] = kRankMask - rank[active[t]];
    m_order[t] = active[t];
    if (t > 0 && static_cast<std::uint32_t>(m_by_rank[t]) <= static_cast<std::uint32_t>(m_by_rank[t - 1]))
      low_ascending = false;
  }
  if (low_ascending) {
    m_high.resize(count);
    for (std::size_t t = 0; t < count; ++t) m_high[t] = static_cast<std::uint32_t>(m_by_rank[t] >> 32);
    radix_sort_pairs(m_high, m_order, 24, m_sort_high, m_sort_values);
  } else {
    radix_sort_pairs(m_by_rank, m_order, 56, m_sort_keys, m_sort_values);
  }
  for (std::size_t t = 0; t < count; ++t) {
    prefetch_ahead(contacts, t, count);
    const std::uint32_t k = m_order[t];
    const auto& c = contacts[k];
    const bool wall = is_wall(c.b);
    std::uint32_t round = m_body_next_round[c.a];
    if (!wall) round = std::max(round, m_body_next_round[c.b]);
    m_body_next_round[c.a] = round + 1;
    if (!wall) m_body_next_round[c.b] = round + 1;
    if (round >= kMaxColourRounds) {
      colour[k] = kOverflowColour;
      continue;
    }
    rounds = std::max(rounds, round + 1);
    if (rule == ColourRule::by_round) {
      colour[k] = round;
      continue;
    }
    colour[k] = take_lowest_free(m_body_used[c.a], wall ? nullptr : &m_body_used[c.b]);
    if (colour[k] != kOverflowColour) colours = std::max(colours, colour[k] + 1);
  }
  if (rounds_out) *rounds_out = rounds;
  return rule == ColourRule::by_round ? rounds : colours;
}
template std::uint32_t ContactColouring::colour_from(const Runs<const Contact>&, const std::vector<std::uint32_t>&,
                                                   const std::uint64_t*, std::size_t, ColourRule,
                                                   std::vector<std::uint32_t>&, std::uint32_t*,
                                                   const std::vector<std::uint32_t>*, const KeptMasks*);
template std::uint32_t ContactColouring::colour_from(const Runs<const FoundContact>&,
                                                   const std::vector<std::uint32_t>&, const std::uint64_t*,
                                                   std::size_t, ColourRule, std::vector<std::uint32_t>&,
                                                   std::uint32_t*, const std::vector<std::uint32_t>*,
                                                   const KeptMasks*);
template std::uint32_t ContactColouring::colour_from(const PlacedPairs&, const std::vector<std::uint32_t>&,
                                                   const std::uint64_t*, std::size_t, ColourRule,
                                                   std::vector<std::uint32_t>&, std::uint32_t*,
                                                   const std::vector<std::uint32_t>*, const KeptMasks*);

void ContactColouring::colour_and_sort(std::vector<Contact>& contacts, std::size_t body_count, ColourRanges& out,
                                       const std::uint8_t* kept_colour, const BodiesView* prepare, real rest_speed,
                                       const std::uint8_t* loaded) {
  // Gathered into the colouring's own buffer (it holds the last call's
  // contacts, so resize() makes few), then swapped in.
  colour_and_sort(ContactRuns(contacts.data()), contacts.size(), m_sorted, body_count, out, kept_colour, prepare,
                  rest_speed, loaded);
  contacts.swap(m_sorted);
}

void ContactColouring::colour_and_place(Runs<const Contact> contacts, std::size_t count, std::size_t body_count,
                                        ColourRanges& out, const std::uint8_t* kept_colour,
                                        const std::uint8_t* loaded, const KeptMasks* masks) {
  place_runs(contacts, count, body_count, out, kept_colour, loaded, masks);
}
void ContactColouring::colour_and_place(Runs<const FoundContact> contacts, std::size_t count, std::size_t body_count,
                                        ColourRanges& out, const std::uint8_t* kept_colour,
                                        const std::uint8_t* loaded, const KeptMasks* masks) {
  place_runs(contacts, count, body_count, out, kept_colour, loaded, masks);
}

template <class C>
void ContactColouring::place_runs(Runs<const C> contacts, std::size_t count_in, std::size_t body_count,
                                  ColourRanges& out, const std::uint8_t* kept_colour, const std::uint8_t* loaded,
                                  const KeptMasks* masks) {
  const auto n = static_cast<std::uint32_t>(count_in);
  m_rank.resize(n);
  m_colour.resize(n);
  m_all.clear();
  m_kept.clear();
  if (kept_colour && masks) {  // no list of the kept: on all threads, the new ones listed in index order
    collect_in_order(n, 20000, m_all, m_all_parts, [&](std::size_t k, std::vector<std::uint32_t>& to) {
      const std::uint8_t kept = kept_colour[k];
      m_colour[k] = kept < kMaxColours ? kept : kUncoloured;
      if (kept >= kMaxColours) to.push_back(static_cast<std::uint32_t>(k));
    });
  } else {
    for (std::uint32_t k = 0; k < n; ++k) {
      const std::uint8_t kept = kept_colour ? kept_colour[k] : kNoKeptColour;
      if (kept < kMaxColours) {
        m_colour[k] = kept;
        m_kept.push_back(k);
      } else {
        m_colour[k] = kUncoloured;
        m_all.push_back(k);
      }
    }
  }
  // The new contacts' ranks in a loop of their own: within the one above,
  // the compiler read every contact's spheres ahead of the branch, kept or
  // not (settle scene of 10^5: that serial loop 0.9 -> 0.6 % of the step's
  // samples; the same colours).
  {
    const std::uint32_t* all = m_all.data();
    const auto fresh = static_cast<std::ptrdiff_t>(m_all.size());
#pragma omp parallel for schedule(static) if (fresh >= 2048)
    for (std::ptrdiff_t t = 0; t < fresh; ++t) {
      const std::uint32_t k = all[t];
      m_rank[k] = contact_rank(contacts[k].a, contacts[k].b, k);
    }
  }
  out.colours = colour_from(contacts, m_all, m_rank.data(), body_count, ColourRule::lowest_free, m_colour,
                            &out.rounds, &m_kept, kept_colour ? masks : nullptr);

  // Colour-major, index order within a colour (a stable counting sort, in
  // parallel): each place's contact first, then the contacts gathered place
  // by place, each prepared on its way when asked. Gathered, the 112-byte
  // contacts are written in order and read ahead of need; moved contact by
  // contact to their places, each write landed on its own lines and the
  // move waited on them (settle scene of 10^5, 2 threads: see
  // docs/architecture.md "The CPU's colour-major gather").
  m_source.resize(n);
  std::uint32_t* source = m_source.data();
  const std::uint32_t* colour_of = m_colour.data();
  const std::uint32_t colours = out.colours, overflow_bucket = colours;
  counting_sort(
      n, colours + 1,  // the colours, then the overflow set
      [&](std::uint32_t k) { return colour_of[k] == kOverflowColour ? overflow_bucket : colour_of[k]; },
      [&](std::uint32_t k, std::uint32_t place) { source[place] = k; }, out.begin, m_bucket_count);
  // With loads, each contact's record: within each colour the loaded
  // contacts' places first, then the others', each in index order (the
  // order of the colour's places): a count and a pass a colour, the colours
  // on all threads; the overflow set's records are its own places.
  if (!loaded) {
    out.unloaded.clear();
    out.record.clear();
  } else {
    out.unloaded.resize(colours);
    out.record.resize(n);  // every word written below; resize() fills only past the last substep's size
    std::uint32_t* record = out.record.data();
    std::uint32_t* unloaded_at = out.unloaded.data();
    const std::uint32_t* begin = out.begin.data();
#pragma omp parallel for schedule(dynamic, 1) if (n >= 20000)
    for (std::ptrdiff_t c = 0; c < static_cast<std::ptrdiff_t>(colours); ++c) {
      std::uint32_t carried = 0;
      for (std::uint32_t p = begin[c]; p < begin[c + 1]; ++p) carried += loaded[source[p]] != 0 ? 1u : 0u;
      std::uint32_t next[2] = {begin[c], begin[c] + carried};  // the loaded part's, the other's
      unloaded_at[c] = next[1];
      for (std::uint32_t p = begin[c]; p < begin[c + 1]; ++p) record[p] = next[loaded[source[p]] != 0 ? 0 : 1]++;
    }
    for (std::uint32_t p = begin[colours]; p < n; ++p) record[p] = p;
  }
}

void ContactColouring::colour_and_sort(ContactRuns contacts, std::size_t count_in, std::vector<Contact>& sorted_out,
                                       std::size_t body_count, ColourRanges& out, const std::uint8_t* kept_colour,
                                       const BodiesView* prepare, real rest_speed, const std::uint8_t* loaded) {
  colour_and_place(contacts, count_in, body_count, out, kept_colour, loaded);
  const auto n = static_cast<std::uint32_t>(count_in);
  const std::uint32_t* source = m_source.data();
  // resize() makes (value-initialises) only the contacts past its size: the
  // callers hand a buffer that kept the last substep's.
  sorted_out.resize(n);
  const Runs<const Contact> in = contacts;
  Contact* sorted = sorted_out.data();
  std::atomic<bool> fast{false};  // written only when seen (rare): no traffic in a pile at rest
  const auto count = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static) if (count >= 20000)
  for (std::ptrdiff_t p = 0; p < count; ++p) {
    hint_place_ahead(in, source, p, count);
    Contact& c = sorted[p];
    c = in[source[p]];
    if (!prepare) continue;
    hint_bodies_ahead(in, source, p, count, *prepare);
    prepare_from_world(c, *prepare);
    if (is_impact_candidate(c, rest_speed)) fast.store(true, std::memory_order_relaxed);
  }
  out.fast_approach = !prepare || fast.load(std::memory_order_relaxed);
}

bool colouring_is_proper(const std::vector<Contact>& contacts, const ColourRanges& ranges, std::size_t body_count) {
  std::vector<std::uint32_t> seen(body_count, kUncoloured);
  for (std::uint32_t c = 0; c < ranges.colours; ++c)
    for (std::uint32_t k = ranges.begin[c]; k < ranges.begin[c + 1]; ++k) {
      for (std::uint32_t body : {contacts[k].a, contacts[k].b}) {
        if (is_wall(body)) continue;
        if (seen[body] == c) return false;
        seen[body] = c;
      }
    }
  return true;
}

}  // namespace marbles::narrowphase
