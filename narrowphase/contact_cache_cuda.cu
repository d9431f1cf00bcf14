#include <cooperative_groups.h>

#include <algorithm>
#include <vector>

#include "core/cuda_check.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/contact_cache_cuda.cuh"
#include "narrowphase/contact_cache_math.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {
namespace {

namespace cg = cooperative_groups;

using ::marbles::cuda::grid_for;
using ::marbles::cuda::kBlock;

// The store reads the contacts' bodies and impulses from the sweep's records
// (solver_math.hpp), where the last sweep left them. A contact without load
// is kept for its colour alone (ContactCache::store); one with neither is
// dropped.
__device__ __forceinline__ bool stored(const SweepRecords& records, const std::uint8_t* colour, std::uint32_t k) {
  return impulse_word(records, k).x > 0 || (colour && colour[k] != kNoKeptColour);
}

// The counting sort by sphere a, of the store's contacts and of the
// renumbering's entries (ContactCache::store_from's and renumbered's):
// each item counted with its sphere, rank[k] its place among that sphere's
// (in the order the atomics came: order_runs_kernel puts each run in
// order), kNoEntry for an item left out; the counts scanned into the runs'
// firsts (whose last is the entry count); each item placed; each run
// ordered by key. An item's sphere and key: a contact's bodies, or a
// renamed entry's key.
struct ContactSphere {
  SweepRecords records;
  __device__ std::uint32_t operator()(std::uint32_t k) const { return records.bodies[k].a; }
};
struct ContactB {  // within a run: b, the cache key's order (a wall after every sphere, walls by index)
  SweepRecords records;
  __device__ std::uint32_t operator()(std::uint32_t k) const { return records.bodies[k].b; }
};
struct EntrySphere {
  const std::uint64_t* key;
  __device__ std::uint32_t operator()(std::uint32_t k) const { return static_cast<std::uint32_t>(key[k] >> 32); }
};
struct EntryKey {
  const std::uint64_t* key;
  __device__ std::uint64_t operator()(std::uint32_t k) const { return key[k]; }
};

// Each stored contact counted; those past the count on the device (a room's)
// are not stored.
__global__ void count_kernel(SweepRecords records, const std::uint8_t* colour, std::uint32_t n,
                             const std::uint32_t* count_on_device, const unsigned long long* skip, std::uint32_t* count,
                             std::uint32_t* rank) {
  if (::marbles::cuda::skipped(skip)) return;
  const std::size_t contacts = ::marbles::cuda::count_within(n, count_on_device);
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x)
    rank[k] = k < contacts && stored(records, colour, k) ? atomicAdd(count + records.bodies[k].a, 1u) : kNoEntry;
}

// Each counted item's index at its place in its sphere's run.
template <class SphereOf>
__global__ void place_kernel(SphereOf sphere_of, std::uint32_t n, const std::uint32_t* rank,
                             const std::uint32_t* first, std::uint32_t* index,
                             const unsigned long long* skip = nullptr) {
  if (::marbles::cuda::skipped(skip)) return;
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x)
    if (rank[k] != kNoEntry) index[first[sphere_of(k)] + rank[k]] = k;
}

// Each sphere's run in key order (sort_run, as on the CPU).
template <class KeyOf>
__global__ void order_runs_kernel(KeyOf key_of, const std::uint32_t* first, std::uint32_t spheres,
                                  std::uint32_t* index, const unsigned long long* skip = nullptr) {
  if (::marbles::cuda::skipped(skip)) return;
  for (std::uint32_t a = blockIdx.x * blockDim.x + threadIdx.x; a < spheres; a += gridDim.x * blockDim.x)
    sort_run(index, first[a], first[a + 1], key_of);
}

// The runs of the spheres past those of the last store (the world grew, or
// nothing was stored: from 0), empty at the entries' end: where a store is
// skipped, the restore that follows reads them.
__global__ void extend_firsts_kernel(std::uint32_t* first, std::uint32_t from, std::uint32_t words) {
  const std::uint32_t end = from > 0 ? first[from - 1] : 0u;
  for (std::uint32_t k = from + blockIdx.x * blockDim.x + threadIdx.x; k < words; k += gridDim.x * blockDim.x)
    first[k] = end;
}

// A store of no contacts: every run empty, unless skipped.
__global__ void clear_firsts_kernel(std::uint32_t* first, std::uint32_t words, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < words; k += gridDim.x * blockDim.x) first[k] = 0;
}

