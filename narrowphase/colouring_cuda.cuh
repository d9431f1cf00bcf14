// narrowphase/colouring_cuda.cuh — the CUDA twin of colouring.cpp: the
// Jones–Plassmann rounds (colouring_math.hpp) as kernels, then a stable
// counting sort of the contacts by colour (core/counting_sort_cuda.cuh).
// Gives the CPU's colouring bit for bit (the CPU computes the same colours
// in one sequential pass; tests prove the two forms equal). Only .cu files
// include this header.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <vector>

#include "core/device_buffer.cuh"
#include "core/spheres.hpp"
#include "narrowphase/colouring_math.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/solver_math.hpp"

namespace marbles::narrowphase::cuda {

using ::marbles::cuda::DeviceBuffer;

// Contacts that take no part in a colouring (not impact candidates).
inline constexpr std::uint32_t kNotActive = 0xfffffffdu;

struct ColouringArrays;  // a call's temporaries (colouring_cuda.cu)

class ColouringCuda {
 public:
  ColouringCuda();
  ~ColouringCuda();
  ColouringCuda(const ColouringCuda&) = delete;
  ColouringCuda& operator=(const ColouringCuda&) = delete;

  // The solver colouring of the contacts of body pairs[0, n): colours by
  // contact_rank; `position` (device) gets each contact's place in
  // colour-major order (index order within a colour, overflow last), `plan`
  // the host ranges (plan_of_firsts: as ColourRanges::begin). Returns
  // the colour count. kept_colour (device, one per contact, may be null):
  // colours kept as ContactColouring::colour_and_sort keeps them;
  // sorted_colour (device, may be null) gets each sorted contact's colour
  // (kNoKeptColour: overflow). Every round runs in one launch, to the first
  // with no contact left; the ranges and the rounds run are read back
  // together, one wait in all. `position` lies in the scratch memory: valid
  // until its next user. With count_on_device (not null), pairs[0, n) is a
  // room and the contacts are its first *count_on_device (count_within;
  // none where they do not fit it): read with the ranges, last_count().
  // position and sorted_colour then have n entries, those past the contacts
  // placed after them. Without `read_back`, nothing is read and nothing
  // waits: the ranges are only device_plan()'s (`plan` is left as it was,
  // and 0 returned; rounds() and last_count() are not known).
  std::uint32_t colour_and_sort(const BodyPair* pairs, std::uint32_t n, const std::uint32_t* count_on_device,
                                std::size_t body_count, const std::uint32_t*& position, ColourPlan& plan,
                                int sm_count, cudaStream_t stream,
                                const std::uint8_t* kept_colour = nullptr, std::uint8_t* sorted_colour = nullptr,
                                bool read_back = true);
  // The last colour_and_sort's ranges in device memory (as `plan`, word for
  // word; for a room, those of the contacts in it, or none where
  // they outgrew it): what the stages that walk every colour in one launch
  // read. Written in the stream's order, valid until the next call.
  const ColourPlan* device_plan() const { return m_plan.get_as<ColourPlan>(); }
  // The rounds the last colour_and_sort ran (as ContactColouring::colour
  // counts them).
  std::uint32_t rounds() const { return m_rounds; }
  // The contacts the last colour_and_sort was given: n, or the count it read
  // (more than n where they did not fit the room; then it coloured none).
  std::uint32_t last_count() const { return m_last_count; }

