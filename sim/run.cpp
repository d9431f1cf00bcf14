#include "sim/run.hpp"

#include <algorithm>
#include <csignal>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>
#include <tuple>
#include <utility>

#include <nlohmann/json.hpp>

#include "broadphase/grid.hpp"
#include "core/device.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/format.hpp"
#include "core/parallel.hpp"
#include "narrowphase/contact_math.hpp"
#include "render/atomic_file.hpp"
#include "render/vtk_output.hpp"
#include "sim/checkpoint.hpp"
#include "sim/limits.hpp"
#include "sim/output.hpp"
#include "sim/particles.hpp"
#include "sim/progress.hpp"
#include "sim/reference.hpp"
#include "sim/scene.hpp"
#include "sim/settings_check.hpp"
#include "sim/signals.hpp"
#include "sim/simulation.hpp"
#include "sim/version.hpp"
#include "sim/world.hpp"

namespace marbles {

broadphase::Backend select_backend(BackendChoice choice, std::ostream& log) {
  switch (choice) {
    case BackendChoice::cpu:
      return broadphase::Backend::cpu;
    case BackendChoice::cuda: {
      const DeviceInfo& dev = cuda_device();
      if (!dev.available) throw RuntimeFailure("--backend cuda: no CUDA device (" + dev.why_not + ")");
      return broadphase::Backend::cuda;
    }
    case BackendChoice::automatic:
      break;
  }
  const DeviceInfo& dev = cuda_device();
  if (dev.available) {
    log << "backend: CUDA on " << dev.name << " (auto)\n";
    return broadphase::Backend::cuda;
  }
  // A machine without a GPU (no driver: cudaGetDeviceCount fails) is the common case: say so plainly.
  const bool none = dev.why_not == "no CUDA device" || dev.why_not.rfind("cudaGetDeviceCount failed", 0) == 0;
  log << "backend: CPU (" << (none ? std::string("no CUDA device") : dev.why_not) << ")\n";
  return broadphase::Backend::cpu;
}

namespace {

// The time now, UTC, ISO 8601 to the second.
std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text;
}

// A depth in radii as the warnings say it: three digits, whole from 100 on.
std::string radii_text(double radii) {
  return radii < 100 ? significant(radii, 3) : std::to_string(std::llround(radii));
}

// The initial-overlap warnings, where spheres start deeper than 1 % of the
// smaller radius into each other or a wall: the solver pushes them apart
// over the first steps, faster than a pile settles, which a user who meant
// them to touch should know.
void warn_initial_overlaps(const StateOverlaps& start, std::ostream& err) {
  for (const std::string& w : initial_overlap_warnings(start)) err << "warning: " << w << "\n";
}

}  // namespace

std::vector<std::string> initial_overlap_warnings(const StateOverlaps& o) {
  std::vector<std::string> out;
  if (o.pairs > 0)
    out.push_back(std::to_string(o.pairs) +
                  " pair(s) of spheres start overlapping by more than 1% of the smaller radius; the solver pushes "
                  "them apart over the first steps");
  if (o.walls > 0)
    out.push_back(std::to_string(o.walls) + " sphere(s) start overlapping a wall by more than 1% of their radius, "
                  "up to " + radii_text(o.deepest_wall) + " radii deep (a centre beyond the wall counts its whole "
                  "radius too); the solver pushes them back over the first steps");
  return out;
}

