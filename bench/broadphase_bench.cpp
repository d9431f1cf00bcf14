// bench/broadphase_bench.cpp — see broadphase_bench.hpp.
#include "bench/broadphase_bench.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "bench/bench_scenes.hpp"
#include "broadphase/broadphase.hpp"
#include "core/error.hpp"
#if defined(MARBLES_BROADPHASE_CUDA)
#include "bench/broadphase_bench_cuda.hpp"
#endif

namespace marbles::bench {
namespace {

namespace bp = marbles::broadphase;

struct Summary {
  double median = 0, min = 0;
};

Summary summarise(std::vector<double> v) {
  if (v.empty()) return {};
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size();
  return {m % 2 ? v[m / 2] : 0.5 * (v[m / 2 - 1] + v[m / 2]), v.front()};
}

// Bytes each stage must move through memory at least (each input read once,
// each output written once; the sort: one read and one write of keys and
// values per radix pass).
struct StageBytes {
  double cell_ids = 0, sort = 0, cell_list = 0, traversal = 0;
  double total() const { return cell_ids + sort + cell_list + traversal; }
};

// Home-cell variant: keys (centres in, one entry out), sort, reorder (ids
// in, spheres gathered, lower bounds written), traversal (spheres and lower
// bounds read once, counts, offsets, pairs).
StageBytes floor_bytes_home(const bp::Stats& s, std::size_t n) {
  const double kb = s.key_width / 8.0, entry = kb + 4.0, nn = double(n);
  const double lb = s.dense_cell_starts ? 4.0 * double(s.grid_cells + 1) : 0.0;
  StageBytes b;
  b.cell_ids = nn * 12.0 + nn * entry;
  b.sort = 2.0 * nn * entry * s.sort_passes;
  b.cell_list = nn * entry + nn * 16.0 + nn * 16.0 + lb;
  b.traversal = nn * (16.0 + kb) + lb + nn * 12.0 + double(s.pairs) * 8.0;
  return b;
}

StageBytes floor_bytes(const bp::Stats& s, std::size_t n, bool home) {
  if (home) return floor_bytes_home(s, n);
  const double kb = s.key_width / 8.0, entry = kb + 4.0;
  const double entries = double(s.cell_entries);
  const unsigned passes = (s.key_bits + 7) / 8;
  StageBytes b;
  b.cell_ids = double(n) * (16.0 + 2.0) + entries * entry;
  b.sort = 2.0 * entries * entry * passes;
  b.cell_list = entries * entry + double(s.collision_cells) * 12.0;
  b.traversal = double(s.collision_cells) * 12.0 + entries * 4.0 + double(n) * 18.0 + double(s.pairs) * 8.0;
  return b;
}

std::string fmt(double v, int prec = 3) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", prec, v);
  return buf;
}

struct CaseResult {
  std::size_t n = 0;
  Summary cell_ids, sort, cell_list, traversal, total;
  bp::Stats last;
  StageBytes bytes;
  double copy_bytes_per_ms = 0;  // 0: not measured (CPU)
  std::string device;
};

CaseResult summarise_calls(std::size_t n, const std::vector<bp::Stats>& calls, bool home) {
  CaseResult r;
  r.n = n;
  std::vector<double> a, b, c, d, e;
  for (const auto& s : calls) {
    a.push_back(s.ms_cell_ids);
    b.push_back(s.ms_sort);
    c.push_back(s.ms_cell_list);
    d.push_back(s.ms_traversal);
    e.push_back(s.ms_total);
  }
  r.cell_ids = summarise(a);
  r.sort = summarise(b);
  r.cell_list = summarise(c);
  r.traversal = summarise(d);
  r.total = summarise(e);
  r.last = calls.back();
  r.bytes = floor_bytes(r.last, n, home);
  return r;
}

// One JSON object on one line per case (gpu-check collects them as JSON lines).
void print_json(std::ostream& out, const BroadphaseBenchOptions& o, const CaseResult& r) {
  auto stage = [&](const Summary& s, double bytes) {
    nlohmann::ordered_json j{{"median_ms", s.median}, {"min_ms", s.min}};
    if (r.copy_bytes_per_ms > 0) j["floor_ms"] = bytes / r.copy_bytes_per_ms;
    j["floor_bytes"] = bytes;
    return j;
  };
  nlohmann::ordered_json j{{"bench", "broadphase"},
                           {"backend", o.backend},
                           {"algorithm", o.algorithm},
                           {"sort_kind", o.backend == "cuda" ? o.sort : std::string("radix-cpu")},
                           {"scene", o.scene},
                           {"n", r.n},
                           {"repeats", o.repeats},
                           {"margin", o.margin},
                           {"cell_ids", stage(r.cell_ids, r.bytes.cell_ids)},
                           {"sort", stage(r.sort, r.bytes.sort)},
                           {"cell_list", stage(r.cell_list, r.bytes.cell_list)},
                           {"traversal", stage(r.traversal, r.bytes.traversal)},
                           {"total", stage(r.total, r.bytes.total())},
                           {"pairs", r.last.pairs},
                           {"cell_entries", r.last.cell_entries},
                           {"collision_cells", r.last.collision_cells},
                           {"tests", r.last.tests},
                           {"key_bits", r.last.key_bits},
                           {"key_width", r.last.key_width},
                           {"sort_passes", r.last.sort_passes},
                           {"cell_size", r.last.cell_size},
                           {"grid_cells", r.last.grid_cells},
                           {"dense_cell_starts", r.last.dense_cell_starts}};
  if (r.copy_bytes_per_ms > 0) {
    j["copy_GBps"] = r.copy_bytes_per_ms * 1e-6;
    j["device"] = r.device;
  }
  out << j.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace) << "\n";
}

