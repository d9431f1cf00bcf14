#include "narrowphase/solver.hpp"

#include "narrowphase/solver_lanes.hpp"

#include "core/parallel.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "core/environment.hpp"
#include "core/error.hpp"

namespace marbles::narrowphase {
namespace {

// Contacts of one colour: in parallel when there are enough of them to pay
// for waking the threads (a sweep is ~14 us of work per thousand contacts on
// one thread, a projection ~5, a fork and join a few us, but far more when
// the cores are shared with other processes, as under `ctest -j`); the
// overflow set always one by one. The settled pile of 10^5 ends its 17
// colours with 16117, 4238, 336 and 12 contacts.
constexpr std::ptrdiff_t kParallelFrom = 4096;

// The position stages' loop: in chunks of 1024 taken in turn, since the
// halves of a colour cost unequally (perf: one thread 27 % busier in the
// projection with halves); the order within a colour changes no bit. The
// sweeps keep halves: chunks made them slower (66 -> 68 ms at 10^5). True
// when f was true for any contact (every f is called).
template <class F>
bool any_in_colour(std::uint32_t begin, std::uint32_t end, F&& f) {
  const auto n = static_cast<std::ptrdiff_t>(end - begin);
  bool any = false;
#pragma omp parallel for schedule(dynamic, 1024) reduction(|| : any) if (n >= kParallelFrom)
  for (std::ptrdiff_t t = 0; t < n; ++t) any = f(begin + static_cast<std::uint32_t>(t)) || any;
  return any;
}

// How many contacts ahead the body loop asks for the bodies it will touch.
// A contact's update is a long dependent chain, so the core's reorder window
// holds about one contact: without the hint, each contact's body records
// (random, mostly from L3) are fetched only once it starts. A hint changes
// no arithmetic. Settled pile of 10^5 on 2 cores: see docs/architecture.md.
constexpr std::uint32_t kPrefetchAhead = 8;

// The hints, branch-free (GCC drops a __builtin_prefetch under a condition):
// the callers clamp the index instead. A wall's index (b without kWallFlag)
// points at some sphere's record: harmless.
inline void prefetch_bodies(const BodyPair& ab, const SolverBody* bodies) {
  __builtin_prefetch(bodies + ab.a);
  __builtin_prefetch(bodies + (ab.b & ~kWallFlag));
}

// A colour's records in halves (static), asking for the bodies of the
// contact kPrefetchAhead later.
template <class F>
void for_colour_ahead(const SweepRecords& s, std::uint32_t begin, std::uint32_t end, const SolverBody* bodies,
                      F&& f) {
  const auto n = static_cast<std::ptrdiff_t>(end - begin);
#pragma omp parallel for schedule(static) if (n >= kParallelFrom)
  for (std::ptrdiff_t t = 0; t < n; ++t) {
    const std::uint32_t k = begin + static_cast<std::uint32_t>(t);
    prefetch_bodies(s.bodies[std::min(k + kPrefetchAhead, end - 1)], bodies);
    f(k);
  }
}

// The last records of a part of a colour, fewer than a block of the
// sweep's lanes: blocks of lanes::W, then one by one.
template <bool Friction, bool Rolling>
void sweep_rest(const SweepRecords& s, std::uint32_t k, std::uint32_t end, SolverBody* bodies, real inv_h) {
  for (; end - k >= lanes::W; k += lanes::W) lanes::solve_block<Friction, Rolling>(s, k, bodies, inv_h);
  for (; k < end; ++k) solve_record<Friction, Rolling>(s, k, bodies, inv_h);
}

// Block t of a colour's sweep: width<V> records side by side
// (solver_lanes.hpp, the same bits as solve_record), the bodies of the next
// ones asked for first.
template <class V, bool Friction, bool Rolling, bool Uniform>
[[gnu::always_inline]] inline void sweep_block(const SweepRecords& s, std::uint32_t begin, std::uint32_t end,
                                               std::ptrdiff_t t, SolverBody* bodies, real inv_h) {
  constexpr std::uint32_t w = lanes::width<V>;
  const std::uint32_t k = begin + static_cast<std::uint32_t>(t) * w;
  for (std::uint32_t l = 0; l < w; ++l) prefetch_bodies(s.bodies[std::min(k + kPrefetchAhead + l, end - 1)], bodies);
  lanes::solve_block_as<Friction, Rolling, V, Uniform>(s, k, bodies, inv_h);
}

// The sweep over one colour, its two parts ([begin, split) the contacts that
// carried a load in, [split, end) the others: ColourRanges::record) each in
// blocks of width<V> records, each part's blocks dealt out in halves, so
// that each thread takes as many of the unloaded part's blocks, which are
// mostly idle (lanes::all_idle), as the other, and works on the same half of
// the colour's spheres in both; then each part's rest in blocks of lanes::W
// and one by one; the blocks' form, with the records' arms or without
// (SweepRecords::uniform), chosen once a colour. Defined once per lane
// kind, each compiled for its instruction set (ATTRIBUTE). The OpenMP
// loops must sit in that function: their outlined bodies take the target
// of the function they are written in, not of the callee inlined into it.
// No FMA in any target, so every operation rounds as the scalar's.
#define MARBLES_SWEEP_BLOCKS(V, UNIFORM)                                                                         \
  _Pragma("omp parallel if (end - begin >= kParallelFrom)")                                                      \
  {                                                                                                              \
    _Pragma("omp for schedule(static) nowait")                                                                   \
    for (std::ptrdiff_t t = 0; t < loaded; ++t)                                                                  \
      sweep_block<V, Friction, Rolling, UNIFORM>(s, begin, split, t, bodies, inv_h);                            \
    _Pragma("omp for schedule(static) nowait")                                                                   \
    for (std::ptrdiff_t t = 0; t < unloaded; ++t)                                                                \
      sweep_block<V, Friction, Rolling, UNIFORM>(s, split, end, t, bodies, inv_h);                              \
  }
#define MARBLES_SWEEP_RANGE(NAME, ATTRIBUTE, V)                                                                  \
  template <bool Friction, bool Rolling>                                                                         \
  [[ATTRIBUTE]] void NAME(const SweepRecords& s, std::uint32_t begin, std::uint32_t split, std::uint32_t end,    \
                          SolverBody* bodies, real inv_h) {                                                      \
    constexpr std::uint32_t w = lanes::width<V>;                                                                 \
    const auto loaded = static_cast<std::ptrdiff_t>((split - begin) / w);                                        \
    const auto unloaded = static_cast<std::ptrdiff_t>((end - split) / w);                                        \
    if (s.arms) {                                                                                                \
      MARBLES_SWEEP_BLOCKS(V, false)                                                                             \
    } else {                                                                                                     \
      MARBLES_SWEEP_BLOCKS(V, true)                                                                              \
    }                                                                                                            \
    sweep_rest<Friction, Rolling>(s, begin + static_cast<std::uint32_t>(loaded) * w, split, bodies, inv_h);      \
    sweep_rest<Friction, Rolling>(s, split + static_cast<std::uint32_t>(unloaded) * w, end, bodies, inv_h);      \
  }
MARBLES_SWEEP_RANGE(sweep_range_sse2, , lanes::L)
MARBLES_SWEEP_RANGE(sweep_range_avx2, gnu::target("avx2"), lanes::Wide)
// AVX-512's 32 vector registers for the same 8 lanes: a block's ~30 live
// vectors stay in registers (stack moves in the sweep 264 -> 94).
MARBLES_SWEEP_RANGE(sweep_range_avx512, gnu::target("avx2,avx512f,avx512vl,avx512dq,avx512bw"), lanes::Wide)
#undef MARBLES_SWEEP_RANGE
#undef MARBLES_SWEEP_BLOCKS

template <bool Friction, bool Rolling>
auto sweep_for(SweepLanes lanes) {
  switch (lanes) {
    case SweepLanes::avx512: return &sweep_range_avx512<Friction, Rolling>;
    case SweepLanes::avx2: return &sweep_range_avx2<Friction, Rolling>;
    default: return &sweep_range_sse2<Friction, Rolling>;
  }
}

template <bool Friction, bool Rolling>
void warm_start_range(const SweepRecords& s, std::uint32_t begin, std::uint32_t end, SolverBody* bodies, real) {
  for_colour_ahead(s, begin, end, bodies, [&](std::uint32_t k) { warm_start_record<Friction, Rolling>(s, k, bodies); });
}

// The contacts into the sweep's records (contact k into record
// colours.record_of(k)) with their impact words, and the impulses and the
// impact stage's words back, in parallel.
template <bool Rolling>
void pack_records(const Contact* contacts, std::size_t count, const ColourRanges& colours, const SweepRecords& s,
                  const ImpactRecords& impacts) {
  const auto n = static_cast<std::ptrdiff_t>(count);
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t k = 0; k < n; ++k)
    pack_contact<Rolling>(contacts[k], s, impacts, colours.record_of(static_cast<std::uint32_t>(k)));
}
template <bool Rolling>
void unpack_records(const SweepRecords& s, const ImpactRecords& impacts, const ColourRanges& colours,
                    Contact* contacts, std::size_t count) {
  const auto n = static_cast<std::ptrdiff_t>(count);
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t k = 0; k < n; ++k) {
    const std::uint32_t r = colours.record_of(static_cast<std::uint32_t>(k));
    unpack_sweep_impulses<Rolling>(s, r, contacts[k]);
    if (impacts.words()) contacts[k].impact_impulse = impacts.impulse[r];
  }
}

