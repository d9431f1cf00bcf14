#!/usr/bin/env python3
"""scripts/bench-ab against a stand-in benchmark whose figures the test sets
through the environment (same bits, bits that change between settings or
between rounds, failed runs, the order of the runs, a repeated setting,
values with commas), then against the program itself on the CPU, where
thread counts and lane kinds must give the same bits.

  bench_ab_test.py BENCH_AB MARBLES WORK_DIR
"""
import json
import os
import subprocess
import sys
from pathlib import Path

# The stand-in: one result a size for `bench step ... --n N... --json`. Its
# energy is FAKE_KE (default 1.0), or FAKE_KE_LATER from its FAKE_AFTER-th
# call on; FAKE_FAIL=1 exits 3, FAKE_FAIL=text prints no JSON. Each call
# appends FAKE_KE (or -) and FAKE_LIST to FAKE_LOG, so the test sees the
# order of the runs and what each was given. The CUDA figures are there,
# the busy time null, as the benchmark writes a figure it did not take.
FAKE = r'''
import json, os, sys
args = sys.argv[1:]
assert args[:2] == ["bench", "step"] and args[-1] == "--json", args
log = os.environ["FAKE_LOG"]
calls = len(open(log).read().splitlines()) if os.path.exists(log) else 0
with open(log, "a") as out:
    out.write(os.environ.get("FAKE_KE", "-") + " " + os.environ.get("FAKE_LIST", "-") + "\n")
if os.environ.get("FAKE_FAIL") == "1":
    print("stand-in failed on purpose", file=sys.stderr)
    sys.exit(3)
if os.environ.get("FAKE_FAIL") == "text":
    print("not a benchmark")
    sys.exit(0)
sizes = [int(a) for a in args[args.index("--n") + 1:-1] if a.isdigit()]
ke = float(os.environ.get("FAKE_KE", "1.0"))
find = float(os.environ.get("FAKE_FIND", "0.5"))
if "FAKE_AFTER" in os.environ and calls >= int(os.environ["FAKE_AFTER"]):
    ke = float(os.environ.get("FAKE_KE_LATER", ke))
    find = float(os.environ.get("FAKE_FIND_LATER", find))
print(json.dumps({"backend": "cuda", "threads": 16, "results": [
    {"n": n, "step_ms_median": 100.0 + n / 1000, "ke_per_sphere_J": ke, "max_overlap_pct": 0.5,
     "verb_ms": {"find_contacts": find, "solve_velocities": 0.25}, "launches_per_step": 238.0, "host_waits_per_step": 2.0,
     "device_busy_ms_per_step": None} for n in sizes]}))
'''

failures = []


def check(what, ok, output=""):
    print(("ok   " if ok else "FAIL ") + what)
    if not ok:
        failures.append(what)
        print(output)


