// narrowphase/solver.hpp — the contact solver: sequential impulses, solved
// colour by colour (colouring.hpp), on the CPU.
//
// Stages of one substep, in order; each visits the colours in order and the
// contacts of one colour in parallel (OpenMP), then the overflow set one by
// one. A colour's contacts share no sphere, so the result does not depend on
// the thread count, and it is the result of the CUDA twin bit for bit (both
// call the per-contact functions of solver_math.hpp; the CPU's sweep takes
// them four at a time in SIMD lanes, or eight where the CPU has AVX2,
// solver_lanes.hpp, with the same bits):
//   prepare       effective masses; approach speed before the solve (done as
//                 the records are made, make_records, or as the colouring
//                 moves the contacts: prepare_from_world)
//   impacts       (with restitution) contacts approaching faster than the
//                 rest speed collide as binary impacts, P_n = (1 + e) m |v_n|
//                 with friction limited to mu P_n. The first pass visits them
//                 in time-of-impact order wherever two share a sphere (a
//                 by_round colouring by time of impact); later passes, while
//                 impacts make new approaches (a chain of touching spheres),
//                 visit every contact colour by colour, impact_passes passes
//                 in all at most (SolverSettings; kImpactPasses by default).
//                 Each impact at its time toi: its spheres' shifts take
//                 -dv toi (ImpactParams::shift, impact_shift()), and the
//                 contacts' gaps the shifts (shifted_gap)
//   warm start    apply the impulses carried over from the last substep
//                 (ContactCache, matched by body pair) when enabled
//   solve         `iterations` sweeps, alternately forwards and backwards
//                 through the colours: friction, rolling resistance (when the
//                 scene enables them), then the normal impulse (speculative:
//                 a positive gap may close within the substep, never more)
// and after the positions are integrated (with the impacts' shifts):
//   project       remove overlap beyond a slop by moving positions only (no velocity
//                 change, so no kinetic energy is added), colour by colour,
//                 in sweeps until one moves no contact by more than
//                 settled_move (position_iterations sweeps at most)
// Which stages and which per-contact terms run is fixed when the solver is
// built: a disabled effect costs no branch per contact (template dispatch).
#pragma once

#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include "core/spheres.hpp"
#include "narrowphase/colouring.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_math.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase {

// The SIMD lanes the CPU's sweep runs in (solver_lanes.hpp): 4 floats
// (SSE2, every x86-64 CPU), 8 floats (AVX2), 8 floats with AVX-512's 32
// registers. Every kind gives the same bits.
enum class SweepLanes { sse2, avx2, avx512 };
const char* name(SweepLanes lanes);
SweepLanes supported_lanes();  // the widest this CPU has
// supported_lanes(), or fewer where the environment's MARBLES_LANES names
// fewer ("sse2", "avx2"; for comparisons; "avx512" or a kind past the CPU's:
// what it has). Any other value: RuntimeFailure naming the variable.
SweepLanes best_lanes();

// A study of another order for the velocity sweeps (docs/architecture.md
// "A local order, studied on the CPU"; on the GPU too: "The local order on
// the GPU, first form"), from the environment:
// MARBLES_SOLVE_ORDER=tiles:D:P:L cuts space into cubes of D largest
// diameters and, in each of P passes (in place of the scene's iterations),
// sweeps each cube's own contacts (both spheres in it, or a sphere and a
// wall) L times, cubes at once, then the contacts between cubes once,
// colour by colour. Unset (or empty, or `colours`): the solver's order. It
// changes the results, the same bits on both backends (the CUDA step's
// LocalSweepsCuda, slower there than the solver's order). A study: the watchdog's
// extra sweeps (set_iteration_factor) do not reach it, and the run's description
// still names the scene's iterations.
struct LocalOrder {
  double tile_diameters = 0;
  int passes = 0, local = 0;
  // Threads of a cube's block on the GPU (MARBLES_LOCAL_THREADS: 32 to
  // 1024, a multiple of 32; 256 unset). The CPU's order does not read it.
  int threads = 256;
};
// The order asked for by MARBLES_SOLVE_ORDER (none: the solver's), with
// MARBLES_LOCAL_THREADS; throws RuntimeFailure on a value of either it
// cannot read (MARBLES_LOCAL_THREADS is checked with or without the order).
std::optional<LocalOrder> local_order_from_environment();

// The local order's cubes: contact k (its bodies pairs[k]) is its cube's own
// where both spheres lie in one cube of edge `edge` (or b is a wall), else
// it lies between cubes. A sphere's cube is its centre's (local_cube,
// solver_math.hpp: cubes far out merge, which loses locality, never the
// order's determinism).
struct CubeSplit {
  std::vector<std::pair<std::uint64_t, std::uint32_t>> own;  // (cube, k), by cube, k ascending within
  std::vector<std::uint32_t> starts;   // each cube's first in `own`, then own.size()
  std::vector<std::uint32_t> between;  // k ascending
};
void split_by_cube(const BodyPair* pairs, std::uint32_t count, const Vec3* position, double edge, CubeSplit& out);

