#!/usr/bin/env python3
"""scripts/bench-ab against a stand-in benchmark whose figures the test sets
through the environment (same bits, different bits, a failed run, the
rounds taken in turn), then against the program itself on the CPU, where
thread counts and lane kinds must give the same bits.

  bench_ab_test.py BENCH_AB MARBLES WORK_DIR
"""
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

# The stand-in: prints one result a size for `bench step ... --n N... --json`,
# its energy from FAKE_KE (default 1.0); FAKE_FAIL=1 exits 3. Each call
# appends its setting to FAKE_LOG, so the test sees the order of the runs.
FAKE = r'''#!/usr/bin/env python3
import json, os, sys
args = sys.argv[1:]
assert args[:2] == ["bench", "step"] and args[-1] == "--json", args
with open(os.environ["FAKE_LOG"], "a") as log:
    log.write(os.environ.get("FAKE_KE", "-") + "\n")
if os.environ.get("FAKE_FAIL") == "1":
    print("stand-in failed on purpose", file=sys.stderr)
    sys.exit(3)
sizes = [int(a) for a in args[args.index("--n") + 1:-1] if a.isdigit()]
ke = float(os.environ.get("FAKE_KE", "1.0"))
print(json.dumps({"results": [{"n": n, "step_ms_median": 1.0 + n / 1000, "ke_per_sphere_J": ke,
                               "max_overlap_pct": 0.5, "verb_ms": {"solve_velocities": 0.25}} for n in sizes]}))
'''

failures = []


def check(what, ok, output=""):
    print(("ok   " if ok else "FAIL ") + what)
    if not ok:
        failures.append(what)
        print(output)


def run(bench_ab, program, *args, env=None):
    done = subprocess.run([sys.executable, bench_ab, "--program", program, *args], capture_output=True, text=True,
                          env={**os.environ, **(env or {})})
    return done.returncode, done.stdout + done.stderr


def main(bench_ab, marbles, work):
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    fake = work / "fake_bench"
    fake.write_text(FAKE)
    fake.chmod(0o755)
    log = work / "fake.log"

    def fake_run(*args):
        log.write_text("")
        code, out = run(bench_ab, str(fake), *args, env={"FAKE_LOG": str(log)})
        return code, out, log.read_text().split()

    code, out, order = fake_run("--rounds", "3", "-", "FAKE_KE=1.0", "--", "--n", "10", "20")
    check("same figures: exit 0 and 'same bits' for each size", code == 0 and out.count("same bits") == 2, out)
    check("the settings taken in turn, round after round", order == ["-", "1.0"] * 3, str(order))
    check("each setting's three rounds listed", out.count("1.010 1.010 1.010") == 2 and out.count("1.020 1.020 1.020") == 2,
          out)

    code, out, _ = fake_run("--rounds", "2", "-", "FAKE_KE=2.5", "--", "--n", "10")
    check("different energies: exit 1, each setting's values named",
          code == 1 and "FAKE_KE=2.5: KE/sphere and overlap % [(2.5, 0.5)]" in out and
          "-: KE/sphere and overlap % [(1.0, 0.5)]" in out, out)

    code, out, _ = fake_run("--rounds", "1", "-", "FAKE_FAIL=1", "--", "--n", "10")
    check("a failed run: exit 1, the setting and its message named",
          code == 1 and "FAKE_FAIL=1, round 1: exit 3" in out and "failed on purpose" in out, out)

    code, out, _ = fake_run("NAME", "--", "--n", "10")
    check("a setting that is not NAME=VALUE refused", code != 0 and "expected - or NAME=VALUE" in out, out)

    with tempfile.NamedTemporaryFile("r", suffix=".jsonl", dir=work) as lines:
        code, out = run(bench_ab, marbles, "--rounds", "2", "--json", lines.name, "-", "OMP_NUM_THREADS=1",
                        "MARBLES_LANES=sse2", "--", "--backend", "cpu", "--scene", "gas", "--n", "3000",
                        "--repeats", "3")
        rows = [json.loads(line) for line in lines.read().splitlines()]
    check("the program on the CPU: one, two threads and SSE lanes give the same bits",
          code == 0 and "same bits" in out, out)
    check("--json: a line a run", len(rows) == 6 and {r["setting"] for r in rows} ==
          {"-", "OMP_NUM_THREADS=1", "MARBLES_LANES=sse2"}, str(rows)[:2000])
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
