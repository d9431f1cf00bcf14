#!/usr/bin/env python3
"""scripts/ncu_table.py NCU_CSV — Nsight Compute's CSV (one row per kernel
and metric) as a table by kernel: launches, time, share, and where measured
the DRAM and L2 bytes with their rates. Used by scripts/gpu-profile."""
import csv
import re
import sys
from collections import defaultdict

TIME = {"ns": 1e-6, "nsecond": 1e-6, "us": 1e-3, "usecond": 1e-3, "ms": 1.0, "msecond": 1.0, "s": 1e3, "second": 1e3}
BYTES = {"byte": 1, "B": 1, "Kbyte": 1e3, "KB": 1e3, "Mbyte": 1e6, "MB": 1e6, "Gbyte": 1e9, "GB": 1e9}


def short(name):
    """A kernel's name without its arguments, `void` and marbles' own
    namespaces (an anonymous one included); its template arguments kept.
    Also scripts/ncu_stalls.py's."""
    name = re.sub(r"\(.*", "", name.replace("(anonymous namespace)::", "")).replace("void ", "")
    return re.sub(r"marbles::(narrowphase::|broadphase::|integrator::)?(cuda::)?", "", name)


def read_rows(path, columns, tool):
    """Nsight Compute's CSV at `path`: its rows, and where each of `columns`
    stands in them; None (said why, as `tool`) where it has no rows or
    lacks a column. Also scripts/ncu_stalls.py's."""
    rows = [r for r in csv.reader(line for line in open(path) if line.startswith('"'))]
    if not rows:
        print(f"{tool}: no rows in {path}")
        return None
    missing = [k for k in columns if k not in rows[0]]
    if missing:
        print(f"{tool}: {path} has no column {', '.join(missing)}")
        return None
    return rows[1:], [rows[0].index(k) for k in columns]


def main(path):
    read = read_rows(path, ("Kernel Name", "Metric Name", "Metric Unit", "Metric Value"), "ncu_table")
    if read is None:
        return 1
    rows, (ki, mi, ui, vi) = read
    ms, dram, l2, count = defaultdict(float), defaultdict(float), defaultdict(float), defaultdict(int)
    for r in rows:
        name, metric, unit = short(r[ki]), r[mi], r[ui]
        value = float(r[vi].replace(",", "") or 0)
        if metric == "gpu__time_duration.sum":
            if unit not in TIME:
                print(f"ncu_table: unknown time unit {unit!r}")
                return 1
            ms[name] += value * TIME[unit]
            count[name] += 1
        elif metric in ("dram__bytes.sum", "lts__t_bytes.sum"):
            if unit not in BYTES:
                print(f"ncu_table: unknown byte unit {unit!r}")
                return 1
            (dram if metric.startswith("dram") else l2)[name] += value * BYTES[unit]
    all_ms = sum(ms.values())
    launches = sum(count.values())
    print(f"{launches} launches, {all_ms:.2f} ms of kernels in the step (each kernel alone, serialised)")
    with_bytes = bool(dram)
    line = f"{'kernel':60} {'launches':>8} {'ms':>8} {'%':>6}"
    if with_bytes:
        line += f" {'DRAM MB':>9} {'TB/s':>6} {'L2 MB':>9} {'TB/s':>6}"
    print(line)
    for name, t in sorted(ms.items(), key=lambda kv: -kv[1])[:30]:
        line = f"{name[:60]:60} {count[name]:>8} {t:8.3f} {100 * t / all_ms:6.1f}"
        if with_bytes:
            rate = lambda b: b / (t * 1e-3) / 1e12 if t > 0 else 0.0
            line += f" {dram[name] / 1e6:9.1f} {rate(dram[name]):6.2f} {l2[name] / 1e6:9.1f} {rate(l2[name]):6.2f}"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]) if len(sys.argv) == 2 else (print("usage: ncu_table.py NCU_CSV") or 2))
