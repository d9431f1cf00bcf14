// sim/cli.cpp — the `marbles` command line (sim/main.cpp picks the precision
// and calls cli_main of the library built for it).
//
// Exit codes: 0 success; 2 bad input (scene, CSV or arguments; the message
// names file:line:column and key, or the argument); 1 failure while running.
#include <CLI/CLI.hpp>

#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <new>
#include <set>
#include <iostream>
#include <string>
#include <vector>

#include "bench/broadphase_bench.hpp"
#include "bench/step_bench.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/format.hpp"
#include "core/parallel.hpp"
#include "render/atomic_file.hpp"
#include "render/camera.hpp"
#include "render/color_map.hpp"
#include "render/frame_output.hpp"
#include "sim/cli.hpp"
#include "sim/checkpoint.hpp"
#include "sim/limits.hpp"
#include "sim/particles.hpp"
#include "sim/output.hpp"
#include "sim/run.hpp"
#include "sim/scene.hpp"
#include "sim/scene_yaml.hpp"
#include "sim/signals.hpp"
#include "sim/study.hpp"

namespace {

const std::map<std::string, marbles::BackendChoice> kBackends{
    {"auto", marbles::BackendChoice::automatic},
    {"cpu", marbles::BackendChoice::cpu},
    {"cuda", marbles::BackendChoice::cuda}};

// Numbers given on the command line: written as a scene writes them (no
// hexadecimal, which CLI11's conversion would take: 0x10 as 16) and finite
// (CLI11 reads "nan").
const CLI::Validator kFinite(
    [](std::string& text) {
      double v = 0;
      if (!marbles::scene::detail::parse_double(text, v)) return "expected a number, got " + text;
      return std::isfinite(v) ? std::string() : "must be a finite number, got " + text;
    },
    "FINITE");

// Lengths that reach the step in its precision (after kFinite): within it.
const CLI::Validator kWithinReal(
    [](std::string& text) {
      const double v = std::strtod(text.c_str(), nullptr);
      return std::abs(v) > static_cast<double>(std::numeric_limits<marbles::real>::max())
                 ? "out of range for " + std::string(marbles::kRealName) + " precision, got " + text
                 : std::string();
    },
    "WITHIN-PRECISION");

// Counts and amounts at or above 0, said in plain words (CLI11's own ranges
// print the largest double in full). A NaN is kFinite's to refuse, in its
// words, and text that is no number the conversion's.
CLI::Validator at_least_zero(bool strictly) {
  return CLI::Validator(
      [strictly](std::string& text) {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        const bool below = strictly ? v <= 0 : v < 0;
        return end != text.c_str() && below ? std::string(strictly ? "must be > 0" : "must be >= 0") + ", got " + text
                                            : std::string();
      },
      strictly ? "POSITIVE" : "NON-NEGATIVE");
}
const CLI::Validator kPositive = at_least_zero(true);
// A sphere count past 64 bits, said as typed (the conversion would make it
// 18446744073709551615); counts within are held to --limit spheres after
// parsing (check_bench_counts).
const CLI::Validator kCount(
    [](std::string& text) {
      std::uint64_t v = 0;
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
      return ec == std::errc::result_out_of_range && end == text.data() + text.size()
                 ? "must be <= " + marbles::shortest(marbles::limits().spheres) +
                       " (--limit spheres=N raises it), got " + text
                 : std::string();
    },
    "COUNT");
const CLI::Validator kNonNegative = at_least_zero(false);
// A whole number as a person writes one: decimal digits, a sign at most (CLI11's
// conversion took 0x10 as 16, 0b11 as 3 and " 100" as 100, where the scene's
// numbers and --seed refuse them), passed on without its leading zeros (which
// the conversion reads as octal: 010 as 8).
const CLI::Validator kWhole(
    [](std::string& text) {
      const std::size_t digits = !text.empty() && (text[0] == '+' || text[0] == '-') ? 1 : 0;
      const bool whole = digits < text.size() && text.find_first_not_of("0123456789", digits) == std::string::npos;
      if (!whole) return "expected a whole number, got '" + text + "'";
      const std::size_t first = std::min(text.find_first_not_of('0', digits), text.size() - 1);
      text.erase(digits, first - digits);
      return std::string();
    },
    "WHOLE");
// Timed calls or steps a benchmark keeps every one of (for their median).
constexpr int kMostRepeats = 1000000;
// A seed: a whole number 0 ... 2^64 - 1, as written (no wrap of -1, no
// saturation past the top).
const CLI::Validator kSeed(
    [](std::string& text) {
      std::uint64_t v = 0;
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
      if (ec != std::errc() || end != text.data() + text.size())
        return "must be a whole number from 0 to 18446744073709551615, got " + text;
      text = std::to_string(v);  // as read here, in decimal (not "010" as octal)
      return std::string();
    },
    "SEED");

// A folder the command writes into: one, or nothing yet (made then, with
// the folders above it that are not there: the nearest one there must be a
// folder).
const CLI::Validator kFolderOrNew([](std::string& text) { return ::marbles::folder_problem(text); }, "FOLDER");

// `--set key.path=value`, repeatable; one value per `--set`.
void add_set_option(CLI::App* command, std::vector<std::string>& overrides) {
  command->add_option("--set", overrides,
                      "override a scene value: key.path=value, e.g. time.dt=5e-4, particles[0].random.count=500, "
                      "gravity=[0,0,-1] (repeatable)")
      ->allow_extra_args(false);
}

// `--limit NAME=VALUE`, repeatable: raises a guard (sim/limits.hpp).
void add_limit_option(CLI::App* command, std::vector<std::string>& limits) {
  command->add_option("--limit", limits,
                      "raise a guard: scene_mib, materials, substeps, spheres (per block), memory (fraction of the "
                      "available memory) or study_runs, e.g. spheres=2e9 (repeatable)")
      ->allow_extra_args(false);
}

// A benchmark's sphere counts, held to the guards a scene's block is held
// to (--limit spheres, memory) before anything is made.
void check_bench_counts(const std::vector<std::size_t>& counts) {
  for (const std::size_t n : counts) {
    if (static_cast<double>(n) > marbles::limits().spheres)
      throw marbles::InputError(marbles::SourceLocation{}, "--n",
                                "must be <= " + marbles::shortest(marbles::limits().spheres) +
                                    " (--limit spheres=N raises it), got " + std::to_string(n));
    marbles::scene::check_sphere_budget(static_cast<double>(n), marbles::SourceLocation{}, "--n");
  }
}

// The --precision option as every command that runs a scene takes it.
void add_precision_option(CLI::App* cmd, std::string& precision) {
  cmd->add_option("--precision", precision, "float|double: the type the run computes in (overrides solver.precision)")
      ->check(CLI::IsMember({"float", "double"}));
}

// A list option given only delimiters ("--effects ,"): CLI11 reads no item
// from it and then takes the next argument as the list, so "--effects ,
// --n 5" named an effect "--n". Refused here, before the parse, by the
// option's name.
void refuse_empty_lists(int argc, char** argv) {
  static const std::vector<std::string> kLists{"--effects"};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    for (const std::string& name : kLists) {
      std::string value;
      if (a == name && i + 1 < argc) value = argv[i + 1];
      else if (a.rfind(name + "=", 0) == 0) value = a.substr(name.size() + 1);
      else continue;
      if (value.find_first_not_of(',') == std::string::npos)
        throw marbles::InputError(marbles::SourceLocation{}, name,
                                  "names nothing in '" + value + "' (a list like gravity,walls)");
      // "gravity,,walls" or "gravity,": CLI11 passes over the empty item, as --vary refuses it.
      if (value.find(",,") != std::string::npos || value.front() == ',' || value.back() == ',')
        throw marbles::InputError(marbles::SourceLocation{}, name,
                                  "an empty item in '" + value + "' (a list like gravity,walls)");
    }
  }
}

