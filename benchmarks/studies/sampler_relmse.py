"""Study (not a test): relMSE of `path` at equal spp with each sampler
(radiometer.samplers) against the independent one, on the canonical Cornell
box (64 x 64, max_depth 8, its Gaussian filter) and optionally other
canonical scenes.

    python -m radiometer.benchmarks.studies.sampler_relmse [--seeds 4] [--spp 4,16,64,256]

Error: relMSE (eps 1e-2, analysis/metrics.py) against the scene's committed
Mitsuba 3 reference (reference.exr, 65536 spp for the Cornell box), minus
the floor the reference's own variance adds (relmse_floor), averaged over
`seeds` renders; time: the median render's wall-clock seconds on all cores.
The ratio column is relMSE / the independent sampler's relMSE at the same
spp; "time to error" is relMSE x seconds relative to independent's at the
same spp.

Writes benchmarks/results/sampler_relmse.json (studies/record.py layout).
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from radiometer.benchmarks.studies import record

SAMPLERS = ("independent", "stratified", "multijitter", "sobol", "zsobol")


def measure(scene_name, samplers, spp_list, seeds, threads):
    import radiometer as rm
    from radiometer.analysis.metrics import relmse, relmse_floor
    from radiometer.reference_scenes import registry

    spec = registry.get(scene_name)
    scene = rm.load_file(spec.xml, **registry.scene_params(spec, {}))
    ref = rm.read_exr(spec.reference_exr)
    floor = relmse_floor(ref.image, ref.variance)
    rows = []
    for spp in spp_list:
        base = None
        for s in samplers:
            errs, secs = [], []
            for k in range(seeds):
                t = time.perf_counter()
                r = rm.render(scene, spp=spp, seed=1000 + k, threads=threads, sampler=s)
                secs.append(time.perf_counter() - t)
                errs.append(relmse(r.image, ref.image) - floor)
            e, sec = float(np.mean(errs)), float(statistics.median(secs))
            se = float(np.std(errs, ddof=1) / np.sqrt(len(errs))) if len(errs) > 1 else float("nan")
            if s == "independent":
                base = (e, sec)
            row = {"scene": scene_name, "spp": spp, "sampler": s, "relmse": e, "relmse_se": se, "seconds": sec,
                   "msamples_per_s": scene.desc.sensor.width * scene.desc.sensor.height * spp / sec / 1e6}
            if base:
                row["relmse_vs_independent"] = e / base[0]
                row["time_to_error_vs_independent"] = e * sec / (base[0] * base[1])
            rows.append(row)
            print(f"{scene_name:<22}{spp:>6}  {s:<12}{e:>11.5f} +- {se:<9.5f}{sec:>8.2f} s"
                  f"{row['msamples_per_s']:>8.2f} Ms/s  {row.get('relmse_vs_independent', float('nan')):>6.3f}"
                  f"{row.get('time_to_error_vs_independent', float('nan')):>8.3f}", flush=True)
    return {"reference": str(spec.reference_exr.relative_to(record.REPO)), "relmse_floor": floor, "rows": rows}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="cornell_box", help="comma-separated canonical scenes with a reference")
    ap.add_argument("--spp", default="4,16,64,256")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--samplers", default=",".join(SAMPLERS))
    ap.add_argument("--out", default=str(record.default_path("sampler_relmse")))
    a = ap.parse_args(argv)
    spp = [int(x) for x in a.spp.split(",")]
    print(f"{'scene':<22}{'spp':>6}  {'sampler':<12}{'relMSE':>11}    {'se':<9}{'time':>10}{'rate':>14}"
          f"{'ratio':>8}{'t2e':>8}")
    results = {"scenes": {}}
    for name in a.scenes.split(","):
        results["scenes"][name] = measure(name, a.samplers.split(","), spp, a.seeds, a.threads)
    path = record.write("sampler_relmse", record.params_of(a), results, out=a.out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