void print_table(std::ostream& out, const BroadphaseBenchOptions& o, const std::vector<CaseResult>& rs) {
  const bool gpu = !rs.empty() && rs.front().copy_bytes_per_ms > 0;
  out << "broadphase " << o.backend << " algorithm=" << o.algorithm
      << (o.backend == "cuda" ? " sort=" + o.sort : std::string()) << " scene="
      << o.scene << "  (ms: median/min over " << o.repeats << " calls"
      << (gpu ? "; [floor] = bytes / measured copy bandwidth" : "") << ")\n";
  if (gpu) out << "device: " << rs.front().device << ", copy " << fmt(rs.front().copy_bytes_per_ms * 1e-6, 0) << " GB/s\n";
  out << "       N   cell_ids       sort  cell_list  traversal      total      pairs  entries\n";
  for (const auto& r : rs) {
    char line[256];
    auto cell = [](const Summary& s) { return fmt(s.median, s.median < 10 ? 3 : 1); };
    std::snprintf(line, sizeof line, "%8zu %10s %10s %10s %10s %10s %10zu %8zu\n", r.n, cell(r.cell_ids).c_str(),
                  cell(r.sort).c_str(), cell(r.cell_list).c_str(), cell(r.traversal).c_str(), cell(r.total).c_str(),
                  r.last.pairs, r.last.cell_entries);
    out << line;
    if (gpu) {
      const double f = r.copy_bytes_per_ms;
      auto bracketed = [](std::string s) { return s.insert(0, 1, '[') + ']'; };  // not "[" + s: a GCC 12 false -Wrestrict
      std::snprintf(line, sizeof line, "   floor %10s %10s %10s %10s %10s   min %s\n",
                    bracketed(fmt(r.bytes.cell_ids / f)).c_str(), bracketed(fmt(r.bytes.sort / f)).c_str(),
                    bracketed(fmt(r.bytes.cell_list / f)).c_str(), bracketed(fmt(r.bytes.traversal / f)).c_str(),
                    bracketed(fmt(r.bytes.total() / f)).c_str(), fmt(r.total.min).c_str());
      out << line;
    } else {
      std::snprintf(line, sizeof line, "     min %10s %10s %10s %10s %10s\n", fmt(r.cell_ids.min).c_str(),
                    fmt(r.sort.min).c_str(), fmt(r.cell_list.min).c_str(), fmt(r.traversal.min).c_str(),
                    fmt(r.total.min).c_str());
      out << line;
    }
  }
}

}  // namespace