// ContactSolver::make_records' loop: true when a contact approaches faster
// than the rest speed (is_impact_candidate).
// `whole(f)`: the whole contact of found contact f.
template <bool Rolling, class C, class Whole>
bool records_made(Runs<const C> found, const std::uint32_t* places, const ColourRanges& colours,
                  const BodiesView& world, const SweepRecords& s, const ImpactRecords& impacts, real rest_speed,
                  Whole&& whole) {
  const auto n = static_cast<std::ptrdiff_t>(colours.size());
  bool fast = false;
#pragma omp parallel for schedule(static) reduction(|| : fast) if (n >= 20000)
  for (std::ptrdiff_t p = 0; p < n; ++p) {
    hint_place_ahead(found, places, p, n);
    hint_bodies_ahead(found, places, p, n, world);
    Contact c = whole(found[places[p]]);
    prepare_from_world(c, world);
    pack_contact<Rolling>(c, s, impacts, colours.record_of(static_cast<std::uint32_t>(p)));
    fast = is_impact_candidate(c, rest_speed) || fast;
  }
  return fast;
}

// The impact stage's passes after the first try every contact, colour by
// colour, while the pass before hit something; most contacts of a pour,
// and all but a few of a pile's, cannot hit there. A contact none of whose
// spheres a hit of this stage has moved (hit_spheres: a flag a sphere, set
// by each hit) meets them as they were when it was prepared (the stage is
// the first to change a solver body, and a wall's velocity is the
// contact's own), so apply_impact's normal speed, dot(A.v - B.v, n), is its
// prepared approach speed bit for bit: the same values in the same
// expression (approach_speed_of). Where that speed is above -rest_speed,
// apply_impact's first test refuses the contact and it writes nothing, so
// passing it over changes no bit. A candidate of the first pass (its
// approach below -rest_speed) or one exactly at -rest_speed (apply_impact's
// test, not is_impact_candidate's) is tried as before. The GPU's stage
// tries every contact: a contact's check there costs about what its
// refusal does (gas, H200: the stage 57.5 against 50.1 us at 10^5, 144.6
// against 136.0 at 10^6 with the flags; docs/architecture.md "Impacts
// passed over"). Record k, its approach speed.
bool impact_passed_over(const SweepRecords& s, const real* approach, std::uint32_t k, const std::uint8_t* hit_spheres,
                        real rest_speed) {
  if (!hit_spheres || !(approach[k] > -rest_speed)) return false;
  const BodyPair ab = s.bodies[k];
  return !hit_spheres[ab.a] && (is_wall(ab.b) || !hit_spheres[ab.b]);
}

