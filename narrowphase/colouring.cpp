#include "narrowphase/colouring.hpp"

#include <algorithm>
#include <atomic>
#include <functional>

namespace marbles::narrowphase {
namespace {

constexpr std::ptrdiff_t kParallelFrom = 20000;  // contacts: below this one thread is faster

// body_word = max(body_word, word), safe under OpenMP.
inline void offer(std::uint64_t& body_word, std::uint64_t word) {
  std::atomic_ref<std::uint64_t> slot(body_word);
  std::uint64_t seen = slot.load(std::memory_order_relaxed);
  while (seen < word && !slot.compare_exchange_weak(seen, word, std::memory_order_relaxed)) {
  }
}

}  // namespace

// The sequential form: in decreasing rank, each contact's round is one more
// than the latest round among its spheres' earlier (higher-ranked) contacts,
// which is the round Jones–Plassmann colours it in; its colour is the lowest
// free one (or its round). Same result as colour_in_rounds, in one pass.
std::uint32_t ContactColouring::colour(const Contact* contacts, const std::vector<std::uint32_t>& active,
                                       const std::uint64_t* rank, std::size_t body_count, ColourRule rule,
                                       std::vector<std::uint32_t>& colour, std::uint32_t* rounds_out) {
  // Clear only the spheres these contacts touch: the work stays in
  // proportion to the contacts, not to the spheres.
  m_body_next_round.resize(body_count);
  m_body_used.resize(body_count);
  for (const std::uint32_t k : active) {
    const Contact& c = contacts[k];
    m_body_next_round[c.a] = 0, m_body_used[c.a] = 0;
    if (!is_wall(c.b)) m_body_next_round[c.b] = 0, m_body_used[c.b] = 0;
  }
  m_by_rank.resize(active.size());
  for (std::size_t t = 0; t < active.size(); ++t) m_by_rank[t] = rank[active[t]];
  std::sort(m_by_rank.begin(), m_by_rank.end(), std::greater<>());
  std::uint32_t colours = 0, rounds = 0;
  for (const std::uint64_t r : m_by_rank) {
    const std::uint32_t k = 0xffffffffu - static_cast<std::uint32_t>(r);  // ranks end in the index
    const Contact& c = contacts[k];
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

// The data-parallel form (what the CUDA twin runs): Jones–Plassmann rounds
// over a shrinking list of uncoloured contacts.
std::uint32_t ContactColouring::colour_in_rounds(const Contact* contacts, const std::vector<std::uint32_t>& active,
                                                 const std::uint64_t* rank, std::size_t body_count, ColourRule rule,
                                                 std::vector<std::uint32_t>& colour, std::uint32_t* rounds_out) {
  m_body_word.assign(body_count, 0);
  if (rule == ColourRule::lowest_free) m_body_used.assign(body_count, 0);
  m_active = active;
  std::uint32_t colours = 0, round = 0;
  for (; !m_active.empty() && round < kMaxColourRounds; ++round) {
    const auto n = static_cast<std::ptrdiff_t>(m_active.size());
    // 1. offers
#pragma omp parallel for schedule(static) if (n >= kParallelFrom)
    for (std::ptrdiff_t t = 0; t < n; ++t) {
      const std::uint32_t k = m_active[t];
      const Contact& c = contacts[k];
      const std::uint64_t word = round_word(round, rank[k]);
      offer(m_body_word[c.a], word);
      if (!is_wall(c.b)) offer(m_body_word[c.b], word);
    }
    // 2. contacts holding both offers take a colour (no two share a sphere)
#pragma omp parallel for schedule(static) if (n >= kParallelFrom)
    for (std::ptrdiff_t t = 0; t < n; ++t) {
      const std::uint32_t k = m_active[t];
      const Contact& c = contacts[k];
      const bool wall = is_wall(c.b);
      const std::uint64_t word = round_word(round, rank[k]);
      if (!holds_both(word, m_body_word[c.a], wall ? 0 : m_body_word[c.b], wall)) continue;
      if (rule == ColourRule::by_round) {
        colour[k] = round;
        continue;
      }
      colour[k] = take_lowest_free(m_body_used[c.a], wall ? nullptr : &m_body_used[c.b]);
    }
    // the uncoloured go on, in index order
    m_next.clear();
    for (std::uint32_t k : m_active) {
      if (colour[k] == kUncoloured) m_next.push_back(k);
      else if (colour[k] != kOverflowColour) colours = std::max(colours, colour[k] + 1);
    }
    m_active.swap(m_next);
  }
  for (std::uint32_t k : m_active) colour[k] = kOverflowColour;  // too many rounds
  if (rounds_out) *rounds_out = round;
  return rule == ColourRule::by_round ? round : colours;
}

void ContactColouring::colour_and_sort(std::vector<Contact>& contacts, std::size_t body_count, ColourRanges& out) {
  const auto n = static_cast<std::uint32_t>(contacts.size());
  m_rank.resize(n);
  m_all.resize(n);
  for (std::uint32_t k = 0; k < n; ++k) {
    m_rank[k] = contact_rank(contacts[k].a, contacts[k].b, k);
    m_all[k] = k;
  }
  m_colour.assign(n, kUncoloured);
  out.colours = colour(contacts.data(), m_all, m_rank.data(), body_count, ColourRule::lowest_free, m_colour,
                       &out.rounds);

  // Counting sort by colour, stable: colour-major, index order within a colour.
  out.begin.assign(out.colours + 2, 0);
  for (std::uint32_t k = 0; k < n; ++k) {
    const std::uint32_t c = m_colour[k] == kOverflowColour ? out.colours : m_colour[k];
    ++out.begin[c + 1];
  }
  for (std::uint32_t c = 0; c <= out.colours; ++c) out.begin[c + 1] += out.begin[c];
  std::vector<std::uint32_t> cursor(out.begin.begin(), out.begin.end() - 1);
  m_sorted.resize(n);
  for (std::uint32_t k = 0; k < n; ++k) {
    const std::uint32_t c = m_colour[k] == kOverflowColour ? out.colours : m_colour[k];
    m_sorted[cursor[c]++] = contacts[k];
  }
  contacts.swap(m_sorted);
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
