"""The broad phase on a NumPy array, against SciPy's cKDTree: the same pairs
of overlapping spheres, and the time each takes.

    PYTHONPATH=build/python python examples/python/pairs_vs_kdtree.py [--n N] [--backend cpu|cuda|auto]
"""
import argparse
import time

import numpy as np
from scipy.spatial import cKDTree

import marbles


def kdtree_pairs(xyzr):
    """Candidate pairs within the largest reach, then the exact test r_i + r_j."""
    tree = cKDTree(xyzr[:, :3])
    candidates = tree.query_pairs(2 * xyzr[:, 3].max(), output_type="ndarray")
    i, j = candidates[:, 0], candidates[:, 1]
    d = np.linalg.norm(xyzr[i, :3] - xyzr[j, :3], axis=1)
    keep = d <= xyzr[i, 3] + xyzr[j, 3]
    pairs = np.sort(candidates[keep], axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def best_of(repeats, f):
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = f()
        times.append(time.perf_counter() - t0)
    return result, sorted(times)[len(times) // 2]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200_000, help="spheres")
    parser.add_argument("--backend", default="auto")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rng = np.random.default_rng(1)
    # a gas at volume fraction 0.1 with radii from 0.5 to 1 (double, to compare exactly)
    radius = rng.uniform(0.5, 1.0, args.n)
    side = (4 / 3 * np.pi * (radius**3).sum() / 0.1) ** (1 / 3)
    xyzr = np.column_stack([rng.uniform(0, side, (args.n, 3)), radius])

    ours, t_ours = best_of(args.repeats, lambda: marbles.pairs(xyzr, backend=args.backend))
    theirs, t_theirs = best_of(args.repeats, lambda: kdtree_pairs(xyzr))
    same = np.array_equal(ours.astype(np.int64), theirs.astype(np.int64))
    print(f"{args.n} spheres, {len(ours)} overlapping pairs; the same pairs: {same}")
    print(f"{'method':<24} {'median ms':>10}")
    print(f"{'marbles.pairs':<24} {1e3 * t_ours:10.2f}")
    print(f"{'cKDTree + exact test':<24} {1e3 * t_theirs:10.2f}")
    if not same:
        raise SystemExit("the pair sets differ")


if __name__ == "__main__":
    main()