def main(bench_ab, marbles, work):
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    fake = work / "fake_bench"
    fake.write_text(f"#!{sys.executable}\n" + FAKE)  # the test's own interpreter
    fake.chmod(0o755)
    log = work / "fake.log"

    def run(program, *args, env=None):
        done = subprocess.run([sys.executable, bench_ab, "--program", program, *args], capture_output=True, text=True,
                              env={**os.environ, **(env or {})})
        return done.returncode, done.stdout + done.stderr

    def fake_run(*args, env=None):
        log.write_text("")
        code, out = run(str(fake), *args, env={"FAKE_LOG": str(log), **(env or {})})
        return code, out, [line.split()[0] for line in log.read_text().splitlines()]

    code, out, order = fake_run("--rounds", "3", "-", "FAKE_KE=1.0", "--", "--n", "10", "20")
    check("same figures: exit 0 and 'same bits' for each size", code == 0 and out.count("same bits") == 2, out)
    check("the settings taken in turn, the order reversed every other round",
          order == ["-", "1.0", "1.0", "-", "-", "1.0"], str(order))
    check("every round's figure listed in full, the CUDA figures' medians, a null busy time as -",
          out.count("100.010 100.010 100.010") == 2 and out.count("100.020 100.020 100.020") == 2 and
          out.count(f" {'238':>6} {'2':>5} ") == 4 and f"100.010 {'-':>7} {'0.250':>7}" in out, out)

    check("no verb table unless asked", "verbs, median ms" not in out, out)

    # --verbs: each verb's median over the rounds. The calls go -, F, F, -,
    # -, F (F: FAKE_FIND=0.75); from the fourth on, every find time is 2.0.
    # So "-" takes 0.5, 2.0, 2.0 (median 2.0, mean 1.5) and F 0.75, 0.75,
    # 2.0 (median 0.75, mean 1.17).
    code, out, _ = fake_run("--rounds", "3", "--verbs", "-", "FAKE_FIND=0.75", "--", "--n", "10",
                            env={"FAKE_AFTER": "3", "FAKE_FIND_LATER": "2.0"})
    verb_rows = [line.split() for line in out.splitlines() if line.split()[:2] in (["-", "10"], ["FAKE_FIND=0.75", "10"])]
    check("--verbs: a header of the verbs and a row a setting with each verb's median over its rounds",
          code == 0 and "verbs, median ms" in out and "find" in out and "solve" in out and
          ["-", "10", "2.000", "0.250"] in verb_rows and ["FAKE_FIND=0.75", "10", "0.750", "0.250"] in verb_rows, out)

    code, out, _ = fake_run("--rounds", "2", "-", "FAKE_KE=2.5", "--", "--n", "10")
    check("different energies: exit 1, each setting's values named",
          code == 1 and "FAKE_KE=2.5: KE/sphere and overlap % [(2.5, 0.5)]" in out and
          "-: KE/sphere and overlap % [(1.0, 0.5)]" in out and "same bits" not in out, out)

    code, out, _ = fake_run("--rounds", "2", "-", "FAKE_KE=1.0", "--", "--n", "10",
                            env={"FAKE_AFTER": "3", "FAKE_KE_LATER": "7.0"})
    check("an energy that changes in a later round: exit 1, both values of that setting named",
          code == 1 and "[(1.0, 0.5), (7.0, 0.5)]" in out and "same bits" not in out, out)

    code, out, order = fake_run("--rounds", "2", "-", "-", "--", "--n", "10")
    check("a setting given twice: two rows, two runs each",
          code == 0 and out.count("- #1 ") == 1 and out.count("- #2 ") == 1 and len(order) == 4, out)

    log.write_text("")
    run(str(fake), "--rounds", "1", "FAKE_LIST=0,1,FAKE_KE=3.0", "--", "--n", "10", env={"FAKE_LOG": str(log)})
    check("a value with a comma kept whole", log.read_text().split() == ["3.0", "0,1"], log.read_text())

    code, out, _ = fake_run("--rounds", "1", "-", "FAKE_FAIL=1", "--", "--n", "10")
    check("a failed run: exit 1, the setting and its message named, nothing said to be the same",
          code == 1 and "FAKE_FAIL=1, round 1: exit 3" in out and "failed on purpose" in out and
          "failed in every round" in out and "nothing compared" in out and "same bits" not in out, out)

    code, out, _ = fake_run("--rounds", "1", "-", "FAKE_FAIL=text", "--", "--n", "10")
    check("output that is no benchmark's: a failed run, no traceback",
          code == 1 and "no benchmark results" in out and "Traceback" not in out, out)

    code, out = run(str(work / "no-such-program"), "-", "--", "--n", "10")
    check("a program that cannot run: a failed run, no traceback",
          code == 1 and "cannot run" in out and "Traceback" not in out, out)

    code, out, _ = fake_run("NAME", "--", "--n", "10")
    check("a setting that is not NAME=VALUE refused", code != 0 and "expected -, NAME=VALUE" in out, out)

    # Another program by setting: a second stand-in whose energy is 4.0
    # unless FAKE_KE says.
    other = work / "fake_bench_other"
    other.write_text(f"#!{sys.executable}\n" + FAKE.replace('os.environ.get("FAKE_KE", "1.0")',
                                                            'os.environ.get("FAKE_KE", "4.0")'))
    other.chmod(0o755)
    code, out, order = fake_run("--rounds", "1", "-", f"@{other}", "--", "--n", "10")
    check("@PROGRAM runs that program: its other energy found",
          code == 1 and "[(4.0, 0.5)]" in out and "[(1.0, 0.5)]" in out and len(order) == 2, out)
    code, out, _ = fake_run("--rounds", "1", "-", f"@{other},FAKE_KE=1.0", "--", "--n", "10")
    check("@PROGRAM,NAME=VALUE: that program under that setting", code == 0 and "same bits" in out, out)

    # The program itself: one and two threads, and SSE lanes, the same bits.
    # Each setting names its thread count, so an exported OMP_NUM_THREADS
    # does not make two settings one.
    lines = work / "cpu.jsonl"
    code, out = run(marbles, "--rounds", "2", "--json", str(lines), "OMP_NUM_THREADS=2", "OMP_NUM_THREADS=1",
                    "OMP_NUM_THREADS=2,MARBLES_LANES=sse2", "--", "--backend", "cpu", "--scene", "gas", "--n",
                    "3000", "--repeats", "3")
    rows = [json.loads(line) for line in lines.read_text().splitlines()] if lines.exists() else []
    check("the program on the CPU: one, two threads and SSE lanes give the same bits",
          code == 0 and "same bits" in out, out)
    check("--json: a line a run, with its setting, round, threads and lanes",
          len(rows) == 6 and sorted({(r["setting"], r["round"]) for r in rows}) ==
          sorted({(s, k) for s in ("OMP_NUM_THREADS=2", "OMP_NUM_THREADS=1", "OMP_NUM_THREADS=2,MARBLES_LANES=sse2")
                  for k in (1, 2)}) and all(r["backend"] == "cpu" and r["n"] == 3000 for r in rows), str(rows)[:2000])
    by = {r["setting"]: r for r in rows}
    if rows:
        check("the settings took effect: the lanes asked for, and one thread where asked (two where OpenMP is on)",
              by["OMP_NUM_THREADS=2,MARBLES_LANES=sse2"]["cpu_lanes"] == "sse2" and
              by["OMP_NUM_THREADS=1"]["threads"] == 1 and by["OMP_NUM_THREADS=2"]["threads"] in (1, 2), str(by))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