namespace {

// `text` as one word of a POSIX shell: as it is where it holds only
// characters no shell treats apart, else in single quotes.
std::string shell_word(const std::string& text) {
  const bool plain = !text.empty() && text.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                                                             "0123456789_./=:,+-@%") == std::string::npos;
  if (plain) return text;
  std::string quoted = "'";
  for (const char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// A path as one word of a shell command that reads no option from it: a
// relative one starting with '-' behind "./".
std::string path_word(const std::string& path) { return shell_word(path.starts_with('-') ? "./" + path : path); }

// The command that resumes this run from the checkpoint at `path`: its
// scene, folder, overrides and duration (the checkpoint holds the scene as
// they made it), its limits, what it writes, and the backend, broad phase
// and threads it was given.
std::string resume_command(const RunOptions& options, const std::string& out_dir, const std::string& path) {
  std::string command = "marbles run " + path_word(options.scene_path) + " --out " + path_word(out_dir);
  for (const std::string& o : options.overrides) command += " --set " + shell_word(o);
  if (options.duration) command += " --duration " + shortest(*options.duration);
  for (const std::string& l : options.limits) command += " --limit " + shell_word(l);
  if (options.summary_only) command += " --summary-only";
  if (!options.render) command += " --no-render";
  if (options.backend != BackendChoice::automatic)
    command += options.backend == BackendChoice::cuda ? " --backend cuda" : " --backend cpu";
  if (options.algorithm == broadphase::Algorithm::seed) command += " --broadphase seed";
  if (options.threads > 0) command += " --threads " + std::to_string(options.threads);
  return command + " --restart " + path_word(path);
}

// A checkpoint in another run's folder, resumed into a new one, brings that
// folder's frames up to its step (RunOutput::resume): only where they are
// its own run's. The frame at the checkpoint's step (or the first, where the
// step has none) must hold as many spheres as the checkpoint, and at the
// step the very positions; else the folder is another run's (a checkpoint
// copied beside it) and the resume is refused, naming the frame.
void check_frames_beside(const std::filesystem::path& from, const World& world, std::uint64_t step, int every,
                         int contacts_every, const std::string& restart) {
  // Every file the resume will copy (RunOutput::resume) whole, before anything is written.
  const std::string copied = "a resume copies the files of its checkpoint's run up to its step, which must be whole; "
                             "resume from a copy of the checkpoint kept outside a run's checkpoints/ folder (it "
                             "brings no files), or mend the run's folder";
  for (const auto& [folder, prefix, n] : {std::tuple{"frames", "frame", every}, std::tuple{"walls", "walls", every},
                                          std::tuple{"contacts", "contacts", contacts_every}}) {
    if (n <= 0) continue;
    for (std::uint64_t k = 0; k * static_cast<std::uint64_t>(n) <= step; ++k) {
      const std::filesystem::path p = from / folder / render::numbered_vtp(prefix, static_cast<std::size_t>(k));
      std::error_code ec;
      if (std::filesystem::is_regular_file(p, ec)) render::require_whole_vtk(p, copied);  // what the resume copies
    }
  }
  if (every <= 0) return;
  const auto frame_at = [&](std::uint64_t k) {
    return from / "frames" / render::numbered_vtp("frame", static_cast<std::size_t>(k));
  };
  const std::uint64_t at = step / static_cast<std::uint64_t>(every);
  std::error_code ec;
  const bool on_step = step % static_cast<std::uint64_t>(every) == 0 && std::filesystem::is_regular_file(frame_at(at), ec);
  const std::filesystem::path frame = on_step ? frame_at(at) : frame_at(0);
  if (!std::filesystem::is_regular_file(frame, ec)) return;
  const render::Snapshot s = render::read_vtp(frame);
  const std::string remedy = "; resume from a copy of the checkpoint kept outside a run's checkpoints/ folder (it "
                             "brings no frames), or into the folder of its own run";
  if (s.size() != world.size())
    throw InputError(SourceLocation{restart, 0, 0}, "--restart",
                     "the frames beside this checkpoint are another run's: " + frame.string() + " holds " +
                         std::to_string(s.size()) + " spheres, the checkpoint " + std::to_string(world.size()) + remedy);
  if (!on_step) return;
  for (std::size_t i = 0; i < s.size(); ++i)
    if (!(s.position[i] == world.position[i]))
      throw InputError(SourceLocation{restart, 0, 0}, "--restart",
                       "the frames beside this checkpoint are another run's: " + frame.string() +
                           ", at the checkpoint's step " + std::to_string(step) + ", holds sphere " + std::to_string(i) +
                           " elsewhere than the checkpoint does (or was written at another output.vtk.every)" +
                           remedy);
}

// The risky-settings warnings (sim/settings_check.hpp), one line each.
void warn_risky_settings(const scene::Scene& sc, const scene::GeneratedParticles& particles, std::ostream& err) {
  for (const std::string& w : risky_settings(sc, particles, sizeof(real) == 4)) err << "warning: " << w << "\n";
}

}  // namespace

std::string json_text(const nlohmann::ordered_json& document) {
  // Text that is not UTF-8 (a path's bytes) is replaced, not refused; a
  // non-finite number is written as null.
  return document.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

CheckedScene checked_scene(const std::string& scene_path, const std::vector<std::string>& overrides) {
  CheckedScene c{scene::load_scene(scene_path, overrides), {}, {}};
  c.particles = scene::generate_particles(c.scene);
  c.world = make_world(c.scene, c.particles);  // masses and inertias in range for the precision
  // The reference's own rules (the sphere it names, the effects it needs), as `run` holds them.
  if (c.scene.reference.kind != scene::ReferenceSpec::Kind::none) ReferenceProbe(c.scene, c.world);
  return c;
}

int check_scene(const std::string& scene_path, const std::vector<std::string>& overrides, std::ostream& out,
                std::ostream& err, bool pipeline) {
  CheckedScene checked = checked_scene(scene_path, overrides);
  const scene::Scene& sc = checked.scene;
  // The folder `run` would write into, held to run's rule (without --out).
  if (const std::string why = folder_problem(sc.output.dir); !why.empty())
    throw InputError(sc.output.dir_where, "output.dir", why);
  const scene::GeneratedParticles& particles = checked.particles;
  const World& world = checked.world;
  out << scene_path << ": ok (" << particles.size() << " spheres, " << sc.materials.size() << " material(s), "
      << sc.walls.size() << " wall(s), " << std::llround(sc.time.duration / sc.time.dt) << " steps of "
      << sc.time.dt << " s, " << kRealName << ")\n";
  warn_risky_settings(sc, particles, err);
  const StepModel model = compile_step_model(sc, broadphase::Algorithm::home);
  warn_initial_overlaps(state_overlaps(world, model, model.wall_shapes, kStartOverlapTolerance), err);
  // The stages `marbles run --backend cpu` would build, as its run prints them.
  if (pipeline) out << Simulation(sc, std::move(checked.world), broadphase::Backend::cpu).describe_pipeline();
  return 0;
}

// An overlap at the end of a run past this fraction of a radius is warned
// of (a settled pile ends near the projection's slop, 0.5 %).
constexpr double kDeepAtTheEnd = 0.1;

int run_scene(const RunOptions& options, std::ostream& out, std::ostream& err) {
  scene::Scene sc = scene::load_scene(options.scene_path, options.overrides, options.duration);
  if (options.out_dir) sc.output.dir = *options.out_dir;
  const scene::OutputSpec written_output = sc.output;  // the cadences the folder's earlier files were written at
  if (options.summary_only) {  // checkpoints stay: a stopped run resumes from them
    sc.output.vtk_every = 0;
    sc.output.contacts_every = 0;
    sc.output.render.enabled = false;
    sc.output.movie.enabled = false;
  }
  // A folder that cannot be made (a file in its place, a link to nothing):
  // named by where it was given, before anything is made.
  if (const std::string why = folder_problem(sc.output.dir); !why.empty())
    throw InputError(options.out_dir ? SourceLocation{} : sc.output.dir_where,
                     options.out_dir ? "--out" : "output.dir", why);
  // One run at a time in the folder, from before the check for an earlier run on.
  const RunFolderLock folder_lock(sc.output.dir, options.out_dir ? "--out" : "output.dir");
  // A checkpoint's run folder, where it lies in one (OUTDIR/checkpoints/
  // step_N.mck): a restart elsewhere copies the output before the
  // checkpoint's step from it.
  std::filesystem::path restart_from;
  bool restart_here = false;
  if (options.restart) {
    std::error_code ec;
    const std::filesystem::path at = std::filesystem::absolute(*options.restart, ec);
    if (!ec && at.parent_path().filename() == "checkpoints") restart_from = at.parent_path().parent_path();
    restart_here = !restart_from.empty() &&
                   std::filesystem::weakly_canonical(restart_from, ec) ==
                       std::filesystem::weakly_canonical(std::filesystem::absolute(sc.output.dir, ec), ec);
  }
  // An earlier run's output in the folder: replaced with --overwrite, else
  // refused (stale frames would mix with new ones). A restart goes on in
  // its own run's folder; one from a checkpoint kept elsewhere (not in a
  // run's checkpoints/) brings no output, and is held to this rule.
  const std::vector<std::filesystem::path> earlier =
      restart_here ? std::vector<std::filesystem::path>{} : earlier_run_files(sc.output.dir);
  if (!earlier.empty() && !options.overwrite) {
    std::string set_aside;  // where a run that did not end left what it replaced (it may be the rest of this one)
    for (const std::filesystem::path& folder : folders_of_ended_processes(sc.output.dir, ".earlier-run-"))
      set_aside += "; " + folder.string() + " holds files set aside by a run that did not end";
    throw InputError(SourceLocation{}, options.out_dir ? "--out" : "output.dir",
                     earlier_run_text(sc.output.dir, earlier) + set_aside +
                         "; --overwrite replaces it, or choose another folder");
  }
  const scene::GeneratedParticles particles = scene::generate_particles(sc);
  warn_risky_settings(sc, particles, err);
  std::ostringstream quiet_sink;  // --quiet: only the summary
  set_thread_count(options.threads > 0 ? options.threads : default_thread_count());
  const std::string started_at = utc_now();
  const broadphase::Backend backend = select_backend(options.backend, options.quiet ? quiet_sink : out);

  World world = make_world(sc, particles);
  // The seed's grid keys every cell of the spheres' box: spheres too far
  // apart for it are refused here, naming the option (they ended the first
  // step, exit 1); the default broad phase hashes its cells and takes them.
  if (options.algorithm == broadphase::Algorithm::seed && world.size() > 0) {
    try {
      broadphase::choose_grid(broadphase::bounds_of({world.position.data(), world.radius.data(), world.size()}), 0);
    } catch (const broadphase::SpanTooLarge&) {
      throw InputError(SourceLocation{}, "--broadphase",
                       std::string("seed: ") + broadphase::SpanTooLarge::kWhy +
                           "; --broadphase home, the default, takes them");
    }
  }
  // The reference's rules before anything runs or is printed (the probe itself is made from the step's world).
  if (sc.reference.kind != scene::ReferenceSpec::Kind::none) ReferenceProbe(sc, world);

  Simulation sim(sc, std::move(world), backend, options.algorithm);
  sim.set_watchdog(true);  // measures the start (and a restart below, again)
  warn_initial_overlaps(sim.watched_overlaps(), err);
  const render::Bounds view = render::scene_bounds(make_snapshot(sim), sim.walls());  // before any restart
  if (!options.quiet) out << sc.name << ": " << sim.world().size() << " spheres\n" << sim.describe_pipeline();

  const std::uint64_t total_steps = static_cast<std::uint64_t>(std::llround(sc.time.duration / sc.time.dt));
  std::optional<ReferenceProbe> probe;
  if (sc.reference.kind != scene::ReferenceSpec::Kind::none) probe.emplace(sc, sim.world());
  const std::uint64_t probe_every = probe ? probe->every(total_steps) : 0;
  const std::uint64_t fingerprint = sc.fingerprint;

  RunTotals totals;
  totals.energy_start = sim.world().kinetic_energy();
  const bool render = options.render;
  if (options.restart) {
    Checkpoint c =
        read_checkpoint(*options.restart, fingerprint, scene_fingerprint(options.scene_path, options.overrides));
    check_checkpoint_fits(c, *options.restart, "--restart", sim.world(), sim.ids(), sc.materials.size(),
                          sim.model().wall_shapes);
    if (c.steps > total_steps)
      throw InputError(SourceLocation{*options.restart, 0, 0}, "--restart",
                       "the checkpoint is at step " + std::to_string(c.steps) + ", past this run's end at step " +
                           std::to_string(total_steps) + " (a duration of " + shortest(sc.time.duration) +
                           " s: give a longer --duration)");
    sim.restore(c.world, c.state, c.steps, c.ids);
    totals = c.totals;
    if (probe) probe->resume(c.probe);
    if (!options.quiet) out << "resumed from " << *options.restart << " at step " << c.steps << "\n";
    if (!restart_here && !restart_from.empty())  // before anything is written in the new folder
      check_frames_beside(restart_from, sim.world(), sim.steps(), sc.output.vtk_every, sc.output.contacts_every,
                          *options.restart);
  }

  // Test hooks: MARBLES_FAULT_NAN_STEP=N (the first try of step N goes
  // non-finite) or N:all (every try); MARBLES_FAULT_KICK_STEP=N[:all] (sphere
  // 0 kicked to 100 radii per step), MARBLES_FAULT_ESCAPE_STEP=N[:all]
  // (sphere 0 put 10 radii beyond the first wall).
  const std::pair<const char*, Simulation::Fault> hooks[] = {{"MARBLES_FAULT_NAN_STEP", Simulation::Fault::nan},
                                                             {"MARBLES_FAULT_KICK_STEP", Simulation::Fault::kick},
                                                             {"MARBLES_FAULT_ESCAPE_STEP", Simulation::Fault::escape}};
  for (const auto& [name, kind] : hooks)
    if (const char* fault = std::getenv(name))
      sim.inject_fault_at(std::strtoull(fault, nullptr, 10), std::strstr(fault, ":all") != nullptr, kind);

  // SIGINT, SIGTERM: end the step in progress, checkpoint, exit 1. Taken from
  // before the earlier run's files are set aside (a stop there would split
  // them) and the start's output (its first image may take long) on: a stop
  // asked there ends the first step.
  const StopRequests stop;
  // --overwrite, once the scene is known to run: the earlier run set aside
  // until this one stands; a resume in its own folder, the files of the
  // steps it makes again (and of any beyond its end).
  // A --summary-only resume writes no frame, image or thermo row: the
  // earlier run's up to its end stay (the same run's), those past it go.
  const std::uint64_t kept_to = options.summary_only ? std::max(total_steps, sim.steps()) : sim.steps();
  const ReplacedFiles replaced = restart_here ? run_files_past(sc.output.dir, sim.steps(), written_output, kept_to)
                                              : ReplacedFiles{earlier, {}};
  EarlierRunAside earlier_aside(sc.output.dir, replaced.later, replaced.rewritten, err, [&] {
    if (restart_here) cut_listings(sc.output.dir, kept_to, written_output);
  });
  // Test hook: MARBLES_FAULT_SIGNAL=NAME@N raises SIGNAME (SEGV, ABRT, INT, TERM) after step N (0: after the
  // start's output; `render`: as a resumed run's closing render begins).
  int fault_signal = 0;
  std::uint64_t fault_signal_step = 0;
  bool fault_at_render = false;
  if (const char* hook = std::getenv("MARBLES_FAULT_SIGNAL")) {
    const std::string text = hook;
    const std::size_t at = text.find('@');
    const std::string name = text.substr(0, at);
    fault_signal = name == "SEGV" ? SIGSEGV : name == "ABRT" ? SIGABRT : name == "INT" ? SIGINT : name == "TERM" ? SIGTERM : 0;
    fault_at_render = at != std::string::npos && text.substr(at + 1) == "render";
    if (at != std::string::npos) fault_signal_step = fault_at_render ? ~std::uint64_t{0} : std::strtoull(text.c_str() + at + 1, nullptr, 10);
  }
  RunOutput output(sc, sc.output.dir, sim.walls(), render, err, options.restart.has_value(), &view);
  // A stop during a resumed run's closing render ends the render (the run is whole by then).
  output.stop_render_when([&stop, fault = fault_at_render ? fault_signal : 0]() mutable {
    if (fault != 0) std::raise(std::exchange(fault, 0));
    return stop.received();
  });
  auto save_checkpoint = [&](const std::string& path) {
    output.flush();  // a resume from it reads thermo.csv's rows up to its step
    write_checkpoint(path, {fingerprint, sim.steps(), sim.world(), sim.save_state(), totals,
                            probe ? probe->progress() : std::vector<double>{}, sim.ids()});
  };
  Progress progress(!options.quiet);
  double step_seconds = 0;
  const std::uint64_t first_step = sim.steps();
  // The checkpoint's run folder: OUTDIR of OUTDIR/checkpoints/step_NNNNNN.mck.
  if (options.restart) output.resume(sim.steps(), sim.dt(), restart_here ? std::filesystem::path{} : restart_from);
  else output.write(sim);
  if (fault_signal != 0 && fault_signal_step == 0) std::raise(fault_signal);
  const auto t0 = std::chrono::steady_clock::now();
  while (sim.steps() < total_steps) {
    const auto s0 = std::chrono::steady_clock::now();
    try {
      sim.step();
    } catch (const WatchdogFailure& e) {
      // The step is back at its start: that is the last good state.
      progress.finish();
      const std::string path = checkpoint_path(sc.output.dir, sim.steps());
      save_checkpoint(path);
      prune_checkpoints(sc.output.dir, sc.output.checkpoint_keep);  // the newest K, this one among them
      throw RuntimeFailure(std::string(e.what()) + "; the last good state is in " + printable_path(path) +
                           " (a run resumed from it with the same settings fails there again: more time.substeps or "
                           "a smaller time.dt, from the start, may get past it)");
    }
    step_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - s0).count();
    for (const std::string& why : sim.last_rollbacks()) {
      progress.finish();
      err << "watchdog: step " << sim.steps() << ": " << why << "; rolled back and redone with the substep halved and the sweeps doubled\n";
    }
    if (!sim.last_kept().empty()) {
      progress.finish();
      err << "watchdog: step " << sim.steps() << ": " << sim.last_kept()
          << " (more time.substeps sweep what the solve sets moving)\n";
    }
    totals.add(sim.last_step(), sim.substeps(), sim.last_rollbacks().size(), !sim.last_kept().empty());
    if (probe && sim.steps() % probe_every == 0) probe->sample(sim.time(), sim.world());
    if (output.due(sim.steps())) {
      progress.finish();
      output.write(sim, step_seconds);
    }
    if (sc.output.checkpoint_every > 0 && sim.steps() % static_cast<std::uint64_t>(sc.output.checkpoint_every) == 0) {
      save_checkpoint(checkpoint_path(sc.output.dir, sim.steps()));
      prune_checkpoints(sc.output.dir, sc.output.checkpoint_keep);
    }
    progress.update(sim.time(), sc.time.duration, sim.steps(), total_steps);
    if (fault_signal != 0 && sim.steps() == fault_signal_step) std::raise(fault_signal);
    if (const int sig = stop.received()) {
      progress.finish();
      const std::string path = checkpoint_path(sc.output.dir, sim.steps());
      if (!std::filesystem::exists(path)) save_checkpoint(path);
      prune_checkpoints(sc.output.dir, sc.output.checkpoint_keep);  // the newest K, this one among them
      earlier_aside.discard();  // this run resumes in its place
      throw RuntimeFailure(std::string("stopped by ") + signal_name(sig) + " after step " + std::to_string(sim.steps()) +
                           " of " + std::to_string(total_steps) + "; the state is in " + printable_path(path) +
                           " (resume with " +
                           resume_command(options, sc.output.dir, path) + ")");
    }
  }
  progress.finish();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string written = output.finish();

  // Per-step means over the steps this run and the run it resumed made.
  const double steps = std::max<double>(1, static_cast<double>(sim.steps()));
  const double candidate_sum = totals.candidate_sum, contact_sum = totals.contact_sum, deepest = totals.deepest;
  const double e_start = totals.energy_start;
  const double steps_run = std::max<double>(1, static_cast<double>(sim.steps() - first_step));
  const double e_end = sim.world().kinetic_energy();
  std::optional<ReferenceResult> reference;
  if (probe) reference = probe->finish(sim.time(), sim.world());
  nlohmann::ordered_json summary;
  summary["scene"] = sc.path;
  summary["scene_name"] = sc.name;
  summary["marbles_version"] = kMarblesVersion;
  summary["commit"] = kMarblesCommit;
  summary["command_line"] = options.command_line;
  summary["date"] = started_at;
  summary["threads"] = thread_count();
  summary["units"] = {{"length", "m"}, {"time", "s"}, {"mass", "kg"}, {"energy", "J"}, {"velocity", "m/s"},
                      {"angular_velocity", "rad/s"}};
  summary["materials"] = nlohmann::ordered_json::array();
  for (const scene::Material& m : sc.materials) summary["materials"].push_back(m.name);
  summary["spheres"] = sim.world().size();
  summary["backend"] = backend == broadphase::Backend::cuda ? "cuda" : "cpu";
  summary["precision"] = kRealName;
  summary["steps"] = sim.steps();
  summary["substeps"] = sim.substeps();
  summary["iterations"] = sc.solver.iterations;
  summary["integrator"] = sc.solver.integrator;
  if (sim.model().closing_solve()) summary["closing_iterations"] = sc.solver.closing_iterations;
  summary["speculative"] = sc.solver.speculative;
  summary["dt"] = sim.dt();
  summary["simulated_time"] = sim.time();
  summary["wall_time"] = wall;
  summary["mean_ms_per_step"] = 1e3 * step_seconds / steps_run;
  summary["mean_candidate_pairs"] = candidate_sum / steps;
  summary["mean_contacts"] = contact_sum / steps;
  summary["max_overlap"] = deepest;
  summary["max_overlap_end"] = totals.overlap_end;
  summary["rollbacks"] = static_cast<std::uint64_t>(totals.rollbacks);  // a count (held as a double in the checkpoint)
  summary["unswept_steps"] = static_cast<std::uint64_t>(totals.unswept);
  summary["kinetic_energy_start"] = e_start;
  summary["kinetic_energy_end"] = e_end;
  for (const EndFigure& f : end_figures(sim.world())) summary[f.name] = f.value;
  if (reference)
    summary["reference"] = {{"kind", reference->kind},
                            {"expected", reference->expected},
                            {"measured", reference->measured},
                            {"error", reference->error},
                            {"note", reference->note}};
  std::filesystem::create_directories(sc.output.dir);
  const std::string summary_path = (std::filesystem::path(sc.output.dir) / "summary.json").string();
  render::write_file_atomic(summary_path, json_text(summary));
  // A closing render that failed (a full disk) left part of the images: the
  // earlier run's that this one replaced stay aside, whole (the note says where).
  if (!output.render_failed()) earlier_aside.discard();
  if (const int sig = output.stopped_render())
    throw RuntimeFailure(std::string("stopped by ") + signal_name(sig) + " during the closing render: the run is whole (" +
                         summary_path + ") but its images are not; `marbles render " + sc.output.dir +
                         "` draws them from the frames");

  out << std::setprecision(4) << sc.name << ": " << sim.steps() << " steps, " << sim.time() << " s simulated in "
      << wall << " s (" << 1e3 * step_seconds / steps_run << " ms/step; " << candidate_sum / steps
      << " candidate pairs, " << contact_sum / steps << " contacts per substep); largest overlap "
      << 100 * deepest << " % of a radius (" << 100 * totals.overlap_end << " % at the end); kinetic energy " << e_start
      << " -> " << e_end << " J"
      << (totals.rollbacks > 0 || totals.unswept > 0
              ? "; watchdog: " + std::to_string(static_cast<std::uint64_t>(totals.rollbacks)) + " rollback(s), " +
                    std::to_string(static_cast<std::uint64_t>(totals.unswept)) + " step(s) kept unswept"
              : std::string())
      << "\n"
      << (reference && std::isfinite(reference->error)
              ? "reference " + reference->kind + ": error " + significant(100 * reference->error, 10) + " %\n"
              : std::string())
      << "output: " << printable_path(sc.output.dir) << "  (" << written << "summary.json)\n";
  // Spheres that end deep in each other or a wall: the run is whole, but
  // its state is not what rigid spheres do; said, not left to summary.json.
  // Measured on the state as it ends, of what the solver moves (glued
  // spheres set into a wall on purpose are not its doing).
  if (totals.overlap_end > kDeepAtTheEnd) {
    const double deepest = state_overlaps(sim.world(), sim.model(), sim.wall_shapes(), 0).deepest_free();
    if (deepest > kDeepAtTheEnd)
      err << "warning: spheres end overlapping by up to " << significant(100 * deepest, 4)
          << " % of a radius: the solve did not hold them apart (a heavy sphere on light ones, or too few "
             "time.substeps or solver.iterations for the load; see the warnings above)\n";
  }
  return 0;
}

int print_pairs(const std::string& csv_path, const std::string& algorithm, BackendChoice choice, double margin,
                std::ostream& out, std::ostream& err) {
  const scene::GeneratedParticles spheres = scene::read_spheres_csv(csv_path);
  const SpheresIn in{spheres.position.data(), spheres.radius.data(), spheres.size()};
  std::vector<broadphase::Pair> pairs;
  if (algorithm == "brute") {
    broadphase::brute_force_pairs(in, static_cast<real>(margin), pairs);
  } else {
    const broadphase::Backend backend = select_backend(choice, err);
    const auto alg = algorithm == "home" ? broadphase::Algorithm::home : broadphase::Algorithm::seed;
    auto bp = backend == broadphase::Backend::cuda ? broadphase::make_subdivision_cuda(alg)
                                                   : broadphase::make_subdivision_cpu(alg);
    try {
      bp->find_pairs(in, static_cast<real>(margin), pairs);
    } catch (const broadphase::SpanTooLarge&) {  // a property of the input, not a failure of the run
      throw InputError(SourceLocation{csv_path, 0, 0}, "--algorithm",
                       algorithm + ": " + broadphase::SpanTooLarge::kWhy + "; --algorithm home or brute take them");
    }
  }
  std::sort(pairs.begin(), pairs.end());
  std::string text;
  text.reserve(pairs.size() * 12);
  for (const auto& p : pairs) {
    text += std::to_string(p.i);
    text += ' ';
    text += std::to_string(p.j);
    text += '\n';
  }
  out << text;
  return 0;
}

}  // namespace marbles
