"""The bias of vpl's clamping on the Cornell box, and what compensation
does about it (not a test; tests/test_vpl.py holds the furnace's).

    python -m radiometer.benchmarks.studies.vpl_clamping [--seeds 8] [--spp 4] [--vpl-count 64]
        [--clampings 0,0.05,0.1,0.3]

Scene: the Cornell box at its reference parameters (64 x 64, max_depth
8), against Mitsuba 3's reference.exr. For each clamping, `vpl` without
and (clamping > 0) with compensation: the image mean of `seeds`
independent renders relative to the reference's (its standard error from
the seeds' spread: the pixels of one pass share their VPLs, so a render's
own per-pixel variances do not give the mean's error), the indirect light's
mean relative to the unclamped renders' (the same seeds), relMSE against
the reference (eps 1e-2) and seconds per render.

Writes a table to stdout and benchmarks/results/vpl_clamping.json (the
studies' layout, studies/record.py). About 3 minutes on two loaded cores.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import radiometer as rm
from radiometer.analysis.metrics import relmse
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import references, registry


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--vpl-count", type=int, default=64)
    ap.add_argument("--clampings", default="0,0.05,0.1,0.3")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=str(record.default_path("vpl_clamping")))
    args = ap.parse_args(argv)

    spec = registry.get("cornell_box")
    params = dict(spec.fixed_params)
    scene = rm.load_file(spec.xml, **params)
    ref = references.reference("cornell_box", params)
    md = registry.max_depth(spec, params)
    ref_mean = float(ref.image.mean())
    rows, unclamped_indirect = [], None
    print(f"{'clamping':>8} {'compensate':>10} {'mean/ref-1':>11} {'se':>7} {'indirect/unclamped-1':>21} "
          f"{'relMSE':>9} {'s/render':>8}")
    for clamping in (float(x) for x in args.clampings.split(",")):
        for comp in ((False,) if clamping == 0 else (False, True)):
            integ = {"type": "vpl", "vpl_count": args.vpl_count, "clamping": clamping, "compensate": comp,
                     "max_depth": md}
            t0 = time.perf_counter()
            runs = [rm.render(scene, integrator=integ, spp=args.spp, seed=s, threads=args.threads)
                    for s in range(args.seeds)]
            sec = (time.perf_counter() - t0) / args.seeds
            means = np.array([r.image.mean() for r in runs]) / ref_mean - 1
            ind = np.array([r.effects["indirect"].mean() for r in runs])
            if clamping == 0:
                unclamped_indirect = ind
            ind_rel = float(ind.mean() / unclamped_indirect.mean() - 1) if unclamped_indirect is not None else None
            img = np.mean([r.image for r in runs], axis=0)
            row = {"clamping": clamping, "compensate": comp, "mean_rel_error": float(means.mean()),
                   "mean_rel_se": float(means.std(ddof=1) / np.sqrt(len(means))),
                   "indirect_rel_to_unclamped": ind_rel, "relmse_of_seed_mean": relmse(img, ref.image),
                   "seconds_per_render": sec}
            rows.append(row)
            print(f"{clamping:>8.2f} {str(comp):>10} {row['mean_rel_error'] * 100:>10.2f}% "
                  f"{row['mean_rel_se'] * 100:>6.2f}% {(ind_rel or 0) * 100:>20.2f}% "
                  f"{row['relmse_of_seed_mean']:>9.2e} {sec:>8.1f}")
    path = record.write("vpl_clamping", record.params_of(args), {"scene": "cornell_box", "rows": rows}, out=args.out)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