  // The impact stage's levels over records[0, n) and their approach speeds
  // (solver_math.hpp: ImpactRecords): the candidates (approach faster than rest_speed)
  // coloured by_round on impact_rank; `order` (device) gets every contact,
  // the candidates level by level (overflow next, then the others), and
  // `first` (device, kMaxColourRounds + 2 words) the firsts of the levels'
  // keys, from which visit_levels (colouring_math.hpp) gives the ranges.
  // Every round runs in one launch, to the first with no contact left:
  // nothing is read on the host, no wait. `order` lies in the scratch
  // memory (or level_memory: below), valid until its next user; `first`
  // until the next call. With
  // count_on_device, records [0, n) are a room and the contacts its first
  // *count_on_device (count_within); the others take no level. The rounds'
  // body words (an 8-byte word a body: the offers; a level is its round, so
  // no colours used are kept) go to `word_memory` where given and it holds
  // them without growing, memory whose contents are dead meanwhile (the
  // CUDA step's cache matches: 4 bytes a contact of the room, which hold
  // them where there are two contacts a sphere; a gas's do not), else to
  // the scratch with the lists. The rest (the colours, the lists, the order
  // and the sort's counts: about 12 bytes a contact of the room) go to
  // `level_memory` where given and it holds them without growing (the CUDA
  // step's cache entries, dead while the impact stage runs in a step that
  // waits: ContactCacheCuda::dead_entries), else to the scratch.
  void impact_levels(const SweepRecords& records, const real* approach, std::uint32_t n, std::size_t body_count,
                     real rest_speed, std::uint32_t*& order, const std::uint32_t*& first, int sm_count,
                     cudaStream_t stream, const std::uint32_t* count_on_device = nullptr,
                     DeviceBuffer* word_memory = nullptr, DeviceBuffer* level_memory = nullptr);

  // Host<->device bytes copied so far (all calls).
  std::uint64_t bytes_copied() const { return m_bytes; }
  // Device bytes it holds of its own (not the shared scratch).
  std::size_t device_bytes() const { return ::marbles::cuda::bytes_of(m_count, m_first_of_key, m_plan, m_own_scratch); }

  // The temporaries (colours, lists, the sort's counts; not the lists
  // given share_round_memory) live in `scratch` from here on, memory that
  // stages which never run at the same time share (core/device_buffer.cuh:
  // Carve); by default in the colouring's own.
  void share_scratch(DeviceBuffer& scratch) { m_scratch = &scratch; }
  // colour_and_sort's round lists and body words (dead once the rounds
  // end, before the sort) in `memory` instead of the scratch: memory whose
  // own contents are dead while contacts are coloured (the CUDA step's
  // records'). The impact levels, which run while the records live, keep
  // their lists in the scratch (their body words: impact_levels).
  void share_round_memory(DeviceBuffer& memory) { m_round_memory = &memory; }

 private:
  std::uint64_t m_bytes = 0;
  // A call's temporaries carved out of the scratch memory: a counting sort
  // over `buckets`, and with `ordered` an array for the sorted order.
  // `rounds`: where the round lists go (null: the scratch, behind the
  // colours, overlapping the sort's arrays); `words`: where the rounds'
  // body words go where it holds them as it is (else, or null: with the
  // lists). The words: the offers, and under `rule` lowest_free each body's
  // colours used (by_round reads none). `part`: where the colours, the
  // sort's arrays and the order (and the lists, where not apart) go where it
  // holds them as it is (else, or null: the scratch).
  ColouringArrays lay_out(std::uint32_t n, std::size_t body_count, std::uint32_t buckets, bool ordered,
                          ColourRule rule, DeviceBuffer* rounds = nullptr, DeviceBuffer* words = nullptr,
                          DeviceBuffer* part = nullptr);
  // Every round over the active list (count[0] contacts, set by the
  // caller), in one launch, its scratch cleared first; `entries` makes a
  // contact's spheres and rank from its index (colouring_cuda.cu).
  template <class Entries>
  void launch_rounds(const Entries& entries, const ColouringArrays& at, std::uint32_t n, std::size_t body_count,
                     ColourRule rule, int sm_count, cudaStream_t stream);
  // The firsts of the sort's buckets (kNoFirst where empty), read back by
  // colour_and_sort, read on the device by the impact stage.
  DeviceBuffer m_count, m_first_of_key, m_plan, m_own_scratch;
  DeviceBuffer* m_scratch = &m_own_scratch;
  DeviceBuffer* m_round_memory = nullptr;  // share_round_memory's, else the scratch
  ::marbles::cuda::PinnedBuffer<std::uint32_t> m_host;  // readbacks
  std::uint32_t m_rounds = 0;       // rounds of the last colour_and_sort
  std::uint32_t m_last_count = 0;   // its contacts (last_count)
};

}  // namespace marbles::narrowphase::cuda
