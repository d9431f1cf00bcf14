// python/bind_simulation.cpp — the Simulation of one precision, for Python.
//
// Built twice into the module, like every library of the program: once as
// is (float) and once with `marbles` renamed to `marbles_f64` and `real` =
// double (python/CMakeLists.txt); marbles/__init__.py picks the class that
// matches the scene's `solver.precision`, as `marbles run` does.
//
// A run from Python is `marbles run` without its output: the same scene
// loading, world, backend and watchdog, the same running totals and reference
// probe (so a checkpoint written here resumes with `marbles run --restart`
// and back). The state is handed out in place: NumPy views of the step's own
// arrays on the CPU, device pointers on the GPU; each step() first checks
// them (non-finite values are refused) when they are out. A scene with
// solver.renumber hands out copies instead (its step numbers the spheres
// its own way and replaces the arrays).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "broadphase/grid.hpp"
#include "core/error.hpp"
#include "core/format.hpp"
#include "core/hash.hpp"
#include "core/parallel.hpp"
#include "python/gil.hpp"
#include "render/atomic_file.hpp"
#include "render/vtk_output.hpp"
#include "sim/checkpoint.hpp"
#include "sim/output.hpp"
#include "sim/particles.hpp"
#include "sim/reference.hpp"
#include "sim/run.hpp"
#include "sim/scene.hpp"
#include "sim/scene_yaml.hpp"
#include "sim/settings_check.hpp"
#include "sim/simulation.hpp"
#include "sim/version.hpp"

namespace nb = nanobind;

namespace marbles {

namespace {

template <class T, ssize_t... Shape>
using HostArray = nb::ndarray<nb::numpy, T, nb::shape<Shape...>, nb::c_contig>;
template <class T, ssize_t... Shape>
using DeviceArray = nb::ndarray<nb::array_api, T, nb::shape<Shape...>, nb::c_contig, nb::device::cuda>;

constexpr ssize_t kAny = -1;  // a dimension of any length

BackendChoice backend_choice(const std::string& name) {
  if (name == "auto") return BackendChoice::automatic;
  if (name == "cpu") return BackendChoice::cpu;
  if (name == "cuda") return BackendChoice::cuda;
  throw InputError(SourceLocation{}, "backend", "must be auto, cpu or cuda, got '" + name + "'");
}

// The process's thread count before any simulation set its own: OMP_NUM_THREADS,
// else every core (read once, at the first simulation made).
int default_threads() {
  static const int n = default_thread_count();
  return n;
}

class PySimulation {
 public:
  // `source`: a scene file's path, or a scene as JSON text when `label` is
  // not empty (errors then name `label`; `stem` names the output folder).
  PySimulation(const std::string& source, const std::string& label, const std::string& stem,
               const std::vector<std::string>& overrides, const std::string& backend, int threads) {
    const bool from_text = !label.empty();
    m_scene = from_text ? scene::load_scene_json(source, label, stem, overrides) : scene::load_scene(source, overrides);
    m_fingerprint = m_scene.fingerprint;
    if (from_text) {
      m_text_fingerprint = [fingerprint = text_fingerprint(source, overrides)] { return fingerprint; };
    } else {  // the file read again only by a restart, as `marbles run --restart` reads it (a later chdir aside)
      m_text_fingerprint = [path = std::filesystem::absolute(source).string(), overrides] {
        return scene_fingerprint(path, overrides);
      };
    }
    const scene::GeneratedParticles particles = scene::generate_particles(m_scene);
    m_warnings = risky_settings(m_scene, particles, sizeof(real) == 4);
    const BackendChoice choice = backend_choice(backend);
    // Its own count, set again before each of its steps: OpenMP's count is
    // the process's, which another simulation may have changed since.
    m_threads = threads > 0 ? threads : default_threads();
    set_thread_count(m_threads);
    std::ostringstream log;
    m_backend = select_backend(choice, log);
    m_backend_note = log.str();
    if (!m_backend_note.empty() && m_backend_note.back() == '\n') m_backend_note.pop_back();
    m_sim = std::make_unique<Simulation>(m_scene, make_world(m_scene, particles), m_backend);
    m_sim->set_watchdog(true);  // measures the start, which the warnings read
    for (std::string& w : initial_overlap_warnings(m_sim->watched_overlaps())) m_warnings.push_back(std::move(w));
    m_totals.energy_start = m_sim->world().kinetic_energy();
    m_size = m_sim->world().size();
    m_total_steps = static_cast<std::uint64_t>(std::llround(m_scene.time.duration / m_scene.time.dt));
    if (m_scene.reference.kind != scene::ReferenceSpec::Kind::none) {
      m_probe.emplace(m_scene, m_sim->world());
      m_probe_every = m_probe->every(m_total_steps);
    }
  }

