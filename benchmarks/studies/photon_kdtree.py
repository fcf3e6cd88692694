"""Performance benchmark (not a test): the photon map's balanced kd-tree
(renderer/photon/photon_map.h), build and query times from 1e5 to 1e7
photons.

    python -m radiometer.benchmarks.studies.photon_kdtree [--sizes 1e5,1e6,1e7] [--threads 1] [--queries 100000]

Photons: a caustic-like distribution (half of them in a small bright disc on
a plane, the rest spread over the faces of a unit box, as a Cornell box's
global map), float32, fixed seed. Queries: points drawn from the same
distribution. For each size: build time, k-nearest time per query for
k = 50 and 120 (Mitsuba's default lookupSize) within a radius of 0.05, and
range-query time (queries in the diffuse part only) at the radius that
would hold 120 photons on one face (edges, corners and the disc's
neighbourhood hold more: the mean count found is reported). Medians of `--repeats` runs. Writes a table to stdout and
benchmarks/results/photon_kdtree.json (the studies' layout, studies/record.py).
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from radiometer import _core
from radiometer.benchmarks.studies import record


def photons(n, rng):
    half = n // 2
    disc = np.zeros((half, 3), np.float32)
    r = 0.05 * np.sqrt(rng.random(half))
    a = 2 * np.pi * rng.random(half)
    disc[:, 0], disc[:, 2] = 0.3 + r * np.cos(a), 0.2 + r * np.sin(a)
    rest = rng.random((n - half, 3), dtype=np.float32)
    face = rng.integers(0, 6, n - half)
    axis, side = face % 3, (face // 3).astype(np.float32)
    rest[np.arange(n - half), axis] = side
    return np.concatenate([disc, rest])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e5,1e6,1e7")
    ap.add_argument("--threads", type=int, default=1, help="build and query threads")
    ap.add_argument("--queries", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(record.default_path("photon_kdtree")))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    rows = []
    print(f"{'photons':>10} {'build s':>9} {'knn50 us':>9} {'knn120 us':>10} {'range us':>9} {'range n':>8}")
    for n in [int(float(s)) for s in args.sizes.split(",")]:
        pts = photons(n, rng)
        q = photons(args.queries, rng)
        q_box = q[len(q) // 2:]  # range queries in the diffuse part (the disc would hold half the map)
        builds, k50, k120, rng_t = [], [], [], []
        # Radius holding ~120 photons of the box part: density (n/2)/6 per unit area.
        r_range = float(np.sqrt(120 / (np.pi * (n / 2) / 6)))
        counts = None
        for _ in range(args.repeats):
            t = time.perf_counter()
            tree = _core.PhotonMap(pts, threads=args.threads)
            builds.append(time.perf_counter() - t)
            t = time.perf_counter()
            tree.knn(q, 50, 0.05, threads=args.threads)
            k50.append((time.perf_counter() - t) / len(q))
            t = time.perf_counter()
            tree.knn(q, 120, 0.05, threads=args.threads)
            k120.append((time.perf_counter() - t) / len(q))
            t = time.perf_counter()
            counts = tree.range_count(q_box, r_range, threads=args.threads)
            rng_t.append((time.perf_counter() - t) / len(q_box))
            del tree
        row = {"photons": n, "build_s": statistics.median(builds), "knn50_us": 1e6 * statistics.median(k50),
               "knn120_us": 1e6 * statistics.median(k120), "range_us": 1e6 * statistics.median(rng_t),
               "range_radius": r_range, "range_mean_count": float(np.mean(counts)),
               "bytes_per_photon": _core.PhotonMap.bytes_per_photon}
        rows.append(row)
        print(f"{n:>10} {row['build_s']:>9.3f} {row['knn50_us']:>9.2f} {row['knn120_us']:>10.2f} "
              f"{row['range_us']:>9.2f} {row['range_mean_count']:>8.1f}", flush=True)
    print(f"wrote {record.write('photon_kdtree', record.params_of(args), {'rows': rows}, out=args.out)}")


if __name__ == "__main__":
    main()