BroadphaseBenchOptions parse_broadphase_bench_args(const std::vector<std::string>& args) {
  BroadphaseBenchOptions o;
  for (std::size_t k = 0; k < args.size(); ++k) {
    const std::string& a = args[k];
    auto value = [&]() -> const std::string& {
      if (k + 1 >= args.size()) throw std::invalid_argument(a + " needs a value");
      return args[++k];
    };
    if (a == "--backend") o.backend = value();
    else if (a == "--algorithm") o.algorithm = value();
    else if (a == "--sort") o.sort = value();
    else if (a == "--scene") o.scene = value();
    else if (a == "--repeats") o.repeats = std::stoi(value());
    else if (a == "--seed") o.seed = std::stoull(value());
    else if (a == "--margin") o.margin = std::stod(value());
    else if (a == "--json") o.json = true;
    else if (a == "--n") {
      std::stringstream ss(value());
      std::string item;
      while (std::getline(ss, item, ',')) o.n.push_back(static_cast<std::size_t>(std::stod(item)));
    } else {
      throw std::invalid_argument("unknown option '" + a + "'");
    }
  }
  return o;
}

int run_broadphase_bench(const BroadphaseBenchOptions& opt, std::ostream& out) {
  BroadphaseBenchOptions o = opt;
  if (o.backend != "cpu" && o.backend != "cuda") {
    out << "bench broadphase: --backend must be cpu or cuda\n";
    return 2;
  }
  if (o.algorithm != "seed" && o.algorithm != "home") {
    out << "bench broadphase: --algorithm must be seed or home\n";
    return 2;
  }
  if (o.sort != "seed" && o.sort != "cub") {
    out << "bench broadphase: --sort must be seed or cub\n";
    return 2;
  }
  if (o.scene != "gas" && o.scene != "pile" && o.scene != "poly") {
    out << "bench broadphase: --scene must be gas, pile or poly\n";
    return 2;
  }
  if (o.repeats < 1) o.repeats = 1;
  if (o.n.empty()) o.n = {10000, 100000, 1000000};

  std::vector<CaseResult> results;
  try {
    for (std::size_t n : o.n) {
      const BenchSpheres s = make_bench_scene(o.scene, n, o.seed);
      CaseResult r;
      const bool home = o.algorithm == "home";
      const bp::Algorithm algorithm = home ? bp::Algorithm::home : bp::Algorithm::seed;
      if (o.backend == "cpu") {
        auto bp = bp::make_subdivision_cpu(algorithm);
        const SpheresIn view{s.centre.data(), s.radius.data(), n};
        std::vector<bp::Pair> pairs;
        bp->find_pairs(view, real(o.margin), pairs);  // warm-up: buffers grow once
        std::vector<bp::Stats> calls;
        for (int k = 0; k < o.repeats; ++k) {
          bp->find_pairs(view, real(o.margin), pairs);
          calls.push_back(bp->last_stats());
        }
        r = summarise_calls(n, calls, home);
      } else {
#if defined(MARBLES_BROADPHASE_CUDA)
        const CudaBenchRun run = run_cuda_broadphase(
            s, algorithm, o.sort == "seed" ? bp::SortKind::seed : bp::SortKind::cub, o.repeats, o.margin);
        r = summarise_calls(n, run.calls, home);
        r.copy_bytes_per_ms = run.copy_bytes_per_ms;
        r.device = run.device;
#else
        out << "bench broadphase: this build has no CUDA backend\n";
        return 1;
#endif
      }
      if (o.json) print_json(out, o, r);
      results.push_back(r);
    }
  } catch (const RuntimeFailure& e) {
    out << "bench broadphase: " << e.what() << "\n";
    return 1;
  }
  if (!o.json) print_table(out, o, results);  // --json: JSON only, one object per line
  return 0;
}

}  // namespace marbles::bench