// Impacts of the records of places order[t] for t in [begin, end) (one
// level of the first pass, `places` their records; order null: records
// [begin, end), one colour of a later pass, which
// passes over the contacts no hit has reached, counted in *passed); each
// hit sets its spheres' flags (hit_spheres, where not null); true if any
// hit. Within a level or a colour no two contacts share a sphere, so no
// two threads write or read another's flag.
template <bool Friction>
bool impact_range(const SweepRecords& s, const ImpactRecords& impact, const std::uint32_t* order, const ColourRanges& places,
                  std::uint32_t begin, std::uint32_t end, SolverBody* bodies, const ImpactParams& p,
                  std::uint8_t* hit_spheres, std::uint64_t* passed) {
  bool hit = false;
  std::uint64_t over = 0;
  const auto n = static_cast<std::ptrdiff_t>(end - begin);
#pragma omp parallel for schedule(static) reduction(|| : hit) reduction(+ : over) if (n >= kParallelFrom)
  for (std::ptrdiff_t t = 0; t < n; ++t) {
    const std::uint32_t place = begin + static_cast<std::uint32_t>(t);
    const std::uint32_t k = order ? places.record_of(order[place]) : place;
    if (!order && impact_passed_over(s, impact.approach, k, hit_spheres, p.rest_speed)) {
      ++over;
      continue;
    }
    if (!impact_record<Friction>(s, impact, k, bodies, p)) continue;
    hit = true;
    if (hit_spheres) {
      const BodyPair ab = s.bodies[k];
      hit_spheres[ab.a] = 1;
      if (!is_wall(ab.b)) hit_spheres[ab.b] = 1;
    }
  }
  *passed += over;
  return hit;
}

