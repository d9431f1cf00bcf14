#include "sim/study.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <optional>
#include <set>
#include <ostream>
#include <sstream>
#include <thread>
#include <tuple>

#include <nlohmann/json.hpp>

#include "core/config.hpp"
#include "core/device.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/format.hpp"
#include "render/atomic_file.hpp"
#include "sim/limits.hpp"
#include "sim/output.hpp"
#include "sim/run.hpp"
#include "sim/scene.hpp"
#include "sim/scene_yaml.hpp"

extern char** environ;

namespace marbles {

namespace {

namespace fs = std::filesystem;

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A run's summary.json (sim/run.cpp), parsed (ordered_json: its keys in
// their order, to write it again); a file that is not JSON is a failure of
// that run, named by its path.
template <class Json = nlohmann::json>
Json read_summary(const fs::path& path) {
  try {
    return Json::parse(read_text(path));
  } catch (const nlohmann::json::exception& e) {
    throw RuntimeFailure("cannot read " + path.string() + ": " + e.what());
  }
}

// A run's summary.json with the `--out FROM` of its command_line made
// `--out TO` (the study moves its runs there when it ends); nothing else
// changes.
void rename_out_folder(const fs::path& path, const fs::path& from, const fs::path& to) {
  nlohmann::ordered_json summary = read_summary<nlohmann::ordered_json>(path);
  if (!summary.contains("command_line") || !summary["command_line"].is_string()) return;
  std::string line = summary["command_line"].get<std::string>();
  const std::string old_out = " --out " + from.string();
  const std::size_t at = line.rfind(old_out);
  if (at == std::string::npos) return;
  line.replace(at, old_out.size(), " --out " + to.string());
  summary["command_line"] = line;
  render::write_file_atomic(path.string(), json_text(summary));
}

// A number in study.csv and the plot's data: 10 significant digits ("nan"
// where not finite: a missing point to gnuplot and to CSV readers).
std::string table_number(double v) { return significant(v, 10); }

// A number of the summary (NaN where absent or null).
double number_of(const nlohmann::json& summary, const char* key) {
  const auto it = summary.find(key);
  return it != summary.end() && it->is_number() ? it->get<double>() : std::nan("");
}

std::string text_of(const nlohmann::json& summary, const char* key) {
  const auto it = summary.find(key);
  return it != summary.end() && it->is_string() ? it->get<std::string>() : std::string();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n == 0 ? std::nan("") : (n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]));
}

