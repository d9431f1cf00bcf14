// bench/order_study_main.cpp — marbles_order_study: the table (and with
// --json the figures) of bench/order_study.hpp's orders on one pile.
//
//   marbles_order_study [--side 30] [--layers 30] [--substeps 30]
//                       [--pile close-packed|cubic|settled] [--n N] [--cache DIR]
//                       [--rolling] [--order NAME]... [--json]
// --order: only the orders so named (repeated for more), in the table's order.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench/order_study.hpp"

namespace {

int parse(const char* name, const char* value, int lo, int hi) {
  char* end = nullptr;
  const long v = value ? std::strtol(value, &end, 10) : 0;
  if (!value || *end != '\0' || v < lo || v > hi) {
    std::fprintf(stderr, "marbles_order_study: %s needs an integer in [%d, %d], got '%s'\n", name, lo, hi,
                 value ? value : "");
    std::exit(2);
  }
  return static_cast<int>(v);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace marbles::order_study;
  int side = 30, layers = 30, substeps = 30, n = 0;
  bool json = false, rolling = false, settled = false;
  std::string cache;
  std::vector<std::string> only;
  PileKind kind = PileKind::close_packed;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const char* next = i + 1 < argc ? argv[i + 1] : nullptr;
    if (a == "--side") side = parse("--side", next, 2, 400), ++i;
    else if (a == "--layers") layers = parse("--layers", next, 1, 400), ++i;
    else if (a == "--substeps") substeps = parse("--substeps", next, 1, 10000), ++i;
    else if (a == "--json") json = true;
    else if (a == "--rolling") rolling = true;
    else if (a == "--n") n = parse("--n", next, 1, 100000000), ++i;
    else if (a == "--order") {
      if (!next) {
        std::fprintf(stderr, "marbles_order_study: --order needs an order's name\n");
        return 2;
      }
      only.push_back(next), ++i;
    } else if (a == "--cache") {
      if (!next) {
        std::fprintf(stderr, "marbles_order_study: --cache needs a folder\n");
        return 2;
      }
      cache = next, ++i;
    } else if (a == "--pile") {
      const std::string v = next ? next : "";
      if (v != "cubic" && v != "close-packed" && v != "settled") {
        std::fprintf(stderr, "marbles_order_study: --pile needs close-packed, cubic or settled, got '%s'\n",
                     v.c_str());
        return 2;
      }
      kind = v == "cubic" ? PileKind::cubic : PileKind::close_packed;
      settled = v == "settled";
      ++i;
    } else {
      std::fprintf(stderr,
                   "marbles_order_study: unknown argument '%s' (usage: marbles_order_study [--side N] [--layers N] "
                   "[--substeps N] [--pile close-packed|cubic|settled] [--n N] [--cache DIR] [--rolling] "
                   "[--order NAME]... "
                   "[--json])\n",
                   a.c_str());
      return 2;
    }
  }
  if (settled && n == 0) {
    std::fprintf(stderr, "marbles_order_study: --pile settled needs --n\n");
    return 2;
  }
  std::vector<Order> orders = default_orders();
  for (const std::string& name : only)
    if (std::none_of(orders.begin(), orders.end(), [&](const Order& o) { return o.name == name; })) {
      std::fprintf(stderr, "marbles_order_study: --order: no order is named '%s'\n", name.c_str());
      return 2;
    }
  if (!only.empty())
    std::erase_if(orders, [&](const Order& o) { return std::find(only.begin(), only.end(), o.name) == only.end(); });
  Pile pile = settled ? settled_pile(static_cast<std::size_t>(n), cache, rolling) : make_pile(kind, side, layers, rolling);
  std::printf("order study: %s pile%s, %zu spheres, %zu contacts, %u colours, %d substeps held still\n",
              settled ? "the benchmark's settled" : kind == PileKind::cubic ? "cubic" : "close-packed",
              rolling ? " (rolling resistance)" : "", pile.world.size(), pile.contacts.size(), pile.ranges.colours,
              substeps);
  std::printf("%-20s %6s %9s %9s %12s %7s %9s %10s\n", "order", "passes", "p99 v/gh", "rms v/gh", "floor/weight",
              "tiles", "between", "ms/substep");
  std::string out = "{\"spheres\": " + std::to_string(pile.world.size()) +
                    ", \"contacts\": " + std::to_string(pile.contacts.size()) + ", \"orders\": [";
  for (std::size_t i = 0; i < orders.size(); ++i) {
    const Order& o = orders[i];
    const Result res = run(o, pile, substeps);
    std::printf("%-20s %6d %9.4f %9.4f %12.4f %7zu %8.1f%% %10.1f\n", o.name.c_str(), o.passes, res.p99, res.rms,
                res.floor_ratio, res.tiles, 100 * res.between, res.ms);
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "%s{\"order\": \"%s\", \"passes\": %d, \"local_sweeps\": %d, \"tile_diameters\": %d, "
                  "\"height_band_diameters\": %d, "
                  "\"p99_speed_over_gh\": %.6g, \"rms_speed_over_gh\": %.6g, \"floor_over_weight\": %.6g, "
                  "\"tiles\": %zu, \"between_fraction\": %.6g, \"ms_per_substep\": %.4g}",
                  i ? ", " : "", o.name.c_str(), o.passes, o.local, o.tile, o.height_band, res.p99, res.rms,
                  res.floor_ratio,
                  res.tiles, res.between, res.ms);
    out += buf;
  }
  out += "]}";
  if (json) std::printf("%s\n", out.c_str());
}