  // Advances n steps (the GIL released); views handed out are checked first.
  // Between steps it looks for a pending signal (Ctrl-C: KeyboardInterrupt,
  // the steps done kept). One thread steps a simulation at a time.
  void step(std::uint64_t n) {
    const Busy busy(*this);
    const Stepping stepping(*this);
    if (m_views_out) check_views();
    set_thread_count(m_threads);
    // Signals are Python's to handle on its main thread only: another
    // thread's step takes the GIL back at its end alone (python/gil.hpp).
    const bool signals_here = _PyOS_IsMainThread() != 0;
    const python::GilLetGo release;
    auto last_check = std::chrono::steady_clock::now();
    for (std::uint64_t i = 0; i < n; ++i) {
      if (i > 0) python::park_if_ending(signals_here);  // a daemon thread's step as the interpreter ends
      if (signals_here && i > 0 && std::chrono::steady_clock::now() - last_check > std::chrono::milliseconds(100)) {
        last_check = std::chrono::steady_clock::now();
        nb::gil_scoped_acquire acquire;
        if (PyErr_CheckSignals() != 0) throw nb::python_error();
      }
      try {
        m_sim->step();
      } catch (const WatchdogFailure& e) {
        throw RuntimeFailure(std::string(e.what()) + " (the state is back at the start of step " +
                             std::to_string(m_sim->steps() + 1) + ")");
      }
      m_totals.add(m_sim->last_step(), m_sim->substeps(), m_sim->last_rollbacks().size(), !m_sim->last_kept().empty());
      if (m_probe && m_sim->steps() % m_probe_every == 0) m_probe->sample(m_sim->time(), m_sim->world());
    }
    if (m_views_out) m_known_state = state_hash();  // what the views hold, unwritten
  }

  // --- the state ---------------------------------------------------------
  std::size_t size() const { return m_size; }  // fixed: read while another thread steps
  bool on_device() const { return m_backend == broadphase::Backend::cuda; }

  // A view of one of the step's own arrays: `what` is position, velocity,
  // angular_velocity (writable), radius or material (read-only).
  nb::object view(const std::string& what) {
    const Busy busy(*this, Busy::reads);
    check_array_name(what);
    nb::object owner = nb::find(this);
    const BodiesView v = m_sim->state_in_place();
    const bool writable = what == "position" || what == "velocity" || what == "angular_velocity";
    // Read-only arrays (radius, material) cannot be written through: only a
    // writable view can edit the state, and on the host only once its bytes
    // change (views_written).
    if (writable && !m_views_out) {
      m_views_out = true;
      m_known_state = state_hash();
    }
    const std::size_t n = v.count;
    real* vec = what == "position" ? &v.position[0].x
                : what == "velocity" ? &v.velocity[0].x
                : what == "angular_velocity" ? &v.angular_velocity[0].x
                                             : nullptr;
    if (n == 0) vec = nullptr;
    if (!on_device()) {
      if (what == "radius") return nb::cast(HostArray<const real, kAny>(v.radius, {n}, owner));
      if (what == "material") return nb::cast(HostArray<const std::uint32_t, kAny>(v.material, {n}, owner));
      return nb::cast(HostArray<real, kAny, 3>(vec, {n, 3}, owner));
    }
    // (the array for DLPack, the address for __cuda_array_interface__)
    if (what == "radius")
      return nb::make_tuple(DeviceArray<const real, kAny>(v.radius, {n}, owner), reinterpret_cast<std::uintptr_t>(v.radius));
    if (what == "material")
      return nb::make_tuple(DeviceArray<const std::uint32_t, kAny>(v.material, {n}, owner),
                            reinterpret_cast<std::uintptr_t>(v.material));
    return nb::make_tuple(DeviceArray<real, kAny, 3>(vec, {n, 3}, owner), reinterpret_cast<std::uintptr_t>(vec));
  }