// Runs `program` (a path, or a name looked up on PATH) with the arguments
// `args` (args[0] its name as it sees it) and stdout and stderr to `log`, no
// shell between; returns its exit status (-1 if it did not exit).
// Where `stop` says so while it runs, it is ended (SIGTERM; SIGKILL after
// 10 s) and StudyStopped thrown.
int run_process(const std::string& program, const std::vector<std::string>& args, const std::string& log,
                const std::function<bool()>& stop = {}) {
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, program.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) throw RuntimeFailure("cannot start " + program + ": " + std::strerror(rc));
  int status = 0;
  if (stop) {
    for (;;) {
      const pid_t done = waitpid(pid, &status, WNOHANG);
      if (done == pid || (done < 0 && errno != EINTR)) break;
      bool stopping = true;
      try {
        stopping = stop();
      } catch (...) {  // as a stop: the run is not left behind
      }
      if (stopping) {
        // Asked to end (a run stops at its next step); one that has not after 10 s is killed.
        ::kill(pid, SIGTERM);
        bool ended = false;
        for (int k = 0; k < 100 && !ended; ++k) {
          ended = waitpid(pid, &status, WNOHANG) != 0;
          if (!ended) std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        if (!ended) {
          ::kill(pid, SIGKILL);
          while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
          }
        }
        throw StudyStopped();
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  } else {
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Every combination of the varied values, first key slowest.
std::vector<std::vector<std::string>> combinations(const std::vector<StudyVary>& vary) {
  std::vector<std::vector<std::string>> out{{}};
  for (const StudyVary& v : vary) {
    std::vector<std::vector<std::string>> next;
    for (const auto& prefix : out)
      for (const std::string& value : v.values) {
        next.push_back(prefix);
        next.back().push_back(value);
      }
    out = std::move(next);
  }
  return out;
}

std::string label_of(const std::vector<StudyVary>& vary, const std::vector<std::string>& values) {
  std::string out;
  for (std::size_t k = 0; k < vary.size(); ++k) out += (k ? " " : "") + vary[k].key + "=" + values[k];
  return out.empty() ? "(scene as is)" : out;
}

std::string fixed(double v, int digits) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream s;
  s << std::setprecision(digits) << v;
  return s.str();
}

// One line rewritten in place on a terminal, one line per run otherwise.
void show_progress(std::ostream& err, bool tty, std::size_t done, std::size_t total, const std::string& what) {
  const int width = 30;
  const int filled = static_cast<int>(width * done / std::max<std::size_t>(1, total));
  std::string bar(filled, '#');
  bar += std::string(width - filled, '.');
  if (tty) {
    err << "\r[" << bar << "] " << done << "/" << total << "  " << what << "\033[K" << std::flush;
    if (done == total) err << "\n";
  } else {
    err << "study: run " << done << "/" << total << "  " << what << "\n";
  }
}

bool have_gnuplot() {
  try {
    return run_process("gnuplot", {"gnuplot", "--version"}, "/dev/null") == 0;
  } catch (const RuntimeFailure&) {  // not on PATH
    return false;
  }
}

// Text as a gnuplot double-quoted string, every byte kept: a backslash and
// a quote escaped, and as octal escapes the control bytes (a line break
// would end the script's line: a folder named with one lost its plot) and
// the backquote (gnuplot runs `...` as a shell command before it reads the
// escapes). The scene's name and the paths are data, never commands.
std::string gnuplot_quoted(const std::string& text) {
  std::string out = "\"";
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '\\' || c == '"') out += {'\\', c};
    else if (u < 0x20 || u == 0x7f || c == '`')
      out += {'\\', char('0' + (u >> 6)), char('0' + ((u >> 3) & 7)), char('0' + (u & 7))};
    else out += c;
  }
  return out + "\"";
}

}  // namespace

StudyVary parse_vary(const std::string& text, const StudyNames& names) {
  const std::size_t eq = text.find('=');
  const SourceLocation where{names.vary + " " + text, 0, 0};
  if (eq == std::string::npos || eq == 0) throw InputError(where, "", "expected KEY=v1,v2,...");
  StudyVary v;
  v.key = text.substr(0, eq);
  // Values split at the commas outside brackets and braces, so that a
  // vector's or a map's own commas stay in it (gravity=[0,0,-1],[0,0,-2]).
  const std::string list = text.substr(eq + 1);
  std::string item;
  int depth = 0;
  // A number's value, where the whole text is one as the scene reads it (1e-3
  // and 0.001 are one setting).
  const auto number = [](const std::string& text) -> std::optional<double> {
    double x = 0;
    if (!scene::detail::parse_double(text, x)) return std::nullopt;
    return x;
  };
  const auto take = [&] {
    // Blanks around a value are not part of it (a value given twice is found
    // with them too).
    const std::size_t first = item.find_first_not_of(" \t"), last = item.find_last_not_of(" \t");
    item = first == std::string::npos ? std::string() : item.substr(first, last - first + 1);
    if (item.empty()) throw InputError(where, v.key, "an empty value in the list");
    for (const std::string& earlier : v.values)
      if (earlier == item || (number(earlier) && number(item) && *number(earlier) == *number(item)))
        throw InputError(where, v.key,
                         "the value " + item + " is given twice" + (earlier == item ? "" : " (as " + earlier + ")") +
                             ": each setting runs once (" + names.repeats + " repeats them all)");
    v.values.push_back(item);
    item.clear();
  };
  for (const char c : list) {
    if (c == ',' && depth == 0) {
      take();
      continue;
    }
    if (c == '[' || c == '{') ++depth;
    if ((c == ']' || c == '}') && --depth < 0) throw InputError(where, v.key, "a ']' or '}' without its opening");
    item += c;
  }
  if (depth != 0) throw InputError(where, v.key, "a '[' or '{' without its closing");
  if (!list.empty()) take();
  if (v.values.empty()) throw InputError(where, v.key, "no values");
  return v;
}

