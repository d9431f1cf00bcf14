// sim/study.hpp — `marbles study`: what accuracy costs in time.
//
// Runs a scene at every combination of the varied settings (time.dt,
// time.substeps, solver.iterations, solver.integrator, solver.speculative,
// precision, backend, or any scene key), each `repeats` times as its own
// `marbles run` process, and reads back from each run's summary.json the
// error against the scene's reference (computed by the run from its own
// states, sim/reference.hpp) and the cost (wall ms per simulated second and
// per step). Writes study.md, study.csv and, with gnuplot, study.png: error
// against cost, log-log, with the Pareto front marked.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace marbles {

struct StudyVary {
  std::string key;                  // time.dt, precision, backend, any scene key path
  std::vector<std::string> values;  // as written on the command line
};

// How a study's messages name what its caller gave: the command line's
// options (the default), or the Python function's arguments (python()).
struct StudyNames {
  std::string vary = "--vary";                            // a setting's list, and the settings
  std::string repeats = "--repeats";                      // the runs a setting
  std::string backend = "--backend";                      // the backend a run is given
  std::string out = "--out";                              // the study's folder, where given
  std::string overwrite = "give --overwrite";             // what replaces a user's files
  std::string runs_limit = "--limit study_runs=N raises it";  // past the runs' limit
  static StudyNames python() {
    return {"vary", "repeats", "backend", "out", "give overwrite=True",
            "a study from Python keeps to it: fewer values or repeats, or several studies"};
  }
};

struct StudyOptions {
  std::string scene_path;
  std::vector<StudyVary> vary;      // the cartesian product is run, first key slowest
  std::vector<std::string> set;     // --set overrides applied to every run
  std::vector<std::string> limits;  // --limit raises, passed to every run
  std::string backend = "auto";     // unless varied
  std::string out_dir;              // default: out/study/<scene stem>
  int repeats = 3;                  // runs per combination; the cost is their median
  std::string marbles = "/proc/self/exe";  // the program that runs each combination
  // The name each run is given as its argv[0] (the start of its summary's
  // command_line): the study's own as typed; empty: `marbles`'s path above.
  std::string program_name;
  bool progress = true;
  // Replace files in the folder that no earlier study there wrote (its
  // tables' names, runs/N): refused without it.
  bool overwrite = false;
  // Asked about every 50 ms while a run runs (from the study's thread): true
  // stops the study, its run ended (SIGTERM; SIGKILL after 10 s), with StudyStopped. The Python
  // module's Ctrl-C, whose signal reaches its process alone (a notebook's
  // interrupt), not the runs.
  std::function<bool()> stop;
  StudyNames names;  // how its messages name the options
};

// A study ended by StudyOptions::stop: the earlier study's runs and tables are
// left whole, as by any study that does not end.
struct StudyStopped : std::runtime_error {
  explicit StudyStopped(const std::string& what = "the study was stopped") : std::runtime_error(what) {}
};

struct StudyRow {
  std::vector<std::string> values;  // one per varied key
  double error = 0;                 // relative error against the reference
  std::vector<double> measured;     // the run's measured quantities
  double ms_per_step = 0;           // medians over the repeats
  double ms_per_simulated_second = 0;
  std::uint64_t steps = 0;
  bool pareto = false;              // no other row is at least as good in both error and cost
};

struct StudyResult {
  std::string reference;            // the reference kind
  std::vector<StudyRow> rows;
  std::string finest;               // for `reference: finest`: the combination used as reference
  bool plotted = false;             // study.png written
};

// "time.dt=1e-3,5e-4" -> {time.dt, {1e-3, 5e-4}}; throws InputError naming --vary (names.vary).
StudyVary parse_vary(const std::string& text, const StudyNames& names = {});

// Runs the study and writes its files; throws InputError (a scene without a
// reference, file:line:col) or RuntimeFailure (a run that failed, with its log).
StudyResult run_study(const StudyOptions& options, std::ostream& out, std::ostream& err);

// Marks the rows on the Pareto front of (cost, error).
void mark_pareto(std::vector<StudyRow>& rows);

}  // namespace marbles