// Runs `range(begin, split, end)` over the colours in the solver's order
// (visit_colours: forwards with the overflow set last, or backwards with it
// first), [begin, split) a colour's records of the contacts that carried a
// load in (ColourRanges::unloaded_from); the overflow set one contact at a
// time, range(k, k + 1, k + 1). The colours come in visit_colours's order,
// one call each, counted off here.
template <class F>
void over_colour_parts(const ColourRanges& colours, bool backwards, F&& range) {
  std::uint32_t c = backwards ? colours.colours : 0;
  visit_colours(colours.begin, colours.colours, backwards,
                [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
                  if (!serial) {
                    const std::uint32_t colour = backwards ? --c : c++;
                    return range(b, colours.unloaded_from(colour), e);
                  }
                  if (reversed)
                    for (std::uint32_t k = e; k > b; --k) range(k - 1, k, k);
                  else
                    for (std::uint32_t k = b; k < e; ++k) range(k, k + 1, k + 1);
                });
}

// The same walk, each colour whole: range(begin, end).
template <class F>
void over_colours(const ColourRanges& colours, bool backwards, F&& range) {
  over_colour_parts(colours, backwards, [&](std::uint32_t b, std::uint32_t, std::uint32_t e) { range(b, e); });
}

}  // namespace

const char* name(SweepLanes lanes) {
  switch (lanes) {
    case SweepLanes::avx512: return "avx512";
    case SweepLanes::avx2: return "avx2";
    default: return "sse2";
  }
}

SweepLanes supported_lanes() {
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512bw"))
    return SweepLanes::avx512;
  if (__builtin_cpu_supports("avx2")) return SweepLanes::avx2;
  return SweepLanes::sse2;
}

SweepLanes best_lanes() {
  const SweepLanes best = supported_lanes();
  const char* asked = std::getenv("MARBLES_LANES");
  if (asked == nullptr || *asked == '\0') return best;
  for (SweepLanes l : {SweepLanes::sse2, SweepLanes::avx2, SweepLanes::avx512})
    if (std::string_view(asked) == name(l)) return std::min(l, best);
  throw RuntimeFailure(std::string("MARBLES_LANES=") + asked + ": expected sse2, avx2 or avx512");
}

ContactSolver::ContactSolver(const SolverSettings& settings, SweepLanes lanes) : m_settings(settings) {
  if (lanes > supported_lanes()) lanes = supported_lanes();
  m_lanes = lanes;
  with_terms(settings.friction, settings.rolling, [&](auto friction, auto rolling) {
    m_sweep = sweep_for<friction, rolling>(lanes);
    m_warm_start = &warm_start_range<friction, rolling>;
  });
  m_impact = settings.friction ? &impact_range<true> : &impact_range<false>;
}

std::optional<LocalOrder> local_order_from_environment() {
  const std::string expected = "expected a multiple of 32 from 32 to 1024";
  const auto threads = static_cast<int>(whole_from_environment("MARBLES_LOCAL_THREADS", 256, 1024, expected));
  if (threads < 32 || threads % 32 != 0)
    throw RuntimeFailure("MARBLES_LOCAL_THREADS=" + std::to_string(threads) + ": " + expected);
  const char* asked = std::getenv("MARBLES_SOLVE_ORDER");
  if (asked == nullptr || *asked == '\0' || std::string_view(asked) == "colours") return std::nullopt;
  LocalOrder o;
  o.threads = threads;
  char tail = 0;
  if (std::sscanf(asked, "tiles:%lf:%d:%d%c", &o.tile_diameters, &o.passes, &o.local, &tail) != 3 ||
      !(o.tile_diameters > 0) || !std::isfinite(o.tile_diameters) || o.passes < 1 || o.local < 1)
    throw RuntimeFailure(std::string("MARBLES_SOLVE_ORDER=") + asked +
                         ": expected colours or tiles:D:P:L (a cube edge of D > 0 largest diameters, P >= 1 passes, "
                         "L >= 1 local sweeps)");
  return o;
}