// The runs' firsts made by a store that may be skipped, taken as the
// cache's (where it is not).
__global__ void adopt_firsts_kernel(const std::uint32_t* made, std::uint32_t words, const unsigned long long* skip,
                                    std::uint32_t* first) {
  if (::marbles::cuda::skipped(skip)) return;
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < words; k += gridDim.x * blockDim.x)
    first[k] = made[k];
}

// The entries in key order, each with the b half of its cache key (a is its
// run's sphere); *size is their count (the runs' last first). tangent and
// rolling are null when the scene has no friction or no rolling resistance:
// those impulses stay zero, nothing to keep.
__global__ void gather_kernel(SweepRecords records, const std::uint8_t* contact_colour, const std::uint32_t* index,
                              const std::uint32_t* size, std::uint32_t* keys, real* normal, Vec3* tangent,
                              Vec3* rolling, std::uint8_t* colour, const unsigned long long* skip) {
  if (::marbles::cuda::skipped(skip)) return;
  const std::uint32_t m = *size;
  for (std::uint32_t e = blockIdx.x * blockDim.x + threadIdx.x; e < m; e += gridDim.x * blockDim.x) {
    const std::uint32_t k = index[e];
    keys[e] = records.bodies[k].b;
    const Real4 i = impulse_word(records, k);
    const bool loaded = i.x > 0;
    normal[e] = loaded ? i.x : real(0);
    if (tangent) tangent[e] = loaded ? Vec3{i.y, i.z, i.w} : Vec3{};
    if (rolling) {
      const Real4 r = records.rolling[k];
      rolling[e] = loaded ? Vec3{r.x, r.y, r.z} : Vec3{};
    }
    colour[e] = contact_colour ? contact_colour[k] : kNoKeptColour;
  }
}

// The first *end entries of an array (at most bound, `words` words each)
// into another: the entries it held before it grew into its new memory, or
// a cache's entries into another cache's arrays; never the room past them
// that no store wrote.
template <typename Word>
__global__ void copy_held_kernel(const std::uint32_t* end, std::uint32_t bound, std::uint32_t words, const Word* from,
                                 Word* to) {
  const std::size_t n = std::size_t(min(*end, bound)) * words;
  for (std::size_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += std::size_t(gridDim.x) * blockDim.x)
    to[k] = from[k];
}

// copy_held_kernel on entries of `size` bytes, in 4-byte words where the
// size allows (keys, impulses), else in bytes (colours).
void copy_held(const std::uint32_t* end, std::uint32_t bound, std::size_t size, const void* from, void* to,
               int sm_count, cudaStream_t s) {
  const std::size_t n = std::size_t(bound) * size;
  if (size % 4 == 0)
    copy_held_kernel<<<grid_for(n / 4, sm_count), kBlock, 0, s>>>(end, bound, static_cast<std::uint32_t>(size / 4),
                                                                   static_cast<const std::uint32_t*>(from),
                                                                   static_cast<std::uint32_t*>(to));
  else
    copy_held_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(end, bound, static_cast<std::uint32_t>(size),
                                                               static_cast<const std::uint8_t*>(from),
                                                               static_cast<std::uint8_t*>(to));
  MARBLES_CUDA_CHECK_LAUNCH();
}

// --- renumber: each entry renamed (renamed_key, as the host's renumbered)
// and counted with its new sphere, then the store's counting sort (above),
// and the entries gathered.

// Sphere a's entries, renamed: key[k], whether it turned round, and its
// rank among its new sphere's (counted in count; rank stays kNoEntry where
// the entry is dropped: renamed_key).
__global__ void rename_kernel(const std::uint32_t* first, std::uint32_t runs, const std::uint32_t* b_of,
                              const std::uint32_t* new_index, std::uint32_t spheres, std::uint64_t* key,
                              std::uint8_t* swapped, std::uint32_t* count, std::uint32_t* rank) {
  for (std::uint32_t a = blockIdx.x * blockDim.x + threadIdx.x; a < runs; a += gridDim.x * blockDim.x)
    for (std::uint32_t k = first[a]; k < first[a + 1]; ++k) {
      const RenamedKey r = renamed_key(a, b_of[k], new_index, spheres);
      if (r.outcome != Renamed::kept) continue;
      key[k] = r.key;
      swapped[k] = r.swapped;
      rank[k] = atomicAdd(count + (r.key >> 32), 1u);
    }
}

