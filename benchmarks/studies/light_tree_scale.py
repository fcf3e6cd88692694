"""Performance benchmark (not a test): the light tree's (and the power
sampler's) build time, memory and depth, and the time of one selection and
one probability, from 10^2 to 10^6 emitters (scene/light_sampler.h).

    python -m radiometer.benchmarks.studies.light_tree_scale [--sizes 1e2,1e3,1e4,1e5,1e6] [--queries 100000]

Emitters (fixed seed): half of them one-sided squares on the six inner faces
of a unit box, facing in (side 0.2 / sqrt(N), as the tiles of an LED wall),
half points inside it; powers log-uniform over four decades. Queries: points
uniform in the box with uniform random normals, one selection (sample) and
one probability of the emitter selected (pmf) each, single-threaded.
Medians of `--repeats` builds. Writes a table to stdout and
benchmarks/results/light_tree_scale.json (studies/record.py). Expected:
tree build O(N log N), memory O(N), depth and per-selection time roughly
logarithmic in N; power: a binary search (logarithmic), uniform: constant.
"""
from __future__ import annotations

import argparse
import statistics

import numpy as np

from radiometer import _core
from radiometer.benchmarks.studies import record


def emitters(n, rng):
    half = n // 2
    walls = rng.random((half, 3), dtype=np.float32)
    face = rng.integers(0, 6, half)
    axis, side = face % 3, (face // 3).astype(np.float32)
    walls[np.arange(half), axis] = side
    normals = np.zeros((n, 3), np.float32)
    normals[np.arange(half), axis] = np.where(side == 0, 1.0, -1.0)  # facing into the box
    points = rng.random((n - half, 3), dtype=np.float32)
    power = (10.0 ** rng.uniform(0, 4, n)).astype(np.float32)
    return np.concatenate([walls, points]), power, normals, half


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e2,1e3,1e4,1e5,1e6")
    ap.add_argument("--queries", type=int, default=100000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(record.default_path("light_tree_scale")))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    rows = []
    print(f"{'emitters':>9} {'sampler':>8} {'build s':>9} {'MB':>8} {'B/emitter':>9} {'depth':>6} "
          f"{'sample ns':>10} {'pmf ns':>8}")
    for n in [int(float(s)) for s in args.sizes.split(",")]:
        pos, power, normals, _ = emitters(n, rng)
        for kind in ("tree", "power", "uniform"):
            runs = []
            for _ in range(args.repeats if kind == "tree" else 1):
                # tiles of half-size 0.1 / sqrt(N); a zero normal makes the rest point lights
                r = _core.light_sampler_scale(pos, power[:, None], normals, half_size=0.1 / np.sqrt(n), kind=kind,
                                              queries=args.queries, seed=1)
                runs.append(r)
            best = {k: statistics.median([r[k] for r in runs]) for k in ("build_seconds", "sample_ns", "pmf_ns")}
            row = {"emitters": n, "sampler": kind, "build_s": best["build_seconds"], "bytes": int(runs[0]["bytes"]),
                   "bytes_per_emitter": runs[0]["bytes"] / n, "nodes": int(runs[0]["nodes"]),
                   "depth": int(runs[0]["depth"]), "sample_ns": best["sample_ns"], "pmf_ns": best["pmf_ns"]}
            rows.append(row)
            print(f"{n:>9} {kind:>8} {row['build_s']:>9.4f} {row['bytes'] / 2**20:>8.2f} "
                  f"{row['bytes_per_emitter']:>9.1f} {row['depth']:>6} {row['sample_ns']:>10.1f} "
                  f"{row['pmf_ns']:>8.1f}", flush=True)
    print(f"wrote {record.write('light_tree_scale', record.params_of(args), {'rows': rows}, out=args.out)}")


if __name__ == "__main__":
    main()
