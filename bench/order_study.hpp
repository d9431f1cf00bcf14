// bench/order_study.hpp — the velocity solve's convergence on a deep pile
// held still, in the solver's order and in a local order (the study behind
// marbles_order_study; bench/order_study.cpp says what it measures).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "narrowphase/colouring.hpp"
#include "narrowphase/contact.hpp"
#include "narrowphase/contact_math.hpp"
#include "sim/world.hpp"

namespace marbles::order_study {

enum class PileKind { close_packed, cubic };

// A pile, its walls and its contacts (found once: the pile does not move),
// in the colouring's colour-major order.
struct Pile {
  World world;
  std::vector<narrowphase::WallShape> walls;
  std::vector<narrowphase::Contact> contacts;
  narrowphase::ColourRanges ranges;
  bool rolling = false;  // rolling resistance (rolling friction 0.05, the benchmark pile's)
};
// side x side x layers spheres of radius 1 cm (close-packed: layers stacked
// ABC on a floor; cubic: columns in a box that touches them), friction 0.5
// and, with `rolling`, rolling resistance.
Pile make_pile(PileKind kind, int side, int layers, bool rolling = false);
// The benchmark's settled pile of n spheres (`marbles bench step --scene
// pile`, friction 0.5, with `rolling` rolling resistance 0.05; from the
// cache in cache_dir, settled there first where it is missing) in its box:
// a pile that rests under the solver's own sweeps, so every order's speeds
// can fall to 0 (the close-packed rhombus's overhanging edges never do).
Pile settled_pile(std::size_t n, const std::string& cache_dir, bool rolling = false);

struct Order {
  std::string name;
  int passes;     // over memory
  int local;      // sweeps of a tile's own contacts a pass (0: the solver's order)
  int tile;       // the tiles' edge, in diameters
  // With local 0: -1 the solver's colour-major order; 0 every contact in
  // the order of its height (the midpoint of its spheres' centres, a wall
  // contact its sphere's), lowest first on even passes and last on odd
  // ones; b > 0 horizontal bands b diameters high, lowest first, each
  // band's contacts colour by colour (groups that share no sphere, as a
  // parallel sweep needs).
  int height_band = -1;
  // Over-relaxation: > 0, each sweep's change of the normal and tangential
  // impulses times omega before the clamps (their effective masses times
  // omega; with omega 1 the solver's bits); 0, the solver's masses.
  double omega = 0;
  // Nonsmooth nonlinear conjugate gradients over the solver's order: after
  // each sweep but the last, the impulses (and the bodies with them) take
  // beta times the last direction, beta the ratio of the last two sweeps'
  // squared changes (0 where it passes 1, a restart). 1: that step as a
  // pass of its own; 2: each contact's share of it taken in the sweep right
  // after the contact is solved, beta the ratio of the two sweeps before
  // (one pass a sweep, as a colour of a parallel sweep could: no two of its
  // contacts share a sphere). 3: as 1, but the step's bodies move by a
  // direction of their own (beta times it plus each sweep's change of their
  // velocities), so the step is a pass over the impulses and one over the
  // bodies, in any order (no colours); the direction then holds the rolling
  // impulses too.
  int nncg = 0;
  // beta above this cap is taken as the cap (past 1 still a restart).
  double beta_cap = 1;
  // Forms 1 and 3: no step before the last `tail` sweeps (with 1, only the
  // last sweep's; as many as the sweeps: the solver's sweeps).
  int tail = 1;
};
// The orders marbles_order_study compares.
std::vector<Order> default_orders();

struct Result {
  double p99 = 0, rms = 0;   // speeds left after the last substep, in units of g h
  double floor_ratio = 0;    // the floor's impulse over the weight's
  double ms = 0;             // per substep
  double between = 0;        // share of the contacts between tiles
  std::size_t tiles = 0;
  std::vector<Vec3> velocity;  // every sphere's after the last substep's solve
};
// `substeps` substeps of order `o` on the pile from impulses of 0.
Result run(const Order& o, Pile& pile, int substeps);

}  // namespace marbles::order_study