// The entries' arrays (b halves, impulses, colours): the old ones in, the
// new ones out (tangent and rolling null where none are kept).
struct EntryArrays {
  std::uint32_t* b;
  real* normal;
  Vec3* tangent;
  Vec3* rolling;
  std::uint8_t* colour;
};
// Entry e of the new order from entry order[e] of the old, for e below the
// kept count (*kept); the room past it cleared.
__global__ void renamed_gather_kernel(const std::uint64_t* key, const std::uint8_t* swapped, const std::uint32_t* order,
                                      const std::uint32_t* kept, std::uint32_t m, EntryArrays in, EntryArrays out) {
  const std::uint32_t size = *kept;
  for (std::uint32_t e = blockIdx.x * blockDim.x + threadIdx.x; e < m; e += gridDim.x * blockDim.x) {
    if (e >= size) {
      out.b[e] = 0;
      out.normal[e] = 0;
      if (out.tangent) out.tangent[e] = Vec3{};
      if (out.rolling) out.rolling[e] = Vec3{};
      out.colour[e] = kNoKeptColour;
      continue;
    }
    const std::uint32_t k = order[e];
    const bool turn = swapped[k] != 0;
    out.b[e] = static_cast<std::uint32_t>(key[k]);
    out.normal[e] = in.normal[k];
    if (out.tangent) out.tangent[e] = turned(in.tangent[k], turn);
    if (out.rolling) out.rolling[e] = turned(in.rolling[k], turn);
    out.colour[e] = in.colour[k];
  }
}

// Each contact's entry (a scan of its sphere's few entries, as on the CPU)
// and kept colour. A sphere from `spheres` on has no entries.
__global__ void restore_kernel(const BodyPair* pairs, std::uint32_t items, const std::uint32_t* count_on_device,
                               const std::uint32_t* keys, const std::uint32_t* first, std::uint32_t spheres,
                               const std::uint8_t* colour, std::uint8_t* matched, std::uint8_t* kept_colour,
                               std::uint32_t* match) {
  const auto n = static_cast<std::uint32_t>(::marbles::cuda::count_within(items, count_on_device));
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < n; k += gridDim.x * blockDim.x) {
    const BodyPair ab = pairs[k];
    const std::uint32_t end = ab.a < spheres ? first[ab.a + 1] : 0;
    const std::uint32_t e = ab.a < spheres ? find_in_run(keys, first[ab.a], end, ab.b) : 0;
    const bool found = e < end;
    kept_colour[k] = found ? colour[e] : kNoKeptColour;
    match[k] = found ? e : kNoEntry;
    if (found) matched[e] = 1;  // keys are unique: one contact per entry
  }
}

// The normal impulse contact k starts with (restore_impulses: the entry's).
__device__ __forceinline__ real restored_normal(const std::uint32_t* match, const real* normal, std::uint32_t k) {
  const std::uint32_t e = match[k];
  return e != kNoEntry ? normal[e] : real(0);
}

// Entry e of sphere a found no contact and carried a load (is_lost_load).
__device__ __forceinline__ bool lost_load_at(const real* normal, const std::uint8_t* matched,
                                             const BodiesView& bodies, real weight_impulse, std::uint32_t a,
                                             std::uint32_t e) {
  return !matched[e] && is_lost_load(normal[e], bodies.inv_mass[a], weight_impulse);
}

// The lost loads, sphere by sphere (a thread walks its sphere's run): spheres
// below `spheres` (the cache's and the world's both), as the CPU counts an
// entry only of a sphere the world has.
__global__ void lost_loads_kernel(const std::uint32_t* first, std::uint32_t spheres, const real* normal,
                                  const std::uint8_t* matched, BodiesView bodies, real weight_impulse,
                                  std::uint32_t* count) {
  std::uint32_t mine = 0;
  for (std::uint32_t a = blockIdx.x * blockDim.x + threadIdx.x; a < spheres; a += gridDim.x * blockDim.x)
    for (std::uint32_t e = first[a]; e < first[a + 1]; ++e)
      if (lost_load_at(normal, matched, bodies, weight_impulse, a, e)) ++mine;
  if (mine) atomicAdd(count, mine);
}