void split_by_cube(const BodyPair* pairs, std::uint32_t count, const Vec3* position, double edge, CubeSplit& out) {
  auto cube = [&](std::uint32_t i) { return local_cube(position[i], edge); };
  out.own.clear();
  out.starts.clear();
  out.between.clear();
  for (std::uint32_t k = 0; k < count; ++k) {
    const BodyPair ab = pairs[k];
    const std::uint64_t t = cube(ab.a);
    if (is_wall(ab.b) || cube(ab.b) == t) out.own.push_back({t, k});
    else out.between.push_back(k);
  }
  std::stable_sort(out.own.begin(), out.own.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  for (std::uint32_t i = 0; i < out.own.size(); ++i)
    if (i == 0 || out.own[i].first != out.own[i - 1].first) out.starts.push_back(i);
  out.starts.push_back(static_cast<std::uint32_t>(out.own.size()));
}

void ContactSolver::local_sweeps(const ColourRanges& colours, const BodiesView& world, SolverBody* bodies,
                                 real inv_h) {
  const SweepRecords& s = m_records;
  real r_max = 0;
  for (std::size_t i = 0; i < world.count; ++i) r_max = std::max(r_max, world.radius[i]);
  const double edge = local_cube_edge(m_local->tile_diameters, r_max);
  split_by_cube(s.bodies, static_cast<std::uint32_t>(m_record_count), world.position, edge, m_cubes);
  // The contacts between cubes are in the records' colour-major order: each
  // colour's first among them, as ColourRanges::begin gives the records'.
  const std::vector<std::uint32_t>& between = m_cubes.between;
  m_between_begin.resize(std::size_t(colours.colours) + 2);
  for (std::uint32_t c = 0; c <= colours.colours; ++c)
    m_between_begin[c] = static_cast<std::uint32_t>(
        std::lower_bound(between.begin(), between.end(), colours.begin[c]) - between.begin());
  m_between_begin[colours.colours + 1] = static_cast<std::uint32_t>(between.size());

  with_terms(m_settings.friction, m_settings.rolling, [&](auto friction, auto rolling) {
    auto solve = [&](std::uint32_t k) { solve_record<friction, rolling>(s, k, bodies, inv_h); };
    const std::vector<std::uint32_t>& start = m_cubes.starts;
    const auto& own = m_cubes.own;
    const auto cubes = static_cast<std::ptrdiff_t>(start.size()) - 1;
    for (int p = 0; p < m_local->passes; ++p) {
      // The cubes share no sphere: at once, each one's sweeps in turn.
#pragma omp parallel for schedule(dynamic, 1) if (cubes > 1)
      for (std::ptrdiff_t t = 0; t < cubes; ++t)
        for (int l = 0; l < m_local->local; ++l) {
          if ((l + p) % 2 == 0)
            for (std::uint32_t i = start[t]; i < start[t + 1]; ++i) solve(own[i].second);
          else
            for (std::uint32_t i = start[t + 1]; i-- > start[t];) solve(own[i].second);
        }
      // Between cubes: colour by colour, in the solver's walk (visit_colours).
      visit_colours(m_between_begin, colours.colours, p % 2 == 1,
                    [&](std::uint32_t b, std::uint32_t e, bool serial, bool reversed) {
                      if (serial) {
                        if (reversed)
                          for (std::uint32_t i = e; i-- > b;) solve(between[i]);
                        else
                          for (std::uint32_t i = b; i < e; ++i) solve(between[i]);
                        return;
                      }
                      const auto count = static_cast<std::ptrdiff_t>(e - b);
#pragma omp parallel for schedule(static) if (count >= kParallelFrom)
                      for (std::ptrdiff_t i = 0; i < count; ++i) solve(between[b + static_cast<std::uint32_t>(i)]);
                    });
    }
  });
}

void ContactSolver::solve_velocities(std::vector<Contact>& contacts, const ColourRanges& colours,
                                     const BodiesView& world, real h, Unpack unpack) {
  // The warm start and the sweeps on the records (48 bytes a contact with
  // friction where the contact is 112), the impact stage on the records and
  // their impact words; the impulses back after the last.
  size_records(contacts.size());
  m_made = false;
  m_packed_from = contacts.data();
  if (m_settings.rolling) pack_records<true>(contacts.data(), contacts.size(), colours, m_records, m_impacts);
  else pack_records<false>(contacts.data(), contacts.size(), colours, m_records, m_impacts);
  solve_packed(colours, world, h);
  m_pending_from = contacts.data();
  if (unpack == Unpack::now) unpack_impulses(contacts, colours);
}

void ContactSolver::make_records(Runs<const Contact> found, const std::uint32_t* places, ColourRanges& colours,
                                 const BodiesView& world) {
  make_records_with(found, places, colours, world, [](const Contact& c) -> const Contact& { return c; });
}

void ContactSolver::make_records(Runs<const FoundContact> found, const std::uint32_t* places, ColourRanges& colours,
                                 const BodiesView& world, const PairTable& table,
                                 const std::vector<WallShape>& walls, const UniformArms* uniform) {
  const WallShape* ws = walls.data();
  make_records_with(
      found, places, colours, world,
      [&world, &table, ws](const FoundContact& f) { return whole_contact(f, world, table, ws); }, uniform);
}

template <class C, class Whole>
void ContactSolver::make_records_with(Runs<const C> found, const std::uint32_t* places, ColourRanges& colours,
                                      const BodiesView& world, Whole&& whole, const UniformArms* uniform) {
  size_records(colours.size(), uniform);
  m_packed_from = nullptr, m_pending_from = nullptr, m_made = true;
  const real rest = m_settings.rest_speed;
  colours.fast_approach = m_settings.rolling
                              ? records_made<true>(found, places, colours, world, m_records, m_impacts, rest, whole)
                              : records_made<false>(found, places, colours, world, m_records, m_impacts, rest, whole);
}

void ContactSolver::solve_records(const ColourRanges& colours, const BodiesView& world, real h) {
  if (m_made) solve_packed(colours, world, h);
}

void ContactSolver::solve_packed(const ColourRanges& colours, const BodiesView& world, real h) {
  SolverBody* bodies = gathered_bodies(world);
  m_rebounds = false;
  if (m_settings.restitution) impacts(colours, bodies, world.count, h);

  // The warm start over each colour's loaded records: the others carry no
  // load in (carries_load), so warm_start_one applies nothing for them.
  if (m_settings.warm_start)
    over_colour_parts(colours, false, [&](std::uint32_t b, std::uint32_t split, std::uint32_t) {
      m_warm_start(m_records, b, split, bodies, 0);
    });
  sweep_all(colours, world, bodies, h, m_settings.iterations);
  scatter_bodies(world);
}

void ContactSolver::close_velocities(const ColourRanges& colours, const BodiesView& world,
                                     const std::vector<WallShape>& walls, real h) {
  if (!m_made || m_record_count == 0) return;
  SolverBody* bodies = gathered_bodies(world);
  const SweepRecords& records = m_records;
  const auto n = static_cast<std::ptrdiff_t>(m_record_count);
  m_kept_gap.resize(m_record_count);
  m_kept_impulse.resize(m_record_count);
  m_kept_rolling.resize(m_settings.rolling ? m_record_count : 0);
  const ClosingKept kept{m_kept_gap.data(), m_kept_impulse.data(), m_kept_rolling.data()};
  const WallShape* ws = walls.data();
  const real rest = m_settings.rest_speed;
  with_terms(m_settings.friction, m_settings.rolling, [&](auto friction, auto rolling) {
#pragma omp parallel for schedule(static) if (n > 20000)
    for (std::ptrdiff_t k = 0; k < n; ++k)
      close_record<friction, rolling>(records, static_cast<std::uint32_t>(k), bodies, world, ws, rest, kept);
  });
  // Any record may carry impulses now, the first solve's: each colour whole.
  if (m_settings.warm_start)
    over_colours(colours, false, [&](std::uint32_t b, std::uint32_t e) { m_warm_start(records, b, e, bodies, 0); });
  sweep_all(colours, world, bodies, h, m_settings.closing_iterations);
  scatter_bodies(world);
  with_terms(m_settings.friction, m_settings.rolling, [&](auto friction, auto rolling) {
#pragma omp parallel for schedule(static) if (n > 20000)
    for (std::ptrdiff_t k = 0; k < n; ++k)
      reopen_record<friction, rolling>(records, static_cast<std::uint32_t>(k), kept);
  });
}

SolverBody* ContactSolver::gathered_bodies(const BodiesView& world) {
  const auto n = static_cast<std::ptrdiff_t>(world.count);
  m_bodies.resize(world.count);
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t i = 0; i < n; ++i) m_bodies[i] = gather_solver_body(world, i);
  return m_bodies.data();
}