  // A host copy of one array (any backend).
  nb::object copy(const std::string& what) {
    const Busy busy(*this, Busy::reads);
    check_array_name(what);
    if (views_written()) m_sim->state_written();  // views may have been written
    const World& w = m_sim->world();
    const std::size_t n = w.size();
    if (what == "radius") return nb::cast(to_numpy(w.radius.data(), {n}));
    if (what == "material") return nb::cast(to_numpy(w.material.data(), {n}));
    const std::vector<Vec3>& vec = what == "position" ? w.position : what == "velocity" ? w.velocity : w.angular_velocity;
    return nb::cast(to_numpy(n ? &vec[0].x : nullptr, {n, 3}));
  }

  // Writes a whole array from a host array of the same shape (a copy; the
  // values are checked first).
  void assign(const std::string& what, HostArray<const real, kAny, 3> values) {
    const Busy busy(*this);
    check_array_name(what);
    if (what == "radius" || what == "material") throw nb::value_error((plural(what) + " are read-only").c_str());
    const std::size_t n = size();
    if (values.shape(0) != n)
      throw nb::value_error((plural(what) + ": expected " + std::to_string(n) + " rows, got " + std::to_string(values.shape(0))).c_str());
    for (std::size_t i = 0; i < n; ++i) {
      const real* row = values.data() + 3 * i;
      const auto refuse = [&](const std::string& why) {
        const std::string text = plural(what) + "[" + std::to_string(i) + "] " + why + "; the state is unchanged";
        throw nb::value_error(text.c_str());
      };
      if (!std::isfinite(row[0]) || !std::isfinite(row[1]) || !std::isfinite(row[2])) refuse("is not finite");
      if (square_overflows(Vec3{row[0], row[1], row[2]}))  // as a scene's vectors: the step squares them
        refuse("is too large for " + std::string(kRealName) + " precision: its squared length overflows");
    }
    // The other arrays' views first: the assignment makes the state known
    // (host_edited), and a value written through them would pass unchecked.
    if (m_views_out) check_views(plural(what));
    if (m_views_out) m_sim->state_written();
    World& w = m_sim->edit_world();
    std::vector<Vec3>& vec = what == "position" ? w.position : what == "velocity" ? w.velocity : w.angular_velocity;
    std::copy(values.data(), values.data() + 3 * n, &vec[0].x);
    host_edited();
  }

  // --- what the step knows ------------------------------------------------
  nb::dict contacts() {
    const Busy busy(*this, Busy::reads);
    if (m_views_out) check_views();
    const render::ContactSnapshot c = make_contact_snapshot(*m_sim);
    const std::size_t m = c.sphere_a.size();
    std::vector<std::uint32_t> pairs(2 * m);
    for (std::size_t k = 0; k < m; ++k) {
      pairs[2 * k] = c.sphere_a[k];
      pairs[2 * k + 1] = c.sphere_b[k];
    }
    nb::dict d;
    d["pairs"] = to_numpy(pairs.data(), {m, 2});
    d["wall"] = to_numpy(c.wall.data(), {m}).attr("astype")("bool");
    d["normal"] = to_numpy(m ? &c.normal[0].x : nullptr, {m, 3});
    d["normal_force"] = to_numpy(c.normal_force.data(), {m});
    d["tangential_force"] = to_numpy(m ? c.tangential_force[0].data() : nullptr, {m, 3});
    d["overlap"] = to_numpy(c.overlap.data(), {m});
    d["point_a"] = to_numpy(m ? &c.a[0].x : nullptr, {m, 3});
    d["point_b"] = to_numpy(m ? &c.b[0].x : nullptr, {m, 3});
    return d;
  }

  // A state written non-finite through a view is refused here too (as by
  // step, write_frame and checkpoint), not summed into a NaN.
  double kinetic_energy() {
    const Busy busy(*this, Busy::reads);
    if (m_views_out) check_views();
    return m_sim->world().kinetic_energy();
  }

