// sim/checkpoint.hpp — a run's state on disk, to resume it bit for bit.
//
// A checkpoint holds everything the rest of a run depends on: the world in
// the run's precision, the step count (time = steps x dt), the warm-start
// cache and the walls as they have moved (StepState), the running totals of
// summary.json and the reference probe's progress. Written under a temporary
// name and renamed (kill -9 at any moment leaves the last complete one);
// refused with a clear message when it belongs to another scene, precision or
// format. The byte layout is in docs/checkpoints.md.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "sim/step_backend.hpp"
#include "sim/world.hpp"

namespace marbles {

// The running totals behind summary.json.
struct RunTotals {
  double candidate_sum = 0;  // candidate pairs per substep, summed over steps
  double contact_sum = 0;    // contacts per substep, summed over steps
  double deepest = 0;        // largest overlap at the end of any step (of the smaller radius)
  double energy_start = 0;   // kinetic energy at step 0, J
  double overlap_end = 0;    // the last step's largest overlap
  double rollbacks = 0;      // steps the watchdog redid
  double unswept = 0;        // steps kept with the unswept rule failing at the last retry (format 4)

  // Adds a step: its counters (of `substeps` substeps), the rollbacks it
  // took, and whether it was kept unswept (Simulation::last_kept).
  void add(const StepCounters& last, int substeps, std::size_t step_rollbacks, bool kept_unswept = false) {
    unswept += kept_unswept ? 1 : 0;
    candidate_sum += static_cast<double>(last.candidate_pairs) / substeps;
    contact_sum += static_cast<double>(last.contacts) / substeps;
    deepest = deepest > static_cast<double>(last.max_overlap) ? deepest : static_cast<double>(last.max_overlap);
    overlap_end = last.max_overlap;
    rollbacks += static_cast<double>(step_rollbacks);
  }
};

struct Checkpoint {
  std::uint64_t scene_hash = 0;  // Scene::fingerprint of the run that wrote it
  std::uint64_t steps = 0;
  World world;
  StepState state;
  RunTotals totals;
  std::vector<double> probe;     // ReferenceProbe::progress()
  std::vector<std::uint32_t> ids;  // Simulation::ids(): the step's numbering (empty: the scene's)
};

// What a checkpoint must match is Scene::fingerprint: the scene as read, its
// overrides applied (not --duration or --out: a resumed run may run longer,
// elsewhere). Checkpoints written before it hold the fingerprint of the
// texts, the scene file's bytes and each --set text, which these make.
std::uint64_t scene_fingerprint(const std::string& scene_path, const std::vector<std::string>& overrides);
// The same of a scene's text (a scene given as JSON).
std::uint64_t text_fingerprint(const std::string& text, const std::vector<std::string>& overrides);

// Writes atomically, making the folder it goes in; throws RuntimeFailure on
// I/O errors. checkpoint_bytes is the file's text (written beside another
// file with render::write_files_atomic); make_parent_folder makes a path's
// folder where it has one.
void write_checkpoint(const std::string& path, const Checkpoint& checkpoint);
std::string checkpoint_bytes(const Checkpoint& checkpoint);
void make_parent_folder(const std::string& path);

// Reads and checks (format, precision, scene, completeness); throws
// InputError naming the file and what does not match. Its scene is
// `scene_hash` (Scene::fingerprint) or, where given, `text_hash` (an
// earlier checkpoint's: scene_fingerprint, text_fingerprint).
Checkpoint read_checkpoint(const std::string& path, std::uint64_t scene_hash,
                           std::optional<std::uint64_t> text_hash = std::nullopt);

// Whether a checkpoint read for a scene fits it: as many spheres as the
// scene makes, each of a material the scene has, and the scene's walls (its
// `walls`: the step model's shapes at t = 0), each as the scene makes it but
// for the point a moving wall has moved. Throws InputError naming the file
// and `key` (the argument that gave it) where not.
// `scene` is the world the scene makes (or the simulation's now, `ids` its
// numbering): each sphere of the checkpoint is of its sphere's material and
// fixed where it is (a run changes neither).
void check_checkpoint_fits(const Checkpoint& checkpoint, const std::string& path, const std::string& key,
                           const World& scene, const std::vector<std::uint32_t>& ids, std::size_t materials,
                           const std::vector<narrowphase::WallShape>& walls);

// "double" or "float": the precision a checkpoint was written in ("float"
// when the file is not one; read_checkpoint then says why).
std::string checkpoint_precision(const std::string& path);

// OUTDIR/checkpoints/step_000123.mck
std::string checkpoint_path(const std::string& out_dir, std::uint64_t steps);

// Removes all but the newest `keep` checkpoints of OUTDIR/checkpoints.
void prune_checkpoints(const std::string& out_dir, int keep);

}  // namespace marbles