void mark_pareto(std::vector<StudyRow>& rows) {
  for (StudyRow& r : rows) {
    r.pareto = std::isfinite(r.error) && std::isfinite(r.ms_per_simulated_second);
    for (const StudyRow& o : rows) {
      if (&o == &r || !std::isfinite(o.error) || !std::isfinite(o.ms_per_simulated_second)) continue;
      const bool no_worse = o.error <= r.error && o.ms_per_simulated_second <= r.ms_per_simulated_second;
      const bool better = o.error < r.error || o.ms_per_simulated_second < r.ms_per_simulated_second;
      if (no_worse && better) r.pareto = false;
    }
  }
}

namespace {

// What one combination runs with: the backend and precision where varied
// (the program's own options), the other varied keys as overrides after the
// study's own.
struct RunSettings {
  std::string backend, precision;
  std::vector<std::string> sets;
};
RunSettings settings_of(const StudyOptions& options, const std::vector<std::string>& values) {
  RunSettings r{options.backend, "", options.set};
  for (std::size_t k = 0; k < options.vary.size(); ++k) {
    const std::string& key = options.vary[k].key;
    if (key == "backend") r.backend = values[k];
    else if (key == "precision") r.precision = values[k];
    else r.sets.push_back(key + "=" + values[k]);
  }
  return r;
}

// Every combination's scene loaded before anything is made or run: a key or
// value the scene refuses is said as the scene says it (file, line, key,
// and the combination), with no run folder or log left behind.
void check_combinations(const StudyOptions& options, const std::vector<std::vector<std::string>>& combos) {
  const auto one_of = [](const std::string& key, const std::string& value, std::initializer_list<const char*> names) {
    for (const char* name : names)
      if (value == name) return;
    std::string list;
    for (const char* name : names) list += (list.empty() ? "" : ", ") + std::string(name);
    throw InputError(SourceLocation{}, key, "expected one of " + list + ", got '" + value + "'");
  };
  one_of("backend", options.backend, {"auto", "cpu", "cuda"});
  std::map<std::tuple<std::string, std::string, std::uint64_t>, std::size_t> made;  // backend, precision, scene
  for (std::size_t c = 0; c < combos.size(); ++c) {
    const std::vector<std::string>& values = combos[c];
    if (options.stop && options.stop())
      throw StudyStopped("the study was stopped while its settings were checked (" + std::to_string(c + 1) + " of " +
                         std::to_string(combos.size()) + "); nothing was run or written");
    RunSettings run = settings_of(options, values);
    one_of(options.names.vary + " backend", run.backend, {"auto", "cpu", "cuda"});
    if (!run.precision.empty()) one_of(options.names.vary + " precision", run.precision, {"float", "double"});
    if (run.backend == "cuda" && !cuda_device().available)
      throw RuntimeFailure("study run " + label_of(options.vary, values) + ": " + options.names.backend +
                           " cuda: no CUDA device (" +
                           cuda_device().why_not + "); nothing was run");
    std::optional<std::uint64_t> fingerprint;
    try {
      // Held as `marbles check` holds it, in this build's precision; a run in
      // the other one is checked by that run (its ranges are its own).
      if (run.precision.empty()) run.precision = scene::scene_precision(options.scene_path, run.sets);
      if (run.precision == kRealName) fingerprint = checked_scene(options.scene_path, run.sets).scene.fingerprint;
    } catch (const InputError& e) {
      throw InputError(e.where(), e.key(), e.message() + " (study run " + label_of(options.vary, values) + ")");
    }
    // Two settings that make one scene (solver.speculative=true,yes) would run it twice.
    if (!fingerprint) continue;
    const auto [at, fresh] = made.try_emplace(std::tuple(run.backend, run.precision, *fingerprint), c);
    if (!fresh)
      throw InputError(SourceLocation{}, options.names.vary,
                       "the settings " + label_of(options.vary, combos[at->second]) + " and " +
                           label_of(options.vary, values) + " make the same scene: each setting runs once (" +
                           options.names.repeats + " repeats them all)");
  }
}

// The staging folders (`.runs-PID`) in `dir` of studies no longer running:
// a failed one's, or one stopped by a signal. A live study's is its own.
void remove_dead_stagings(const fs::path& dir) {
  std::error_code ec;
  for (const fs::path& p : folders_of_ended_processes(dir, ".runs-")) fs::remove_all(p, ec);
}

// What a study writes in its folder, named relative to it: the tables, the
// plot with its script, data and log, and each setting's run and log. The
// study's record (`.marbles-study`, a name a line) names those of the last
// study there, so that a study replaces only what a study wrote.
constexpr const char* kStudyRecord = ".marbles-study";

std::vector<std::string> study_files(std::size_t runs) {
  std::vector<std::string> names{"study.csv", "study.md", "study.dat", "study_front.dat",
                                 "study.gp",  "study.gp.log", "study.png"};
  for (std::size_t c = 0; c < runs; ++c) names.insert(names.end(), {"runs/" + std::to_string(c), "runs/" + std::to_string(c) + ".log"});
  return names;
}

std::set<std::string> earlier_study_files(const fs::path& dir) {
  std::set<std::string> names;
  std::ifstream in(dir / kStudyRecord);
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) names.insert(line);
  return names;
}

