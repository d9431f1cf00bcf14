#include "sim/output.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <optional>
#include <ostream>
#include <sstream>

#include "core/error.hpp"
#include "core/files.hpp"
#include "core/format.hpp"
#include "narrowphase/contacts.hpp"
#include "render/atomic_file.hpp"
#include "render/frame_output.hpp"
#include "render/renderer.hpp"
#include "render/vtk_output.hpp"
#include "sim/scene.hpp"
#include "sim/signals.hpp"
#include "sim/simulation.hpp"
#include "sim/version.hpp"

namespace marbles {

namespace {

// A contact that presses: it carries an impulse or its spheres overlap (not
// a speculative contact whose gap stayed open).
bool presses(const narrowphase::Contact& c) {
  return c.normal_impulse + c.impact_impulse > 0 || c.separation < 0;
}

}  // namespace

render::FrameMetadata frame_metadata(const scene::Scene& scene) {
  render::FrameMetadata metadata;
  for (const scene::Material& m : scene.materials) metadata.material_names.push_back(m.name);
  metadata.producer = std::string("marbles ") + kMarblesVersion + " (commit " + kMarblesCommit + ")";
  return metadata;
}

render::ContactSnapshot make_contact_snapshot(const Simulation& sim) {
  const World& w = sim.world();
  const auto& shapes = sim.model().wall_shapes;
  const std::vector<std::uint32_t> owners = narrowphase::wall_shape_owners(sim.model().walls);
  const double h = sim.dt() / sim.substeps();  // the contacts are the last substep's
  render::ContactSnapshot c;
  c.time = sim.time();
  c.step = sim.steps();
  for (const narrowphase::Contact& k : sim.contacts()) {
    if (!presses(k)) continue;
    const bool wall = narrowphase::is_wall(k.b);
    const std::uint32_t b = wall ? (k.b & ~narrowphase::kWallFlag) : k.b;
    c.a.push_back(w.position[k.a]);
    // The wall end: the contact point on the wall's surface.
    c.b.push_back(wall ? w.position[k.a] - k.normal * (w.radius[k.a] + k.separation) : w.position[b]);
    c.normal.push_back(k.normal);
    c.normal_force.push_back((double(k.normal_impulse) + double(k.impact_impulse)) / h);
    c.tangential_force.push_back({double(k.tangent_impulse.x) / h, double(k.tangent_impulse.y) / h,
                                  double(k.tangent_impulse.z) / h});
    c.overlap.push_back(k.separation < 0 ? -k.separation : real(0));
    c.sphere_a.push_back(k.a);
    c.sphere_b.push_back(wall ? owners.at(b) : b);  // a wall by its place in the scene
    c.material_a.push_back(w.material[k.a]);
    c.material_b.push_back(wall ? shapes.at(b).material : w.material[b]);
    c.wall.push_back(wall ? 1 : 0);
  }
  return c;
}

render::Snapshot make_snapshot(const Simulation& sim, bool with_contacts) {
  const World& w = sim.world();
  render::Snapshot s;
  if (with_contacts) {
    s.contacts.assign(w.size(), 0);
    for (const narrowphase::Contact& k : sim.contacts()) {
      if (!presses(k)) continue;
      ++s.contacts[k.a];
      if (!narrowphase::is_wall(k.b)) ++s.contacts[k.b];
    }
  }
  s.time = sim.time();
  s.step = sim.steps();
  s.position = w.position;
  s.velocity = w.velocity;
  s.angular_velocity = w.angular_velocity;
  s.radius = w.radius;
  s.material = w.material;
  s.id.resize(w.size());
  for (std::size_t i = 0; i < w.size(); ++i) s.id[i] = static_cast<std::uint32_t>(i);
  return s;
}

namespace {

// The folders of a run's numbered files (beside the files at its top).
struct Numbered {
  const char* folder;
  const char* prefix;
  const char* extension;
};
constexpr Numbered kNumbered[] = {{"frames", "frame_", ".vtp"},
                                  {"images", "frame_", ".png"},
                                  {"checkpoints", "step_", ".mck"},
                                  {"contacts", "contacts_", ".vtp"},
                                  {"walls", "walls_", ".vtp"}};
constexpr const Numbered& kFrames = kNumbered[0];
constexpr const Numbered& kContacts = kNumbered[3];
constexpr const Numbered& kWalls = kNumbered[4];

// The number of a file named PREFIX + digits + EXTENSION of `n`; none for another name.
std::optional<std::uint64_t> number_of(std::string_view name, const Numbered& n) {
  if (!name.starts_with(n.prefix) || !name.ends_with(n.extension)) return std::nullopt;
  const std::size_t prefix = std::strlen(n.prefix), digits = name.size() - prefix - std::strlen(n.extension);
  return whole_number(name.substr(prefix, digits));
}

// A thermo.csv row of a step up to `step` (a row of digits first, its step).
bool thermo_row_up_to(const std::string& line, std::uint64_t step) {
  return !line.empty() && std::isdigit(static_cast<unsigned char>(line[0])) &&
         std::strtoull(line.c_str(), nullptr, 10) <= step;
}

}  // namespace

namespace {

// The files of a run's in `dir`: those at its top named in `top`, and the
// numbered ones (kNumbered: PREFIX + digits + EXTENSION) for which
// `take(folder, number)` holds.
template <class Take>
std::vector<std::filesystem::path> run_files(const std::filesystem::path& dir, std::initializer_list<const char*> top,
                                             Take take) {
  namespace fs = std::filesystem;
  std::vector<fs::path> found;
  std::error_code ec;
  for (const char* name : top)
    if (fs::is_regular_file(dir / name, ec)) found.push_back(dir / name);
  for (const Numbered& n : kNumbered) {
    if (!fs::is_directory(dir / n.folder, ec)) continue;
    for (const auto& entry : fs::directory_iterator(dir / n.folder, ec)) {
      if (!entry.is_regular_file(ec)) continue;
      const auto number = number_of(entry.path().filename().string(), n);
      if (number && take(std::string_view(n.folder), *number)) found.push_back(entry.path());
    }
  }
  return found;
}

}  // namespace

std::vector<std::filesystem::path> earlier_run_files(const std::filesystem::path& dir) {
  return run_files(dir,
                   {"summary.json", "series.pvd", "contacts.pvd", "walls.pvd", "thermo.csv", "walls.json",
                    "materials.txt", "movie.mp4"},
                   [](std::string_view, std::uint64_t) { return true; });
}

ReplacedFiles run_files_past(const std::filesystem::path& dir, std::uint64_t step, const scene::OutputSpec& output,
                             std::uint64_t kept_to) {
  const auto none = [](std::string_view, std::uint64_t) { return false; };
  return {run_files(dir, {"summary.json", "movie.mp4"},
                    [&](std::string_view folder, std::uint64_t number) {
                      if (folder == "checkpoints") return number > step;  // numbered by their step
                      const int every = folder == "contacts" ? output.contacts_every
                                        : folder == "images" ? (output.render.enabled ? output.render.every : 0)
                                                             : output.vtk_every;  // frames, walls
                      return every > 0 && number > kept_to / static_cast<std::uint64_t>(every);
                    }),
          run_files(dir, {"series.pvd", "walls.pvd", "contacts.pvd", "thermo.csv"}, none)};
}

void cut_listings(const std::filesystem::path& dir, std::uint64_t step, const scene::OutputSpec& output) {
  namespace fs = std::filesystem;
  std::error_code ec;
  // Each line kept where `keep` takes it; the file rewritten where one is not.
  const auto cut = [&](const fs::path& path, const auto& keep) {
    if (!fs::is_regular_file(path, ec)) return;
    std::ifstream file(path, std::ios::binary);
    std::stringstream text;
    text << file.rdbuf();
    if (!file) throw RuntimeFailure("cannot read " + path.string());
    std::istringstream in(text.str());
    std::string kept, line;
    bool dropped = false;
    while (std::getline(in, line)) {
      if (keep(line)) kept += line + "\n";
      else dropped = true;
    }
    if (dropped) render::write_file_atomic(path, kept);
  };
  // A .pvd's DataSet line names FOLDER/PREFIXnnnnnn.vtp: numbered past step / every, it goes.
  const auto series = [&](const char* pvd, const Numbered& n, int every) {
    if (every <= 0) return;
    cut(dir / pvd, [&](const std::string& line) {
      const std::size_t from = line.find("file=\""), to = line.find('"', from + 6);
      if (line.find("<DataSet") == std::string::npos || from == std::string::npos || to == std::string::npos)
        return true;
      const auto number = number_of(fs::path(line.substr(from + 6, to - from - 6)).filename().string(), n);
      return !number || *number <= step / static_cast<std::uint64_t>(every);
    });
  };
  series("series.pvd", kFrames, output.vtk_every);
  series("walls.pvd", kWalls, output.vtk_every);
  series("contacts.pvd", kContacts, output.contacts_every);
  bool header = true;
  cut(dir / "thermo.csv",
      [&](const std::string& line) { return std::exchange(header, false) || thermo_row_up_to(line, step); });
}

std::string earlier_run_text(const std::string& dir, const std::vector<std::filesystem::path>& files) {
  return printable_path(dir) + " holds the output of an earlier run (" + std::to_string(files.size()) +
         " files, e.g. " + printable_path(files.front().filename().string()) + ")";
}

RunFolderLock::RunFolderLock(const std::filesystem::path& dir, const std::string& option) {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (fs::path p = fs::absolute(dir, ec).lexically_normal(); !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    m_made.push_back(p);
    if (p == p.parent_path()) break;
  }
  fs::create_directories(dir, ec);
  if (ec) throw RuntimeFailure("cannot create the output folder " + dir.string() + ": " + ec.message());
  m_path = dir / ".marbles-run.lock";
  // The run that held the lock removes its file as it ends: a lock taken on
  // the file it removed is no lock, so it is taken again on the one there.
  for (int tries = 0;; ++tries) {
    // Never through a link: the process's number written into the file would
    // replace whatever the link names, outside the folder.
    m_fd = ::open(m_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
    const int why = errno;
    if (m_fd < 0 && why == EACCES)  // another user's: locks too
      m_fd = ::open(m_path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (m_fd < 0 && why == EACCES && errno == ENOENT)  // none there, and none may be made: the folder is not ours
      throw RuntimeFailure("cannot write in the output folder " + printable_path(dir.string()) + ": " +
                           std::strerror(why));
    if (m_fd < 0 && (errno == ELOOP || errno == EISDIR))
      throw InputError(SourceLocation{}, option,
                       printable_path(m_path.string()) +
                           (errno == ELOOP ? " is a link where a run keeps its lock file (made there, never through "
                                             "a link: remove it)"
                                           : " is a folder where a run keeps its lock file (remove it)"));
    if (m_fd < 0) throw RuntimeFailure("cannot open " + printable_path(m_path.string()) + ": " + std::strerror(errno));
    if (::flock(m_fd, LOCK_EX | LOCK_NB) != 0) {
      char holder[32] = {};
      const ssize_t n = ::pread(m_fd, holder, sizeof holder - 1, 0);
      ::close(m_fd);
      m_fd = -1;
      const auto pid = whole_number(std::string_view(holder, n > 0 ? static_cast<std::size_t>(n) : 0));
      if (pid && *pid == static_cast<std::uint64_t>(getpid()))  // a Python simulation's frames, in this process
        throw InputError(SourceLocation{}, option,
                         dir.string() + " is being written by another series of frames of this process; " +
                             "end_frames() of the simulation that writes it lets it go, or choose another folder");
      throw InputError(SourceLocation{}, option,
                       dir.string() + " is being written by another marbles command" +
                           (pid ? " (process " + std::to_string(*pid) + ")" : std::string()) +
                           "; wait for it to end, or choose another folder");
    }
    struct stat held {}, named {};
    if (::fstat(m_fd, &held) == 0 && ::lstat(m_path.c_str(), &named) == 0 && held.st_ino == named.st_ino &&
        held.st_dev == named.st_dev)
      break;
    ::close(m_fd);
    m_fd = -1;
    if (tries == 100) throw RuntimeFailure("cannot lock " + m_path.string() + ": it is removed and made again");
  }
  // The process's number, for another run's message only (its loss is no failure).
  const std::string pid = std::to_string(getpid());
  [[maybe_unused]] const bool said =
      ::ftruncate(m_fd, 0) == 0 && ::pwrite(m_fd, pid.data(), pid.size(), 0) == static_cast<ssize_t>(pid.size());
}

RunFolderLock::~RunFolderLock() {
  std::error_code ec;
  std::filesystem::remove(m_path, ec);  // before the lock is let go: a run that opened it meanwhile tries again
  ::close(m_fd);
  for (const std::filesystem::path& made : m_made) std::filesystem::remove(made, ec);  // where it is empty
}

namespace {

// A rename, or across filesystems (a folder linked to another) a copy and a removal.
void move_file(const std::filesystem::path& from, const std::filesystem::path& to, std::error_code& ec) {
  std::filesystem::rename(from, to, ec);
  if (ec == std::errc::cross_device_link) {
    ec.clear();
    copy_plain_file(from, to, ec);
    if (!ec) std::filesystem::remove(from, ec);
  }
}

}  // namespace

EarlierRunAside::EarlierRunAside(const std::filesystem::path& dir, const std::vector<std::filesystem::path>& moved,
                                 const std::vector<std::filesystem::path>& copied, std::ostream& log,
                                 const std::function<void()>& before_moving)
    : m_log(log) {
  namespace fs = std::filesystem;
  for (const fs::path& left : folders_of_ended_processes(dir, ".earlier-run-"))
    log << "note: " << left.string() << " holds an earlier run's files, set aside by a run that did not end "
        << "(--overwrite, or a resume in its folder); remove it when it is not needed\n";
  if (moved.empty() && copied.empty()) return;
  // A folder of its own: one of this number (an earlier process's) is kept.
  const fs::path base = dir / (".earlier-run-" + std::to_string(getpid()));
  fs::path folder = base;
  std::error_code ec;
  for (int k = 2; fs::exists(folder, ec); ++k) folder = base.string() + "." + std::to_string(k);
  auto place = [&](const fs::path& file, bool copy) {
    const fs::path to = folder / file.lexically_relative(dir);
    fs::create_directories(to.parent_path(), ec);
    if (ec) return;
    if (copy) {
      copy_plain_file(file, to, ec);
    } else {
      move_file(file, to, ec);
      if (!ec) m_moved.emplace_back(file, to);
    }
  };
  for (const fs::path& file : copied)
    if (!ec) place(file, true);
  // The copies back over the files before_moving rewrote (all of them, or
  // the folder stays: it holds the only whole ones).
  const auto copies_back = [&] {
    bool all = true;
    for (const fs::path& file : copied) {
      std::error_code renamed;
      fs::rename(folder / file.lexically_relative(dir), file, renamed);
      all = all && !renamed;
    }
    return all;
  };
  bool rewrote = false;
  if (!ec && before_moving) {
    try {
      rewrote = true;
      before_moving();
    } catch (...) {
      if (copies_back()) fs::remove_all(folder, ec);
      throw;
    }
  }
  for (const fs::path& file : moved)
    if (!ec) place(file, false);
  if (!ec) {
    m_folder = folder;
    return;
  }
  // Put back what was moved, and the copies over what was rewritten: the
  // earlier run stays as it was.
  const std::string why = ec.message();
  const bool back = move_back() && (!rewrote || copies_back());
  if (back) fs::remove_all(folder, ec);
  throw RuntimeFailure("cannot set the earlier run's files aside in " + folder.string() + ": " + why +
                       (back ? " (they are left as they were)" : " (what could not be put back lies there)"));
}

EarlierRunAside::~EarlierRunAside() {
  if (!m_folder.empty())
    m_log << "note: the files of the earlier run that this run was to replace are kept whole in " << m_folder.string()
          << "\n";
}

bool EarlierRunAside::move_back() {
  bool all = true;
  for (auto it = m_moved.rbegin(); it != m_moved.rend(); ++it) {
    std::error_code ec;
    if (std::filesystem::exists(it->first, ec)) {  // taken meanwhile: the earlier file stays aside
      all = false;
      continue;
    }
    move_file(it->second, it->first, ec);
    all = all && !ec;
  }
  return all;
}

void EarlierRunAside::put_back() {
  if (m_folder.empty() || !move_back()) return;
  std::error_code ec;
  std::filesystem::remove_all(m_folder, ec);
  m_folder.clear();
}

void EarlierRunAside::discard() {
  if (m_folder.empty()) return;
  std::error_code ec;
  std::filesystem::remove_all(m_folder, ec);
  if (ec)
    m_log << "warning: cannot remove " << m_folder.string() << " (the earlier run's output, replaced): " << ec.message()
          << "\n";
  m_folder.clear();
}

render::RenderOptions render_options(const scene::Scene& scene) {
  const scene::RenderSpec& spec = scene.output.render;
  render::RenderOptions o;
  for (const scene::Material& m : scene.materials) o.material_names.push_back(m.name);
  o.width = spec.width;
  o.height = spec.height;
  if (spec.camera.given) o.camera = render::Camera{spec.camera.position, spec.camera.look_at, spec.camera.up, spec.camera.fov};
  if (auto by = render::parse_color_by(spec.color_by)) o.color_by = *by;
  return o;
}

struct RunOutput::Impl {
  std::string dir;
  int vtk_every = 0;
  int render_every = 0;
  std::unique_ptr<render::VtkSeriesWriter> vtk;
  std::unique_ptr<render::FrameOutput> frames;
  std::unique_ptr<render::ContactSeriesWriter> contacts;
  std::unique_ptr<render::WallSeriesWriter> walls;  // with the VTK frames, when the scene has walls
  Walls initial_walls;
  int contacts_every = 0;
  bool with_contact_counts = false;  // the `contacts` point field is asked for
  bool render_at_finish = false;  // a resumed run: images and movie from the frames
  render::RunImages run_images;   // drawn at the run's own cadence, camera and colours (stopped: a stop request)
  int render_stopped = 0;         // the signal that stopped the closing render
  bool render_failed = false;     // the closing render failed otherwise
  render::RenderOptions render_options;
  render::MovieOptions movie;
  std::ostream* log = nullptr;
  bool thermo = false;
  int thermo_every = 0;     // steps: the VTK cadence, else the images' (also in builds without VTK or OSMesa)
  std::string thermo_text;  // header and rows so far, rewritten whole (atomically) where due
  render::Relisting thermo_relisting;  // when thermo.csv is written (as a .pvd)
  std::uint64_t thermo_step = 0;
  double thermo_seconds = 0;

  void write_thermo() {
    render::write_file_atomic((std::filesystem::path(dir) / "thermo.csv").string(), thermo_text);
    thermo_relisting.written(thermo_text.size());
  }
};

std::vector<EndFigure> end_figures(const World& world) {
  const World::Motion motion = world.motion();
  return {{"kinetic_energy_end_translational", motion.translational},
          {"kinetic_energy_end_rotational", motion.rotational},
          {"max_speed_end", motion.max_speed}};
}

namespace {

std::string thermo_row(const Simulation& sim, double ms_per_step) {
  const World& w = sim.world();
  const StepModel& model = sim.model();
  const World::Motion motion = w.motion();
  double potential = 0;
  if (model.gravity)
    for (std::size_t i = 0; i < w.size(); ++i)
      if (w.inv_mass[i] > 0) potential -= (1.0 / w.inv_mass[i]) * static_cast<double>(dot(model.g, w.position[i]));
  const StepCounters& last = sim.last_step();
  std::string row = std::to_string(sim.steps());
  row += ',';
  row += time_text(sim.time());
  for (const double v : {motion.translational, motion.rotational, potential,
                         static_cast<double>(last.contacts) / sim.substeps(), static_cast<double>(last.max_overlap),
                         motion.max_speed, ms_per_step}) {
    row += ',';
    row += shortest(v);
  }
  row += '\n';
  return row;
}

}  // namespace

RunOutput::RunOutput(const scene::Scene& scene, const std::string& dir, const Walls& walls, bool render,
                     std::ostream& log, bool resumed, const render::Bounds* view)
    : m(std::make_unique<Impl>()) {
  m->dir = dir;
  m->log = &log;
  m->thermo_every = scene.output.vtk_every > 0                        ? scene.output.vtk_every
                    : render && scene.output.render.enabled ? scene.output.render.every
                                                             : 0;
  m->thermo = m->thermo_every > 0;
  if (m->thermo) m->thermo_text = std::string(kThermoHeader) + "\n";
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw RuntimeFailure("cannot create the output folder " + dir + ": " + ec.message());
  // A dead run's temporaries, in every folder a run writes files into.
  render::remove_stale_temporaries(dir);
  for (const Numbered& n : kNumbered) render::remove_stale_temporaries(std::filesystem::path(dir) / n.folder);
  const render::FrameMetadata metadata = frame_metadata(scene);
  // The material names of the frames and images (`marbles render` reads them).
  if (scene.output.vtk_every > 0 || scene.output.contacts_every > 0 || (render && scene.output.render.enabled))
    render::write_material_names(dir, metadata.material_names);
  if (scene.output.vtk_every > 0) {
    const std::vector<render::PointField> fields = render::parse_point_fields(scene.output.fields);
    m->with_contact_counts =
        std::find(fields.begin(), fields.end(), render::PointField::contacts) != fields.end();
    m->vtk = std::make_unique<render::VtkSeriesWriter>(dir, fields, metadata);
    m->vtk->list_in_steps();
    m->vtk_every = scene.output.vtk_every;
    if (!walls.empty()) {
      const render::Bounds b = view ? *view : render::Bounds{};
      const bool known = view && !b.empty();
      const Vec3 lo = known ? Vec3(real(b.lo[0]), real(b.lo[1]), real(b.lo[2])) : Vec3(-1, -1, -1);
      const Vec3 hi = known ? Vec3(real(b.hi[0]), real(b.hi[1]), real(b.hi[2])) : Vec3(1, 1, 1);
      m->walls = std::make_unique<render::WallSeriesWriter>(dir, lo, hi, metadata);
      m->walls->list_in_steps();
      m->initial_walls = walls;
    }
  }
  if (scene.output.contacts_every > 0) {
    m->contacts = std::make_unique<render::ContactSeriesWriter>(dir, metadata);
    m->contacts->list_in_steps();
    m->contacts_every = scene.output.contacts_every;
  }
  if (render && scene.output.render.enabled && resumed) {
    const std::vector<std::string>& fields = scene.output.fields;
    if (!m->vtk) {
      log << "warning: a resumed run renders its images from the VTK frames, and this run writes none: no images\n";
    } else if (std::find(fields.begin(), fields.end(), "radius") == fields.end()) {
      log << "warning: a resumed run renders its images from the VTK frames, and output.fields lacks radius: no "
             "images\n";
    } else if (!render::renderer_available()) {
      log << "warning: no images: this build has no OSMesa\n";
    } else {
      m->render_at_finish = true;
      m->render_options = render_options(scene);
      m->movie.enabled = scene.output.movie.enabled;
      m->movie.fps = scene.output.movie.fps;
      // The images the run draws as it goes come every render.every steps,
      // the frames every vtk.every: the frames at the images' steps, where
      // every image step has a frame; else at the steps both share, said.
      const auto frames_every = static_cast<std::uint64_t>(scene.output.vtk_every);
      const auto images_every = static_cast<std::uint64_t>(scene.output.render.every);
      const std::uint64_t both = std::lcm(frames_every, images_every);
      m->run_images.stride = static_cast<std::size_t>(both / frames_every);
      if (both != images_every)
        log << "warning: a resumed run draws its images from the VTK frames, every " << scene.output.vtk_every
            << " steps, and the images come every " << scene.output.render.every << ": its images come every "
            << both << " steps (the frames' and images' common steps)\n";
      if (view) m->run_images.view = *view;
    }
  } else if (render && scene.output.render.enabled) {
    try {
      render::MovieOptions movie;
      movie.enabled = scene.output.movie.enabled;
      movie.fps = scene.output.movie.fps;
      m->frames = std::make_unique<render::FrameOutput>(dir, render_options(scene), movie, walls, log);
      m->render_every = scene.output.render.every;
    } catch (const RuntimeFailure& e) {
      log << "warning: no images: " << e.what() << "\n";
    }
  }
}

RunOutput::~RunOutput() {
  try {
    flush();
  } catch (...) {  // a run that fails or stops: the listings written before stand, naming files that are there
  }
}

void RunOutput::stop_render_when(std::function<int()> stopped) { m->run_images.stopped = std::move(stopped); }

int RunOutput::stopped_render() const { return m->render_stopped; }

bool RunOutput::render_failed() const { return m->render_failed; }

void RunOutput::flush() {
  if (m->vtk) m->vtk->flush();
  if (m->walls) m->walls->flush();
  if (m->contacts) m->contacts->flush();
  if (m->thermo && m->thermo_relisting.stale(m->thermo_text.size())) m->write_thermo();
}

bool RunOutput::due(std::uint64_t step) const {
  return (m->vtk && step % m->vtk_every == 0) || (m->frames && step % m->render_every == 0) ||
         (m->thermo && step % m->thermo_every == 0) || (m->contacts && step % m->contacts_every == 0);
}

void RunOutput::write(const Simulation& sim, double step_seconds) {
  const std::uint64_t step = sim.steps();
  if (!due(step)) return;
  if (m->thermo && step % m->thermo_every == 0) {
    const double ms = step > m->thermo_step ? 1e3 * (step_seconds - m->thermo_seconds) / double(step - m->thermo_step) : 0.0;
    m->thermo_text += thermo_row(sim, ms);
    m->thermo_step = step;
    m->thermo_seconds = step_seconds;
    if (m->thermo_relisting.due(m->thermo_text.size())) m->write_thermo();
  }
  if (m->contacts && step % m->contacts_every == 0) m->contacts->write(make_contact_snapshot(sim));
  if (!(m->vtk && step % m->vtk_every == 0) && !(m->frames && step % m->render_every == 0)) return;
  const render::Snapshot snapshot = make_snapshot(sim, m->with_contact_counts);
  if (m->vtk && step % m->vtk_every == 0) {
    m->vtk->write(snapshot);
    if (m->walls) m->walls->write(render::walls_at(m->initial_walls, sim.time()), sim.time(), step);
  }
  if (m->frames && step % m->render_every == 0) m->frames->add(snapshot);
}

void RunOutput::resume(std::uint64_t steps, double dt, const std::filesystem::path& from) {
  m->thermo_step = steps;
  if (m->thermo) {  // the rows up to the checkpoint's step, from the run that wrote it
    std::error_code ec;
    const std::filesystem::path here = std::filesystem::path(m->dir) / "thermo.csv";
    std::ifstream in(std::filesystem::exists(here, ec) || from.empty() ? here : from / "thermo.csv");
    std::string line;
    if (std::getline(in, line) && line == kThermoHeader) {
      while (std::getline(in, line) && thermo_row_up_to(line, steps)) m->thermo_text += line + "\n";
    }
  }
  if (m->contacts)
    for (std::uint64_t step = 0; step <= steps; step += static_cast<std::uint64_t>(m->contacts_every))
      m->contacts->adopt(static_cast<double>(step) * dt, from);
  // Written now too, so that a resumed run with no frame or row left to
  // write still leaves its folder whole.
  if (m->contacts) m->contacts->write_pvd();
  if (m->thermo) m->write_thermo();
  if (!m->vtk) return;
  for (std::uint64_t step = 0; step <= steps; step += static_cast<std::uint64_t>(m->vtk_every)) {
    m->vtk->adopt(static_cast<double>(step) * dt, from);
    if (m->walls) m->walls->adopt(static_cast<double>(step) * dt, from);
  }
  m->vtk->write_pvd();
  if (m->walls) m->walls->write_pvd();
}

std::string RunOutput::finish() {
  flush();  // the listings whole before the closing render reads series.pvd
  std::ostringstream out;
  if (m->vtk) out << m->vtk->frames() << " frames in frames/, series.pvd, ";
  if (m->walls) out << "walls in walls/, walls.pvd, ";
  if (m->contacts) out << m->contacts->frames() << " contact frames in contacts/, contacts.pvd, ";
  if (m->render_at_finish) {
    try {  // the run's own outputs (summary, thermo) stand whatever the images do
      render::render_output_dir(m->dir, m->render_options, m->movie, false, *m->log, &m->run_images);
      out << "images in images/";
      if (std::filesystem::exists(std::filesystem::path(m->dir) / "movie.mp4")) out << ", movie.mp4";
      out << ", ";
    } catch (const render::RenderStopped& e) {
      m->render_stopped = e.signal;
      *m->log << "warning: no images: the closing render was stopped by " << signal_name(e.signal) << " ("
              << e.what() << "); `marbles render " << m->dir << "` draws them from the frames\n";
    } catch (const std::exception& e) {
      // A Ctrl-C from the terminal reaches ffmpeg too, whose end the movie
      // reports first: still a stop.
      if (m->run_images.stopped) m->render_stopped = m->run_images.stopped();
      m->render_failed = m->render_stopped == 0;
      *m->log << "warning: no images: " << e.what() << "\n";
    }
  }
  if (m->frames) {
    m->frames->finish();
    out << m->frames->frames() << " images in images/";
    if (std::filesystem::exists(std::filesystem::path(m->dir) / "movie.mp4")) out << ", movie.mp4";
    out << ", ";
  }
  return out.str();
}

}  // namespace marbles
