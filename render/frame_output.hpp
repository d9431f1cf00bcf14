// render/frame_output.hpp — images and a movie, during a run or afterwards.
//
// During a run the simulation owns a FrameOutput and hands it a snapshot
// whenever a frame is due; afterwards `marbles render OUTDIR` calls
// render_output_dir(), which re-renders every frame listed in
// OUTDIR/series.pvd (with the walls of OUTDIR/walls.pvd, if present).
//
//   DIR/images/frame_000123.png   one per frame, written atomically
//   DIR/movie.mp4                 H.264, yuv420p, when ffmpeg is on PATH
#pragma once

#include <filesystem>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "core/walls.hpp"
#include "render/movie.hpp"
#include "render/renderer.hpp"
#include "render/snapshot.hpp"

namespace marbles::render {

/// Renders the frames of a running simulation.
///
/// The camera is fixed at the first frame (the options' camera, or the
/// default view of the first snapshot and the walls). Without fixed colour
/// limits the colour range is the union of the ranges of all frames so far
/// (it only widens, so colours never jump back). Missing ffmpeg or libpng
/// produce one warning on `log`, not an error.
class FrameOutput {
 public:
  /// Creates DIR/images and the renderer. Throws marbles::RuntimeFailure when
  /// rendering is unavailable (built without OSMesa) or the folder cannot be
  /// made; the caller may turn that into a warning and run on without images.
  FrameOutput(std::string dir, RenderOptions options, MovieOptions movie, Walls walls, std::ostream& log = std::cerr);
  ~FrameOutput();
  FrameOutput(const FrameOutput&) = delete;
  FrameOutput& operator=(const FrameOutput&) = delete;

  /// Renders `snapshot` to DIR/images/frame_NNNNNN.png (NNNNNN = 0, 1, 2, ...
  /// in call order, matching VtkSeriesWriter's numbering when both start
  /// together) and appends it to the movie. Throws marbles::RuntimeFailure on
  /// I/O errors.
  void add(const Snapshot& snapshot);

  /// Finishes DIR/movie.mp4. Throws marbles::RuntimeFailure when ffmpeg
  /// failed. Called by the destructor if not called (errors then go to log).
  void finish();

  std::size_t frames() const { return m_frames; }
  /// The camera in use (set by the first frame).
  const std::optional<Camera>& camera() const { return m_camera; }

 private:
  std::filesystem::path m_dir;
  RenderOptions m_options;
  MovieOptions m_movie_options;
  Walls m_walls;
  std::ostream& m_log;
  std::unique_ptr<Renderer> m_renderer;
  std::unique_ptr<MovieWriter> m_movie;
  std::optional<Camera> m_camera;
  std::optional<ColorRange> m_range;
  std::size_t m_frames = 0;
  bool m_finished = false;
  bool m_png_warned = false;
};

/// DIR/materials.txt: the scene's material names, one a line in id order,
/// written at the start of a run (atomically) so that `marbles render` can
/// label the colour-by-material legend. Reading a missing file gives none.
void write_material_names(const std::filesystem::path& dir, const std::vector<std::string>& names);
std::vector<std::string> read_material_names(const std::filesystem::path& dir);

/// Re-renders every frame of OUT_DIR/series.pvd into OUT_DIR/images and
/// OUT_DIR/movie.mp4 (for `marbles render OUTDIR`).
///
/// Walls come from OUT_DIR/walls.pvd when present (frame k, the walls' k-th). Without a camera in
/// `options`, the view frames everything any frame contains; without fixed
/// colour limits, the colour range spans all frames (both found in a first
/// pass over the frames). `movie.fps <= 0` derives the rate from the frame
/// times (real time when that gives 10..60 fps, else 30). With `progress`, a
/// one-line progress bar is redrawn on `log` (pass true only for a terminal);
/// otherwise only a summary line is printed. Returns 0 on success. Throws
/// marbles::RuntimeFailure when there is no series.pvd, when the build lacks
/// VTK or OSMesa, or on I/O errors; a missing ffmpeg is only a warning.
///
/// With `as_run`, the images are those the run itself would have drawn as
/// it went (FrameOutput), for a resumed run's closing render: every
/// `stride`-th frame of the series (the images' cadence over the frames'),
/// numbered 0, 1, 2, ... as FrameOutput numbers them, seen by the camera of
/// the run's first view (`view`: the scene's bounds at step 0, unless
/// `options` has a camera), each coloured over the range of the frames drawn
/// so far (it only widens, as FrameOutput's does).
/// `stopped`, where given, is asked before each frame: a signal number
/// (SIGINT, SIGTERM) ends the render there with RenderStopped.
struct RunImages {
  std::size_t stride = 1;
  Bounds view;
  std::function<int()> stopped;
};
/// A closing render ended by a stop request (RunImages::stopped).
struct RenderStopped : RuntimeFailure {
  RenderStopped(int sig, const std::string& what) : RuntimeFailure(what), signal(sig) {}
  int signal;
};
int render_output_dir(const std::string& out_dir, const RenderOptions& options, const MovieOptions& movie,
                      bool progress, std::ostream& log, const RunImages* as_run = nullptr);

}  // namespace marbles::render
