// narrowphase/contact_cache.hpp — warm starting.
//
// The accumulated impulses of the last substep, keyed by body pair (a, b)
// (b a sphere, or a wall with kWallFlag), sorted by key. A contact that
// persists starts the next solve from its old impulses (found by binary
// search on the GPU, contact_cache_math.hpp; on the CPU by a scan of its
// sphere's few entries), so a resting stack needs few iterations to hold.
//
// When a load goes away (a contact that carried more than a few times its
// sphere's weight impulse is gone, e.g. the heavy top of a stack was lifted
// off), the old impulses of everything still touching that sphere, directly
// or through other spheres, are too large: applied, they would launch the
// stack, and a few sweeps cannot take the excess back out of a long chain.
// So the whole group of touching spheres (its island) starts cold for that
// substep when the lost impulse is at least a quarter of the largest one the
// island still carries: a cold start can only under-support, never push. (A
// sphere leaving the surface of a deep pile is no such load.)
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "core/kept_sets.hpp"
#include "core/spheres.hpp"
#include "narrowphase/colouring.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase {

struct SweepRecords;  // solver_math.hpp

// The cache's entries as arrays, sorted by key. `colour`: the solver colour
// each entry's contact had (kNoKeptColour: none), which it keeps while it
// persists (colouring_math.hpp); empty when no colours are known (a
// checkpoint of format 1).
struct CacheEntries {
  std::vector<std::uint64_t> key;
  std::vector<real> normal_impulse;
  std::vector<Vec3> tangent_impulse, rolling_impulse;
  std::vector<std::uint8_t> colour;
  // Every rolling impulse is known +0 (a store of contacts without rolling
  // resistance wrote them so): the next such store leaves them, the restore
  // reads none (12 bytes an entry each way). False: not known.
  bool rolling_zero = false;
  std::size_t size() const { return key.size(); }
  void resize(std::size_t n) {
    key.resize(n);
    normal_impulse.resize(n);
    tangent_impulse.resize(n);
    rolling_impulse.resize(n);
    colour.resize(n);
  }
};

// The runs of sorted keys[0, m) by sphere a: first[a] for a <= spheres
// (first[a + 1] - first[a] entries of sphere a; entries of spheres from
// `spheres` on are in no run).
void key_runs(const std::uint64_t* keys, std::uint32_t m, std::size_t spheres, std::vector<std::uint32_t>& first);

// The entries with every sphere i named new_index[i] (walls keep theirs),
// sorted by key again. A pair of spheres is keyed with its lower index
// first (a < b; narrowphase/contact.hpp: the contact's normal from b towards
// a, its tangential and rolling impulses acting on a as given and on b
// opposed), so a pair whose spheres change order swaps and its tangential
// and rolling impulses change sign: the same impulses on the same spheres.
// Exact: the inverse numbering gives back the entries bit for bit. Entries
// of spheres past new_index are dropped (no lookup finds them); a new index
// past the spheres throws std::out_of_range.
CacheEntries renumbered(const CacheEntries& entries, const std::vector<std::uint32_t>& new_index);

// Entries from outside the run (a checkpoint) keep their colours only if they
// are a proper colouring: one colour per entry, below kMaxColours or none,
// no sphere with two entries of one colour. Otherwise every colour is
// dropped (the next colouring starts afresh). True if they were kept.
bool keep_proper_colours(CacheEntries& entries);

// The island rule's lists (cold_start_unloaded_islands): the lost loads'
// entries and the threads' parts of them, reused from substep to substep.
struct IslandScratch {
  std::vector<std::uint32_t> unloaded;
  std::vector<std::vector<std::uint32_t>> parts;
};

// The island rule: contacts of islands that lost a load (unmatched entries
// for which is_lost_load holds) start cold. `matched[k]` says whether entry
// k found its contact. Returns the number of contacts it set cold. Islands
// by union-find here; the CUDA twin finds the same islands by min-label
// propagation (contact_cache_cuda.cu).
// `contacts`: `count` of them, in runs (Runs). `loaded` (not null): one
// flag a contact, cleared where a contact is set cold. `scratch` (not null):
// its lists, kept from call to call.
// C: Contact or FoundContact (made for those two in contact_cache.cpp).
template <class C>
std::size_t cold_start_unloaded_islands(Runs<C> contacts, std::size_t count, const std::uint64_t* keys,
                                        const real* normal_impulse, const std::uint8_t* matched,
                                        std::size_t entry_count, const BodiesView& bodies, real weight_impulse,
                                        std::uint8_t* loaded = nullptr, IslandScratch* scratch = nullptr);