void ContactSolver::scatter_bodies(const BodiesView& world) {
  const auto n = static_cast<std::ptrdiff_t>(world.count);
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t i = 0; i < n; ++i) scatter_solver_body(world, i, m_bodies[i]);
}

void ContactSolver::sweep_all(const ColourRanges& colours, const BodiesView& world, SolverBody* bodies, real h,
                              int sweeps) {
  const real inv_h = real(1) / h;
  if (m_local) local_sweeps(colours, world, bodies, inv_h);
  else
    for (int it = 0; it < sweeps; ++it)
      over_colour_parts(colours, it % 2 == 1, [&](std::uint32_t b, std::uint32_t split, std::uint32_t e) {
        m_sweep(m_records, b, split, e, bodies, inv_h);
      });
}

const SweepRecords* ContactSolver::pending_records(const std::vector<Contact>& contacts) const {
  const bool pending = m_pending_from && m_pending_from == contacts.data() && m_record_count == contacts.size();
  return pending ? &m_records : nullptr;
}

void ContactSolver::unpack_impulses(std::vector<Contact>& contacts, const ColourRanges& colours) {
  if (!pending_records(contacts)) return;
  if (m_settings.rolling) unpack_records<true>(m_records, m_impacts, colours, contacts.data(), contacts.size());
  else unpack_records<false>(m_records, m_impacts, colours, contacts.data(), contacts.size());
  m_pending_from = nullptr;
}

