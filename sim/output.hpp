// sim/output.hpp — what a run writes, and when: VTK frames + series.pvd,
// rendered images + movie, all from host snapshots taken only when due.
#pragma once

#include <iosfwd>
#include <memory>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/walls.hpp"
#include "render/camera.hpp"
#include "render/snapshot.hpp"
#include "render/vtk_output.hpp"

namespace marbles {

namespace scene {
struct Scene;
struct OutputSpec;
}
class Simulation;
struct World;

// The frames' metadata of a scene's run: its material names and the producer.
render::FrameMetadata frame_metadata(const scene::Scene& scene);

// `with_contacts`: also count each sphere's pressing contacts (the
// `contacts` field; on the GPU this downloads the contacts).
render::Snapshot make_snapshot(const Simulation& sim, bool with_contacts = false);
// The pressing contacts of the last substep, with forces = impulses / substep.
render::ContactSnapshot make_contact_snapshot(const Simulation& sim);

// The files of an earlier run in `dir` (what a run writes: summary.json,
// series.pvd, contacts.pvd, walls.pvd, thermo.csv, an old walls.json, materials.txt, movie.mp4, frames/frame_*.vtp,
// images/frame_*.png, checkpoints/step_*.mck, contacts/contacts_*.vtp); other files are not ours.
std::vector<std::filesystem::path> earlier_run_files(const std::filesystem::path& dir);
// The files in `dir` that a run resumed there at `step` replaces: `later`,
// those of later steps (frames, wall and contact frames, images,
// checkpoints, by the cadences of `output`: an every of 0 leaves that kind
// alone), summary.json and movie.mp4 (the whole earlier run's);
// `rewritten`, the series and thermo.csv, written again from their entries
// up to the step.
struct ReplacedFiles {
  std::vector<std::filesystem::path> later, rewritten;
};
// `kept_to` (>= step): the numbered files of the series and images past it
// are replaced; those between `step` and it stay (a `--summary-only` resume,
// which writes none of them: its folder then holds the earlier run's files
// up to its own end and none past it).
ReplacedFiles run_files_past(const std::filesystem::path& dir, std::uint64_t step, const scene::OutputSpec& output,
                             std::uint64_t kept_to);
// The listings in `dir` cut to what a run of `step` steps lists: series.pvd,
// walls.pvd and contacts.pvd to the files numbered up to `step` by their
// cadences in `output`, thermo.csv to its rows up to `step`; each rewritten
// (atomically) only where it lists more. A resume in its run's folder cuts
// them before it sets the files past its step aside, so that no listing
// names a file that is gone, whenever the process dies.
void cut_listings(const std::filesystem::path& dir, std::uint64_t step, const scene::OutputSpec& output);
// "DIR holds the output of an earlier run (N files, e.g. NAME)": a refusal's
// first words, its remedy the caller's (`files` not empty).
std::string earlier_run_text(const std::string& dir, const std::vector<std::filesystem::path>& files);

// One command at a time writing in an output folder (run, study, render):
// DIR/.marbles-run.lock, locked (flock) from before the check for an
// earlier run to the command's end, then removed; another command into the
// folder meanwhile is refused (InputError naming `option` and the process
// that holds it). The system lets go of the lock however the process ends.
// The folders it made are removed again where the command leaves them
// empty (refused before writing anything).
class RunFolderLock {
 public:
  RunFolderLock(const std::filesystem::path& dir, const std::string& option);
  ~RunFolderLock();
  RunFolderLock(const RunFolderLock&) = delete;
  RunFolderLock& operator=(const RunFolderLock&) = delete;

