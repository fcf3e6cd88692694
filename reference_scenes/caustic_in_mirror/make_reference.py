"""Makes caustic_in_mirror's reference.exr: the mean of `runs` independent
renders (seeds 0 .. runs-1) of our `bdpt` on unfolded.xml, the scene with
its mirror replaced by the mirror image of the world in front of it, and
the variance of that mean from the spread across runs (s^2 / runs), as
make_reference.py does for the Mitsuba references.

    nice -n 10 python -m radiometer.reference_scenes.caustic_in_mirror.make_reference [--res 128] [--runs N] [--spp N]

Why it can be trusted (card.md): the mirror is a perfect conductor (F = 1
at every angle), every object, the light and the camera lie in front of it
and project into it, so the method of images is exact: every pixel of
scene.xml equals the same pixel of unfolded.xml in expectation (path
lengths aside: unfolded paths are shorter by their mirror bounces; at
max_depth 16 the paths cut off are measured in card.md). In the unfolded
scene the caustic is seen directly, L S S D E, which bdpt's light-tracing
strategies (t = 1) sample in proportion to its brightness; bdpt is
unbiased and tested against Mitsuba on glass_sphere_caustic, the same
objects and light.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import radiometer as rm

HERE = Path(__file__).resolve().parent
PARAMS = {"res": 64, "max_depth": 16}


def make(runs: int, spp: int, threads: int = 0, out=None, res=None):
    """Renders the reference at resolution `res` (None: 64, PARAMS; else
    one the registry's more_refs declares) into `out` (default: the
    committed file of that resolution)."""
    from radiometer.reference_scenes.registry import get

    spec = get("caustic_in_mirror")
    out = out or spec.reference_file(res)  # ValueError naming the resolutions with a reference
    params = {**PARAMS, **({"res": int(res)} if res is not None else {})}
    scene = rm.load_file(HERE / "unfolded.xml", **params)
    imgs = []
    t0 = time.time()
    for seed in range(runs):
        r = rm.render(scene, integrator={"type": "bdpt", "max_depth": params["max_depth"]}, spp=spp, seed=seed,
                      threads=threads)
        imgs.append(np.asarray(r.image, np.float64))
    a = np.stack(imgs)
    mean, var_mean = a.mean(0), a.var(0, ddof=1) / runs
    secs = time.time() - t0
    rm.write_exr(out, None, image=mean.astype(np.float32), variance=var_mean.astype(np.float32),
                 kind="ours reference: bdpt on unfolded.xml, mean over runs, variance of that mean",
                 estimator="bdpt", scene="unfolded.xml", runs=runs, spp_per_run=spp, total_spp=runs * spp,
                 params=str(params), seconds=round(secs, 1))
    return mean, var_mean, secs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, help="resolution (default 64; 128: reference_128.exr, the registry's "
                                            "more_refs budget)")
    ap.add_argument("--runs", type=int)
    ap.add_argument("--spp", type=int)
    ap.add_argument("--threads", type=int, default=0)
    a = ap.parse_args(argv)
    from radiometer.reference_scenes.registry import get

    runs, spp, _ = get("caustic_in_mirror").budget(a.res)
    a.runs, a.spp = a.runs or runs, a.spp or spp
    mean, var, secs = make(a.runs, a.spp, a.threads, res=a.res)
    print(f"res {a.res or PARAMS['res']}: {a.runs} x {a.spp} spp of bdpt on unfolded.xml in {secs:.0f} s; image mean "
          f"{mean.mean():.5g}, mean variance of the mean {var.mean():.3g}")


if __name__ == "__main__":
    main()
