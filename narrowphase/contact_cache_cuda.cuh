// narrowphase/contact_cache_cuda.cuh — the CUDA twin of contact_cache.cpp:
// entries in key order as the CPU sorts them (a counting sort by sphere a,
// then each sphere's few entries ordered by b), and each contact's entry
// found among its sphere's (the counting sort's firsts, kept with the
// entries), one thread per contact. An entry keeps only the b half of its
// key (4 bytes, not 8): its run says a. The entry count (the runs' last
// first) stays on the device (a checkpoint's download reads it). When a
// load was lost (rare: a counter says so, read by the device alone), the
// island rule runs in one cooperative launch: islands by min-label
// propagation with pointer jumping (the same islands as the CPU's
// union-find), their largest impulse by an atomic max, then the cold
// islands' contacts cleared. Neither store nor restore waits for the
// device. A watchdog's step start is kept without a copy (keep,
// back_to_kept: two sets of entries, as the CPU's cache holds). Only .cu
// files include it.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "core/device_buffer.cuh"
#include "core/kept_sets.hpp"
#include "core/spheres.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_cache.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {

using ::marbles::cuda::DeviceBuffer;

// A contact without a cache entry (ContactCacheCuda::restore's match).
inline constexpr std::uint32_t kNoEntry = 0xffffffffu;

// The impulses of the cache's entries, by entry (device pointers).
struct CacheImpulses {
  const real* normal = nullptr;
  const Vec3* tangent = nullptr;  // null: none kept (no friction)
  const Vec3* rolling = nullptr;  // null: none kept (no rolling resistance)
};

class ContactCacheCuda {
 public:
  ContactCacheCuda();
  ~ContactCacheCuda();
  ContactCacheCuda(const ContactCacheCuda&) = delete;
  ContactCacheCuda& operator=(const ContactCacheCuda&) = delete;