void ContactSolver::contacts_of_records(const ColourRanges& colours, const BodiesView& world, const PairTable& table,
                                        const std::vector<WallShape>& walls, std::vector<Contact>& out) const {
  if (!m_made) {
    out.clear();
    return;
  }
  out.resize(m_record_count);
  const auto n = static_cast<std::ptrdiff_t>(m_record_count);
  const WallShape* ws = walls.data();
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::ptrdiff_t p = 0; p < n; ++p)
    out[p] = contact_of_record(m_records, m_impacts, colours.record_of(static_cast<std::uint32_t>(p)), world, table, ws);
}

// Impact stage, on the records and their impact words. Pass 0: the
// candidates, levelled by time of impact (a by_round colouring: of two
// candidates sharing a sphere the earlier is in the lower level), level by
// level. Later passes: every contact, colour by colour, while the pass
// before hit something. The candidates, ranks and levels go by colour-major
// place (the contact index of solve_velocities), each read from its record.
void ContactSolver::impacts(const ColourRanges& colours, SolverBody* bodies, std::size_t body_count, real h) {
  const real rest = m_settings.rest_speed;
  ImpactParams params{rest, h, m_settings.wall_accel};
  const auto n = static_cast<std::uint32_t>(m_record_count);
  m_candidates.clear();  // in place order, scanned on all threads
  m_impact_passed_over = 0;
  if (!colours.fast_approach) return;  // every approach speed was seen: none is a candidate
  const SweepRecords& s = m_records;
  const ImpactRecords& impact = m_impacts;
  auto approach = [&](std::uint32_t place) { return load_approach(s, impact.approach, colours.record_of(place)); };
  collect_in_order(n, kParallelFrom, m_candidates, m_candidate_parts, [&](std::size_t k, std::vector<std::uint32_t>& to) {
    if (is_impact_candidate(approach(static_cast<std::uint32_t>(k)), rest)) to.push_back(static_cast<std::uint32_t>(k));
  });
  if (m_candidates.empty()) return;
  m_shift.assign(body_count, Vec3{});
  params.shift = m_shift.data();
  std::uint8_t* hit_spheres = nullptr;
  if (m_settings.impact_pass_over) {
    m_hit_spheres.assign(body_count, 0);
    hit_spheres = m_hit_spheres.data();
  }
  m_rank.resize(n);
  m_level.assign(n, kUncoloured);
  for (std::uint32_t k : m_candidates) m_rank[k] = impact_rank(time_of_impact(approach(k)), k);
  std::uint32_t rounds = 0;
  m_impact_colouring.colour(PlacedPairs{s.bodies, &colours}, m_candidates, m_rank.data(), body_count,
                            ColourRule::by_round, m_level, &rounds);
  // Candidates level by level (overflow last), place order within a level.
  std::vector<std::uint32_t> begin(rounds + 2, 0);
  auto level_of = [&](std::uint32_t k) { return m_level[k] == kOverflowColour ? rounds : m_level[k]; };
  for (std::uint32_t k : m_candidates) ++begin[level_of(k) + 1];
  for (std::uint32_t l = 0; l <= rounds; ++l) begin[l + 1] += begin[l];
  m_order.resize(m_candidates.size());
  {
    std::vector<std::uint32_t> cursor(begin.begin(), begin.end() - 1);
    for (std::uint32_t k : m_candidates) m_order[cursor[level_of(k)]++] = k;
  }
  bool hit = false;
  std::uint64_t* passed = &m_impact_passed_over;
  const std::uint32_t* order = m_order.data();
  for (std::uint32_t l = 0; l < rounds; ++l)
    hit = m_impact(s, impact, order, colours, begin[l], begin[l + 1], bodies, params, hit_spheres, passed) || hit;
  for (std::uint32_t k = begin[rounds]; k < begin[rounds + 1]; ++k)
    hit = m_impact(s, impact, order, colours, k, k + 1, bodies, params, hit_spheres, passed) || hit;

  m_rebounds = hit;
  // A colour's records are its places' (ColourRanges::record), the same
  // range: no two share a sphere, in any order.
  for (int pass = 1; pass < m_settings.impact_passes && hit; ++pass) {
    hit = false;
    over_colours(colours, false, [&](std::uint32_t b, std::uint32_t e) {
      hit = m_impact(s, impact, nullptr, colours, b, e, bodies, params, hit_spheres, passed) || hit;
    });
    m_rebounds = m_rebounds || hit;
  }
  if (!m_rebounds) return;
  const Vec3* shift = m_shift.data();
#pragma omp parallel for schedule(static) if (n >= kParallelFrom)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(n); ++k)
    shifted_gap(s, shift, static_cast<std::uint32_t>(k));
}

