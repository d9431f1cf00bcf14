// sim/run.hpp — the verbs of the command line that run or inspect a scene.
//
// Data flows one way: scene file → Scene → GeneratedParticles → World →
// Simulation::step() → output (VTK frames, images, summary.json).
#pragma once

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "broadphase/broadphase.hpp"
#include "sim/particles.hpp"
#include "sim/scene.hpp"
#include "sim/simulation.hpp"
#include "sim/step_model.hpp"
#include "sim/world.hpp"

namespace marbles {

// A JSON document as marbles writes it (summary.json, bench --json): two
// spaces of indent, keys in the order given, non-finite numbers as null,
// bytes that are not UTF-8 replaced; ends with a newline.
std::string json_text(const nlohmann::ordered_json& document);

enum class BackendChoice { automatic, cpu, cuda };

// Resolves auto/cpu/cuda to a backend; says on `log` what auto chose and why.
// `cuda` without a device (or without the CUDA build) throws RuntimeFailure.
broadphase::Backend select_backend(BackendChoice choice, std::ostream& log);

// What `marbles check` holds a scene to, without a word: the scene with its
// overrides, its particles, its world (masses in range for the precision)
// and its reference's own rules; throws InputError.
struct CheckedScene {
  scene::Scene scene;
  scene::GeneratedParticles particles;
  World world;
};
CheckedScene checked_scene(const std::string& scene_path, const std::vector<std::string>& overrides);

// The warnings `run` and `check` give where spheres start overlapping each
// other or a wall by more than 1 % of the smaller radius (a measure of the
// start past kStartOverlapTolerance; without "warning: "); none where none do.
std::vector<std::string> initial_overlap_warnings(const StateOverlaps& start);

struct RunOptions {
  std::string scene_path;
  std::optional<std::string> out_dir;  // overrides output.dir
  BackendChoice backend = BackendChoice::automatic;
  broadphase::Algorithm algorithm = broadphase::kDefaultCpuAlgorithm;  // seed | home
  bool quiet = false;
  bool render = true;                  // false: skip images and movie even if the scene asks
  std::optional<double> duration;      // overrides time.duration
  std::vector<std::string> overrides;  // --set key.path=value, applied to the scene in order
  std::optional<std::string> restart;  // a checkpoint to resume from
  bool summary_only = false;           // write only summary.json (no frames, images or movie)
  bool overwrite = false;              // replace an earlier run's output in the folder (else refused)
  int threads = 0;                     // CPU threads (0: OpenMP's default, OMP_NUM_THREADS or every core)
  std::vector<std::string> limits;     // --limit NAME=VALUE as given (raised already), for the resume command
  std::string command_line;            // as typed, for summary.json
};

// `marbles run`. Returns the process exit code; throws InputError for scene
// problems and RuntimeFailure for failures while running.
int run_scene(const RunOptions& options, std::ostream& out, std::ostream& err);

// `marbles check`: loads (with the `--set` overrides), validates and
// generates the particles without running; prints a one-line summary, and
// with `pipeline` (--pipeline) the stages a CPU run of it would build.
int check_scene(const std::string& scene_path, const std::vector<std::string>& overrides, std::ostream& out,
                std::ostream& err, bool pipeline = false);

// `marbles pairs`: prints the overlapping pairs "i j" (i < j, sorted) of the
// spheres in a CSV of x,y,z,r rows. `algorithm`: subdivision (the seed's
// spatial subdivision), home (its home-cell variant) or brute (the oracle).
int print_pairs(const std::string& csv_path, const std::string& algorithm, BackendChoice backend, double margin,
                std::ostream& out, std::ostream& err);

}  // namespace marbles