// --- the island rule, data-parallel ----------------------------------------
// Islands are the connected components of the sphere-sphere contacts; each
// sphere's label converges to the smallest index of its island (min-label
// propagation with pointer jumping), whatever the order of the updates: the
// CPU's union-find gives the same islands. The plain reads of labels that
// other threads lower at the same time are intended: a label only ever falls
// to another sphere of the same island, so any value read is a valid one, and
// the loop ends only after a pass that changed nothing.
// What the island rule reads and writes: the contacts (pairs, match), the
// cache's entries, the lost-load count, and scratch per body.
struct IslandRule {
  const BodyPair* pairs;
  std::uint32_t* match;
  std::uint32_t n;  // contacts (their room, with `count`)
  const std::uint32_t* count;  // null, or the contacts' count on the device (count_within)
  const std::uint32_t* keys;   // the entries' b
  const std::uint32_t* first;  // the runs of spheres [0, spheres)
  std::uint32_t spheres;
  const real* normal;
  const std::uint8_t* matched;
  BodiesView bodies;
  real weight_impulse;
  const std::uint32_t* lost;  // lost_loads_kernel's count
  std::uint32_t* label;
  unsigned long long* island_max;
  std::uint8_t* cold;
  unsigned* changed;  // two words, used in turn by the label passes
};

// One hook pass: each contact lowers its spheres' labels (and the larger
// label's root) to the smaller of the two.
__device__ void label_hook(const IslandRule& r, std::uint32_t first, std::uint32_t stride, unsigned* changed) {
  for (std::uint32_t k = first; k < r.n; k += stride) {
    const BodyPair c = r.pairs[k];
    if (is_wall(c.b)) continue;
    const std::uint32_t la = r.label[c.a], lb = r.label[c.b];
    if (la == lb) continue;
    const std::uint32_t lo = la < lb ? la : lb, hi = la < lb ? lb : la;
    atomicMin(&r.label[hi], lo);  // hook the larger label's root onto the smaller
    atomicMin(&r.label[c.a], lo);
    atomicMin(&r.label[c.b], lo);
    *changed = 1u;
  }
}

__device__ void label_jump(const IslandRule& r, std::uint32_t first, std::uint32_t stride) {
  for (std::uint32_t i = first; i < r.bodies.count; i += stride) {
    std::uint32_t l = r.label[i];
    while (r.label[l] != l) l = r.label[l];
    r.label[i] = l;
  }
}

// The largest impulse each island carries (non-negative reals order as their bits).
__device__ void island_max_pass(const IslandRule& r, std::uint32_t first, std::uint32_t stride) {
  for (std::uint32_t k = first; k < r.n; k += stride) {
    const real p = restored_normal(r.match, r.normal, k);
    if (!(p > 0)) continue;
    atomicMax(&r.island_max[r.label[r.pairs[k].a]], bits_of_real(p));
  }
}

// Islands that lost a load start cold (a plain store of 1: order-free).
__device__ void island_cold_pass(const IslandRule& r, std::uint32_t first, std::uint32_t stride) {
  for (std::uint32_t a = first; a < r.spheres; a += stride)
    for (std::uint32_t e = r.first[a]; e < r.first[a + 1]; ++e) {
      if (!lost_load_at(r.normal, r.matched, r.bodies, r.weight_impulse, a, e)) continue;
      for (const std::uint32_t body : {a, r.keys[e]}) {
        if (is_wall(body) || body >= r.bodies.count) continue;
        const std::uint32_t l = r.label[body];
        if (island_starts_cold(r.normal[e], real_of_bits(r.island_max[l]))) r.cold[l] = 1;
      }
    }
}

// A cold island's contacts start without impulses (no entry).
__device__ void island_clear_pass(const IslandRule& r, std::uint32_t first, std::uint32_t stride) {
  for (std::uint32_t k = first; k < r.n; k += stride)
    if (r.cold[r.label[r.pairs[k].a]] && restored_normal(r.match, r.normal, k) > 0) r.match[k] = kNoEntry;
}

// The whole island rule in one cooperative launch, a grid-wide barrier
// between its passes, and nothing at all when no load was lost (every block
// reads the same count and returns alike): the host never waits for the
// count. Label passes repeat until one changes nothing; each pass's flag
// word is cleared a pass ahead, while no thread reads or writes it.
__global__ void island_rule_kernel(IslandRule r) {
  if (*r.lost == 0u) return;
  r.n = static_cast<std::uint32_t>(::marbles::cuda::count_within(r.n, r.count));
  const cg::grid_group grid = cg::this_grid();
  const std::uint32_t first = blockIdx.x * blockDim.x + threadIdx.x, stride = gridDim.x * blockDim.x;
  for (std::uint32_t i = first; i < r.bodies.count; i += stride) {
    r.label[i] = i;
    r.island_max[i] = 0;
    r.cold[i] = 0;
  }
  if (first == 0) r.changed[0] = 0u;
  grid.sync();
  for (std::uint32_t pass = 0;; ++pass) {
    unsigned* changed = r.changed + (pass & 1u);
    label_hook(r, first, stride, changed);
    grid.sync();
    label_jump(r, first, stride);
    if (first == 0) r.changed[(pass + 1) & 1u] = 0u;
    grid.sync();
    if (::marbles::cuda::read_volatile(changed) == 0u) break;
  }
  island_max_pass(r, first, stride);
  grid.sync();
  island_cold_pass(r, first, stride);
  grid.sync();
  island_clear_pass(r, first, stride);
}

}  // namespace