int ContactSolver::project_positions(const std::vector<Contact>& contacts, const ColourRanges& colours,
                                     const BodiesView& bodies, const std::vector<WallShape>& walls) const {
  // The sweeps read the position records (load_position_contact, as the
  // GPU's do): the contacts' a, b and normal, 24 bytes a contact where each
  // sweep over the contacts read two 64-byte lines of each. Settled pile of
  // 10^5: 14 MB that stay in cache instead of 75 MB a sweep. They are part of
  // the sweep's records, which the velocity solve packed from these contacts
  // (it changes no contact's bodies or normal); packed here only without a
  // solve since the last projection. deepest_overlap reads them after the
  // last sweep.
  const Contact* cs = contacts.data();
  const bool solved = m_packed_from == cs && m_record_count == contacts.size();
  if (!solved) {
    const auto n = static_cast<std::ptrdiff_t>(contacts.size());
    size_records(contacts.size());
    m_made = false;
#pragma omp parallel for schedule(static) if (n > 20000)
    for (std::ptrdiff_t k = 0; k < n; ++k) pack_position_record(cs[k], m_records, static_cast<std::uint32_t>(k));
  }
  m_packed_from = nullptr;
  // The sweeps walk each colour's range of records, whatever order they hold it in.
  return project_packed(colours, bodies, walls);
}

int ContactSolver::project_records(const ColourRanges& colours, const BodiesView& bodies,
                                   const std::vector<WallShape>& walls) const {
  return m_made ? project_packed(colours, bodies, walls) : 0;
}

int ContactSolver::project_packed(const ColourRanges& colours, const BodiesView& bodies,
                                  const std::vector<WallShape>& walls) const {
  const WallShape* ws = walls.data();
  const SweepRecords& records = m_records;
  // Sweeps until one moves no contact by more than settled_move
  // (project_one), position_iterations at most, and on while one moves some
  // contact by more than deep_move (projection_sweep_settings): a pile at
  // rest takes one, a pour's impacts the most.
  int sweeps = 0;
  const int limit = projection_limit(m_settings);
  for (bool moved = true; moved && sweeps < limit; ++sweeps) {
    moved = false;
    const SolverSettings settings = projection_sweep_settings(m_settings, sweeps);
    over_colours(colours, false, [&](std::uint32_t b, std::uint32_t e) {
      moved = any_in_colour(b, e, [&](std::uint32_t k) {
        return project_one(load_position_contact(records, k), bodies, ws, settings);
      }) || moved;
    });
  }
  return sweeps;
}

void ContactSolver::size_records(std::size_t count, const UniformArms* uniform) const {
  // The rolling words only with rolling resistance (contact_of_record reads
  // them where they are), the arms only where they differ; every other
  // array as the CPU's sweeps read them.
  const bool rolling = m_settings.rolling, arms = uniform == nullptr;
  m_record_words.resize((SweepRecords::bytes_for(count, true, arms, rolling) + sizeof(Real4) - 1) / sizeof(Real4));
  m_records = SweepRecords::in(m_record_words.data(), count, true, arms, arms ? UniformArms{} : *uniform, rolling);
  // The approach speeds, and with restitution the impact impulses, the
  // separations as found and the restitutions (ImpactRecords).
  const bool words = m_settings.restitution;
  m_impact_words.resize(ImpactRecords::real4_words(count, words, true));
  m_impacts = ImpactRecords::in(m_impact_words.data(), count, words, true);
  m_record_count = count;
}

// The GPU's max_overlap_kernel on the CPU, in chunks taken in turn: with
// halves, one thread took a third longer than the other (settle scene of
// 10^5, 2 threads: 1.05 -> 0.90 ms a step in chunks). The largest is the
// same in any order.
real ContactSolver::deepest_overlap(const BodiesView& bodies, const std::vector<WallShape>& walls) const {
  const auto n = static_cast<std::ptrdiff_t>(m_record_count);
  const SweepRecords& records = m_records;
  const WallShape* ws = walls.data();
  real deepest = 0;
#pragma omp parallel for schedule(dynamic, 8192) reduction(max : deepest) if (n > 20000)
  for (std::ptrdiff_t k = 0; k < n; ++k)
    deepest = std::max(deepest, overlap_ratio(load_position_contact(records, static_cast<std::uint32_t>(k)),
                                              bodies, ws));
  return deepest;
}

}  // namespace marbles::narrowphase