void write_study_record(const fs::path& dir, const std::set<std::string>& names) {
  std::string text;
  for (const std::string& name : names) text += name + "\n";
  render::write_file_atomic(dir / kStudyRecord, text);
}

// study.png and study.gp.log: the files gnuplot writes, where it is there.
bool drawn_by_gnuplot(const std::string& name) { return name == "study.png" || name == "study.gp.log"; }

bool there(const fs::path& path) {
  std::error_code ec;
  return fs::symlink_status(path, ec).type() != fs::file_type::not_found;
}

// Refuses (naming `key`, --out or study) a file this study would replace
// that no earlier study in the folder wrote: a folder of the user's, or a
// study's from before the record, is replaced only with --overwrite. `plots`:
// gnuplot runs (its files are this study's to write).
void check_study_folder(const fs::path& dir, std::size_t runs, const std::set<std::string>& earlier,
                        const std::string& key, const StudyNames& names, bool plots) {
  std::error_code ec;
  if (there(dir / "runs") && !fs::is_directory(dir / "runs", ec))
    throw InputError(SourceLocation{}, key,
                     printable_path((dir / "runs").string()) +
                         " is there and is not a folder: the study keeps its runs in it (move it)");
  for (const std::string& name : study_files(runs))
    if ((plots || !drawn_by_gnuplot(name)) && !earlier.contains(name) && there(dir / name))
      throw InputError(SourceLocation{}, key,
                       printable_path((dir / name).string()) + " is there, and no earlier study in " +
                           printable_path(dir.string()) +
                           " wrote it: a study replaces only its own files (move it, or " + names.overwrite + ")");
}