class ContactSolver {
 public:
  // `lanes`: at most what the CPU supports.
  explicit ContactSolver(const SolverSettings& settings, SweepLanes lanes = best_lanes());

  SweepLanes lanes() const { return m_lanes; }

  const SolverSettings& settings() const { return m_settings; }
  // The velocity sweeps per substep: the scene's times `factor` (the
  // watchdog's retries raise it), the closing solve's too.
  void set_iteration_factor(int factor, int iterations, int closing_iterations) {
    m_settings.iterations = iterations * factor;
    m_settings.closing_iterations = closing_iterations * factor;
  }

  // When the solve's impulses go back into the contacts: at its end, or
  // when asked (unpack_impulses), the cache storing them from the records
  // in between (pending_records): 112-byte contacts neither read nor
  // written for them.
  enum class Unpack { now, when_asked };

  // impacts, warm start, sweeps on the velocities in `bodies`; `contacts` in
  // colour-major order as `colours` describes, prepared on the way there
  // (ContactColouring::colour_and_sort with the bodies); the sweeps' records
  // placed as `colours` says (ColourRanges::record: each colour's loaded
  // contacts first, where the colouring was told the loads).
  void solve_velocities(std::vector<Contact>& contacts, const ColourRanges& colours, const BodiesView& bodies,
                        real h, Unpack unpack = Unpack::now);
  // The records holding the impulses of the last solve of `contacts` (with
  // Unpack::when_asked) not yet unpacked; null when there are none.
  const SweepRecords* pending_records(const std::vector<Contact>& contacts) const;
  // Those impulses into the contacts (nothing when none are pending), from
  // their records as `colours` (the solve's) places them.
  void unpack_impulses(std::vector<Contact>& contacts, const ColourRanges& colours);
  // The solved contacts are being replaced: their records are no longer theirs.
  void forget_records() { m_pending_from = nullptr, m_packed_from = nullptr, m_made = false; }

  // The CPU step's form, as the GPU's: the records made straight from the
  // contacts as found, no colour-major copy of the 112-byte contacts.
  // places[p] is the found contact at colour-major place p
  // (ContactColouring::places, `colours` its ranges and records); each is
  // prepared from the world's bodies on its way (nothing moves them before
  // the solve) and packed into its record with its impact word (on the
  // GPU's terms: a whole word with restitution, the approach speed alone
  // without). colours.fast_approach tells whether one approaches faster
  // than the rest speed.
  void make_records(Runs<const Contact> found, const std::uint32_t* places, ColourRanges& colours,
                    const BodiesView& world);
  // The same from the contacts as found (the CPU step's), each made whole
  // (whole_contact) from the world's bodies, the pair table and the walls
  // the search used. `uniform` (not null): every contact's arms and
  // friction coefficients are these (UniformArms: one radius, one pair of
  // coefficients, as the GPU's records take them), and the records leave
  // their arms word out.
  void make_records(Runs<const FoundContact> found, const std::uint32_t* places, ColourRanges& colours,
                    const BodiesView& world, const PairTable& table, const std::vector<WallShape>& walls,
                    const UniformArms* uniform = nullptr);
  // solve_velocities and project_positions on the made records.
  void solve_records(const ColourRanges& colours, const BodiesView& bodies, real h);
  int project_records(const ColourRanges& colours, const BodiesView& bodies, const std::vector<WallShape>& walls) const;
  // Velocity Verlet's closing solve on the made records, after the second
  // half kick, the projection and the store (close_record: each record's gap at the
  // substep's end, an approach faster than the rest speed left to the next
  // substep's impacts), then each record's separation put back and its
  // impulses both solves' (reopen_record). `walls` the step's, moved to the
  // substep's end.
  void close_velocities(const ColourRanges& colours, const BodiesView& world, const std::vector<WallShape>& walls,
                        real h);
  // The made records (their impulses as the last solve left them), or null
  // when none were made since forget_records.
  const SweepRecords* made_records() const { return m_made ? &m_records : nullptr; }
  // The made records as whole contacts in colour-major order
  // (contact_of_record: the contacts colour_and_sort and solve_velocities
  // give, bit for bit), `table` and `walls` the step's.
  void contacts_of_records(const ColourRanges& colours, const BodiesView& world, const PairTable& table,
                           const std::vector<WallShape>& walls, std::vector<Contact>& out) const;

  // Position projection over the same contacts at the integrated positions
  // (unchanged since solve_velocities, or not solved: the solve's records
  // are used when it ran on these contacts); returns the sweeps it ran.
  int project_positions(const std::vector<Contact>& contacts, const ColourRanges& colours,
                        const BodiesView& bodies, const std::vector<WallShape>& walls) const;

  // The largest overlap_ratio over the contacts of the last project_positions
  // (from its records: 8 bytes a contact read where a contact is 112).
  real deepest_overlap(const BodiesView& bodies, const std::vector<WallShape>& walls) const;

