"""Image bytes of every estimator on every canonical scene, at a small
budget, as SHA-256 digests: a refactor that claims to keep the random
streams (the plumbing of the estimators) must reproduce them exactly.

    python -m radiometer.benchmarks.studies.stream_identity --out A.json
    python -m radiometer.benchmarks.studies.stream_identity --against A.json

`--against` renders again and prints, per (scene, estimator), `same` or
`DIFFERS` with the relative change of the image mean; it exits 1 if any
image of an estimator in --must-match differs.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys

import numpy as np

ESTIMATORS = {
    "path": {"type": "path"},
    "direct": {"type": "direct"},
    "ptracer": {"type": "ptracer"},
    "bdpt": {"type": "bdpt"},
    "photonmapper": {"type": "photonmapper", "global_photons": 20000, "caustic_photons": 20000,
                     "volume_photons": 20000, "direct_samples": 1, "gather_rays": 4},
    "sppm": {"type": "sppm", "photon_count": 10000},
    "whitted": {"type": "whitted"},
}
KEEP_STREAMS = ("path", "direct", "ptracer", "bdpt", "whitted")


def _render_all(spp: int, estimators=None):
    import radiometer as rm
    from radiometer.reference_scenes import registry as sc

    out = {}
    for name, spec in sorted(sc.SCENES.items()):
        params = sc.scene_params(spec, {})
        for est, integ in ESTIMATORS.items():
            if estimators and est not in estimators:
                continue
            key = f"{name}/{est}"
            try:
                scene = rm.load_file(spec.xml, **params)
                res = rm.render(scene, integrator=dict(integ), spp=spp, seed=3, threads=2)
            except Exception as e:  # unsupported combinations are recorded as such
                out[key] = {"error": type(e).__name__}
                continue
            img = np.ascontiguousarray(res.image)
            out[key] = {"sha256": hashlib.sha256(img.tobytes()).hexdigest(), "mean": float(img.mean())}
            print(f"{key:45s} {out[key]['sha256'][:12]} {out[key]['mean']:.6g}", flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out")
    ap.add_argument("--against")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--must-match", default=",".join(KEEP_STREAMS))
    ap.add_argument("--estimators", help="comma-separated subset of " + ",".join(ESTIMATORS) + " (default: all)")
    a = ap.parse_args(argv)
    chosen = a.estimators.split(",") if a.estimators else None
    unknown = sorted(set(chosen or ()) - set(ESTIMATORS))
    if unknown:
        ap.error(f"unknown estimator(s) {', '.join(unknown)} (known: {', '.join(ESTIMATORS)})")
    res = _render_all(a.spp, chosen)
    if a.out:
        with open(a.out, "w") as f:
            json.dump(res, f, indent=1, sort_keys=True)
    if a.against:
        with open(a.against) as f:
            base = json.load(f)
        must = set(a.must_match.split(","))
        bad = 0
        keys = set(base) | set(res)
        if chosen:
            keys = {k for k in keys if k.split("/")[1] in chosen}
        for key in sorted(keys):
            b, r = base.get(key, {}), res.get(key, {})
            if b.get("sha256") == r.get("sha256") and b.get("error") == r.get("error"):
                state = "same"
            else:
                state = "DIFFERS"
                if key.split("/")[1] in must:
                    bad += 1
            rel = ""
            if "mean" in b and "mean" in r and b["mean"]:
                rel = f"{r['mean'] / b['mean'] - 1:+.2e}"
            print(f"{key:45s} {state:8s} {rel}")
        print(f"{bad} images that must keep their bytes differ")
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