// The study's runs (`staging`/N and N.log) moved into `runs`, in the place
// of an earlier study's; that study's runs past this one's count (runs/N and
// runs/N.log that `earlier` names, or any so named with `overwrite`)
// removed, so that runs/ holds this study's runs only. Nothing else in
// runs/ is touched.
void keep_runs(const fs::path& staging, const fs::path& runs, std::size_t count, const std::set<std::string>& earlier,
               bool overwrite) {
  for (std::size_t c = 0; c < count; ++c)  // all there before anything of the earlier study goes
    for (const std::string& name : {std::to_string(c), std::to_string(c) + ".log"})
      if (!fs::exists(staging / name))
        throw RuntimeFailure("the study's run " + (staging / name).string() + " is gone (another study in " +
                             staging.parent_path().string() + "?); the earlier runs in " + runs.string() +
                             " are left as they were");
  fs::create_directories(runs);
  std::vector<fs::path> stale;
  std::error_code ec;
  for (fs::directory_iterator it(runs, ec), end; !ec && it != end; it.increment(ec)) {
    std::string name = it->path().filename().string();
    if (name.ends_with(".log")) name.resize(name.size() - 4);
    const bool studys = overwrite || earlier.contains("runs/" + it->path().filename().string());
    if (const auto n = whole_number(name); n && *n >= count && studys) stale.push_back(it->path());
  }
  for (const fs::path& p : stale) fs::remove_all(p, ec);
  for (std::size_t c = 0; c < count; ++c)
    for (const std::string& name : {std::to_string(c), std::to_string(c) + ".log"}) {
      fs::remove_all(runs / name);
      fs::rename(staging / name, runs / name);
    }
}

}  // namespace