// An option given an empty value (`--repeats ''`, `--camera=`): CLI11 takes
// it as the option's zero or empty string, past the option's checks
// (`--repeats ''` was 0 repeats, which --repeats 0 is refused for). Refused by
// name in the subcommands given, flags aside.
marbles::InputError empty_value(const std::string& option) {
  return marbles::InputError(marbles::SourceLocation{}, option, "an empty value (leave the option out for its default)");
}
void refuse_empty_values(const CLI::App& app) {
  for (const CLI::Option* option : app.get_options()) {
    if (option->get_type_size_min() == 0 || !option->nonpositional()) continue;
    for (const std::string& value : option->results())
      if (value.empty()) throw empty_value(option->get_name());
  }
  for (const CLI::App* sub : app.get_subcommands()) refuse_empty_values(*sub);
}

// The option given an empty value on the command line where it takes one
// (`--repeats ''`, `--margin=`), or "": where the option's own check fails
// on the empty text first ("Value  not in range 1 to 1000"), the parse's
// error is this one.
std::string option_given_nothing(const CLI::App& app, int argc, char** argv) {
  std::set<std::string> takes;  // --name and -n of the options of any command that take a value
  const std::function<void(const CLI::App&)> gather = [&](const CLI::App& a) {
    for (const CLI::Option* option : a.get_options())
      if (option->get_type_size_min() > 0 && option->nonpositional()) {
        for (const std::string& name : option->get_lnames()) takes.insert("--" + name);
        for (const std::string& name : option->get_snames()) takes.insert("-" + name);
      }
    for (const CLI::App* sub : a.get_subcommands([](const CLI::App*) { return true; })) gather(*sub);
  };
  gather(app);
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const std::size_t equals = a.find('=');
    if (a.starts_with("--") && equals + 1 == a.size() && takes.contains(a.substr(0, equals)))
      return a.substr(0, equals);
    if (takes.contains(a) && i + 1 < argc && argv[i + 1][0] == '\0') return a;
  }
  return "";
}

