// python/module.cpp — the extension `marbles._marbles`.
//
// Holds the Simulation and the broad phase of both precisions, each with
// the translation of its failures into Python exceptions
// (bind_simulation.cpp, built twice), and the study.
#include <chrono>
#include <exception>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "core/device.hpp"
#include "core/error.hpp"
#include "python/gil.hpp"
#include "sim/checkpoint.hpp"
#include "sim/limits.hpp"
#include "sim/scene.hpp"
#include "sim/scene_overrides.hpp"
#include "sim/study.hpp"
#include "sim/version.hpp"

namespace nb = nanobind;

namespace marbles {
void bind_simulation(nb::module_& m, const char* name, const char* pairs_name);
}
namespace marbles_f64 {
void bind_simulation(nb::module_& m, const char* name, const char* pairs_name);
}

namespace {

// `marbles study`, each combination run by `program`; the rows as dicts.
nb::list study(const std::string& scene_path, const std::vector<std::string>& vary, const std::vector<std::string>& set,
               const std::string& backend, int repeats, const std::string& out_dir, const std::string& program,
               bool overwrite) {
  marbles::StudyOptions options;
  options.names = marbles::StudyNames::python();
  options.scene_path = scene_path;
  for (const std::string& v : vary) options.vary.push_back(marbles::parse_vary(v, options.names));
  options.set = set;
  options.backend = backend;
  options.repeats = repeats;
  options.out_dir = out_dir;
  options.marbles = program;
  options.overwrite = overwrite;
  options.progress = false;
  // Ctrl-C (Python's, on its main thread: a notebook's interrupt reaches this
  // process alone, not its runs) stops the study between two looks, its run
  // ended, and raises KeyboardInterrupt; the earlier study stays whole.
  // In another thread, the interpreter's end stops it (python/gil.hpp).
  std::exception_ptr interrupt;
  if (_PyOS_IsMainThread())
    options.stop = [&interrupt] {
      nb::gil_scoped_acquire acquire;
      if (PyErr_CheckSignals() == 0) return false;
      try {
        throw nb::python_error();  // takes the pending KeyboardInterrupt
      } catch (...) {
        interrupt = std::current_exception();
      }
      return true;
    };
  else
    options.stop = [] { return marbles::python::ending.load(); };
  std::ostringstream out, err;
  marbles::StudyResult result;
  try {
    const marbles::python::GilLetGo release;
    result = marbles::run_study(options, out, err);
  } catch (const marbles::StudyStopped&) {
    if (interrupt) std::rethrow_exception(interrupt);
    throw marbles::RuntimeFailure("the study was stopped");
  }
  nb::list rows;
  for (const marbles::StudyRow& r : result.rows) {
    nb::dict row;
    for (std::size_t k = 0; k < options.vary.size(); ++k) row[options.vary[k].key.c_str()] = r.values[k];
    row["reference"] = result.reference;
    row["error"] = r.error;
    row["measured"] = r.measured;
    row["ms_per_step"] = r.ms_per_step;
    row["ms_per_simulated_second"] = r.ms_per_simulated_second;
    row["steps"] = r.steps;
    row["pareto"] = r.pareto;
    rows.append(row);
  }
  return rows;
}

}  // namespace

NB_MODULE(_marbles, m) {
  marbles::bind_simulation(m, "SimulationFloat", "pairs_float");
  marbles_f64::bind_simulation(m, "SimulationDouble", "pairs_double");
  m.def("study", &study, nb::arg("scene"), nb::arg("vary"), nb::arg("set"), nb::arg("backend"), nb::arg("repeats"),
        nb::arg("out"), nb::arg("program"), nb::arg("overwrite"));
  m.def("scene_precision", &marbles::scene::scene_precision, nb::arg("path"), nb::arg("overrides"));
  m.def("scene_precision_json", &marbles::scene::scene_precision_json, nb::arg("text"), nb::arg("overrides"));
  m.def("checkpoint_precision", &marbles::checkpoint_precision, nb::arg("path"));
  // The interpreter's end (atexit, python/gil.hpp): each call that let go
  // of the GIL (a step, pairs(), a study) takes it back or parks before the
  // interpreter lets its threads go. A parked step holds its simulation,
  // which nanobind would otherwise report as leaked.
  m.def("at_exit", [] {
    namespace py = marbles::python;
    py::ending = true;
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (py::let_go.load() > py::parked.load() && std::chrono::steady_clock::now() < until) {
      nb::gil_scoped_release release;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (py::parked.load() > 0) nb::set_leak_warnings(false);
  });
  m.def("cuda_device", [] {
    const marbles::DeviceInfo& d = marbles::cuda_device();
    return nb::make_tuple(d.available, d.available ? d.name : d.why_not);
  });
  // The substeps a run may take (sim/limits.hpp), to which Simulation.step and run hold each call.
  m.def("substeps_limit", [] { return marbles::limits().substeps; });
  m.def("reads_as_itself", &marbles::scene::detail::reads_as_itself, nb::arg("value"));
  m.attr("version") = marbles::kMarblesVersion;
  m.attr("commit") = marbles::kMarblesCommit;
}