StudyResult run_study(const StudyOptions& options, std::ostream& out, std::ostream& err) {
  const scene::Scene scene = scene::load_scene(options.scene_path, options.set);
  if (scene.reference.kind == scene::ReferenceSpec::Kind::none)
    throw InputError(SourceLocation{scene.path, 1, 1}, "reference",
                     "the study needs the scene's known answer: add a `reference:` block (docs/accuracy.md), "
                     "or `reference: finest` to compare with the finest setting");
  StudyResult result;
  result.reference = scene::reference_name(scene.reference.kind);
  // Absolute: the plot's script names its files by it, and gnuplot reads a
  // name starting with '<' or '|' as a command.
  const fs::path dir = fs::absolute(options.out_dir.empty() ? fs::path("out/study") / fs::path(scene.path).stem()
                                                            : fs::path(options.out_dir));
  double runs = options.repeats;
  for (const StudyVary& v : options.vary) runs *= static_cast<double>(v.values.size());
  if (runs > limits().study_runs)
    throw InputError(SourceLocation{}, options.names.vary,
                     shortest(runs) + " runs (the settings' combinations x " + options.names.repeats + " " +
                         std::to_string(options.repeats) + "), more than the limit " + shortest(limits().study_runs) +
                         " (" + options.names.runs_limit + ")");
  const auto combos = combinations(options.vary);
  check_combinations(options, combos);
  // One study at a time in the folder (its runs/, tables and plots).
  const std::string key = options.out_dir.empty() ? "study" : options.names.out;
  const RunFolderLock lock(dir, key);
  const std::set<std::string> earlier = earlier_study_files(dir);
  const bool gnuplot = have_gnuplot();  // asked once: each ask starts gnuplot
  if (!options.overwrite) check_study_folder(dir, combos.size(), earlier, key, options.names, gnuplot);
  // The runs are made in a folder of their own (`.runs-PID`) and take the
  // place of an earlier study's in runs/ only once all of them have run: a
  // study that fails or is stopped leaves the earlier one whole, its tables
  // and its runs. A failed or dead study's folder (the failed run's log is
  // in it) is removed at the next start; a live one's is left alone. A
  // failed run's log names the folder it was made in; a kept run's
  // summary.json names its folder in runs/ (rename_out_folder).
  remove_dead_stagings(dir);
  const fs::path staging = dir / (".runs-" + std::to_string(getpid()));
  fs::create_directories(staging);
  const std::size_t total = combos.size() * static_cast<std::size_t>(options.repeats);
  const bool tty = options.progress && isatty(fileno(stderr));
  std::size_t done = 0;
  std::vector<std::vector<double>> shapes;  // reference finest: what each run measured
  // How fine each setting is: smaller substep, then more iterations, then
  // double, then velocity Verlet, then speculative contacts on.
  std::vector<std::tuple<double, double, int, int, int>> fineness;
  for (std::size_t c = 0; c < combos.size(); ++c) {
    StudyRow row;
    row.values = combos[c];
    std::vector<double> per_step, per_second;
    const RunSettings run = settings_of(options, row.values);
    const std::string& name = options.program_name.empty() ? options.marbles : options.program_name;
    std::vector<std::string> args{name, "run", options.scene_path, "--quiet", "--summary-only", "--overwrite"};
    for (const std::string& s : run.sets) args.insert(args.end(), {"--set", s});
    for (const std::string& l : options.limits) args.insert(args.end(), {"--limit", l});
    args.insert(args.end(), {"--backend", run.backend});
    if (!run.precision.empty()) args.insert(args.end(), {"--precision", run.precision});
    const fs::path run_dir = staging / std::to_string(c);
    args.insert(args.end(), {"--out", run_dir.string()});
    nlohmann::json summary;
    for (int r = 0; r < options.repeats; ++r) {
      if (options.progress) show_progress(err, tty, done, total, label_of(options.vary, row.values));
      const std::string log = (run_dir.string() + ".log");
      fs::create_directories(run_dir);
      const auto stopped = [&] {
        if (tty) err << "\n";
        return StudyStopped("the study was stopped during run " + label_of(options.vary, row.values) + " (" +
                            std::to_string(done + 1) + " of " + std::to_string(total) + "); its runs so far are in " +
                            staging.string() + " (the next study in the folder removes them), and an earlier "
                            "study's runs and tables in " + dir.string() + " are left whole");
      };
      int status = 0;
      try {
        status = run_process(options.marbles, args, log, options.stop);
      } catch (const StudyStopped&) {
        throw stopped();
      }
      if (status != 0 && options.stop && options.stop()) throw stopped();  // the run stopped by the same signal
      if (status != 0) {
        if (tty) err << "\n";
        const std::string text = read_text(log);
        if (status == 2) throw InputError(SourceLocation{}, "", "study run " + label_of(options.vary, row.values) + ": " + text);
        throw RuntimeFailure("study run " + label_of(options.vary, row.values) + " failed (exit " +
                             std::to_string(status) + "): " + text);
      }
      summary = read_summary(run_dir / "summary.json");
      const double steps = number_of(summary, "steps");
      const double wall = number_of(summary, "wall_time");
      per_step.push_back(number_of(summary, "mean_ms_per_step"));
      per_second.push_back(1e3 * wall / std::max(1e-300, number_of(summary, "simulated_time")));
      row.steps = static_cast<std::uint64_t>(steps);
      ++done;
    }
    // The run's command line names the folder it ends in (runs/N), not its staging folder.
    rename_out_folder(run_dir / "summary.json", run_dir, dir / "runs" / std::to_string(c));
    row.ms_per_step = median(per_step);
    row.ms_per_simulated_second = median(per_second);
    const nlohmann::json reference = summary.value("reference", nlohmann::json::object());
    row.error = number_of(reference, "error");
    for (const auto& v : reference.value("measured", nlohmann::json::array()))
      row.measured.push_back(v.is_number() ? v.get<double>() : std::nan(""));
    const double h = number_of(summary, "dt") / std::max(1.0, number_of(summary, "substeps"));
    fineness.emplace_back(h, -number_of(summary, "iterations"), text_of(summary, "precision") == "double" ? 0 : 1,
                          text_of(summary, "integrator") == "velocity_verlet" ? 0 : 1,
                          summary.value("speculative", false) ? 0 : 1);
    shapes.push_back(row.measured);
    result.rows.push_back(std::move(row));
  }
  if (options.progress) show_progress(err, tty, done, total, "done");
  // Again once the runs have run (hours, it may be): a file put there meanwhile is not replaced.
  if (!options.overwrite) check_study_folder(dir, combos.size(), earlier, key, options.names, gnuplot);
  {  // the record names what the folder may hold meanwhile: the earlier study's and this one's
    std::set<std::string> both = earlier;
    for (const std::string& name : study_files(combos.size())) both.insert(name);
    write_study_record(dir, both);
  }
  keep_runs(staging, dir / "runs", combos.size(), earlier, options.overwrite);
  fs::remove_all(staging);

  if (scene.reference.kind == scene::ReferenceSpec::Kind::finest) {
    // The finest combination (smallest substep, most iterations, double, ...) is the
    // reference: each row's error is the largest change of the centre of
    // mass or radius of gyration, in mean radii.
    const std::size_t f = std::min_element(fineness.begin(), fineness.end()) - fineness.begin();
    result.finest = label_of(options.vary, result.rows[f].values);
    for (StudyRow& row : result.rows) {
      const std::vector<double>& a = row.measured;
      const std::vector<double>& b = result.rows[f].measured;
      double e = 0;
      if (a.size() >= 5 && b.size() >= 5)
        for (int k = 0; k < 4; ++k) e = std::max(e, std::abs(a[k] - b[k]) / b[4]);
      row.error = e;
    }
  }
  mark_pareto(result.rows);

  // study.csv and study.md
  std::ostringstream csv, md;
  for (const StudyVary& v : options.vary) csv << v.key << ",";
  csv << "error,ms_per_simulated_second,ms_per_step,steps,pareto\n";
  md << "# Study: " << scene.name << "\n\n"
     << "Scene `" << scene.path << "`, reference `" << result.reference << "`"
     << (result.finest.empty() ? "" : " (finest setting: " + result.finest + ")") << "; " << options.repeats
     << " runs per setting, cost = median wall time; # is the point's number in study.png.\n\n| # |";
  for (const StudyVary& v : options.vary) md << " " << v.key << " |";
  md << " error | ms per simulated s | ms per step | steps | Pareto |\n|";
  for (std::size_t k = 0; k < options.vary.size() + 6; ++k) md << "---|";
  md << "\n";
  for (std::size_t i = 0; i < result.rows.size(); ++i) {
    const StudyRow& r = result.rows[i];
    md << "| " << i + 1 << " |";
    for (const std::string& v : r.values) {
      csv << v << ",";
      md << " " << v << " |";
    }
    csv << table_number(r.error) << "," << table_number(r.ms_per_simulated_second) << "," << table_number(r.ms_per_step)
        << "," << r.steps << "," << (r.pareto ? 1 : 0) << "\n";
    md << " " << fixed(100 * r.error, 3) << " % | " << fixed(r.ms_per_simulated_second, 4) << " | "
       << fixed(r.ms_per_step, 4) << " | " << r.steps << " | " << (r.pareto ? "yes" : "") << " |\n";
  }
  render::write_file_atomic((dir / "study.csv").string(), csv.str());
  render::write_file_atomic((dir / "study.md").string(), md.str());

  // study.png: error against cost, log-log; the Pareto front as a line.
  // Points are numbered as in study.md; the front's points also say their values.
  constexpr double kFloor = 1e-15;  // a zero error (the finest setting itself) is drawn here
  std::ostringstream data, front;
  for (std::size_t i = 0; i < result.rows.size(); ++i) {
    const StudyRow& r = result.rows[i];
    std::string label = std::to_string(i + 1);
    if (r.pareto)
      for (const std::string& v : r.values) label += "_" + v;
    data << table_number(r.ms_per_simulated_second) << " " << table_number(std::max(r.error, kFloor)) << " " << label
         << "\n";
  }
  std::vector<const StudyRow*> on_front;
  for (const StudyRow& r : result.rows)
    if (r.pareto) on_front.push_back(&r);
  std::sort(on_front.begin(), on_front.end(),
            [](const StudyRow* a, const StudyRow* b) { return a->ms_per_simulated_second < b->ms_per_simulated_second; });
  for (const StudyRow* r : on_front)
    front << table_number(r->ms_per_simulated_second) << " " << table_number(std::max(r->error, kFloor)) << "\n";
  render::write_file_atomic((dir / "study.dat").string(), data.str());
  render::write_file_atomic((dir / "study_front.dat").string(), front.str());
  const std::string png = (dir / "study.png").string();
  std::ostringstream gp;
  gp << "set terminal pngcairo size 1000,700 noenhanced\n"
     << "set output " << gnuplot_quoted(png + ".tmp") << "\n"
     << "set logscale xy\nset grid\nset key top right\n"
     << "set title " << gnuplot_quoted(scene.name + ": error against cost (" + result.reference + ")") << "\n"
     << "set xlabel 'wall ms per simulated second'\nset ylabel 'relative error (0 drawn at 1e-15)'\n"
     << "plot " << gnuplot_quoted((dir / "study.dat").string())
     << " using 1:2 with points pt 7 ps 1.5 title 'settings', \\\n"
     << "     '' using 1:2:3 with labels font ',8' left offset 0.7,0.5 notitle, \\\n"
     << "     " << gnuplot_quoted((dir / "study_front.dat").string())
     << " using 1:2 with linespoints lw 2 pt 6 ps 2.2 title 'Pareto front'\n";
  render::write_file_atomic((dir / "study.gp").string(), gp.str());
  if (gnuplot) {
    const std::string log = (dir / "study.gp.log").string();
    if (run_process("gnuplot", {"gnuplot", (dir / "study.gp").string()}, log) == 0 && fs::exists(png + ".tmp")) {
      fs::rename(png + ".tmp", png);
      result.plotted = true;
    } else {
      std::error_code ec;
      fs::remove(png + ".tmp", ec);  // a half-drawn image is no study.png
      err << "warning: gnuplot failed (see " << log << "); study.png not written\n";
    }
  } else {
    err << "warning: gnuplot not found: study.png not written (install gnuplot-nox; study.gp is ready for it)\n";
  }

  out << "study of " << scene.name << " (" << result.rows.size() << " settings x " << options.repeats
      << " runs), reference " << result.reference << ":\n";
  std::size_t width = 8;
  for (const StudyRow& r : result.rows) width = std::max(width, label_of(options.vary, r.values).size() + 2);
  out << std::left << std::setw(static_cast<int>(width)) << "setting" << std::right << std::setw(12) << "error %" << std::setw(14)
      << "ms/sim s" << std::setw(12) << "ms/step" << "  Pareto\n";
  for (const StudyRow& r : result.rows)
    out << std::left << std::setw(static_cast<int>(width)) << label_of(options.vary, r.values) << std::right << std::setw(12)
        << fixed(100 * r.error, 3) << std::setw(14) << fixed(r.ms_per_simulated_second, 4) << std::setw(12)
        << fixed(r.ms_per_step, 4) << (r.pareto ? "  *" : "") << "\n";
  // The record now names this study's files alone, and an earlier study's
  // plot where this one drew none (still that study's).
  std::set<std::string> written;
  for (const std::string& name : study_files(result.rows.size())) {
    const bool drawn = name == "study.png" ? result.plotted : gnuplot;
    const bool ours = !drawn_by_gnuplot(name) || drawn || earlier.contains(name);
    if (ours && there(dir / name)) written.insert(name);
  }
  write_study_record(dir, written);
  out << "output: " << printable_path(dir.string()) << "  (study.md, study.csv" << (result.plotted ? ", study.png" : "") << ")\n";
  return result;
}

}  // namespace marbles