  // OUTDIR/frames/frame_NNNNNN.vtp and OUTDIR/series.pvd, as `marbles run`
  // writes them (the scene's point fields); frames written to one folder
  // from one simulation make one series.
  std::string write_frame(const std::string& dir, bool overwrite) {
    const Busy busy(*this);
    if (dir.empty() || dir.find('\0') != std::string::npos)
      throw nb::value_error("write_frame: a folder is needed (not empty, no NUL byte)");
    if (m_views_out) check_views();
    const std::filesystem::path folder = series_key(dir);
    const std::string key = folder.string();
    auto it = m_frames.find(key);
    if (it == m_frames.end()) {
      // A folder new to this simulation that holds another run's output is
      // refused, as `marbles run` refuses it: new frames would replace some
      // of its frames and its series.pvd would no longer name the rest.
      // The folder is this series' alone until it ends (end_frames(), or
      // the simulation's end), as a run's is: another command, or another
      // simulation, writing there is refused.
      auto series = std::make_unique<FrameSeries>();
      series->lock = std::make_unique<RunFolderLock>(folder, "write_frame: dir");
      const std::vector<std::filesystem::path> earlier = earlier_run_files(key);
      if (!earlier.empty() && !overwrite)
        throw nb::value_error((earlier_run_text(dir, earlier) +
                               "; write_frame(dir, overwrite=True) replaces it, or choose another folder")
                                  .c_str());
      // Set aside, as `marbles run --overwrite` sets them aside, and removed
      // only once this series stands (its first frame written) and ends.
      series->aside = std::make_unique<EarlierRunAside>(folder, earlier, std::vector<std::filesystem::path>{}, std::cerr);
      series->writer = std::make_unique<render::VtkSeriesWriter>(
          folder, render::parse_point_fields(m_scene.output.fields), frame_metadata(m_scene));
      it = m_frames.emplace(key, std::move(series)).first;
    }
    const bool counts = std::find(m_scene.output.fields.begin(), m_scene.output.fields.end(), "contacts") !=
                        m_scene.output.fields.end();
    try {
      const std::filesystem::path written = it->second->writer->write(make_snapshot(*m_sim, counts));
      it->second->stands = true;
      return written.string();
    } catch (...) {
      // A series with no frame yet ends here: the earlier run set aside goes
      // back (nothing took its place), and the folder is let go.
      if (!it->second->stands) {
        if (it->second->aside) it->second->aside->put_back();
        m_frames.erase(it);
      }
      throw;
    }
  }

  // Ends the series written to `dir` (all of them with none): its folder is
  // let go (`marbles render` may read it, another run write there) and the
  // files of an earlier run it replaced are removed. A later write_frame
  // there finds this series as an earlier run's output.
  void end_frames(const std::optional<std::string>& dir) {
    const Busy busy(*this);
    if (!dir) {
      m_frames.clear();
      return;
    }
    if (dir->empty() || dir->find('\0') != std::string::npos)
      throw nb::value_error("end_frames: a folder is needed (not empty, no NUL byte)");
    m_frames.erase(series_key(*dir));
  }

  // A checkpoint `marbles run --restart` reads (and restart() here), and
  // where given, `record` beside it (path + ".scene.json"), each written to
  // a temporary and renamed.
  void checkpoint(const std::string& path, const std::string& record) {
    const Busy busy(*this);
    if (path.empty() || path.find('\0') != std::string::npos)
      throw nb::value_error("checkpoint: a path is needed (not empty, no NUL byte)");
    if (m_views_out) check_views();
    const std::string bytes =
        checkpoint_bytes({m_fingerprint, m_sim->steps(), m_sim->world(), m_sim->save_state(), m_totals,
                          m_probe ? m_probe->progress() : std::vector<double>{}, m_sim->ids()});
    make_parent_folder(path);
    // Both or neither: a checkpoint without its record, or beside another's, is not restarted from.
    if (record.empty()) render::write_file_atomic(path, bytes);
    else render::write_files_atomic({{path, bytes}, {path + ".scene.json", record}});
  }

  void restart(const std::string& path) {
    const Busy busy(*this);
    Checkpoint c = read_checkpoint(path, m_fingerprint, m_text_fingerprint());
    check_checkpoint_fits(c, path, "restart", m_sim->world(), m_sim->ids(), m_scene.materials.size(),
                          m_sim->model().wall_shapes);
    if (m_views_out) m_sim->state_written();
    m_sim->restore(c.world, c.state, c.steps, c.ids);
    host_edited();
    m_totals = c.totals;
    if (m_probe) m_probe->resume(c.probe);
  }