  // What the last solve's impacts owe each sphere's position
  // (ImpactParams::shift), for the integration to add; null where none hit.
  const Vec3* impact_shift() const { return m_rebounds ? m_shift.data() : nullptr; }

  // The contacts the last solve's impact stage passed over in its later
  // passes (impact_passed_over), summed over those passes.
  std::uint64_t impact_passed_over() const { return m_impact_passed_over; }

 private:
  // The solve and the projection on the records (packed or made).
  void solve_packed(const ColourRanges& colours, const BodiesView& world, real h);
  int project_packed(const ColourRanges& colours, const BodiesView& bodies, const std::vector<WallShape>& walls) const;
  void impacts(const ColourRanges& colours, SolverBody* bodies, std::size_t body_count, real h);
  // The velocity state packed into m_bodies, and back to the world.
  SolverBody* gathered_bodies(const BodiesView& world);
  void scatter_bodies(const BodiesView& world);
  // `sweeps` sweeps in the solver's order; under the local order study its
  // passes instead, whatever `sweeps` asks (the closing solve's too).
  void sweep_all(const ColourRanges& colours, const BodiesView& world, SolverBody* bodies, real h, int sweeps);
  // m_records over m_record_words and m_impacts over m_impact_words for
  // `count` contacts; without the arms array where `uniform` gives them.
  void size_records(std::size_t count, const UniformArms* uniform = nullptr) const;
  // make_records' body for either form of the found contacts: whole(found
  // contact) is the Contact its record is made from.
  template <class C, class Whole>
  void make_records_with(Runs<const C> found, const std::uint32_t* places, ColourRanges& colours,
                         const BodiesView& world, Whole&& whole, const UniformArms* uniform = nullptr);
  // The sweeps in the local order (LocalOrder) on the packed records.
  void local_sweeps(const ColourRanges& colours, const BodiesView& world, SolverBody* bodies, real inv_h);

  using RangeFn = void (*)(const SweepRecords& records, std::uint32_t begin, std::uint32_t end, SolverBody* bodies,
                           real inv_h);
  // A colour's sweep: [begin, split) the contacts that carried a load in.
  using SweepFn = void (*)(const SweepRecords& records, std::uint32_t begin, std::uint32_t split, std::uint32_t end,
                           SolverBody* bodies, real inv_h);
  using ImpactFn = bool (*)(const SweepRecords& s, const ImpactRecords& impact, const std::uint32_t* order,
                            const ColourRanges& places, std::uint32_t begin, std::uint32_t end, SolverBody* bodies,
                            const ImpactParams& p, std::uint8_t* hit_spheres, std::uint64_t* passed);
  SolverSettings m_settings;
  SweepLanes m_lanes = SweepLanes::sse2;
  bool m_rebounds = false;  // an impact hit in this substep's solve (some sphere has a shift: m_shift)
  SweepFn m_sweep = nullptr;
  RangeFn m_warm_start = nullptr;
  ImpactFn m_impact = nullptr;

  // Scratch of the impact stage.
  ContactColouring m_impact_colouring;
  std::vector<std::uint32_t> m_candidates, m_level, m_order;
  std::vector<std::vector<std::uint32_t>> m_candidate_parts;  // per thread
  std::vector<std::uint64_t> m_rank;
  std::vector<std::uint8_t> m_hit_spheres;  // a flag a sphere: a hit of the impact stage moved it
  std::vector<Vec3> m_shift;                // a sphere's shift from the impacts (ImpactParams), for the integration
  std::uint64_t m_impact_passed_over = 0;
  std::vector<SolverBody> m_bodies;  // the velocity state, packed for the solve
  // The records' separations and first solve's impulses while the closing
  // solve holds the records (ClosingKept).
  std::vector<real> m_kept_gap;
  std::vector<Real4> m_kept_impulse, m_kept_rolling;
  // The sweep's records (SweepRecords::in) of m_record_count contacts,
  // made (make_records) or packed by a velocity solve of whole contacts;
  // the projection and deepest_overlap read their position part (bodies,
  // geometry). m_packed_from: the contacts a solve packed them from, until
  // a projection used them.
  mutable std::vector<Real4> m_record_words, m_impact_words;
  mutable SweepRecords m_records;
  mutable ImpactRecords m_impacts;  // beside the records: the approach speeds, with restitution the impact words
  mutable std::size_t m_record_count = 0;
  mutable const Contact* m_packed_from = nullptr;
  const Contact* m_pending_from = nullptr;  // the contacts whose impulses the records hold, not yet unpacked
  mutable bool m_made = false;              // the records were made (make_records), not packed from contacts
  std::optional<LocalOrder> m_local = local_order_from_environment();
  CubeSplit m_cubes;                      // the local order's scratch
  std::vector<std::uint32_t> m_between_begin;  // its contacts between cubes, by colour
};

}  // namespace marbles::narrowphase
