"""Photon-mapping images of a build against those of an earlier build, for a
refactor of photon tracing that may change its random streams: every
canonical scene with `photonmapper` and `sppm` (stream_identity's settings),
a few seeds each, compared pixel by pixel under analysis.stats.z_test (both
renders' own variance, alpha 0.01) and by their largest relative difference.

    python -m radiometer.benchmarks.studies.photon_agreement --save DIR      # the earlier build
    python -m radiometer.benchmarks.studies.photon_agreement --against DIR   # the later one

`--save` writes DIR/<scene>__<estimator>__<seed>.npz (image, variance);
`--against` renders the same jobs again and prints, per job, whether the
bytes are identical, the largest relative pixel difference, the z-test's
mean z and its rejected fraction (pixel-channels with p < 0.01); it exits 1
if any z-test fails. With the same seed and unchanged streams the two images
are the same samples, so their differences are rounding only (the z-test
counts differences within 1e-5 relative as zero); where the streams changed
the renders are independent and the test is the ordinary two-sample one
(it then sees the camera samples' variance, not the photon map's, so it is
strict for photonmapper, whose photons are shared by all pixels).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from radiometer.benchmarks.studies.stream_identity import ESTIMATORS

PHOTON_ESTIMATORS = ("photonmapper", "sppm")
SEEDS = (1, 2, 3)


def _jobs():
    from radiometer.benchmarks import scenes as sc

    for name, spec in sorted(sc.SCENES.items()):
        for est in PHOTON_ESTIMATORS:
            for seed in SEEDS:
                yield name, spec, est, seed


def _render(spec, est, seed, spp):
    import radiometer as rm
    from radiometer.benchmarks import scenes as sc

    scene = rm.load_file(spec.xml, **sc.scene_params(spec, {}))
    res = rm.render(scene, integrator=dict(ESTIMATORS[est]), spp=spp, seed=seed, threads=2)
    return np.asarray(res.image, np.float32), np.asarray(res.variance, np.float32)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save", help="directory to write the images to")
    ap.add_argument("--against", help="directory of an earlier build's images")
    ap.add_argument("--out", help="JSON file for the comparison's figures")
    ap.add_argument("--spp", type=int, default=4)
    a = ap.parse_args(argv)
    if bool(a.save) == bool(a.against):
        ap.error("give exactly one of --save and --against")
    from radiometer.analysis.stats import z_test

    rows, failed = {}, 0
    for name, spec, est, seed in _jobs():
        key = f"{name}__{est}__{seed}"
        try:
            img, var = _render(spec, est, seed, a.spp)
        except Exception as e:  # unsupported combinations (sppm in media) are recorded as such
            if a.save:
                print(f"{key:50s} {type(e).__name__}")
            continue
        if a.save:
            Path(a.save).mkdir(parents=True, exist_ok=True)
            np.savez(Path(a.save) / f"{key}.npz", image=img, variance=var)
            print(f"{key:50s} saved, mean {img.mean():.6g}", flush=True)
            continue
        f = Path(a.against) / f"{key}.npz"
        if not f.exists():
            print(f"{key:50s} no earlier image")
            continue
        base = np.load(f)
        b_img, b_var = base["image"], base["variance"]
        same = hashlib.sha256(img.tobytes()).digest() == hashlib.sha256(b_img.tobytes()).digest()
        scale = np.maximum(np.abs(img), np.abs(b_img))
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(scale > 0, np.abs(img - b_img) / scale, 0.0)
        # Pixels without a variance estimate (sppm's single pass) count as exact.
        v_a = np.nan_to_num(var, nan=0.0)
        v_b = np.nan_to_num(b_var, nan=0.0)
        zt = z_test(img, v_a, b_img, v_b, alpha=0.01)
        frac = zt.rejected / zt.n
        failed += not zt.passed
        rows[key] = {"identical": bool(same), "max_rel_diff": float(rel.max()), "mean_z": zt.mean_z,
                     "rejected_fraction": frac, "passed": bool(zt.passed)}
        print(f"{key:50s} {'identical' if same else 'differs':9s} max rel {rel.max():.2e}  "
              f"mean z {zt.mean_z:+.2f}  rejected {frac:.4f}  {'PASS' if zt.passed else 'FAIL'}", flush=True)
    if a.against:
        n = len(rows)
        ident = sum(r["identical"] for r in rows.values())
        print(f"{n} images compared: {ident} byte-identical, {failed} z-tests failed; largest relative difference "
              f"{max((r['max_rel_diff'] for r in rows.values()), default=0):.2e}; mean z in "
              f"[{min((r['mean_z'] for r in rows.values()), default=0):+.2f}, "
              f"{max((r['mean_z'] for r in rows.values()), default=0):+.2f}]")
        if a.out:
            with open(a.out, "w") as fh:
                json.dump({"spp": a.spp, "seeds": list(SEEDS), "jobs": rows}, fh, indent=1, sort_keys=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