  // The reference's verdict so far (kind, expected, measured, error, note).
  nb::object reference() {
    const Busy busy(*this, Busy::reads);
    if (!m_probe) return nb::none();
    if (m_views_out) check_views();
    ReferenceProbe probe = *m_probe;  // finish() on a copy: stepping may go on
    const ReferenceResult r = probe.finish(m_sim->time(), m_sim->world());
    nb::dict d;
    d["kind"] = r.kind;
    d["expected"] = r.expected;
    d["measured"] = r.measured;
    d["error"] = r.error;
    d["note"] = r.note;
    return d;
  }

  nb::dict totals() const {
    const Busy busy(*this, Busy::reads);
    const double steps = std::max<double>(1, static_cast<double>(m_sim->steps()));
    nb::dict d;
    d["mean_candidate_pairs"] = m_totals.candidate_sum / steps;
    d["mean_contacts"] = m_totals.contact_sum / steps;
    d["max_overlap"] = m_totals.deepest;
    d["max_overlap_end"] = m_totals.overlap_end;
    d["rollbacks"] = static_cast<std::uint64_t>(m_totals.rollbacks);
    d["unswept_steps"] = static_cast<std::uint64_t>(m_totals.unswept);
    d["kinetic_energy_start"] = m_totals.energy_start;
    return d;
  }

  // summary.json's figures of the world at its end, beside kinetic_energy_end.
  nb::dict end_figures() const {
    const Busy busy(*this, Busy::reads);
    nb::dict d;
    for (const EndFigure& f : ::marbles::end_figures(m_sim->world())) d[f.name] = f.value;
    return d;
  }

  const Simulation& sim() const { return *m_sim; }
  int threads() const { return m_threads; }
  const scene::Scene& scene() const { return m_scene; }
  const std::vector<std::string>& warnings() const { return m_warnings; }
  const std::string& backend_note() const { return m_backend_note; }
  std::uint64_t total_steps() const { return m_total_steps; }

 private:
  template <class T>
  static nb::object to_numpy(const T* data, std::initializer_list<std::size_t> shape) {
    std::size_t count = 1;
    for (std::size_t s : shape) count *= s;
    T* copy = new T[count > 0 ? count : 1];
    if (count > 0) std::copy(data, data + count, copy);
    nb::capsule owner(copy, [](void* p) noexcept { delete[] static_cast<T*>(p); });
    return nb::cast(nb::ndarray<nb::numpy, T>(copy, shape.size(), shape.begin(), owner));
  }

  // An edit of the host copy goes to the arrays handed out at once (on the
  // GPU they are device memory, which would otherwise win at the next step).
  void host_edited() {
    if (!m_views_out) return;
    m_sim->state_in_place();
    m_known_state = state_hash();  // the edit is the step's own (an assignment, a restart): known
  }

  // The arrays handed out may have been written: the step takes them as an
  // edit, after checking that every value is finite.
  static void check_array_name(const std::string& what) {
    for (const char* name : {"position", "velocity", "angular_velocity", "radius", "material"})
      if (what == name) return;
    throw nb::value_error(("no state array '" + what + "' (position, velocity, angular_velocity, radius, material)").c_str());
  }

  // Whether the writable views handed out may have been written since the
  // state was last known (handed out, or after the last step): on the host
  // where their bytes changed, on the GPU always (device memory, not hashed
  // here). Reading them is no edit: the next step keeps the watchdog's
  // figures of its start, as `marbles run` does, and the same bits.
  bool views_written() {
    if (!m_views_out) return false;
    return on_device() || state_hash() != m_known_state;
  }
  // The bytes of the writable arrays on the host (0 on the GPU: not read).
  std::uint64_t state_hash() {
    if (on_device()) return 0;
    const BodiesView v = m_sim->state_in_place();
    const std::size_t bytes = v.count * sizeof(Vec3);
    return fnv1a(v.angular_velocity, bytes, fnv1a(v.velocity, bytes, fnv1a(v.position, bytes)));
  }