ContactCacheCuda::ContactCacheCuda() = default;
ContactCacheCuda::~ContactCacheCuda() = default;

void ContactCacheCuda::store(const SweepRecords& contacts, const std::uint8_t* contact_colour, std::uint32_t n,
                             std::uint32_t spheres, int sm_count, cudaStream_t s, const std::uint32_t* count_on_device,
                             const unsigned long long* skip) {
  Set& e = m_sets.writable();
  // Entries: the contacts with load or a colour, at most n, in key order by
  // a counting sort by sphere (count, scan into the kept firsts, place) and
  // an insertion sort of each sphere's run. Their count (the firsts' last)
  // stays on the device, and the host holds only the bound n (no wait).
  // A store that may be skipped scans into its temporaries and takes the
  // firsts over only where it is not; the entries' arrays, where they grow,
  // keep the entries they hold, and the bound covers both.
  const std::uint32_t old_bound = e.bound, old_runs = std::min(e.bound > 0 ? e.spheres + 1 : 0u, spheres + 1);
  e.bound = skip ? std::max(e.bound, n) : n;
  e.stored = n;
  e.spheres = spheres;
  // The kept runs are every word written; of the entries, those the kept
  // runs reach (their last first, read on the device: the room past it was
  // never written).
  auto* kept_first = static_cast<std::uint32_t*>(
      skip ? e.first.reserve_keeping((std::size_t(spheres) + 1) * 4 + 16, std::size_t(old_runs) * 4, s)
           : e.first.reserve((std::size_t(spheres) + 1) * 4 + 16));
  auto room = [&](DeviceBuffer& b, std::size_t size) {
    if (!skip || old_runs == 0) return b.reserve(n * size + 16);
    return b.reserve_copying(n * size + 16, s, [&](void* to, const void* from, std::size_t held) {
      const auto bound = static_cast<std::uint32_t>(std::min<std::size_t>(old_bound, held / size));
      copy_held(kept_first + old_runs - 1, bound, size, from, to, sm_count, s);
    });
  };
  auto* keys = static_cast<std::uint32_t*>(room(e.keys, sizeof(std::uint32_t)));
  auto* normal = static_cast<real*>(room(e.normal, sizeof(real)));
  auto* tangent = m_keep_tangent ? static_cast<Vec3*>(room(e.tangent, sizeof(Vec3))) : nullptr;
  auto* rolling = m_keep_rolling ? static_cast<Vec3*>(room(e.rolling, sizeof(Vec3))) : nullptr;
  auto* colour = static_cast<std::uint8_t*>(room(e.colour, 1));
  if (skip && old_runs < spheres + 1) {
    extend_firsts_kernel<<<grid_for(std::size_t(spheres) + 1 - old_runs, sm_count), kBlock, 0, s>>>(
        kept_first, old_runs, spheres + 1);
    MARBLES_CUDA_CHECK_LAUNCH();
  }
  if (n == 0) {
    if (skip) {
      clear_firsts_kernel<<<grid_for(std::size_t(spheres) + 1, sm_count), kBlock, 0, s>>>(kept_first, spheres + 1,
                                                                                         skip);
      MARBLES_CUDA_CHECK_LAUNCH();
    } else {
      MARBLES_CUDA_CHECK(cudaMemsetAsync(kept_first, 0, (std::size_t(spheres) + 1) * sizeof(std::uint32_t), s));
    }
    return;
  }
  // Temporaries in the scratch memory (or the memory share_store_memory lent):
  // the counts (one more than the spheres: the scan's last is the entry
  // count) with the scan's storage, each contact's rank among its sphere's,
  // the entries' contacts, and the firsts where the store may be skipped.
  const std::size_t scan_bytes = ::marbles::cuda::exclusive_sum_bytes<std::uint32_t>(std::size_t(spheres) + 1);
  std::uint32_t *count = nullptr, *rank = nullptr, *index = nullptr, *first = kept_first;
  void* scan_temp = nullptr;
  ::marbles::cuda::carve(m_store_memory ? *m_store_memory : *m_scratch, [&](::marbles::cuda::Carve& c) {
    count = c.take<std::uint32_t>(std::size_t(spheres) + 1);
    scan_temp = c.take<char>(scan_bytes);
    rank = c.take<std::uint32_t>(n);
    index = c.take<std::uint32_t>(n);
    if (skip) first = c.take<std::uint32_t>(std::size_t(spheres) + 1);
  });
  MARBLES_CUDA_CHECK(cudaMemsetAsync(count, 0, (std::size_t(spheres) + 1) * sizeof(std::uint32_t), s));
  count_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(contacts, contact_colour, n, count_on_device, skip, count,
                                                        rank);
  MARBLES_CUDA_CHECK_LAUNCH();
  ::marbles::cuda::device_exclusive_sum(count, first, std::size_t(spheres) + 1, scan_temp, scan_bytes, s);
  place_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(ContactSphere{contacts}, n, rank, first, index, skip);
  MARBLES_CUDA_CHECK_LAUNCH();
  order_runs_kernel<<<grid_for(spheres, sm_count), kBlock, 0, s>>>(ContactB{contacts}, first, spheres, index, skip);
  MARBLES_CUDA_CHECK_LAUNCH();
  gather_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(contacts, contact_colour, index, first + spheres, keys,
                                                         normal, tangent, rolling, colour, skip);
  MARBLES_CUDA_CHECK_LAUNCH();
  if (skip) {
    adopt_firsts_kernel<<<grid_for(std::size_t(spheres) + 1, sm_count), kBlock, 0, s>>>(first, spheres + 1, skip,
                                                                                       kept_first);
    MARBLES_CUDA_CHECK_LAUNCH();
  }
}