 private:
  std::filesystem::path m_path;
  std::vector<std::filesystem::path> m_made;  // the folders it made, the deepest first
  int m_fd = -1;
};

// `run --overwrite` (or a resume in its run's folder, run_files_past): the
// earlier run's files `moved` (by their paths below `dir`) into a folder of
// this process's, DIR/.earlier-run-PID (.2, .3 where one of that number
// lies there), with copies of the files `copied` (those the new run writes
// again from their rows, a resume's series and thermo.csv), while the new
// run runs, so that a run that fails, or a process that dies, loses
// nothing. Where a file cannot be moved, those moved are put back and
// RuntimeFailure says so. `discard()` once the new run stands (ended, or
// stopped with its checkpoint) removes them; otherwise they stay whole there
// and the destructor says where on `log`. Such folders of processes that
// ended are named on `log` at the start.
class EarlierRunAside {
 public:
  // `before_moving` runs once the copies are made, before the first move.
  EarlierRunAside(const std::filesystem::path& dir, const std::vector<std::filesystem::path>& moved,
                  const std::vector<std::filesystem::path>& copied, std::ostream& log,
                  const std::function<void()>& before_moving = {});
  ~EarlierRunAside();
  EarlierRunAside(const EarlierRunAside&) = delete;
  EarlierRunAside& operator=(const EarlierRunAside&) = delete;
  void discard();
  // Where nothing took their places (a series whose first frame failed),
  // the files go back where they were; those that cannot stay aside, and
  // the destructor says where.
  void put_back();

 private:
  // The moved files back where they were (those whose place is free); all of them?
  bool move_back();

  std::filesystem::path m_folder;  // empty: nothing set aside
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> m_moved;  // from, to
  std::ostream& m_log;
};

// summary.json's figures of the world at a run's end beside
// kinetic_energy_end (World::motion), named as the summary names them; the
// Python module's summary() gives the same.
struct EndFigure {
  const char* name;
  double value;
};
std::vector<EndFigure> end_figures(const World& world);

// OUTDIR/thermo.csv, one row per output frame (VTK or image):
//   step,t,ke_translational,ke_rotational,potential_energy,contacts,max_overlap,max_speed,ms_per_step
// J for energies (potential: of gravity, zero at the origin), contacts per
// substep of the last step, max_overlap in radii of the smaller sphere, m/s,
// ms per step since the row before.
inline constexpr const char* kThermoHeader =
    "step,t,ke_translational,ke_rotational,potential_energy,contacts,max_overlap,max_speed,ms_per_step";

class RunOutput {
 public:
  // Creates `dir`; `render` false skips images and movie. A run resumed from
  // a checkpoint (`resumed`) renders its images and movie at finish() from
  // every frame of the series, as `marbles render DIR` does, so the camera
  // and colour range span the whole run.
  // `view`: the bounds the walls' drawing is sized to (planes as squares
  // across it): the scene at its start, so a resumed run draws the same.
  RunOutput(const scene::Scene& scene, const std::string& dir, const Walls& walls, bool render, std::ostream& log,
            bool resumed = false, const render::Bounds* view = nullptr);

  // True when the step just completed (or step 0) has output due.
  bool due(std::uint64_t step) const;
  // Writes what is due for sim.steps(): frames, images and a row of
  // thermo.csv; `step_seconds` is the wall time of the steps so far (this
  // process), for the row's ms per step.
  void write(const Simulation& sim, double step_seconds = 0);
  // A run resumed at `steps`: the frames due up to it count as written, and
  // thermo.csv keeps its rows up to it.
  // `from`: the folder of the run that wrote the checkpoint, whose frames,
  // contact and wall frames and thermo rows up to `steps` are copied where
  // this folder lacks them (a run resumed elsewhere is whole too).
  void resume(std::uint64_t steps, double dt, const std::filesystem::path& from);
  // A resumed run's closing render (finish) asks `stopped` before each
  // image: a signal number ends it there (its images left as they are,
  // a warning) and finish() returns; stopped_render() then says which.
  void stop_render_when(std::function<int()> stopped);
  int stopped_render() const;
  // True where the closing render failed (a full disk, say; a warning):
  // the run then keeps what it replaced of the earlier run's images.
  bool render_failed() const;
  // Writes the listings (series.pvd, walls.pvd, contacts.pvd, thermo.csv)
  // where they lag behind what was written (render::Relisting: while a run
  // goes on they are rewritten once a sixteenth of them, or a second, is
  // new); a checkpoint's step, the end and a stop have them whole.
  void flush();
  // Closes the movie (a resumed run: renders images and movie from the
  // frames); returns a short description of what was written.
  std::string finish();
  // Flushes (best effort: a run that fails keeps the listings it wrote).
  ~RunOutput();

 private:
  struct Impl;
  std::unique_ptr<Impl> m;
};

}  // namespace marbles
