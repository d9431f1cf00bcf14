#!/usr/bin/env python3
"""scripts/ncu_stalls.py NCU_CSV — Nsight Compute's CSV (one row per launch
and metric) as a table by launch: grid, time, registers, occupancy, issue
rate, hit rates, and the stall reasons (cycles a warp spends in each per
issued instruction), the largest first. Used by scripts/gpu-profile's
STALLS=REGEX."""
import csv
import sys
from collections import defaultdict

STALL = "smsp__average_warps_issue_stalled_"
SHOWN = [  # (metric, heading)
    ("launch__grid_size", "grid"),
    ("gpu__time_duration.sum", "us"),
    ("launch__registers_per_thread", "regs"),
    ("launch__occupancy_limit_registers", "blk/SM"),
    ("sm__maximum_warps_per_active_cycle_pct", "occ max%"),
    ("sm__warps_active.avg.pct_of_peak_sustained_active", "occ %"),
    ("smsp__issue_active.avg.pct_of_peak_sustained_active", "issue %"),
    ("smsp__warps_eligible.avg.per_cycle_active", "eligible"),
    ("lts__t_sector_hit_rate.pct", "L2 hit%"),
    ("l1tex__t_sector_hit_rate.pct", "L1 hit%"),
    ("dram__throughput.avg.pct_of_peak_sustained_elapsed", "DRAM %"),
]
TIME_US = {"ns": 1e-3, "nsecond": 1e-3, "us": 1.0, "usecond": 1.0, "ms": 1e3, "msecond": 1e3}


def main(path):
    rows = [r for r in csv.reader(line for line in open(path) if line.startswith('"'))]
    if not rows:
        print(f"ncu_stalls: no rows in {path}")
        return 1
    head, rows = rows[0], rows[1:]
    ii, mi, ui, vi = (head.index(k) for k in ("ID", "Metric Name", "Metric Unit", "Metric Value"))
    launches = defaultdict(dict)
    for r in rows:
        try:
            value = float(r[vi].replace(",", ""))
        except ValueError:
            continue
        if r[mi] == "gpu__time_duration.sum":
            value *= TIME_US.get(r[ui], float("nan"))
        launches[int(r[ii])][r[mi]] = value
    ids = sorted(launches)
    print(f"{len(ids)} launches")
    print(f"{'':28}" + "".join(f"{i:>9}" for i in ids))
    for metric, name in SHOWN:
        if any(metric in launches[i] for i in ids):
            print(f"{name:28}" + "".join(f"{launches[i].get(metric, float('nan')):9.1f}" for i in ids))
    stalls = {m for i in ids for m in launches[i] if m.startswith(STALL) and m.endswith("_per_issue_active.ratio")}
    mean = lambda m: sum(launches[i].get(m, 0.0) for i in ids) / len(ids)
    print("stalls (cycles per issued instruction)")
    for m in sorted(stalls, key=lambda m: -mean(m)):
        if mean(m) >= 0.05:
            reason = m[len(STALL):-len("_per_issue_active.ratio")]
            print(f"  {reason:26}" + "".join(f"{launches[i].get(m, 0.0):9.2f}" for i in ids))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]) if len(sys.argv) == 2 else (print("usage: ncu_stalls.py NCU_CSV") or 2))