CacheEntries ContactCacheCuda::download(cudaStream_t s) {
  const Set& held = m_sets.current();
  // The runs first: their last first is the entry count (the store leaves
  // the room past it unwritten); then that many entries, and the whole keys
  // from each run's sphere and the b.
  CacheEntries e;
  if (held.bound == 0) return e;
  std::vector<std::uint32_t> first(std::size_t(held.spheres) + 1);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(first.data(), held.first.get(), first.size() * sizeof(std::uint32_t),
                                     cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  const std::size_t m = std::min<std::size_t>(first[held.spheres], held.bound);
  e.resize(m);
  if (m == 0) return e;
  std::vector<std::uint32_t> b(m);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(b.data(), held.keys.get(), m * sizeof(std::uint32_t), cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(e.normal_impulse.data(), held.normal.get(), m * sizeof(real), cudaMemcpyDeviceToHost, s));
  if (m_keep_tangent)  // else zero, as resize left them
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(e.tangent_impulse.data(), held.tangent.get(), m * sizeof(Vec3), cudaMemcpyDeviceToHost, s));
  if (m_keep_rolling)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(e.rolling_impulse.data(), held.rolling.get(), m * sizeof(Vec3), cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(e.colour.data(), held.colour.get(), m, cudaMemcpyDeviceToHost, s));
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
  for (std::uint32_t a = 0; a < held.spheres; ++a)
    for (std::uint32_t k = first[a]; k < std::min<std::size_t>(first[a + 1], m); ++k) e.key[k] = cache_key(a, b[k]);
  return e;
}

