// render/frame_output.cpp — see frame_output.hpp.
#include "render/frame_output.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <regex>
#include <utility>

#include "core/error.hpp"
#include "core/files.hpp"
#include "render/atomic_file.hpp"
#include "render/image.hpp"
#include "render/vtk_output.hpp"

namespace marbles::render {

namespace fs = std::filesystem;

namespace {

fs::path image_path(const fs::path& dir, std::size_t frame) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%06zu.png", frame);
  return dir / "images" / name;
}

void make_images_dir(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir / "images", ec);
  if (ec) throw RuntimeFailure("cannot create " + (dir / "images").string() + ": " + ec.message());
}

// "\rrender [##########..........]  12/40  0.31 s/frame  ETA 9 s"
void draw_progress(std::ostream& log, const char* what, std::size_t done, std::size_t total, double elapsed) {
  constexpr int kWidth = 30;
  const int filled = total ? int(kWidth * done / total) : kWidth;
  std::string bar(filled, '#');
  bar.append(kWidth - filled, '.');
  char tail[96];
  const double per = done ? elapsed / done : 0;
  std::snprintf(tail, sizeof tail, " %zu/%zu  %.2f s/frame  ETA %.0f s   ", done, total, per, per * (total - done));
  log << '\r' << what << " [" << bar << "]" << tail << std::flush;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

// ---- during a run ------------------------------------------------------------

FrameOutput::FrameOutput(std::string dir, RenderOptions options, MovieOptions movie, Walls walls, std::ostream& log)
    : m_dir(std::move(dir)),
      m_options(std::move(options)),
      m_movie_options(movie),
      m_walls(std::move(walls)),
      m_log(log) {
  make_images_dir(m_dir);
  m_renderer = std::make_unique<Renderer>(m_options);
  if (m_movie_options.enabled) {
    if (ffmpeg_available())
      m_movie = std::make_unique<MovieWriter>(m_dir / "movie.mp4", m_options.width, m_options.height,
                                              m_movie_options.fps, m_movie_options.crf);
    else
      m_log << "warning: ffmpeg is not on PATH: no movie.mp4, only PNG frames\n";
  }
  if (!png_available()) m_log << "warning: built without libpng: no PNG frames are written\n";
}

FrameOutput::~FrameOutput() {
  if (m_finished) return;
  try {
    finish();
  } catch (const std::exception& e) {
    m_log << "warning: " << e.what() << "\n";
  }
}

void FrameOutput::add(const Snapshot& snapshot) {
  if (!m_camera)
    m_camera = m_options.camera ? *m_options.camera
                                : default_camera(scene_bounds(snapshot, m_walls), m_options.width, m_options.height);
  ColorRange range = data_range(snapshot, m_options.color_by);
  if (m_range) range.add(*m_range);
  m_range = range;
  if (m_options.color_min) range.lo = *m_options.color_min;
  if (m_options.color_max) range.hi = *m_options.color_max;

  const Image image = m_renderer->render(snapshot, walls_at(m_walls, snapshot.time), *m_camera, range);
  if (png_available()) write_png(image_path(m_dir, m_frames), image);
  if (m_movie) {
    try {
      m_movie->add(image);
    } catch (const RuntimeFailure& e) {
      m_log << "warning: " << e.what() << "; continuing without a movie\n";
      m_movie.reset();
    }
  }
  ++m_frames;
}

void FrameOutput::finish() {
  if (m_finished) return;
  m_finished = true;
  if (m_movie) m_movie->finish();
}

// ---- after a run -------------------------------------------------------------

void write_material_names(const fs::path& dir, const std::vector<std::string>& names) {
  std::string text;
  for (const std::string& name : names) text += name + "\n";
  write_file_atomic(dir / "materials.txt", text);
}

std::vector<std::string> read_material_names(const fs::path& dir) {
  std::vector<std::string> names;
  if (!fs::exists(dir / "materials.txt")) return names;
  require_plain_file(dir / "materials.txt");
  std::ifstream in(dir / "materials.txt");
  for (std::string line; std::getline(in, line);) names.push_back(line);
  return names;
}

int render_output_dir(const std::string& out_dir, const RenderOptions& options, const MovieOptions& movie,
                      bool progress, std::ostream& log, const RunImages* as_run) {
  const fs::path dir(out_dir);
  const fs::path pvd = dir / "series.pvd";
  if (!fs::exists(pvd))
    throw InputError(SourceLocation{pvd.string(), 0, 0}, "",
                     "not found: `marbles render` draws the VTK frames of a finished run; run the scene with "
                     "VTK output (output.vtk.every) first");
  if (!renderer_available())
    throw RuntimeFailure("marbles was built without OSMesa (libosmesa6-dev): cannot render images");

  std::vector<SeriesEntry> entries = read_pvd(pvd);
  // The walls of each frame (moving walls move), from walls.pvd when the run had walls.
  std::vector<SeriesEntry> wall_entries;
  if (fs::exists(dir / "walls.pvd")) wall_entries = read_pvd(dir / "walls.pvd");
  if (as_run && as_run->stride > 1) {  // the frames at the images' cadence, with their walls
    std::vector<SeriesEntry> frames, walls;
    for (std::size_t k = 0; k < entries.size(); k += as_run->stride) {
      frames.push_back(entries[k]);
      if (!wall_entries.empty()) walls.push_back(wall_entries[std::min(k, wall_entries.size() - 1)]);
    }
    entries = std::move(frames);
    wall_entries = std::move(walls);
  }
  auto walls_of = [&](std::size_t k) {
    return wall_entries.empty() ? Walls{} : read_walls_vtp(wall_entries[std::min(k, wall_entries.size() - 1)].path);
  };
  RenderOptions with_names = options;
  if (with_names.material_names.empty()) with_names.material_names = read_material_names(dir);
  Renderer renderer(with_names);
  const auto t0 = std::chrono::steady_clock::now();

  // A frame without its spheres' radii cannot be drawn: said with its file.
  // Nor is a frame of another count of spheres than the series' first (a
  // frame of another run mixed in): every frame of a run holds its spheres.
  std::optional<std::pair<std::size_t, fs::path>> first;
  const auto read_frame = [&first](const fs::path& path) {
    Snapshot s = read_vtp(path);
    if (s.radius.size() != s.position.size())
      throw InputError(SourceLocation{path.string(), 0, 0}, "",
                       "has no radius array: images need the spheres' radii (the run's output.fields must list "
                       "radius)");
    if (!first) first.emplace(s.position.size(), path);
    if (s.position.size() != first->first)
      throw InputError(SourceLocation{path.string(), 0, 0}, "",
                       "holds " + std::to_string(s.position.size()) + " spheres where the series' first frame, " +
                           printable_path(first->second.string()) + ", holds " + std::to_string(first->first) +
                           ": every frame of a run holds its spheres (a frame of another run?)");
    return s;
  };

  // Pass 1 (only when needed): the view and colour range that suit every frame.
  Bounds bounds;
  ColorRange range{1e300, -1e300};
  const bool need_camera = !options.camera && !as_run;
  const bool need_range = !(options.color_min && options.color_max) && !as_run;
  if (need_camera || need_range) {
    for (std::size_t k = 0; k < entries.size(); ++k) {
      const Snapshot s = read_frame(entries[k].path);
      if (need_camera) bounds.add(scene_bounds(s, walls_of(k)));
      if (need_range) range.add(data_range(s, options.color_by));
      if (progress) draw_progress(log, "scan  ", k + 1, entries.size(), seconds_since(t0));
    }
    if (progress) log << "\n";
  }
  if (range.lo > range.hi) range = {0, 1};
  if (options.color_min) range.lo = *options.color_min;
  if (options.color_max) range.hi = *options.color_max;
  const Camera camera = options.camera ? *options.camera
                        : default_camera(as_run ? as_run->view : bounds, options.width, options.height);
  std::optional<ColorRange> so_far;  // as_run: the frames drawn so far

  double fps = movie.fps;
  if (fps <= 0) {
    fps = 30;
    if (entries.size() >= 2) {
      const double dt = (entries.back().time - entries.front().time) / double(entries.size() - 1);
      if (dt > 0 && 1 / dt >= 10 && 1 / dt <= 60) fps = 1 / dt;
    }
  }
  std::unique_ptr<MovieWriter> writer;
  if (movie.enabled) {
    if (ffmpeg_available())
      writer = std::make_unique<MovieWriter>(dir / "movie.mp4", options.width, options.height, fps, movie.crf);
    else
      log << "warning: ffmpeg is not on PATH: no movie.mp4, only PNG frames\n";
  }
  if (!png_available()) log << "warning: built without libpng: no PNG frames are written\n";
  make_images_dir(dir);

  // Pass 2: render. Images keep the frame numbers of the .vtp files.
  static const std::regex numbered(R"(frame_(\d+)\.vtp)");
  const auto t1 = std::chrono::steady_clock::now();
  std::vector<fs::path> drawn;
  for (std::size_t k = 0; k < entries.size(); ++k) {
    if (as_run && as_run->stopped)
      if (const int sig = as_run->stopped())
        throw RenderStopped(sig, "stopped at image " + std::to_string(k) + " of " + std::to_string(entries.size()));
    Snapshot s = read_frame(entries[k].path);
    if (k == 0 && !has_color_data(s, options.color_by))
      log << "warning: " << entries[k].path.filename().string() << " carries no "
          << color_data_name(options.color_by) << " array: colouring by " << color_by_name(options.color_by)
          << " draws every sphere in one colour (the run's output.fields lacks it)\n";
    if (s.time == 0 && entries[k].time != 0) s.time = entries[k].time;
    if (as_run) {
      ColorRange r = data_range(s, options.color_by);
      if (so_far) r.add(*so_far);
      so_far = r;
      if (options.color_min) r.lo = *options.color_min;
      if (options.color_max) r.hi = *options.color_max;
      range = r;
    }
    const Image image = renderer.render(s, walls_of(k), camera, range);
    std::size_t number = k;
    std::smatch m;
    const std::string name = entries[k].path.filename().string();
    if (!as_run && std::regex_match(name, m, numbered))
      if (const auto n = whole_number(m[1].str())) number = static_cast<std::size_t>(*n);  // (more digits: its place)
    if (png_available()) write_png(image_path(dir, number), image);
    drawn.push_back(image_path(dir, number).filename());
    if (writer) writer->add(image);
    if (progress) draw_progress(log, "render", k + 1, entries.size(), seconds_since(t1));
  }
  if (progress) log << "\n";
  if (writer) writer->finish();
  // Images of frames the series no longer names (an earlier render of a
  // longer series) would pass for this render's: removed, once it is whole.
  std::sort(drawn.begin(), drawn.end());
  std::vector<fs::path> stale;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir / "images", ec))
    if (entry.path().filename().string().rfind("frame_", 0) == 0 && entry.path().extension() == ".png" &&
        !std::binary_search(drawn.begin(), drawn.end(), entry.path().filename()))
      stale.push_back(entry.path());
  for (const fs::path& image : stale) fs::remove(image, ec);
  if (!stale.empty()) log << "removed " << stale.size() << " image(s) of frames the series no longer names\n";

  const double total = seconds_since(t1);
  char line[256];
  std::snprintf(line, sizeof line, "rendered %zu frames (%dx%d) in %.1f s (%.2f s/frame)", entries.size(),
                options.width, options.height, total, total / double(entries.size()));
  log << line << " to " << (dir / "images").string();
  if (writer) {
    std::snprintf(line, sizeof line, "%.3g", fps);
    log << "; movie " << (dir / "movie.mp4").string() << " at " << line << " fps";
  }
  log << "\n";
  return 0;
}

}  // namespace marbles::render
