#!/usr/bin/env python3
"""scripts/ncu_table.py and scripts/ncu_stalls.py on Nsight Compute CSVs
made here (random times in mixed units, kernels in an anonymous namespace,
templates, CUB's nested templates): each kernel a row of its own under its
own name, the launches counted and the times summed as the CSV says.

  ncu_scripts_test.py SCRIPTS_DIR WORK_DIR
"""
import csv
import random
import re
import subprocess
import sys
from pathlib import Path

KERNELS = {  # the CSV's name -> the table's name, the stalls' name
    "void marbles::narrowphase::(anonymous namespace)::record_sweep_kernel<true, true, false>"
    "(marbles::narrowphase::SweepRecords, marbles::narrowphase::ContactRange, float)":
        ("record_sweep_kernel<true, true, false>", "rsk<ttf>"),
    "void marbles::narrowphase::(anonymous namespace)::records_kernel(marbles::narrowphase::ContactInputs)":
        ("records_kernel", "rk"),
    "void marbles::broadphase::home_write_kernel<unsigned int, true>(unsigned int *)":
        ("home_write_kernel<unsigned int, true>", "hwk<ut>"),
    "void cub::CUB_300001_SM_900::detail::scan::DeviceScanKernel<cub::Policy<int>, int>(int)":
        ("cub::CUB_300001_SM_900::detail::scan::DeviceScanKernel<cub::Policy<int>, int>", "D<ci>"),
}
UNITS = {"nsecond": 1e-6, "usecond": 1e-3, "msecond": 1.0}  # ms a unit


def write_csv(path, rows):
    with open(path, "w", newline="") as out:
        out.write("==PROF== a line the scripts skip\n")
        w = csv.writer(out, quoting=csv.QUOTE_ALL)
        w.writerow(["ID", "Kernel Name", "Metric Name", "Metric Unit", "Metric Value"])
        w.writerows(rows)


def main(scripts, work):
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    rng = random.Random(20261129)
    failures = []
    for trial in range(5):
        rows, ms, launches, stall = [], {}, {}, {}
        for launch in range(rng.randint(4, 12)):
            name = rng.choice(list(KERNELS))
            unit = rng.choice(list(UNITS))
            t = rng.uniform(1e-3, 5e-2) / UNITS[unit]  # 1-50 us
            rows.append([launch, name, "gpu__time_duration.sum", unit, f"{t:,.6f}"])
            rows.append([launch, name, "launch__registers_per_thread", "register/thread", str(rng.randint(32, 128))])
            s = rng.uniform(0.1, 9.0)
            rows.append([launch, name, "smsp__average_warps_issue_stalled_long_scoreboard_per_issue_active.ratio",
                         "", f"{s:.4f}"])
            table = KERNELS[name][0]
            ms[table] = ms.get(table, 0.0) + t * UNITS[unit]
            launches[table] = launches.get(table, 0) + 1
            stall[launch] = (KERNELS[name][1], s)
        path = work / f"ncu-{trial}.csv"
        write_csv(path, rows)

        out = subprocess.run([sys.executable, "-B", f"{scripts}/ncu_table.py", str(path)], capture_output=True, text=True)
        if out.returncode != 0:
            failures.append(f"trial {trial}: ncu_table.py exit {out.returncode}: {out.stderr}")
            continue
        seen = {}
        for line in out.stdout.splitlines()[2:]:
            m = re.match(r"^(.{60}) +(\d+) +([\d.]+) +([\d.]+)$", line)
            if not m:
                failures.append(f"trial {trial}: ncu_table.py row not read: {line!r}")
                continue
            seen[m.group(1).strip()] = (int(m.group(2)), float(m.group(3)))
        want = {name[:60]: (launches[name], ms[name]) for name in ms}
        if set(seen) != set(want):
            failures.append(f"trial {trial}: ncu_table.py rows {sorted(seen)} against {sorted(want)}")
        for name, (n, t) in want.items():
            if name in seen and (seen[name][0] != n or abs(seen[name][1] - t) > 0.0005 + 1e-9):
                failures.append(f"trial {trial}: {name}: {seen[name]} against {n} launches, {t:.4f} ms")
        if f"{sum(launches.values())} launches, {sum(ms.values()):.2f} ms" not in out.stdout:
            failures.append(f"trial {trial}: ncu_table.py total wrong:\n{out.stdout}")

        out = subprocess.run([sys.executable, "-B", f"{scripts}/ncu_stalls.py", str(path)], capture_output=True, text=True)
        if out.returncode != 0:
            failures.append(f"trial {trial}: ncu_stalls.py exit {out.returncode}: {out.stderr}")
            continue
        lines = out.stdout.splitlines()
        names = next((l.split()[1:] for l in lines if l.startswith("kernel")), [])
        if names != [stall[i][0][:8] for i in sorted(stall)]:
            failures.append(f"trial {trial}: ncu_stalls.py names {names} against {[stall[i][0] for i in sorted(stall)]}")
        scoreboard = next((l.split()[1:] for l in lines if l.strip().startswith("long_scoreboard")), [])
        if [float(v) for v in scoreboard] != [round(stall[i][1], 2) for i in sorted(stall)]:
            failures.append(f"trial {trial}: ncu_stalls.py stalls {scoreboard}")
    for f in failures:
        print("FAIL:", f)
    print("ncu scripts:", "FAILED" if failures else "passed", "(5 trials)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
