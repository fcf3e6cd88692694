"""What volpath's `equiangular` option buys (renderer/estimators/volpath.cpp,
step 5): our `path` on a media scene with and without it, at equal spp,
over several seeds: relMSE against the scene's committed Mitsuba reference
(minus the floor the reference's own variance adds, as time_to_error does),
the per-sample variance (the render's per-pixel variance of the mean times
spp, averaged over pixels and channels), the image mean over the
reference's and the render's wall time.

    python -m radiometer.benchmarks.studies.equiangular [--scene fog_room]
        [--spp 64,256] [--seeds 1,2,3,4] [--out PATH]

Writes benchmarks/results/equiangular.json (studies/record.py).
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from radiometer.benchmarks.studies import record


def measure(scene_name: str, ladder, seeds):
    import radiometer as rm
    from radiometer.analysis.metrics import relmse, relmse_floor
    from radiometer.reference_scenes import registry

    spec = registry.get(scene_name)
    ref = rm.read_exr(spec.reference_exr)
    floor = relmse_floor(ref.image, ref.variance)
    scene = rm.load_file(spec.xml, **registry.scene_params(spec, {}))
    own = scene.desc.integrator
    rows = []
    for eq in (False, True):
        integ = {"type": own.type, **dict(own.params), "equiangular": eq}
        rm.render(scene, integrator=integ, spp=1, seed=99)  # first-touch costs out of the timings
        for spp in ladder:
            errs, pvar, secs, means = [], [], [], []
            for s in seeds:
                t0 = time.perf_counter()
                r = rm.render(scene, integrator=integ, spp=spp, seed=s)
                secs.append(time.perf_counter() - t0)
                errs.append(relmse(r.image, ref.image) - floor)
                pvar.append(float(np.mean(r.variance.astype(np.float64))) * spp)
                means.append(float(r.image.mean() / ref.image.mean()))
            rows.append({"equiangular": eq, "spp": spp, "relmse": errs, "relmse_mean": float(np.mean(errs)),
                         "variance_per_sample": float(np.mean(pvar)), "image_mean_over_ref": means,
                         "seconds_median": statistics.median(secs)})
            print(f"{scene_name} equiangular={str(eq).lower():5s} {spp:5d} spp: relMSE "
                  f"{np.mean(errs):.4f} ({', '.join(f'{e:.4f}' for e in errs)}), variance/sample "
                  f"{np.mean(pvar):.4g}, mean/ref {np.mean(means):.4f}, {statistics.median(secs):.2f} s", flush=True)
    return {"relmse_floor": floor, "rows": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="fog_room")
    ap.add_argument("--spp", default="64,256")
    ap.add_argument("--seeds", default="1,2,3,4")
    ap.add_argument("--out", default=str(record.default_path("equiangular")))
    args = ap.parse_args(argv)
    ladder = [int(x) for x in args.spp.split(",")]
    seeds = [int(x) for x in args.seeds.split(",")]
    res = measure(args.scene, ladder, seeds)
    path = record.write("equiangular", record.params_of(args), {args.scene: res}, out=args.out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
