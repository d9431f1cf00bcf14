"""What stepping from Python costs against the command line: the same scene
(scenes/rain.yaml, 100,000 spheres, by default) run for the same steps by
`marbles run --summary-only` (its mean_ms_per_step times the steps alone) and
by marbles.Simulation.step() one step per call, alternately, `--repeats` times
each; medians, their ratio, JSON and a table.

    PYTHONPATH=build/python python bench/python_step.py [--steps 40] [--repeats 3] [--backend cpu] [--views]

--views: the Python run holds views of the state (each step then checks them).
"""
import argparse
import json
import os
import pathlib
import statistics
import subprocess
import tempfile
import time

import marbles

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default=str(ROOT / "scenes" / "rain.yaml"))
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--backend", default="cpu")
    parser.add_argument("--views", action="store_true")
    parser.add_argument("--program", default=os.environ.get("MARBLES_PROGRAM", str(ROOT / "build" / "bin" / "marbles")))
    args = parser.parse_args()
    probe = marbles.Simulation(args.scene, backend=args.backend)
    dt = probe.dt
    spheres = len(probe)
    del probe
    overrides = [f"time.duration={args.steps * dt!r}"]
    cli, python = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            out = pathlib.Path(tmp) / f"run{r}"
            command = [args.program, "run", args.scene, "--summary-only", "--quiet", "--out", str(out),
                       "--backend", args.backend]
            for o in overrides:
                command += ["--set", o]
            subprocess.run(command, check=True, capture_output=True)
            cli.append(json.loads((out / "summary.json").read_text())["mean_ms_per_step"])

            sim = marbles.Simulation(args.scene, backend=args.backend, set=overrides)
            if args.views:
                views = (sim.positions, sim.velocities)
            t0 = time.perf_counter()
            for _ in range(args.steps):
                sim.step()
            python.append(1e3 * (time.perf_counter() - t0) / args.steps)
            del sim
    result = {"scene": args.scene, "spheres": spheres, "backend": args.backend, "steps": args.steps,
              "repeats": args.repeats, "views": args.views,
              "cli_ms_per_step": statistics.median(cli), "python_ms_per_step": statistics.median(python),
              "cli_runs": cli, "python_runs": python}
    result["python_over_cli"] = result["python_ms_per_step"] / result["cli_ms_per_step"]
    print(json.dumps(result))
    print(f"{'':<10} {'median ms/step':>15}   runs")
    print(f"{'cli':<10} {result['cli_ms_per_step']:15.3f}   " + " ".join(f"{v:.3f}" for v in cli))
    print(f"{'python':<10} {result['python_ms_per_step']:15.3f}   " + " ".join(f"{v:.3f}" for v in python))
    print(f"python / cli = {result['python_over_cli']:.4f}  (target < 1.02)")


if __name__ == "__main__":
    main()