  // `replaced`: an array an assignment is about to write whole, whose
  // values are not looked at.
  void check_views(const std::string& replaced = "") {
    if (!views_written()) return;  // nothing written: the state as the last step left it
    m_sim->state_written();
    if (m_sim->state_finite()) return;  // on the GPU a flag, not a copy
    const World& w = m_sim->world();
    const std::pair<const char*, const std::vector<Vec3>*> arrays[] = {
        {"positions", &w.position}, {"velocities", &w.velocity}, {"angular_velocities", &w.angular_velocity}};
    for (const auto& [name, vec] : arrays)
      for (std::size_t i = 0; i < vec->size() && name != replaced; ++i) {
        const Vec3& p = (*vec)[i];
        if (!is_finite(p))
          throw nb::value_error((std::string(name) + "[" + std::to_string(i) +
                                 "] is not finite; write a finite value before stepping or reading the state")
                                    .c_str());
        if (square_overflows(p))
          throw nb::value_error((std::string(name) + "[" + std::to_string(i) + "] is too large for " + kRealName +
                                 " precision: its squared length overflows; write a smaller value before stepping")
                                    .c_str());
      }
  }

  scene::Scene m_scene;
  int m_threads = 1;  // the CPU threads its steps run on
  std::size_t m_size = 0;  // its spheres (a restart keeps the count)
  std::uint64_t m_fingerprint = 0;       // Scene::fingerprint, which its checkpoints hold
  std::function<std::uint64_t()> m_text_fingerprint;  // an earlier checkpoint's, of the texts
  std::vector<std::string> m_warnings;
  broadphase::Backend m_backend = broadphase::Backend::cpu;
  std::string m_backend_note;
  std::unique_ptr<Simulation> m_sim;
  RunTotals m_totals;
  std::optional<ReferenceProbe> m_probe;
  std::uint64_t m_probe_every = 1, m_total_steps = 0;
  bool m_views_out = false;       // a writable view of the state handed out
  std::uint64_t m_known_state = 0;  // state_hash() when the state was last known unwritten
  // Held by the call that steps or changes the simulation: a call from
  // another thread meanwhile (step() lets the GIL go) is refused, not raced.
  // A reader called from within the step's own thread (a Python signal
  // handler, run at the step's look for Ctrl-C between two steps, where the
  // state is whole) reads; a call that would step or change it there is
  // refused (and never try_locks the mutex its thread holds).
  mutable std::mutex m_busy;
  mutable std::atomic<std::thread::id> m_stepping{};  // the thread inside step(), where one is
  struct Busy {
    enum Kind { changes, reads };
    std::unique_lock<std::mutex> lock;
    explicit Busy(const PySimulation& s, Kind kind = changes) {
      if (s.m_stepping.load() == std::this_thread::get_id()) {
        if (kind == reads) return;
        throw RuntimeFailure("this Simulation is stepping in this thread (a signal handler during step()): read it "
                             "there, step or change it once step() has returned");
      }
      lock = std::unique_lock<std::mutex>(s.m_busy, std::try_to_lock);
      if (!lock.owns_lock())
        throw RuntimeFailure("this Simulation is stepping in another thread; step or change it from one thread at a time");
    }
  };
  // step()'s thread, named while it steps.
  struct Stepping {
    const PySimulation& s;
    explicit Stepping(const PySimulation& sim) : s(sim) { s.m_stepping.store(std::this_thread::get_id()); }
    ~Stepping() { s.m_stepping.store(std::thread::id{}); }
  };
  static std::string plural(const std::string& what) {
    return what == "velocity" ? "velocities" : what == "angular_velocity" ? "angular_velocities" : what + "s";
  }
  // A folder's frames: the writer, the lock that keeps the folder this
  // series' own, and an earlier run's files set aside (overwrite=True),
  // removed as the series ends if it has a frame.
  struct FrameSeries {
    std::unique_ptr<RunFolderLock> lock;
    std::unique_ptr<EarlierRunAside> aside;
    std::unique_ptr<render::VtkSeriesWriter> writer;
    bool stands = false;
    FrameSeries() = default;
    FrameSeries(const FrameSeries&) = delete;
    FrameSeries& operator=(const FrameSeries&) = delete;
    ~FrameSeries() {
      writer.reset();
      if (stands && aside) aside->discard();
      aside.reset();
      lock.reset();  // last: the folder is let go once nothing more is written in it
    }
  };
  // By the folder, however it is written ("out", "out/", "./out", through
  // a link), and written there by that name: a later chdir moves neither.
  // Its links resolved as the system resolves them ("link/.." is the
  // link's target's parent, not the folder the link is in).
  static std::filesystem::path series_key(const std::string& dir) {
    std::filesystem::path folder = std::filesystem::weakly_canonical(std::filesystem::absolute(dir));
    if (!folder.has_filename() && folder.has_parent_path() && folder != folder.root_path())
      folder = folder.parent_path();  // "out/" normalises to "/.../out/": the folder is "/.../out"
    return folder;
  }
  std::map<std::string, std::unique_ptr<FrameSeries>> m_frames;
};

// Raises marbles.errors.<name>(*args) as the pending Python exception.
template <class... Args>
void raise(const char* name, Args&&... args) {
  nb::object type = nb::module_::import_("marbles.errors").attr(name);
  nb::object error = type(std::forward<Args>(args)...);
  PyErr_SetObject(type.ptr(), error.ptr());
}

// InputError -> marbles.SceneError (file, line, column, key, message);
// RuntimeFailure -> marbles.RuntimeFailure (marbles/errors.py).
void translate(const std::exception_ptr& p, void*) {
  try {
    std::rethrow_exception(p);
  } catch (const InputError& e) {
    raise("SceneError", std::string(e.what()), e.where().file, e.where().line, e.where().column, e.key(),
          e.message());
  } catch (const RuntimeFailure& e) {
    raise("RuntimeFailure", std::string(e.what()));
  } catch (const std::filesystem::filesystem_error& e) {  // an I/O failure is a run's failure
    raise("RuntimeFailure", std::string(e.what()));
  }
}

// The overlapping pairs (i < j, sorted) of the spheres of an (N, 4) array of
// x, y, z, r, as `marbles pairs` prints them.
nb::object pairs(HostArray<const real, kAny, 4> xyzr, const std::string& algorithm, const std::string& backend,
                 double margin) {
  const std::size_t n = xyzr.shape(0);
  std::vector<Vec3> centre(n);
  std::vector<real> radius(n);
  for (std::size_t i = 0; i < n; ++i) {
    const real* row = xyzr.data() + 4 * i;
    // As `marbles pairs` reads a row of its CSV (sphere_value_problem): a
    // centre whose squared length overflows was found apart from its neighbours.
    const std::string key = "xyzr[" + std::to_string(i) + "]";
    for (int c = 0; c < 4; ++c)
      if (const std::string problem = scene::sphere_value_problem(c, row[c]); !problem.empty())
        throw InputError(SourceLocation{}, key, std::string(1, "xyzr"[c]) + ": " + problem + ", got " + shortest(row[c]));
    if (const std::string problem = scene::sphere_vector_problem({row[0], row[1], row[2]}, "x, y, z"); !problem.empty())
      throw InputError(SourceLocation{}, key, problem);
    centre[i] = {row[0], row[1], row[2]};
    radius[i] = row[3];
  }
  if (!(margin >= 0) || !std::isfinite(margin)) throw InputError(SourceLocation{}, "margin", "must be finite and >= 0");
  if (!std::isfinite(static_cast<real>(margin)))  // finite in double, inf once the precision's
    throw InputError(SourceLocation{}, "margin", std::string("out of range for ") + kRealName + " precision");
  const BackendChoice where_asked = backend_choice(backend);  // checked for every algorithm
  const SpheresIn in{centre.data(), radius.data(), n};
  std::vector<broadphase::Pair> found;
  if (algorithm == "brute") {
    broadphase::brute_force_pairs(in, static_cast<real>(margin), found);
  } else if (algorithm == "home" || algorithm == "subdivision") {
    std::ostringstream log;
    const broadphase::Backend where = select_backend(where_asked, log);
    const auto alg = algorithm == "home" ? broadphase::Algorithm::home : broadphase::Algorithm::seed;
    auto bp = where == broadphase::Backend::cuda ? broadphase::make_subdivision_cuda(alg)
                                                 : broadphase::make_subdivision_cpu(alg);
    const python::GilLetGo release;
    try {
      bp->find_pairs(in, static_cast<real>(margin), found);
    } catch (const broadphase::SpanTooLarge&) {
      throw InputError(SourceLocation{}, "algorithm",
                       algorithm + ": " + broadphase::SpanTooLarge::kWhy + "; algorithm='home' or 'brute' take them");
    }
  } else {
    throw InputError(SourceLocation{}, "algorithm", "must be home, subdivision or brute, got '" + algorithm + "'");
  }
  std::sort(found.begin(), found.end());
  std::uint32_t* out = new std::uint32_t[2 * found.size() + 1];
  for (std::size_t k = 0; k < found.size(); ++k) {
    out[2 * k] = found[k].i;
    out[2 * k + 1] = found[k].j;
  }
  nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<std::uint32_t*>(p); });
  return nb::cast(HostArray<std::uint32_t, kAny, 2>(out, {found.size(), 2}, owner));
}

}  // namespace

