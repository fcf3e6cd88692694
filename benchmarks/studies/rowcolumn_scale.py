"""Matrix row-column sampling in the regime of Hasan, Pellacini and Bala
2007, in miniature (not a test): about 10^5 VPLs, a few hundred rows and
columns, against the full VPL sum.

    python -m radiometer.benchmarks.studies.rowcolumn_scale [--res 64] [--vpl-count 31250]
        [--rows 300] [--columns 100,300,900] [--threads 2]

Scene: the Cornell box (reference_scenes/cornell_box, box filter), one
pass (spp 1): vpl_count light paths leave the VPLs (about 3.2 per path
there), shared by both estimators (the same seed: the same VPLs and camera
samples, vpl_internal.h). The full sum is `vpl` (every VPL at every
pixel); `rowcolumn` renders the same pass from `rows` full rows and
`columns` clustered representatives. Reported per configuration: seconds
(wall clock, whole render), the speed-up over the full sum, the error of
the row-column image against the full sum (relMSE, eps 1e-2, and the
relative error of the image mean), and the time split (VPL tracing,
reduced matrix plus clustering, the rest: the final gather).

Writes a table to stdout and benchmarks/results/rowcolumn_scale.json (the
studies' layout, studies/record.py). About 5 minutes on two loaded cores
at the defaults (the full sum is 4 x 10^8 shadow rays).
"""
from __future__ import annotations

import argparse
import time

import radiometer as rm
from radiometer.analysis.metrics import relmse
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry


def _render(scene, integ, threads):
    t0 = time.perf_counter()
    r = rm.render(scene, integrator=integ, spp=1, seed=0, threads=threads)
    return r, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--vpl-count", type=int, default=31250, help="light paths (about 3.2 VPLs each here)")
    ap.add_argument("--rows", type=int, default=300)
    ap.add_argument("--columns", default="100,300,900")
    ap.add_argument("--clamping", type=float, default=0.1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=str(record.default_path("rowcolumn_scale")))
    args = ap.parse_args(argv)

    spec = registry.get("cornell_box")
    scene = rm.load_file(spec.xml, res=args.res, rfilter="box")
    base = {"vpl_count": args.vpl_count, "clamping": args.clamping}
    full, t_full = _render(scene, {"type": "vpl", **base}, args.threads)
    vm = full.stats["photon_maps"]["vpl"]
    n_vpl = int(vm["photons"])
    print(f"cornell_box {args.res} x {args.res}, {n_vpl} VPLs from {args.vpl_count} light paths, "
          f"full sum: {t_full:.1f} s ({full.stats['shadow_rays'] / 1e6:.0f} M shadow rays)")
    print(f"{'rows':>5} {'columns':>8} {'seconds':>8} {'speed-up':>9} {'relMSE':>10} {'mean err':>9} "
          f"{'trace s':>8} {'R+clust s':>10} {'gather s':>9}")
    rows = []
    for c in (int(x) for x in args.columns.split(",")):
        r, t = _render(scene, {"type": "rowcolumn", **base, "rows": args.rows, "columns": c}, args.threads)
        pm = r.stats["photon_maps"]["vpl"]
        row = {"rows": args.rows, "columns": c, "seconds": t, "speedup": t_full / t,
               "relmse": relmse(r.image, full.image),
               "mean_rel_error": float(r.image.mean() / full.image.mean() - 1),
               "trace_seconds": pm["trace_seconds"], "matrix_and_clustering_seconds": pm["build_seconds"],
               "gather_seconds": t - pm["trace_seconds"] - pm["build_seconds"],
               "shadow_rays": r.stats["shadow_rays"]}
        rows.append(row)
        print(f"{args.rows:>5} {c:>8} {t:>8.1f} {row['speedup']:>9.1f} {row['relmse']:>10.2e} "
              f"{row['mean_rel_error'] * 100:>8.2f}% {row['trace_seconds']:>8.1f} "
              f"{row['matrix_and_clustering_seconds']:>10.1f} {row['gather_seconds']:>9.1f}")
    full_sum = {"seconds": t_full, "shadow_rays": full.stats["shadow_rays"], "trace_seconds": vm["trace_seconds"]}
    out = {"scene": "cornell_box", "vpls": n_vpl, "full_sum": full_sum, "rowcolumn": rows}
    print(f"wrote {record.write('rowcolumn_scale', record.params_of(args), out, out=args.out)}")


if __name__ == "__main__":
    main()