void ContactCacheCuda::upload(const CacheEntries& e, std::uint32_t spheres, cudaStream_t s) {
  Set& held = m_sets.edited();
  // Sorted by key, so grouped by sphere a: runs over the world's spheres and
  // any beyond them that have entries (those are never looked up, but a
  // download gives every entry back), and each entry's b.
  const auto m = static_cast<std::uint32_t>(e.size());
  held.bound = m;
  held.spheres = m > 0 ? std::max(spheres, static_cast<std::uint32_t>(e.key[m - 1] >> 32) + 1) : spheres;
  std::vector<std::uint32_t> first, b(m);
  key_runs(e.key.data(), m, held.spheres, first);
  for (std::uint32_t k = 0; k < m; ++k) b[k] = static_cast<std::uint32_t>(e.key[k] & 0xffffffffu);
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(held.first.as<std::uint32_t>(first.size()), first.data(),
                                     first.size() * sizeof(std::uint32_t), cudaMemcpyHostToDevice, s));
  if (m == 0) {
    MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
    return;
  }
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(held.keys.as<std::uint32_t>(m), b.data(), m * sizeof(std::uint32_t),
                                     cudaMemcpyHostToDevice, s));
  MARBLES_CUDA_CHECK(cudaMemcpyAsync(held.normal.as<real>(m), e.normal_impulse.data(), m * sizeof(real), cudaMemcpyHostToDevice, s));
  if (m_keep_tangent)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(held.tangent.as<Vec3>(m), e.tangent_impulse.data(), m * sizeof(Vec3), cudaMemcpyHostToDevice, s));
  if (m_keep_rolling)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(held.rolling.as<Vec3>(m), e.rolling_impulse.data(), m * sizeof(Vec3), cudaMemcpyHostToDevice, s));
  auto* colour = held.colour.as<std::uint8_t>(m);
  if (e.colour.size() == m)
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(colour, e.colour.data(), m, cudaMemcpyHostToDevice, s));
  else
    MARBLES_CUDA_CHECK(cudaMemsetAsync(colour, kNoKeptColour, m, s));  // none known: coloured afresh
  MARBLES_CUDA_CHECK(cudaStreamSynchronize(s));
}

void ContactCacheCuda::renumber(const std::uint32_t* new_index, std::uint32_t spheres, int sm_count,
                                cudaStream_t s) {
  Set& e = m_sets.edited();
  const std::uint32_t m = e.bound;
  const std::uint32_t runs = e.spheres;  // the old runs (a checkpoint's may pass the world's spheres)
  const std::size_t runs_new = std::size_t(spheres) + 1;
  if (m == 0) {
    MARBLES_CUDA_CHECK(cudaMemsetAsync(e.first.as<std::uint32_t>(runs_new), 0, runs_new * sizeof(std::uint32_t), s));
    e.spheres = spheres;
    return;
  }
  // The runs' room too small for the world's spheres (it gained them by an
  // edit since the room was made): the old runs move to a grown room first.
  e.first.reserve_keeping(runs_new * sizeof(std::uint32_t) + 16, (std::size_t(runs) + 1) * sizeof(std::uint32_t), s);
  auto* first = e.first.get_as<std::uint32_t>();
  // The temporaries in the stream's order (no wait; not held past the
  // call): the new keys, turns and ranks, the counts and their scan (the new
  // runs), the new order and the entries gathered, copied back over the old
  // (never more of them: the bound stays).
  const std::size_t scan_bytes = ::marbles::cuda::exclusive_sum_bytes<std::uint32_t>(runs_new);
  std::uint64_t* key = nullptr;
  std::uint8_t* swapped = nullptr;
  std::uint32_t *rank = nullptr, *count = nullptr, *new_first = nullptr, *order = nullptr;
  void* scan_temp = nullptr;
  EntryArrays out{};
  DeviceBuffer temporaries(s);
  ::marbles::cuda::carve(temporaries, [&](::marbles::cuda::Carve& c) {
    key = c.take<std::uint64_t>(m);
    swapped = c.take<std::uint8_t>(m);
    rank = c.take<std::uint32_t>(m);
    count = c.take<std::uint32_t>(runs_new);
    scan_temp = c.take<char>(scan_bytes);
    new_first = c.take<std::uint32_t>(runs_new);
    order = c.take<std::uint32_t>(m);
    out.b = c.take<std::uint32_t>(m);
    out.normal = c.take<real>(m);
    out.tangent = m_keep_tangent ? c.take<Vec3>(m) : nullptr;
    out.rolling = m_keep_rolling ? c.take<Vec3>(m) : nullptr;
    out.colour = c.take<std::uint8_t>(m);
  });
  MARBLES_CUDA_CHECK(cudaMemsetAsync(rank, 0xff, m * sizeof(std::uint32_t), s));  // kNoEntry: past the entries too
  MARBLES_CUDA_CHECK(cudaMemsetAsync(count, 0, runs_new * sizeof(std::uint32_t), s));
  rename_kernel<<<grid_for(runs, sm_count), kBlock, 0, s>>>(first, runs, e.keys.get_as<std::uint32_t>(), new_index,
                                                            spheres, key, swapped, count, rank);
  MARBLES_CUDA_CHECK_LAUNCH();
  ::marbles::cuda::device_exclusive_sum(count, new_first, runs_new, scan_temp, scan_bytes, s);
  place_kernel<<<grid_for(m, sm_count), kBlock, 0, s>>>(EntrySphere{key}, m, rank, new_first, order);
  MARBLES_CUDA_CHECK_LAUNCH();
  order_runs_kernel<<<grid_for(spheres, sm_count), kBlock, 0, s>>>(EntryKey{key}, new_first, spheres, order);
  MARBLES_CUDA_CHECK_LAUNCH();
  const EntryArrays in{e.keys.get_as<std::uint32_t>(), e.normal.get_as<real>(),
                       m_keep_tangent ? e.tangent.get_as<Vec3>() : nullptr,
                       m_keep_rolling ? e.rolling.get_as<Vec3>() : nullptr, e.colour.get_as<std::uint8_t>()};
  renamed_gather_kernel<<<grid_for(m, sm_count), kBlock, 0, s>>>(key, swapped, order, new_first + spheres, m, in, out);
  MARBLES_CUDA_CHECK_LAUNCH();
  auto back = [&](void* to, const void* from, std::size_t bytes) {
    MARBLES_CUDA_CHECK(cudaMemcpyAsync(to, from, bytes, cudaMemcpyDeviceToDevice, s));
  };
  back(in.b, out.b, m * sizeof(std::uint32_t));
  back(in.normal, out.normal, m * sizeof(real));
  if (out.tangent) back(in.tangent, out.tangent, m * sizeof(Vec3));
  if (out.rolling) back(in.rolling, out.rolling, m * sizeof(Vec3));
  back(in.colour, out.colour, m);
  back(first, new_first, runs_new * sizeof(std::uint32_t));
  e.spheres = spheres;
}

