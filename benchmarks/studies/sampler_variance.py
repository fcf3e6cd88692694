"""Study (not a test): is a render's reported variance honest under each
sampler? Decides the default sampler (issue 13 point 1, docs/samplers.md).

    python -m radiometer.benchmarks.studies.sampler_variance
        [--scenes cornell_box,veach_mis,glass_sphere_caustic,fog_room]
        [--samplers independent,stratified,multijitter,sobol,zsobol]
        [--spp 64] [--seeds 12]

`res.variance` is the variance of each pixel's mean computed from the
spread of its samples, the formula for independent samples. Every z-test of
the suite divides by it. Here each scene is rendered by `path` `seeds` times
per sampler; per pixel-channel, the mean reported variance is divided by the
variance of the image over the seeds (ddof 1). The median of that ratio and
the ratio of the sums (pixels weighted by their variance) are written down:
1 is honest, above 1 overstates the error (a z-test then loses power), below
1 understates it (false alarms). With `seeds` = 12 the median ratio of an
honest estimate is about 1.07 (the median of 11 / chi-square with 11
degrees of freedom), not 1.

Writes benchmarks/results/sampler_variance.json (studies/record.py).
"""
from __future__ import annotations

import argparse

import numpy as np

from radiometer.benchmarks.studies import record

SCENES = "cornell_box,veach_mis,glass_sphere_caustic,fog_room"
SAMPLERS = "independent,stratified,multijitter,sobol,zsobol"


def measure(scene, sampler: str, spp: int, seeds: int) -> dict:
    import radiometer as rm

    imgs, reps = [], []
    for s in range(seeds):
        r = rm.render(scene, integrator={"type": "path"}, spp=spp, seed=100 + s, sampler=sampler)
        imgs.append(r.image.astype(np.float64))
        reps.append(r.variance.astype(np.float64))
    actual = np.var(np.array(imgs), axis=0, ddof=1)
    reported = np.mean(np.array(reps), axis=0)
    m = (reported > 0) & (actual > 0)
    return {"median_ratio": float(np.median(reported[m] / actual[m])),
            "sum_ratio": float(reported[m].sum() / actual[m].sum()),
            "relative_error_of_mean_sq": float(np.mean(actual[m] / np.maximum(np.mean(imgs, axis=0)[m], 1e-2) ** 2)),
            "pixels": int(m.sum())}


def main(argv=None):
    import radiometer as rm
    from radiometer.reference_scenes import registry

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=SCENES)
    ap.add_argument("--samplers", default=SAMPLERS)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    rows = []
    for name in a.scenes.split(","):
        scene = rm.load_file(registry.get(name).xml)
        for smp in a.samplers.split(","):
            row = {"scene": name, "sampler": smp, **measure(scene, smp, a.spp, a.seeds)}
            rows.append(row)
            print(f"{name:22s} {smp:12s} reported / actual variance: median {row['median_ratio']:6.2f}, "
                  f"sums {row['sum_ratio']:6.2f}; actual relative variance {row['relative_error_of_mean_sq']:.3g}",
                  flush=True)
    path = record.write("sampler_variance", record.params_of(a), {"rows": rows}, out=a.out)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