  // Warm start of the contacts of body pairs[0, n) (device; with
  // count_on_device, not null, the first *count_on_device of them where that
  // fits n, none where it does not: count_within): each one's entry (match,
  // device, n entries: an index into entries(), or kNoEntry where it starts
  // cold) and its kept colour (kept_colour, device, n entries), as
  // ContactCache::restore finds them, the island rule included.
  // The impulses themselves are restored when the contacts are made
  // (restore_impulses, with the contact's normal). False, writing nothing,
  // when there are no contacts or the last store had none (the bound is 0);
  // a cache that kept no entry of its contacts gives every contact no entry
  // and no kept colour, which colours and restores as `false` does.
  bool restore(const BodyPair* pairs, std::uint32_t n, const std::uint32_t* count_on_device, const BodiesView& bodies,
               real weight_impulse, std::uint8_t* kept_colour, std::uint32_t* match, int sm_count,
               cudaStream_t stream);
  // The entries' impulses (device; tangent and rolling null where the scene
  // keeps none): valid until the next store, upload, renumbering,
  // back_to_kept, trim_entries or dead_entries (the last two take this
  // set's memory where the current set is not the kept one: the next store
  // then writes it).
  CacheImpulses entries() const {
    const Set& e = m_sets.current();
    return {e.normal.get_as<real>(), m_keep_tangent ? e.tangent.get_as<Vec3>() : nullptr,
            m_keep_rolling ? e.rolling.get_as<Vec3>() : nullptr};
  }
  // The contacts as the sweep's records hold them after the last sweep, with
  // their colours (contact_colour, device, per contact; null: none).
  // `spheres`: how many there are (every contact's a is one of them).
  // With count_on_device, contacts [0, n) are a room and the contacts its
  // first *count_on_device (count_within). With `skip` (not null) the
  // entries are kept as they were where it is set when the store runs
  // (cuda::skipped: a substep that outgrew a room without a wait).
  void store(const SweepRecords& contacts, const std::uint8_t* contact_colour, std::uint32_t n, std::uint32_t spheres,
             int sm_count, cudaStream_t stream, const std::uint32_t* count_on_device = nullptr,
             const unsigned long long* skip = nullptr);
  // The entries are at most this many (the contacts of the last store, or
  // where stores may have been skipped the most of them and of the entries
  // before): the count itself stays on the device, where the kernels read it.
  std::uint32_t bound() const { return m_sets.current().bound; }
  // Every store since stores began to pass `skip` ran: the bound is the last
  // one's contacts again.
  void stores_kept() {
    Set& e = m_sets.current();
    e.bound = e.stored;
  }
  // Device bytes it holds of its own (the entries, their runs; not the
  // shared scratch), less the other set of entries (kept_bytes).
  std::size_t device_bytes() const {
    return m_sets.current().bytes() + ::marbles::cuda::bytes_of(m_counter, m_own_scratch);
  }
  // Device bytes of the other set of entries: the kept ones (keep), or the
  // set a keep once made and that stores write in turn.
  std::size_t kept_bytes() const { return m_sets.other().bytes(); }
  // The entries as the CPU cache holds them (a checkpoint's copy), and back.
  CacheEntries download(cudaStream_t stream);
  // `spheres`: the world's (entries of other spheres are never found).
  void upload(const CacheEntries& entries, std::uint32_t spheres, cudaStream_t stream);
  // The entries with every sphere i named new_index[i] (device, `spheres`
  // words: the world's spheres), as renumbered (contact_cache.hpp) names
  // them: sorted by key again with the store's counting sort by sphere, their
  // runs made again, the same bits as the host's for a numbering (new_index
  // a permutation, as the step's are: an entry that one which is not would
  // send past the world is dropped, where the host throws). Entries of
  // spheres past the world's are dropped (no lookup finds them). The
  // temporaries are the stream's (no wait); it waits only where the runs'
  // room is too small for the world's spheres (it grows).
  void renumber(const std::uint32_t* new_index, std::uint32_t spheres, int sm_count, cudaStream_t stream);
  // The entries as they are now, kept for back_to_kept (a watchdog's step
  // start), without a copy: the cache holds two sets of entries, and from a
  // keep on the next store moves to the other set (which trim_entries and
  // dead_entries take before it, not moving), so the kept one stays as it
  // was until the next keep. An upload or a
  // renumbering writes the entries in place and keeps none.
  void keep() { m_sets.keep(); }
  // The entries keep() kept become the entries again (and stay kept); none
  // kept: nothing changes. Also a step without waits whose first store was
  // skipped goes back so: that store found the other set, and wrote nothing.
  void back_to_kept() { m_sets.back_to_kept(); }
  // Which impulses the scene's terms make (before the first store): without
  // friction the tangential impulses, without rolling resistance the rolling
  // ones stay zero, and the cache neither stores nor reads them.
  void set_terms(bool friction, bool rolling) { m_keep_tangent = friction, m_keep_rolling = rolling; }
  // The temporaries (the store's counts, ranks and order unless given
  // share_store_memory, the restore's matches and island labels) live in
  // `scratch` from here on, memory that
  // stages which never run at the same time share (core/device_buffer.cuh:
  // Carve); by default in the cache's own.
  void share_scratch(DeviceBuffer& scratch) { m_scratch = &scratch; }
  // The store's temporaries (counts, ranks, the entries' contacts) in
  // `memory` instead of the scratch: memory the caller lends, whose own
  // contents are dead while the contacts are stored (the CUDA step's body
  // pairs' memory, which holds the solver bodies during the solve).
  void share_store_memory(DeviceBuffer& memory) { m_store_memory = &memory; }
  // Memory for another stage's temporaries, whose contents are dead from
  // the records' making, which read the entries (entries()), to the next
  // store, which writes them anew: the largest impulse array (tangent or
  // rolling, 12 bytes an entry of the last store's room, and a sixteenth
  // more; null where neither is kept) of the set that store writes (after
  // a keep, the other set: the kept one stays as it was, and current until
  // the store moves past it). Only in a step whose stores are never skipped
  // (with a skipped store the entries stay the warm start's, for the
  // substep done again: `store`'s skip). The pointer is valid until that
  // store; nothing may read the entries in between (a step that throws
  // there leaves them for a reload, not a download).
  DeviceBuffer* dead_entries() {
    Set& e = m_sets.next_written();
    DeviceBuffer* largest = nullptr;
    if (m_keep_tangent) largest = &e.tangent;
    if (m_keep_rolling && (largest == nullptr || e.rolling.bytes() > largest->bytes())) largest = &e.rolling;
    return largest;
  }
  // The entries' arrays trimmed to the most entries asked of them since the
  // last trim (DeviceBuffer::trim); returns how many were freed. Only where
  // the entries are dead: after the restore and the records' making that
  // read them, before the store that writes them (the set it writes: after
  // a keep, the other one).
  std::uint32_t trim_entries() { return trim(m_sets.next_written()); }
  // The other set's entry arrays trimmed so, where they are dead: at a
  // step's start, before keep (the set the last keep kept is past undoing).
  std::uint32_t trim_spare() { return trim(m_sets.other()); }

 private:
  // A set of entries: their keys' b halves, impulses and colours, and
  // their runs: the entries of sphere a are [first[a], first[a + 1]) for
  // a < spheres (spheres + 1 words, device); a sphere from `spheres` on has
  // none.
  struct Set {
    DeviceBuffer keys, normal, tangent, rolling, colour, first;
    std::uint32_t spheres = 0;
    std::uint32_t bound = 0;
    std::uint32_t stored = 0;  // the contacts of the last store
    std::size_t bytes() const { return ::marbles::cuda::bytes_of(keys, normal, tangent, rolling, colour, first); }
  };
  static std::uint32_t trim(Set& e) {
    std::uint32_t freed = 0;
    for (DeviceBuffer* b : {&e.keys, &e.normal, &e.tangent, &e.rolling, &e.colour}) freed += b->trim() ? 1 : 0;
    return freed;
  }
  // The entries' two sets: a store writes m_sets.writable(), an upload or
  // a renumbering m_sets.edited() (in place, nothing kept).
  KeptSets<Set> m_sets;
  DeviceBuffer m_counter, m_own_scratch;
  DeviceBuffer* m_scratch = &m_own_scratch;
  DeviceBuffer* m_store_memory = nullptr;  // share_store_memory's, else the scratch
  bool m_keep_tangent = true, m_keep_rolling = true;
};

}  // namespace marbles::narrowphase::cuda