bool ContactCacheCuda::restore(const BodyPair* pairs, std::uint32_t n, const std::uint32_t* count_on_device,
                               const BodiesView& bodies, real weight_impulse, std::uint8_t* kept_colour,
                               std::uint32_t* match, int sm_count, cudaStream_t s) {
  const Set& e = m_sets.current();
  const std::uint32_t m = e.bound;  // the entries are at most this many (their count: the runs' last first)
  if (m == 0 || n == 0) return false;
  // Temporaries in the scratch memory: which entries were matched, and for
  // the island rule the bodies' labels, island maxima and cold flags.
  const auto bodies_n = static_cast<std::uint32_t>(bodies.count);
  std::uint8_t *matched = nullptr, *cold = nullptr;
  std::uint32_t* label = nullptr;
  unsigned long long* island_max = nullptr;
  ::marbles::cuda::carve(*m_scratch, [&](::marbles::cuda::Carve& c) {
    matched = c.take<std::uint8_t>(m);
    label = c.take<std::uint32_t>(bodies_n);
    island_max = c.take<unsigned long long>(bodies_n);
    cold = c.take<std::uint8_t>(bodies_n);
  });
  auto* counter = m_counter.as<std::uint32_t>(3);  // the lost loads, then the label passes' two flags
  MARBLES_CUDA_CHECK(cudaMemsetAsync(matched, 0, m, s));
  MARBLES_CUDA_CHECK(cudaMemsetAsync(counter, 0, sizeof(std::uint32_t), s));
  const auto* keys = e.keys.get_as<std::uint32_t>();
  const auto* normal = e.normal.get_as<real>();
  const auto* first = e.first.get_as<std::uint32_t>();
  const std::uint32_t spheres = std::min(e.spheres, bodies_n);  // the spheres with runs that the world has
  restore_kernel<<<grid_for(n, sm_count), kBlock, 0, s>>>(pairs, n, count_on_device, keys, first, spheres,
                                                          e.colour.get_as<std::uint8_t>(), matched, kept_colour, match);
  MARBLES_CUDA_CHECK_LAUNCH();
  if (spheres > 0) {
    lost_loads_kernel<<<grid_for(spheres, sm_count), kBlock, 0, s>>>(first, spheres, normal, matched, bodies,
                                                                     weight_impulse, counter);
    MARBLES_CUDA_CHECK_LAUNCH();
  }

  // The island rule, on the device, where a load was lost (the kernel reads the count).
  const IslandRule rule{pairs,  match,          n,       count_on_device, keys,       first, spheres,
                        normal, matched,        bodies,  weight_impulse,  counter,    label, island_max,
                        cold,   counter + 1};
  ::marbles::cuda::launch_cooperative<island_rule_kernel>(std::max<std::size_t>(n, bodies_n), sm_count, s, rule);
  return true;
}

}  // namespace marbles::narrowphase::cuda