// A command CLI11 would answer only with "A subcommand is required"
// (`marbles runn x.yaml`, `marbles bench bogus`, `marbles --bogus`): named,
// with the nearest command. Help and version pass.
void refuse_unknown_commands(const CLI::App& app, int argc, char** argv) {
  const CLI::App* at = &app;
  std::string path = "marbles";
  for (int i = 1; i < argc && at->get_require_subcommand_min() > 0; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help" || a == "--help-all" || a == "--version") return;
    std::vector<std::string> names;
    const CLI::App* next = nullptr;
    for (const CLI::App* sub : at->get_subcommands([](const CLI::App*) { return true; })) {
      names.push_back(sub->get_name());
      if (sub->get_name() == a) next = sub;
    }
    if (!next)
      throw marbles::InputError(marbles::SourceLocation{}, path,
                                (a.rfind('-', 0) == 0 ? "unknown option '" + a + "' where a command goes"
                                                       : "unknown command '" + a + "'") +
                                    marbles::scene::detail::suggestion(a, names));
    at = next;
    path += " " + a;
  }
}

}  // namespace

namespace marbles {

std::string requested_precision(int argc, char** argv) {
  static const std::vector<std::string> kTakesValue{"--out", "--backend", "--broadphase", "--duration", "--set",
                                                    "--limit", "--threads"};
  std::string command, scene_path, from_set, restart;
  std::vector<std::string> sets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--precision" && i + 1 < argc) return argv[i + 1];
    if (a.rfind("--precision=", 0) == 0) return a.substr(12);
    if (a == "--set" && i + 1 < argc) {
      const std::string s = argv[++i];
      if (s.rfind("solver.precision=", 0) == 0) from_set = s.substr(17);
      sets.push_back(s);
      continue;
    }
    if (a == "--restart" && i + 1 < argc) {
      restart = argv[++i];
      continue;
    }
    if (std::find(kTakesValue.begin(), kTakesValue.end(), a) != kTakesValue.end()) {
      ++i;
      continue;
    }
    if (a.empty() || a[0] == '-') continue;
    if (command.empty()) command = a;
    else if (scene_path.empty()) scene_path = a;
  }
  // A set of solver.precision wins over a checkpoint's precision; its value
  // read as the loader reads it (a quoted "double" too) where there is a scene.
  if (!from_set.empty())
    return (command == "run" || command == "check") && !scene_path.empty() ? scene::scene_precision(scene_path, sets)
                                                                             : from_set;
  if (!restart.empty()) return checkpoint_precision(restart);
  // The scene's, with every --set applied as the loader applies them (a
  // nested or quoted solver.precision too).
  if ((command == "run" || command == "check") && !scene_path.empty()) return scene::scene_precision(scene_path, sets);
  return "float";
}

