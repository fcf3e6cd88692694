"""SPPM's consistency at the largest budget run (not a test: minutes of
CPU). On the Cornell box and glass_sphere_caustic (64 x 64,
Mitsuba's references), `seeds` independent SPPM renders of `passes` passes
of `photon_count` light paths, with checkpoints at 4, 16, 64, ...: per
checkpoint, the relative bias of the mean over seeds in every region of the
scene (tests/test_photon.py's region lists) with its standard error (seed
spread and the reference's variance), and the RMS error of single renders.

    python -m radiometer.benchmarks.studies.photon_sppm [--passes 1024] [--seeds 4] [--photon-count 20000]

Writes a table to stdout and benchmarks/results/photon_sppm.json (the studies'
layout, studies/record.py).
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import radiometer as rm
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry

sys.path.insert(0, str(record.REPO / "tests"))
from test_photon import CORNELL_REGIONS, GLASS_REGIONS  # noqa: E402

SCENES = {"cornell_box": CORNELL_REGIONS, "glass_sphere_caustic": GLASS_REGIONS}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", type=int, default=1024)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--photon-count", type=int, default=20000)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--out", default=str(record.default_path("photon_sppm")))
    args = ap.parse_args(argv)
    cps = [4 ** k for k in range(1, 10) if 4 ** k < args.passes] + [args.passes]
    rows = []
    for name in args.scenes.split(","):
        regions, spec = SCENES[name], registry.get(name)
        md = registry.max_depth(spec)
        scene = rm.load_file(spec.xml, **spec.fixed_params)
        ref = rm.read_exr(spec.reference_exr)
        R, RV = np.asarray(ref.image, np.float64), np.asarray(ref.variance, np.float64)
        runs, secs = [], []
        for s in range(args.seeds):
            t = time.perf_counter()
            r = rm.render(scene, integrator={"type": "sppm", "max_depth": md, "photon_count": args.photon_count},
                          spp=args.passes, seed=s, checkpoints=cps)
            secs.append(time.perf_counter() - t)
            runs.append([(c[0], c[1], np.asarray(c[2], np.float64)) for c in r.checkpoints])
            print(f"{name}: seed {s} done in {secs[-1]:.1f} s", flush=True)
        for i, p in enumerate(cps):
            imgs = [run[i][2] for run in runs]
            rmse = float(np.mean([np.sqrt(((im - R) ** 2).mean()) for im in imgs]) / R.mean())
            row = {"scene": name, "passes": p, "seconds": float(np.mean([run[i][1] for run in runs])),
                   "rel_rmse_single": rmse, "regions": {}}
            for rname, (x0, y0, x1, y1) in regions.items():
                got = np.array([im[y0:y1, x0:x1].mean() for im in imgs])
                want = float(R[y0:y1, x0:x1].mean())
                ref_se = float(np.sqrt(RV[y0:y1, x0:x1].mean(axis=2).sum()) / ((x1 - x0) * (y1 - y0)))
                se = float(np.hypot(got.std(ddof=1) / np.sqrt(len(got)), ref_se))
                row["regions"][rname] = {"rel_bias": float(got.mean() / want - 1), "rel_se": se / want}
            rows.append(row)
            worst = max(row["regions"].items(), key=lambda kv: abs(kv[1]["rel_bias"]))
            print(f"{name:<22} passes {p:>5} ({row['seconds']:.1f} s)  rel RMSE {rmse:.4f}  worst region "
                  f"{worst[0]}: {100 * worst[1]['rel_bias']:+.2f} % (se {100 * worst[1]['rel_se']:.2f} %)  all: "
                  + ", ".join(f"{k} {100 * v['rel_bias']:+.2f}" for k, v in row["regions"].items()), flush=True)
    print(f"wrote {record.write('photon_sppm', record.params_of(args), {'rows': rows}, out=args.out)}")


if __name__ == "__main__":
    main()
