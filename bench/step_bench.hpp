// bench/step_bench.hpp — time one full step (forces, broad phase, contacts,
// solver, integration) of one of two scenes in a box:
//
//   gas   a jittered lattice at volume fraction 0.1 with random velocities
//         (few contacts: the cost of the step's fixed stages);
//   pile  a dense settled pile of spheres of r = 1 cm, about 30 layers deep,
//         friction 0.5, rolling friction 0.05, restitution 0.3, 10 solver
//         iterations, dt 1 ms, one substep, gravity: an fcc stack, every
//         sphere touching 6 in its layer, 3 below and 3 above (about 5.5
//         contacts per sphere, each pair counted once);
//   settle  the same spheres and box, 25 layers on a looser lattice (in-plane
//         spacing 2.02 r), friction 0.5, no rolling resistance, stepped from
//         the lattice (not cached): the steps after the warm-up (40 by
//         default) are the dense phase, when the in-plane gaps have closed.
//
// The pile is made once per N: a loose ABC-stacked lattice, in-plane spacing
// 2.004 r, each layer 0.003 r above resting on the one below, with a small
// horizontal jitter, stepped on the benchmark's backend (velocities zeroed
// every few steps) until the kinetic energy per sphere is small or the step
// budget is spent, then saved to <cache>/pile-v<version>-n<N>-<precision>.bin
// and reloaded by later runs, which time only steps. The file holds no
// warm-start impulses: the first steps after loading rebuild them (the pile
// moves by a few cm/s for some tens of steps; the contacts stay the same).
#pragma once

#include <cstddef>
#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/world.hpp"

namespace marbles::bench {

struct StepBenchOptions {
  std::string backend = "cpu";       // cpu | cuda (the step backend)
  std::string scene = "gas";         // gas | pile | settle
  std::vector<std::size_t> n{10000, 100000, 1000000};
  int repeats = 10;                  // timed steps per size (after the warm-up steps), and as many profiled ones
  int warmup = -1;                   // untimed steps first; < 0: 2 (gas), 5 (pile: warm starts rebuilt) or 40 (settle)
  bool json = false;                 // JSON only on stdout (progress on stderr)
  std::vector<std::string> effects{"gravity", "collisions", "walls", "restitution"};  // gas only
  std::string cache_dir;             // pile cache; empty: $XDG_CACHE_HOME/marbles or ~/.cache/marbles
  int settle_steps = 8000;           // pile: step budget of the settle (a pile that rests stops sooner)
  double settle_ke = 1e-8;           // pile: a settled pile's bound of the kinetic energy per sphere (J)
  int settle_quench = 10;            // pile: zero the velocities every this many steps until first below it (0: never)
  bool rebuild = false;              // pile: settle again even when a cached pile is there
  // The spheres' index order the steps see (a study of memory locality):
  // made (as generated or settled: rows of the lattice), shuffled (a
  // random permutation, seed 1: the order a long pour drifts towards), or
  // morton (along a Z curve of cells two largest radii wide) or cells (by
  // the home-cell broad phase's cell key for these spheres, rows of x, then
  // y, then z: nearly the order of the pairs it finds).
  std::string sphere_order = "made";
  // solver.renumber of the timed scene (0: never; a numbering at the start
  // of the first warm-up step and every this many steps after).
  int renumber = 0;
  // solver.integrator of the timed steps (the pile settles as cached):
  // symplectic_euler (the scenes' own) or velocity_verlet, whose closing
  // solve the verb breakdown times apart (close_velocities).
  std::string integrator = "symplectic_euler";
  // pile: rolling resistance (rolling friction 0.05) on, or off (friction
  // only; settled and cached apart).
  bool rolling = true;
  // pile: friction (0.5) on, or off (then rolling off too: a frictionless
  // pile, settled and cached apart).
  bool friction = true;
  // The run's watchdog (marbles run keeps it on) in every step the
  // benchmark times, counts or profiles (not the pile's settle): the state
  // kept at each step's start and the watch's figures (kinetic energy,
  // spheres past a wall) read with the step's flags; what that safety costs.
  bool watchdog = false;
  // Not empty: each N's scene written to this folder as files
  // (write_bench_scene), nothing timed.
  std::string write_scene;
};

// The world with its spheres in the order StepBenchOptions::sphere_order
// names (made: unchanged). Throws InputError naming --sphere-order for
// another name.
World in_sphere_order(World world, const std::string& how);

// The pile cache's file for N spheres (version and precision in the name).
std::string pile_cache_path(const std::string& cache_dir, std::size_t n, bool rolling = true, bool friction = true);

int run_step_bench(const StepBenchOptions& options, std::ostream& out);

// The scene and the world `bench step` times for N spheres (before
// --sphere-order): the settling lattice (settle), the gas (gas, with
// options.effects) or the settled pile (pile: loaded from the cache, or
// settled on options.backend and saved there first; progress on `log`).
std::pair<scene::Scene, World> bench_start(const StepBenchOptions& options, std::size_t n, std::ostream& log);

// That start as files to run (`marbles run`), look at or time with another
// build: DIR/bench-SCENE-nN.yaml (format 1: time, solver iterations,
// effects, gravity, drag, the material, the box; the pile without rolling
// resistance bench-pile-friction-nN, without friction
// bench-pile-frictionless-nN) and its .csv of spheres (x, y, z, r, vx, vy,
// vz, and wx, wy, wz where a sphere spins; every value in the fewest digits
// that read back to the same bits), the duration the warm-up and timed
// steps. The pile's warm-start impulses are not in a scene file, nor in the
// pile's cache: its timed steps start without them either way. Each file is
// written under a temporary name and renamed. Returns the YAML's path.
std::string write_bench_scene(const StepBenchOptions& options, std::size_t n, const std::string& dir,
                              std::ostream& log);

// The cost of each effect: the same dense gas stepped with collisions and
// walls only, then with each effect added, then with all of them.
struct EffectsBenchOptions {
  std::string backend = "cpu";
  std::size_t n = 20000;
  double volume_fraction = 0.4;
  int repeats = 20;
  bool json = false;
};

int run_effects_bench(const EffectsBenchOptions& options, std::ostream& out);

}  // namespace marbles::bench
