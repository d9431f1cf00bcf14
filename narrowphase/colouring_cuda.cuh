// narrowphase/colouring_cuda.cuh — the CUDA twin of colouring.cpp: the
// Jones–Plassmann rounds (colouring_math.hpp) as kernels, then a stable sort
// of the contacts by colour. Gives the CPU's colouring bit for bit (the CPU
// computes the same colours in one sequential pass; tests prove the two
// forms equal). Only .cu files include this header.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <vector>

#include "core/device_buffer.cuh"
#include "core/spheres.hpp"
#include "narrowphase/colouring_math.hpp"
#include "narrowphase/contact.hpp"

namespace marbles::narrowphase::cuda {

using ::marbles::cuda::DeviceBuffer;

// Contacts that take no part in a colouring (not impact candidates).
inline constexpr std::uint32_t kNotActive = 0xfffffffdu;

class ColouringCuda {
 public:
  ColouringCuda();
  ~ColouringCuda();
  ColouringCuda(const ColouringCuda&) = delete;
  ColouringCuda& operator=(const ColouringCuda&) = delete;

  // The solver colouring of contacts[0, n): colours by contact_rank, then
  // writes the contacts in colour-major order to `sorted` (index order
  // within a colour, overflow last); `begin` gets the host ranges as
  // ColourRanges::begin (colours + 2 entries). Returns the colour count.
  // kept_colour (device, one per contact, may be null): colours kept as
  // ContactColouring::colour_and_sort keeps them; sorted_colour (device, may
  // be null) gets each sorted contact's colour (kNoKeptColour: overflow);
  // with `prepare` (the world's bodies, device) the sorted contacts come out
  // prepared (prepare_from_world).
  std::uint32_t colour_and_sort(const Contact* contacts, std::uint32_t n, std::size_t body_count, Contact* sorted,
                                std::vector<std::uint32_t>& begin, std::uint32_t& rounds, int sm_count,
                                cudaStream_t stream, const std::uint8_t* kept_colour = nullptr,
                                std::uint8_t* sorted_colour = nullptr, const BodiesView* prepare = nullptr);

  // The impact stage's levels: the candidates (approach faster than
  // rest_speed) coloured by_round on impact_rank; `order` (device) gets them
  // level by level (overflow last), `begin` the host ranges (levels + 2
  // entries). Returns the level count (0: no candidate).
  std::uint32_t impact_levels(const Contact* contacts, std::uint32_t n, std::size_t body_count, real rest_speed,
                              std::uint32_t*& order, std::vector<std::uint32_t>& begin, int sm_count,
                              cudaStream_t stream);

 // Host<->device bytes copied so far (all calls).
  std::uint64_t bytes_copied() const { return m_bytes; }

 private:
  std::uint64_t m_bytes = 0;
  // Rounds over the active list (count[0] entries, set by the caller);
  // returns the rounds run.
  std::uint32_t rounds(std::uint32_t n, std::size_t body_count, ColourRule rule, int sm_count, cudaStream_t stream);
  void reserve(std::uint32_t n);
  // Stable sort of the indices by key (overflow -> overflow_key, inactive
  // last) and the host ranges [0, key_count + 1]; no key is at or above
  // key_bound except the overflow's.
  void sort_by_colour(std::uint32_t n, std::uint32_t overflow_key, int key_bits, std::uint32_t key_bound,
                      std::vector<std::uint32_t>& begin, int sm_count, cudaStream_t stream);

  DeviceBuffer m_colour, m_active, m_next, m_count, m_body_word, m_body_used, m_keys, m_keys_out,
      m_index, m_index_out, m_first_of_key, m_temp;
  std::uint32_t* m_host = nullptr;  // pinned readbacks
  std::uint32_t m_last_rounds[2] = {0, 0};  // rounds of the last colouring by rule (lowest_free, by_round)
};

}  // namespace marbles::narrowphase::cuda