void bind_simulation(nb::module_& m, const char* name, const char* pairs_name) {
  nb::register_exception_translator(translate);
  m.def(pairs_name, &pairs, nb::arg("xyzr"), nb::arg("algorithm"), nb::arg("backend"), nb::arg("margin"));
  nb::class_<PySimulation>(m, name)
      .def(nb::init<const std::string&, const std::string&, const std::string&, const std::vector<std::string>&,
                    const std::string&, int>(),
           nb::arg("source"), nb::arg("label"), nb::arg("stem"), nb::arg("overrides"), nb::arg("backend"),
           nb::arg("threads"))
      .def("step", &PySimulation::step, nb::arg("n"))
      .def("view", &PySimulation::view, nb::arg("what"))
      .def("copy", &PySimulation::copy, nb::arg("what"))
      .def("assign", &PySimulation::assign, nb::arg("what"), nb::arg("values"))
      .def("contacts", &PySimulation::contacts)
      .def("kinetic_energy", &PySimulation::kinetic_energy)
      .def("write_frame", &PySimulation::write_frame, nb::arg("dir"), nb::arg("overwrite"))
      .def("end_frames", &PySimulation::end_frames, nb::arg("dir").none())
      .def("checkpoint", &PySimulation::checkpoint, nb::arg("path"), nb::arg("record") = std::string())
      .def("restart", &PySimulation::restart, nb::arg("path"))
      .def("reference", &PySimulation::reference)
      .def("totals", &PySimulation::totals)
      .def("end_figures", &PySimulation::end_figures)
      .def_prop_ro("size", &PySimulation::size)
      .def_prop_ro("on_device", &PySimulation::on_device)
      .def_prop_ro("renumbers", [](const PySimulation& s) { return s.sim().model().renumber_every > 0; })
      .def_prop_ro("time", [](const PySimulation& s) { return s.sim().time(); })
      .def_prop_ro("steps", [](const PySimulation& s) { return s.sim().steps(); })
      .def_prop_ro("dt", [](const PySimulation& s) { return s.sim().dt(); })
      .def_prop_ro("substeps", [](const PySimulation& s) { return s.sim().substeps(); })
      .def_prop_ro("duration", [](const PySimulation& s) { return s.scene().time.duration; })
      .def_prop_ro("total_steps", &PySimulation::total_steps)
      .def_prop_ro("name", [](const PySimulation& s) { return s.scene().name; })
      .def_prop_ro("output_dir", [](const PySimulation& s) { return s.scene().output.dir; })
      .def_prop_ro("materials", [](const PySimulation& s) {
        std::vector<std::string> names;
        for (const scene::Material& mat : s.scene().materials) names.push_back(mat.name);
        return names;
      })
      .def_prop_ro("pipeline", [](const PySimulation& s) { return s.sim().describe_pipeline(s.threads()); })
      .def_prop_ro("backend", [](const PySimulation& s) { return s.sim().backend_name(); })
      .def_prop_ro("backend_note", &PySimulation::backend_note)
      .def_prop_ro("precision", [](const PySimulation&) { return std::string(kRealName); })
      .def_prop_ro("warnings", &PySimulation::warnings)
      .def_prop_ro("max_overlap", [](const PySimulation& s) { return static_cast<double>(s.sim().last_step().max_overlap); })
      .def_prop_ro("rollbacks", [](const PySimulation& s) { return s.sim().rollbacks(); })
      .def_prop_ro("unswept_steps", [](const PySimulation& s) { return s.sim().unswept_kept(); });
}

}  // namespace marbles
