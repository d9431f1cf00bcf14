"""Restitution sweep: the bouncing ball of scenes/bouncing_ball.yaml at several
coefficients of restitution e, the first rebounds' heights measured from
Python, against the law h_k = h_0 e^(2k); a plot of both.

    PYTHONPATH=build/python python examples/python/restitution_sweep.py [--out DIR] [--quick]
"""
import argparse
import pathlib

import numpy as np

import marbles

ROOT = pathlib.Path(__file__).resolve().parents[2]


def rebound_heights(e, bounces, quick):
    """Apex heights of the ball's lowest point above the floor: the drop, then each rebound."""
    sim = marbles.Simulation(ROOT / "scenes" / "bouncing_ball.yaml", backend="cpu",
                             set={"materials.rubber.restitution": e, "time.duration": 1.5 if quick else 3.0})
    radius = float(sim.radii[0])
    z = sim.positions[:, 2]   # a view: it follows the ball
    w = sim.velocities[:, 2]
    heights = [float(z[0]) - radius]
    rising = False

    def watch(s):
        nonlocal rising
        if rising and w[0] <= 0:  # the apex of a rebound
            heights.append(float(z[0]) - radius)
        rising = w[0] > 0
        return len(heights) <= bounces

    sim.run(callback=watch)
    return np.array(heights)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/examples", help="folder for restitution_sweep.png")
    parser.add_argument("--quick", action="store_true", help="two coefficients, two bounces")
    args = parser.parse_args()
    coefficients = [0.5, 0.8] if args.quick else [0.3, 0.5, 0.7, 0.8, 0.9]
    bounces = 2 if args.quick else 3
    rows = []
    print(f"{'e':>5} {'bounce':>6} {'measured':>10} {'h0 e^2k':>10} {'error %':>8}")
    for e in coefficients:
        h = rebound_heights(e, bounces, args.quick)
        for k in range(1, len(h)):
            expected = h[0] * e ** (2 * k)
            rows.append((e, k, h[k], expected))
            print(f"{e:5.2f} {k:6d} {h[k]:10.4f} {expected:10.4f} {100 * (h[k] / expected - 1):8.2f}")
    worst = max(abs(h / x - 1) for _, _, h, x in rows)
    print(f"largest error {100 * worst:.2f} % over {len(rows)} rebounds")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    for e in coefficients:
        k = np.array([r[1] for r in rows if r[0] == e])
        ax.semilogy(k, [r[2] for r in rows if r[0] == e], "o", label=f"e = {e} (marbles)")
        ax.semilogy(k, [r[3] for r in rows if r[0] == e], "k--", lw=0.8)
    ax.set_xlabel("rebound k")
    ax.set_ylabel("apex height above the floor (m)")
    ax.set_title("Rebound heights against h0 e^(2k) (dashed)")
    ax.legend(fontsize=8)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "restitution_sweep.png", dpi=120, bbox_inches="tight")
    print(f"plot: {out / 'restitution_sweep.png'}")


if __name__ == "__main__":
    main()