int cli_main(int argc, char** argv) {
  install_fatal_handlers();
  CLI::App app{"marbles: a rigid-sphere simulator (spatial-subdivision broad phase, impulse contacts)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "marbles 0.1");

  RunOptions run;
  for (int i = 0; i < argc; ++i) {
    if (i > 0) run.command_line += ' ';
    run.command_line += argv[i];
  }
  double run_duration = -1;
  bool no_render = false;
  auto* run_cmd = app.add_subcommand("run", "run a scene and write its output");
  run_cmd->add_option("scene", run.scene_path, "scene file (YAML)")->required();
  run_cmd->add_option("--out", run.out_dir, "output folder (overrides output.dir)")->check(kFolderOrNew);
  std::string run_backend = "auto", run_broadphase = "home";
  run_cmd
      ->add_option("--backend", run_backend, "where the whole step runs: auto (CUDA when a device is there), cpu, cuda")
      ->check(CLI::IsMember({"auto", "cpu", "cuda"}));
  run_cmd->add_option("--broadphase", run_broadphase,
                      "broad phase algorithm: home (home-cell variant, default) or seed (8 cells per sphere)")
      ->check(CLI::IsMember({"home", "seed"}));
  run_cmd->add_flag("--quiet", run.quiet, "print only the summary");
  run_cmd->add_flag("--no-render", no_render, "skip images and movie even if the scene asks for them");
  run_cmd->add_option("--duration", run_duration, "simulated seconds (overrides time.duration)")
      ->check(kFinite & kPositive);
  add_set_option(run_cmd, run.overrides);
  std::vector<std::string> limit_args;
  add_limit_option(run_cmd, limit_args);
  run_cmd->add_option("--restart", run.restart, "resume from a checkpoint (OUTDIR/checkpoints/step_NNNNNN.mck)")
      ->check(CLI::ExistingFile);
  run_cmd->add_flag("--summary-only", run.summary_only,
                    "write only summary.json and any checkpoints (no frames of any series, images or movie)");
  run_cmd->add_option("--threads", run.threads, "CPU threads (default: OMP_NUM_THREADS, else every core)")
      ->transform(kWhole)
      ->check(CLI::Range(1, kMostThreads));
  run_cmd->add_flag("--overwrite", run.overwrite,
                    "replace an earlier run's output in the folder (without it such a folder is refused)");
  std::string precision;
  add_precision_option(run_cmd, precision);

  std::string check_path;
  auto* check_cmd = app.add_subcommand("check", "validate a scene without running it");
  std::vector<std::string> check_overrides;
  check_cmd->add_option("scene", check_path, "scene file (YAML)")->required();
  add_set_option(check_cmd, check_overrides);
  add_limit_option(check_cmd, limit_args);
  add_precision_option(check_cmd, precision);
  bool check_pipeline = false;
  check_cmd->add_flag("--pipeline", check_pipeline,
                      "also print the stages a run would build (as `marbles run --backend cpu` prints them)");

  StudyOptions study;
  std::vector<std::string> study_vary;
  auto* study_cmd = app.add_subcommand(
      "study", "run a scene at every combination of accuracy settings: error against its reference, and cost");
  study_cmd->add_option("scene", study.scene_path, "scene file (YAML) with a reference: block")->required();
  study_cmd->add_option("--vary", study_vary,
                        "KEY=v1,v2,... (repeatable): time.dt, time.substeps, solver.iterations, solver.integrator, "
                        "solver.speculative, precision, backend or any scene key");
  add_set_option(study_cmd, study.set);
  add_limit_option(study_cmd, study.limits);
  study_cmd->add_option("--backend", study.backend, "auto|cpu|cuda (unless varied)")
      ->check(CLI::IsMember({"auto", "cpu", "cuda"}));
  study_cmd->add_option("--out", study.out_dir, "output folder (default out/study/<scene>)")->check(kFolderOrNew);
  study_cmd->add_option("--repeats", study.repeats, "runs per setting (the cost is their median)")
      ->transform(kWhole)
      ->check(CLI::Range(1, 1000));
  bool study_quiet = false;
  study_cmd->add_flag("--quiet", study_quiet, "no progress bar");
  study_cmd->add_flag("--overwrite", study.overwrite,
                      "also replace files in the folder that no earlier study there wrote (its tables' names, "
                      "runs/N)");

  std::string pairs_csv, pairs_algorithm = "subdivision";
  std::string pairs_backend = "cpu";
  double pairs_margin = 0;
  auto* pairs_cmd = app.add_subcommand("pairs", "print the overlapping pairs 'i j' of spheres given as x,y,z,r rows");
  pairs_cmd->add_option("spheres", pairs_csv, "CSV file of x,y,z,r rows")->required();
  pairs_cmd->add_option("--algorithm", pairs_algorithm,
                        "subdivision (the seed's spatial subdivision), home (its home-cell variant) or brute")
      ->check(CLI::IsMember({"subdivision", "home", "brute"}));
  pairs_cmd->add_option("--backend", pairs_backend, "cpu (default), cuda or auto (subdivision and home)")
      ->check(CLI::IsMember({"auto", "cpu", "cuda"}));
  pairs_cmd->add_option("--margin", pairs_margin, "report pairs whose gap is below this (m)")
      ->check(kFinite & kWithinReal & kNonNegative);

  auto* bench_cmd = app.add_subcommand("bench", "benchmarks (JSON and a table)");
  bench_cmd->require_subcommand(1);
  bench::BroadphaseBenchOptions bp;
  std::vector<std::size_t> bp_n;
  auto* bench_bp = bench_cmd->add_subcommand("broadphase", "time the broad phase per stage");
  bench_bp->add_option("--backend", bp.backend, "cpu|cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  bench_bp->add_option("--algorithm", bp.algorithm, "seed|home")->check(CLI::IsMember({"seed", "home"}));
  bench_bp->add_option("--sort", bp.sort, "seed|cub (cuda)")->check(CLI::IsMember({"seed", "cub"}));
  bench_bp->add_option("--scene", bp.scene, "gas|pile|poly")->check(CLI::IsMember({"gas", "pile", "poly"}));
  bench_bp->add_option("--n", bp_n, "sphere counts (repeatable)")->transform(kWhole)->check(kPositive)->check(kCount);
  bench_bp->add_option("--repeats", bp.repeats, "timed calls per size")
      ->transform(kWhole)
      ->check(CLI::Range(1, kMostRepeats));
  bench_bp->add_option("--margin", bp.margin, "pair margin (m)")->check(kFinite & kWithinReal & kNonNegative);
  bench_bp->add_option("--seed", bp.seed, "random seed of the sphere sets")->transform(kSeed);
  bench_bp->add_flag("--json", bp.json, "print JSON");
  add_limit_option(bench_bp, limit_args);

  bench::StepBenchOptions st;
  std::vector<std::size_t> st_n;
  auto* bench_step = bench_cmd->add_subcommand(
      "step", "time whole steps of a gas at volume fraction 0.1 or of a dense settled pile (cached per N)");
  bench_step->add_option("--backend", st.backend, "cpu|cuda (the pile also settles there)")
      ->check(CLI::IsMember({"cpu", "cuda"}));
  bench_step->add_option("--scene", st.scene, "gas (default) | pile | settle")
      ->check(CLI::IsMember({"gas", "pile", "settle"}));
  bench_step->add_option("--n", st_n, "sphere counts (repeatable)")->transform(kWhole)->check(kPositive)->check(kCount);
  bench_step->add_option("--repeats", st.repeats, "timed steps per size (and as many profiled ones)")
      ->transform(kWhole)
      ->check(CLI::Range(1, kMostRepeats));
  bench_step->add_option("--warmup", st.warmup, "untimed steps first (default 2 for gas, 5 for pile)")
      ->transform(kWhole)
      ->check(kNonNegative);
  bench_step->add_option("--effects", st.effects, "effects of the pipeline (gas only)")->delimiter(',');
  bench_step->add_option("--cache", st.cache_dir,
                         "folder of settled piles (default $XDG_CACHE_HOME/marbles or ~/.cache/marbles)")
      ->check(kFolderOrNew);
  bench_step->add_option("--settle-steps", st.settle_steps,
                         "pile: step budget of the settle (a cached pile that ran out of a smaller one settles again)")
      ->transform(kWhole)
      ->check(kPositive);
  bench_step->add_option("--settle-ke", st.settle_ke,
                         "pile: settled below this kinetic energy per sphere (J), 50 steps or more after the last quench")
      ->check(kFinite & kPositive);
  bench_step->add_option("--settle-quench", st.settle_quench,
                         "pile: zero the velocities every this many settle steps until first below the bound (0: never)")
      ->transform(kWhole)
      ->check(kNonNegative);
  bench_step->add_flag("--rebuild", st.rebuild, "pile: settle again, replacing the cached pile");
  bench_step->add_option("--sphere-order", st.sphere_order,
                         "the spheres' index order the timed steps see: made (default), shuffled, morton or cells")
      ->check(CLI::IsMember({"made", "shuffled", "morton", "cells"}));
  bench_step->add_option("--renumber", st.renumber,
                         "solver.renumber of the timed scene: the spheres numbered again every this many steps")
      ->transform(kWhole)
      ->check(kNonNegative);
  bench_step->add_option("--integrator", st.integrator,
                         "solver.integrator of the timed steps: symplectic_euler (default) or velocity_verlet "
                         "(its closing solve timed apart)")
      ->check(CLI::IsMember({"symplectic_euler", "velocity_verlet"}));
  bench_step->add_option("--write-scene", st.write_scene,
                         "write each N's start (the settle, the gas or the settled pile) to this folder as "
                         "bench-SCENE-nN.yaml and .csv, to run with `marbles run` or time with another build; "
                         "nothing is timed")
      ->check(kFolderOrNew);
  std::string st_rolling = "on";
  bench_step->add_option("--rolling", st_rolling,
                         "pile: rolling resistance on (default) or off (friction only; settled and cached apart)")
      ->check(CLI::IsMember({"on", "off"}));
  std::string st_friction = "on";
  bench_step->add_option("--friction", st_friction,
                         "pile: friction on (default) or off (with --rolling off: a frictionless pile, cached apart)")
      ->check(CLI::IsMember({"on", "off"}));
  std::string st_watchdog = "off";
  bench_step->add_option("--watchdog", st_watchdog,
                         "the run's watchdog in the benchmark's steps: off (default) or on (as marbles run steps)")
      ->check(CLI::IsMember({"on", "off"}));
  bench_step->add_flag("--json", st.json, "print JSON only (progress on stderr)");
  add_limit_option(bench_step, limit_args);

  bench::EffectsBenchOptions ef;
  auto* bench_effects = bench_cmd->add_subcommand("effects", "time the step with and without each effect");
  bench_effects->add_option("--backend", ef.backend, "cpu|cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  bench_effects->add_option("--n", ef.n, "sphere count")->transform(kWhole)->check(kPositive)->check(kCount);
  bench_effects->add_option("--volume-fraction", ef.volume_fraction, "packing of the gas")->check(kFinite & CLI::Range(0.01, 0.5));
  bench_effects->add_option("--repeats", ef.repeats, "timed steps per pipeline")
      ->transform(kWhole)
      ->check(CLI::Range(1, kMostRepeats));
  bench_effects->add_flag("--json", ef.json, "print JSON");
  add_limit_option(bench_effects, limit_args);

  render::RenderOptions rd;
  render::MovieOptions rd_movie;
  rd_movie.fps = 0;  // from the frame times unless given
  std::string rd_dir, rd_color_by, rd_camera;
  auto* render_cmd = app.add_subcommand("render", "render the frames of an output folder to PNG and a movie");
  render_cmd->add_option("outdir", rd_dir, "output folder of a run (holds series.pvd)")
      ->required()
      ->check(CLI::ExistingDirectory);
  render_cmd->add_option("--color-by", rd_color_by, "speed|id|radius|material")
      ->check(CLI::IsMember({"speed", "id", "radius", "material"}));
  render_cmd->add_option("--camera", rd_camera, "camera position and target: x,y,z:lx,ly,lz");
  render_cmd->add_option("--width", rd.width, "image width in pixels")->transform(kWhole)->check(CLI::Range(16, 8192));
  render_cmd->add_option("--height", rd.height, "image height in pixels")->transform(kWhole)->check(CLI::Range(16, 8192));
  render_cmd->add_option("--fps", rd_movie.fps, "movie frames per second, 0.01 to 1000 (default: from the frame times)")
      ->check(kFinite & CLI::Range(0.01, 1000.0));
  bool rd_no_movie = false;
  render_cmd->add_flag("--no-movie", rd_no_movie, "PNG frames only");

  try {
    refuse_empty_lists(argc, argv);
    refuse_unknown_commands(app, argc, argv);
  } catch (const InputError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    if (const std::string option = option_given_nothing(app, argc, argv); !option.empty()) {
      std::cerr << empty_value(option).what() << "\n";
      return 2;
    }
    // CLI11 lists the arguments it did not expect bare, so an empty one
    // said nothing (`marbles run x.yaml ''`): each is quoted here.
    if (dynamic_cast<const CLI::ExtrasError*>(&e)) {
      const std::vector<std::string> extra = app.remaining(true);
      std::string list;
      for (const std::string& x : extra)
        list += (list.empty() ? "'" : ", '") + marbles::printable_path(x) + "'" + (x.empty() ? " (an empty one)" : "");
      if (!list.empty()) {
        std::cerr << "marbles: " << (extra.size() == 1 ? "an argument" : "arguments")
                  << " that no command or option here takes: " << list << "\n(see marbles --help)\n";
        return 2;
      }
    }
    std::cerr << "marbles: " << e.what() << "\n(see marbles --help)\n";
    return 2;
  }

  try {
    refuse_empty_values(app);
    for (const std::string& l : limit_args) raise_limit(l);
    for (const std::string& l : study.limits) raise_limit(l);
    if (*run_cmd) {
      if (run_duration > 0) run.duration = run_duration;
      run.backend = kBackends.at(run_backend);
      run.algorithm = run_broadphase == "seed" ? broadphase::Algorithm::seed : broadphase::Algorithm::home;
      run.render = !no_render;
      run.limits = limit_args;
      return run_scene(run, std::cout, std::cerr);
    }
    if (*check_cmd) return check_scene(check_path, check_overrides, std::cout, std::cerr, check_pipeline);
    if (*study_cmd) {
      for (const std::string& v : study_vary) {
        StudyVary vary = parse_vary(v);
        for (const StudyVary& earlier : study.vary)
          if (earlier.key == vary.key)
            throw InputError(SourceLocation{"--vary " + v, 0, 0}, vary.key,
                             "varied twice: give all its values in one --vary " + vary.key + "=v1,v2,...");
        study.vary.push_back(std::move(vary));
      }
      study.progress = !study_quiet;
      study.program_name = argv[0];  // the runs' summaries name the program as typed
      // Ctrl-C (or SIGTERM) stops the study, its running run too, as it stops a run.
      const StopRequests stops;
      study.stop = [&stops] { return stops.received() != 0; };
      try {
        run_study(study, std::cout, std::cerr);
      } catch (const StudyStopped& e) {
        std::cerr << "marbles: stopped by " << signal_name(stops.received()) << ": " << e.what() << "\n";
        return 1;
      }
      return 0;
    }
    if (*bench_bp || *bench_step || *bench_effects) (void)default_thread_count();  // OMP_NUM_THREADS, bounded
    if (*pairs_cmd) return print_pairs(pairs_csv, pairs_algorithm, kBackends.at(pairs_backend), pairs_margin, std::cout, std::cerr);
    if (*bench_bp) {
      if (bench_bp->count("--sort") > 0 && bp.backend != "cuda")
        throw InputError(SourceLocation{}, "--sort", "chooses the GPU's sort: give --backend cuda (the CPU's is its own)");
      if (!bp_n.empty()) bp.n = bp_n;
      check_bench_counts(bp.n);
      return bench::run_broadphase_bench(bp, std::cout);
    }
    if (*bench_step) {
      if (bench_step->count("--effects") > 0 && st.scene != "gas")
        throw InputError(SourceLocation{}, "--effects",
                         "is for --scene gas only (the pile's terms: --friction, --rolling)");
      for (std::size_t i = 0; i < st.effects.size(); ++i)
        if (std::find(st.effects.begin(), st.effects.begin() + i, st.effects[i]) != st.effects.begin() + i)
          throw InputError(SourceLocation{}, "--effects", "'" + st.effects[i] + "' is given twice");
      if (!st_n.empty()) st.n = st_n;
      check_bench_counts(st.n);
      st.rolling = st_rolling == "on";
      st.friction = st_friction == "on";
      st.watchdog = st_watchdog == "on";
      if (st.backend == "cuda") select_backend(BackendChoice::cuda, std::cerr);
      return bench::run_step_bench(st, std::cout);
    }
    if (*bench_effects) {
      check_bench_counts({ef.n});
      if (ef.backend == "cuda") select_backend(BackendChoice::cuda, std::cerr);
      return bench::run_effects_bench(ef, std::cout);
    }
    if (*render_cmd) {
      if (!rd_color_by.empty()) rd.color_by = *render::parse_color_by(rd_color_by);
      if (!rd_camera.empty()) rd.camera = render::parse_camera(rd_camera, "--camera");
      rd_movie.enabled = !rd_no_movie;
      const RunFolderLock lock(rd_dir, "outdir");  // not while a run writes the folder (its images would go)
      // A killed render's (or run's) temporaries: its movie, its log, a half-written image.
      render::remove_stale_temporaries(rd_dir);
      render::remove_stale_temporaries(std::filesystem::path(rd_dir) / "images");
      return render::render_output_dir(rd_dir, rd, rd_movie, isatty(fileno(stderr)) != 0, std::cerr);
    }
  } catch (const InputError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  } catch (const RuntimeFailure& e) {
    std::cerr << "marbles: " << e.what() << "\n";
    return 1;
  } catch (const std::bad_alloc&) {
    std::cerr << "marbles: out of memory\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "marbles: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

}  // namespace marbles
