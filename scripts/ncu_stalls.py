#!/usr/bin/env python3
"""scripts/ncu_stalls.py NCU_CSV — Nsight Compute's CSV (one row per launch
and metric) as a table by launch: grid, time, registers, occupancy, issue
rate, hit rates, and the stall reasons (cycles a warp spends in each per
issued instruction), the largest first. Used by scripts/gpu-profile's
STALLS=REGEX."""
import math
import sys
from collections import defaultdict

from ncu_table import TIME, read_rows
from ncu_table import short as table_short

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


def short(name):
    """A kernel's name as ncu_table's short() gives it, without any
    namespace, its words and template arguments by their first letters
    (record_sweep_kernel<true, true, false> -> rsk<ttf>)."""
    base, _, args = table_short(name).partition("<")
    base = base.split("::")[-1]
    letters = "".join(w[0] for w in base.split("_") if w)
    return letters + ("<" + "".join(a.strip()[:1] for a in args.rstrip(">").split(",")) + ">" if args else "")


def main(path):
    read = read_rows(path, ("ID", "Kernel Name", "Metric Name", "Metric Unit", "Metric Value"), "ncu_stalls")
    if read is None:
        return 1
    rows, (ii, ki, mi, ui, vi) = read
    launches, names = defaultdict(dict), {}
    for r in rows:
        try:
            value = float(r[vi].replace(",", ""))
        except ValueError:
            continue
        if r[mi] == "gpu__time_duration.sum":
            if r[ui] not in TIME:
                print(f"ncu_stalls: unknown time unit {r[ui]!r}")
                return 1
            value *= TIME[r[ui]] * 1e3  # us
        launches[int(r[ii])][r[mi]] = value
        names[int(r[ii])] = short(r[ki])
    ids = sorted(launches)
    print(f"{len(ids)} launches")
    print(f"{'':28}" + "".join(f"{i:>9}" for i in ids))
    print(f"{'kernel':28}" + "".join(f"{names[i][:8]:>9}" for i in ids))
    for metric, name in SHOWN:
        if any(metric in launches[i] for i in ids):
            print(f"{name:28}" + "".join(f"{launches[i].get(metric, float('nan')):9.1f}" for i in ids))
    stalls = {m for i in ids for m in launches[i] if m.startswith(STALL) and m.endswith("_per_issue_active.ratio")}
    mean = lambda m: sum(launches[i].get(m, 0.0) for i in ids) / len(ids)
    print("stalls (cycles per issued instruction; nan: not measured for that launch)")
    for m in sorted(stalls, key=lambda m: -mean(m)):
        if mean(m) >= 0.05:
            reason = m[len(STALL):-len("_per_issue_active.ratio")]
            print(f"  {reason:26}" + "".join(f"{launches[i].get(m, math.nan):9.2f}" for i in ids))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]) if len(sys.argv) == 2 else (print("usage: ncu_stalls.py NCU_CSV") or 2))