class ContactCache {
 public:
  // Copies the impulses of matching cached contacts into `contacts`, except
  // in islands that lost a load. `weight_impulse` is |g| h (m/s). Returns the
  // number of contacts warm-started. `kept_colour` (one per contact) gets the
  // colour of each matching entry, kNoKeptColour for the others (also for
  // those of an island started cold: a colour does not depend on impulses).
  // `loaded` (not null; one per contact) gets whether each contact carries
  // a load in (carries_load of its restored normal impulse), which the
  // colouring orders by.
  std::size_t restore(std::vector<Contact>& contacts, const BodiesView& bodies, real weight_impulse,
                      std::vector<std::uint8_t>& kept_colour, std::vector<std::uint8_t>* loaded = nullptr);
  // The same for `count` contacts held in runs (Runs).
  std::size_t restore(ContactRuns contacts, std::size_t count, const BodiesView& bodies, real weight_impulse,
                      std::vector<std::uint8_t>& kept_colour, std::vector<std::uint8_t>* loaded = nullptr);
  // The same for the contacts as found (the CPU step's).
  std::size_t restore(FoundRuns contacts, std::size_t count, const BodiesView& bodies, real weight_impulse,
                      std::vector<std::uint8_t>& kept_colour, std::vector<std::uint8_t>* loaded = nullptr);
  // After restore(): the colours its matched entries keep at their spheres
  // (`body_count` of them; KeptMasks, colouring.hpp), the same the
  // colouring's kept contacts would hold, read from the entries' keys in
  // order instead of from the contacts. Returns KeptMasks::colours (0,
  // and no colour at any sphere, where the entries changed since).
  std::uint32_t kept_masks(std::size_t body_count, std::vector<std::uint64_t>& used);
  // Remembers the impulses and colours of `contacts` (colour-major, as
  // `ranges` says) for the next substep.
  void store(const std::vector<Contact>& contacts, const ColourRanges& ranges);
  // The same from the sweep's records of `count` contacts (solver_math.hpp),
  // which hold the impulses the solve left there (ContactSolver, Unpack::
  // when_asked): what store() of the unpacked contacts keeps, without
  // reading the 112-byte contacts. Without `rolling` (records packed without
  // their rolling words) the rolling impulses kept are zero, as every
  // contact's is in a scene without rolling resistance.
  // `spheres`: the bodies' count, as the CUDA twin's store takes it.
  void store(const SweepRecords& records, std::uint32_t count, bool rolling, const ColourRanges& ranges,
             std::uint32_t spheres);
  void clear() { writable().resize(0); }
  // The entries themselves (a checkpoint's copy).
  const CacheEntries& entries() const { return m_arrays.current(); }
  void set_entries(CacheEntries entries) { writable() = std::move(entries); }
  std::size_t size() const { return entries().size(); }
  // The entries as they are now kept for back_to_kept() (a watchdog's step
  // start) without a copy: the cache holds two sets of arrays (KeptSets),
  // and what changes the entries after (store, clear, set_entries) writes
  // into the set not kept.
  void keep() { m_arrays.keep(); }
  // The entries keep() kept become the entries again (and stay kept).
  void back_to_kept() {
    m_arrays.back_to_kept();
    m_matched.clear();
    m_runs_spheres = kNoRuns;
  }

 private:
  // The arrays the next change of the entries writes: the entries' own,
  // unless kept. Whatever the restore matched is of entries that go.
  CacheEntries& writable() {
    m_matched.clear();
    m_runs_spheres = kNoRuns;
    return m_arrays.writable();
  }
  template <class C>
  std::size_t restore_runs(Runs<C> contacts, std::size_t count, const BodiesView& bodies, real weight_impulse,
                           std::vector<std::uint8_t>& kept_colour, std::vector<std::uint8_t>* loaded);
  KeptSets<CacheEntries> m_arrays;
  // Scratch, reused.
  std::vector<std::uint8_t> m_matched;
  std::vector<std::uint32_t> m_order, m_first;
  // m_first holds the entries' runs by sphere (key_runs) for this many
  // spheres: the store's counting sort leaves them so (and a restore that
  // found them), and the restore that follows reads them instead of
  // finding them again. kNoRuns: it does not (any other change of the
  // entries).
  static constexpr std::size_t kNoRuns = ~std::size_t(0);
  std::size_t m_runs_spheres = kNoRuns;
  IslandScratch m_islands;                   // restore(): the island rule's lists
  struct Stored {  // the impulses store() keeps of one contact
    real normal_impulse;
    Vec3 tangent_impulse, rolling_impulse;
  };
  // pair_of(t) -> BodyPair, normal_of(t) -> its normal impulse, load(t) ->
  // Stored of contact t; hint(t) asks for what load(t) will read; a contact
  // whose a is not below `groups` is not kept (no lookup would find it).
  // `rolling`: some contact may carry a rolling impulse (false: load(t)'s
  // are all +0).
  template <class PairOf, class NormalOf, class Load, class Hint>
  void store_from(std::uint32_t n, std::uint32_t groups, const ColourRanges& ranges, bool rolling, PairOf&& pair_of,
                  NormalOf&& normal_of, Load&& load, Hint&& hint);
  std::vector<std::uint64_t> m_source;   // store(): each place's b << 32 | contact
  std::vector<std::uint8_t> m_colour_of;  // store(): each contact's colour (kNoKeptColour: none)
};

}  // namespace marbles::narrowphase
