"""Why photon mapping exists: on glass_sphere_caustic, the
wall-clock time `path`, `photonmapper` and `sppm` need to bring the caustic
region's relMSE under a target, and the ratios path / photonmapper and
path / sppm. A benchmark, not a timed test.

    python -m radiometer.benchmarks.studies.photon_caustic [--target 0.02] [--threads 0]

Region: the sphere's shadow with the caustic focus in it (card.md: pixel box
(20, 29, 58, 47) at 64 x 64). relMSE (DESIGN section 4, eps 1e-2): mean over
the region's pixels and channels of (a - r)^2 / (r^2 + eps), r Mitsuba's
reference (reference.exr, 524288 spp). Curves:
- path: checkpoints of one render at 1, 2, 4, ... spp (max_depth 12); past
  its last checkpoint the time to the target is extrapolated with relMSE ~
  1 / time (unbiased: the error is all variance), and marked so;
- photonmapper: checkpoints of one render at 1, 2, 4, ... 64 spp with
  caustic and global maps of 50000 photons (lookup_size 30) and one with
  200000 (lookup_size 60), direct_samples 1, gather_rays 8, their seconds including the photon passes; its relMSE
  includes its bias, so it levels off (measured: with the spp fixed at 4 and
  the maps grown from 12500 to 1.6e6 photons the relMSE stayed at ~0.055:
  the camera-side noise of final gathering through the sphere into the
  caustic dominates, not the maps);
- sppm: checkpoints of one render at 1, 2, 4, ... passes of 50000 photon
  paths.
The time to the target is read off each curve (log-log interpolation between
the first point under the target and the one before). Writes a table to
stdout and benchmarks/results/photon_caustic.json (the studies' layout,
studies/record.py).
"""
from __future__ import annotations

import argparse
import math

import numpy as np

import radiometer as rm
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry

SPEC = registry.get("glass_sphere_caustic")
SCENE = SPEC.xml
MAX_DEPTH = registry.max_depth(SPEC)  # 12, as the reference was made
REGION = (20, 29, 58, 47)


def rel_mse(img, ref, eps=1e-2):
    x0, y0, x1, y1 = REGION
    a = np.asarray(img, np.float64)[y0:y1, x0:x1]
    r = np.asarray(ref, np.float64)[y0:y1, x0:x1]
    return float(np.mean((a - r) ** 2 / (r * r + eps)))


def time_to(curve, target):
    """(seconds, extrapolated) at which the curve [(seconds, relMSE)] first
    reaches `target`; None when it never does and cannot be extrapolated."""
    pts = sorted(curve)
    for i, (t, e) in enumerate(pts):
        if e <= target:
            if i == 0:
                return t, False
            (t0, e0), (t1, e1) = pts[i - 1], (t, e)
            if e0 <= e1 or t0 <= 0:
                return t1, False
            s = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + s * (math.log(t1) - math.log(t0))), False
    return None, False


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target", type=float, default=0.02, help="caustic-region relMSE to reach")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--path-max-spp", type=int, default=4096)
    ap.add_argument("--out", default=str(record.default_path("photon_caustic")))
    args = ap.parse_args(argv)
    ref = rm.read_exr(SPEC.reference_exr).image
    scene = rm.load_file(SCENE, **SPEC.fixed_params)
    curves = {}

    cps = [1 << k for k in range(0, 30) if (1 << k) <= args.path_max_spp]
    r = rm.render(scene, integrator={"type": "path", "max_depth": MAX_DEPTH}, spp=args.path_max_spp, seed=1,
                  threads=args.threads, checkpoints=cps)
    curves["path"] = [(c[1], rel_mse(c[2], ref)) for c in r.checkpoints]

    # Maps of 50000 (n = 30) and 200000 photons (n = 60); the camera passes' checkpoints trace the
    # curve (their seconds include the photon passes). Final gathering through
    # the sphere into the caustic is the noisy part, so the spp matters.
    cps = [1 << k for k in range(0, 7)]
    for n_photons, n in ((50000, 30), (200000, 60)):
        r = rm.render(scene, integrator={"type": "photonmapper", "max_depth": MAX_DEPTH, "global_photons": n_photons,
                                         "caustic_photons": n_photons, "lookup_size": n, "direct_samples": 1,
                                         "gather_rays": 8}, spp=cps[-1], seed=1, threads=args.threads,
                      checkpoints=cps)
        curves[f"photonmapper N={n_photons}"] = [(c[1], rel_mse(c[2], ref)) for c in r.checkpoints]

    cps = [1 << k for k in range(0, 9)]
    r = rm.render(scene, integrator={"type": "sppm", "max_depth": MAX_DEPTH, "photon_count": 50000}, spp=cps[-1],
                  seed=1, threads=args.threads, checkpoints=cps)
    curves["sppm"] = [(c[1], rel_mse(c[2], ref)) for c in r.checkpoints]

    times = {}
    for name, curve in curves.items():
        t, _ = time_to(curve, args.target)
        extrapolated = False
        if t is None and name == "path":
            t_last, e_last = max(curve)
            t, extrapolated = t_last * e_last / args.target, True  # unbiased: relMSE ~ 1 / time
        times[name] = (t, extrapolated)
        pts = ", ".join(f"{s:.2f}s:{e:.4f}" for s, e in sorted(curve))
        print(f"{name:<26} relMSE curve (seconds:relMSE): {pts}")
    print(f"\ntime to caustic-region relMSE {args.target}:")
    for name, (t, ex) in times.items():
        print(f"  {name:<26} {'never (bias floor above the target)' if t is None else f'{t:.2f} s'}"
              f"{' (extrapolated)' if ex else ''}")
    ratios = {}
    for other in ("photonmapper", "sppm"):
        # The best of an estimator's configurations.
        ts = [v[0] for k, v in times.items() if k.split(" ")[0] == other and v[0]]
        if times["path"][0] and ts:
            ratios[f"path/{other}"] = times["path"][0] / min(ts)
            print(f"  ratio path / {other} (best configuration): {ratios[f'path/{other}']:.1f}")
    out = {"target_rel_mse": args.target, "region": REGION,
           "curves": {k: [list(p) for p in v] for k, v in curves.items()},
           "time_to_target": {k: {"seconds": v[0], "extrapolated": v[1]} for k, v in times.items()},
           "ratios": ratios}
    print(f"wrote {record.write('photon_caustic', record.params_of(args), out, out=args.out)}")


if __name__ == "__main__":
    main()
