// narrowphase/contact.hpp — one contact between a sphere and another sphere or a wall.
//
// Sign conventions: `normal` is the unit vector from the other body (b) towards
// sphere a; `separation` is the gap along it (m), negative when they overlap.
// The contact point on a is  p_a - ra·n, on b it is  p_b + rb·n  (rb = 0 for walls).
// The solver's accumulated impulses live here too, so that a contact carries
// everything one velocity iteration needs and nothing else.
#pragma once

#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "core/vec3.hpp"

namespace marbles::narrowphase {

// `b` of a wall contact: kWallFlag | wall index (planes first, then box faces).
inline constexpr std::uint32_t kWallFlag = 0x80000000u;
MARBLES_HD_INLINE bool is_wall(std::uint32_t b) { return (b & kWallFlag) != 0; }

// Coefficients of one material pair, mixed once when the scene is loaded.
struct PairCoefficients {
  real restitution = 0;       // e in [0, 1]
  real friction = 0;          // Coulomb mu
  real rolling_friction = 0;  // mu_r: rolling torque <= mu_r * R_eff * normal force
  real twisting_friction = 0; // mu_t: torque about the normal <= mu_t * R_eff * normal force
};

// Material pair table, row-major over material ids (walls use their own
// material id in the same table).
struct PairTable {
  const PairCoefficients* coefficients = nullptr;
  std::uint32_t material_count = 0;
  MARBLES_HD_INLINE const PairCoefficients& operator()(std::uint32_t m1, std::uint32_t m2) const {
    return coefficients[m1 * material_count + m2];
  }
};

// A contact's two bodies (b may be a wall: kWallFlag | index), as the
// sweep's records and the GPU's contact list hold them.
struct alignas(8) BodyPair {
  std::uint32_t a = 0, b = 0;
};

// 16-byte aligned, fields in 16-byte groups. The GPU holds no Contact
// array: a contact lives there as the sweep's records (solver_math.hpp) and
// is made whole only when the host asks for the contacts.
struct alignas(16) Contact {
  // Accumulated impulses of this substep: what a velocity sweep writes.
  real normal_impulse = 0;  // N s, >= 0, the sustained (velocity-solve) part
  Vec3 tangent_impulse;     // N s, |.| <= mu * normal_impulse
  Vec3 rolling_impulse;     // N m s
  real impact_impulse = 0;  // N s, what the impact stage applied (not carried over)

  // Filled by the solver's prepare stage.
  real normal_mass = 0;     // kg,   1 / (1/m_a + 1/m_b)
  real tangent_mass = 0;    // kg,   1 / (1/m_a + 1/m_b + ra^2/I_a + rb^2/I_b)
  real rolling_mass = 0;    // kg m^2, 1 / (1/I_a + 1/I_b)
  real approach_speed = 0;  // m/s, normal relative velocity before the solve (< 0: approaching)

  std::uint32_t a = 0, b = 0;
  real separation = 0;     // m, < 0 when overlapping
  real spare = 0;          // unused: keeps the fields in 16-byte groups and no padding (contacts compare whole)
  Vec3 normal;             // from b towards a, unit
  real ra = 0, rb = 0;     // m, lever arms along the normal
  Vec3 wall_velocity;      // m/s, velocity of the wall surface (b is a wall)
  PairCoefficients coeff;

  // World-space point midway across the overlap (or gap).
  MARBLES_HD_INLINE Vec3 point(const Vec3& position_a) const {
    return position_a - normal * (ra + real(0.5) * separation);
  }
};
static_assert(sizeof(Contact) % 16 == 0);

// A contact as the CPU's search finds it, before its records are made: its
// bodies, normal and separation, and the impulses the cache's restore gives
// it; 52 bytes in float where a Contact takes 112 (the search writes them,
// the restore reads and writes them, the records' making gathers them, and
// each follows the bytes it moves: docs/architecture.md "The CPU's contacts
// as found"). The arms, the coefficients and a wall's surface velocity are
// made again as the records are made (whole_contact, contact_math.hpp) from
// the bodies and walls, which nothing moves in between: the search's bits.
struct FoundContact {
  real normal_impulse = 0;
  Vec3 tangent_impulse;
  Vec3 rolling_impulse;
  std::uint32_t a = 0, b = 0;
  real separation = 0;
  Vec3 normal;
};
static_assert(sizeof(FoundContact) == 11 * sizeof(real) + 8);

// A list of contacts held in two runs: first[0, first_count), then second
// from its start. From a plain array (first_count unbounded) it is that
// array. The CPU's contact search leaves its threads' parts so, the first
// thread's and then the others', where joining them into one array would
// copy half the contacts once more (docs/architecture.md "The CPU's contact
// search on one thread and two").
template <class C>  // Contact or const Contact
struct Runs {
  C* first = nullptr;
  C* second = nullptr;
  std::size_t first_count = ~std::size_t(0);
  Runs(C* all) : first(all) {}  // NOLINT: an array is one run
  Runs(C* first_run, std::size_t first_run_count, C* second_run)
      : first(first_run), second(second_run), first_count(first_run_count) {}
  template <class D, class = std::enable_if_t<std::is_convertible_v<D*, C*>>>  // C++17: the CUDA files
  Runs(const Runs<D>& other) : first(other.first), second(other.second), first_count(other.first_count) {}
  // Without a branch (selects): the colouring reads the runs in random order.
  C& operator[](std::size_t k) const {
    const bool in_first = k < first_count;
    return (in_first ? first : second)[in_first ? k : k - first_count];
  }
};
using ContactRuns = Runs<Contact>;
using FoundRuns = Runs<FoundContact>;

}  // namespace marbles::narrowphase
