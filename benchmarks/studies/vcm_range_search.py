"""Performance benchmark (not a test): vcm's and bpm's merge queries on the
hash grid against photon_map.h's kd-tree (range_search = hash_grid or
kd_tree, renderer/estimators/vcm.cpp), per iteration.

    python -m radiometer.benchmarks.studies.vcm_range_search [--scenes cornell_box,glass_sphere_caustic]
        [--res 128] [--spp 8] [--radius 0.01,0.03] [--threads 1] [--repeats 3]

For each scene, estimator, radius and structure: the median over
--repeats of the render's seconds per iteration, of the time spent
building the structure (the render's photon-map stats), and the merge
candidates stored per iteration. Both structures find the same light
vertices (tests/test_vcm.py), so the images differ only in summation order.
Writes a table and benchmarks/results/vcm_range_search.json (studies/record.py).
"""
from __future__ import annotations

import argparse
import statistics

from radiometer.benchmarks.studies import record


def main(argv=None):
    import radiometer as rm
    from radiometer.reference_scenes import registry

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="cornell_box,glass_sphere_caustic")
    ap.add_argument("--estimators", default="vcm,bpm")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--radius", default="0.01,0.03")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(record.default_path("vcm_range_search")))
    args = ap.parse_args(argv)
    rows = []
    print(f"{'scene':22s} {'est':4s} {'radius':>6s} {'structure':10s} {'s/iter':>8s} {'build s/iter':>12s} "
          f"{'stored/iter':>11s}")
    for name in args.scenes.split(","):
        spec = registry.get(name)
        params = dict(spec.fixed_params)
        params["res"] = args.res
        scene = rm.load_file(spec.xml, **params)
        md = registry.max_depth(spec, params)
        for est in args.estimators.split(","):
            for radius in (float(r) for r in args.radius.split(",")):
                for structure in ("hash_grid", "kd_tree"):
                    integ = {"type": est, "radius": radius, "range_search": structure}
                    if md is not None:
                        integ["max_depth"] = md
                    secs, build = [], []
                    for rep in range(args.repeats):
                        r = rm.render(scene, integrator=integ, spp=args.spp, seed=rep, threads=args.threads)
                        secs.append(r.seconds / r.spp)
                        pm = r.stats["photon_maps"][est]
                        build.append(pm["build_seconds"] / r.spp)
                        stored = pm["photons"] / r.spp
                    row = {"scene": name, "estimator": est, "radius": radius, "structure": structure,
                           "seconds_per_iteration": statistics.median(secs),
                           "build_seconds_per_iteration": statistics.median(build), "stored_per_iteration": stored}
                    rows.append(row)
                    print(f"{name:22s} {est:4s} {radius:6.3f} {structure:10s} {row['seconds_per_iteration']:8.4f} "
                          f"{row['build_seconds_per_iteration']:12.5f} {stored:11.0f}", flush=True)
    print(f"wrote {record.write('vcm_range_search', record.params_of(args), {'rows': rows}, out=args.out)}")


if __name__ == "__main__":
    main()
