"""Performance benchmark (not a test): how close our renders come to
Embree's single-ray limit, and what Embree's robust mode costs.

    python -m radiometer.benchmarks.studies.embree_limit [--spp 16] [--res 64]
        [--cases path:cornell_box,bdpt:ajar_door] [--repeats 5]

For each case (estimator on a canonical scene), on one thread:
1. one render with every ray it traces recorded (`_core.RayLog`: origin,
   direction, range and whether it is a shadow ray; the record is kept out
   of the timed renders);
2. the same render timed `repeats` times (the fastest): rays / seconds is
   our throughput;
3. the recorded rays traced again with bare `rtcIntersect1` /
   `rtcOccluded1` on the same BVH (the fastest of `repeats` passes): Embree
   alone, the limit; and through our `Scene::intersect` / `occluded` (ray
   set-up, range check, the hit record), which separates the wrapper's cost
   from the estimator's;
4. the same three with Embree's robust mode off (RTC_SCENE_FLAG_NONE), for
   its cost.

"of limit" = our render's rays per second over bare Embree's on the same
rays: the share of the render spent inside Embree. The rest is the
estimator (sampling, BSDFs, lights, film). Writes
benchmarks/results/embree_limit.json (studies/record.py layout).
"""
from __future__ import annotations

import argparse
import time

from radiometer.benchmarks.studies import record

CASES = "path:cornell_box,bdpt:ajar_door"


def measure(estimator: str, scene_name: str, res: int, spp: int, repeats: int) -> dict:
    import radiometer as rm
    from radiometer import _core
    from radiometer.reference_scenes import registry

    spec = registry.get(scene_name)
    scene = rm.load_file(spec.xml, **registry.scene_params(spec, {"res": res}))
    core = scene.core()
    row = {"estimator": estimator, "scene": scene_name, "res": res, "spp": spp}
    for robust in (True, False):
        core.set_robust(robust)
        log = _core.RayLog()
        _core.attach_ray_log(log)
        try:
            rm.render(scene, integrator=estimator, spp=spp, seed=7, threads=1)
        finally:
            _core.attach_ray_log(None)
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            r = rm.render(scene, integrator=estimator, spp=spp, seed=7, threads=1)
            best = min(best, time.perf_counter() - t0)
        bare = core.replay_rays(log, bare=True, repeats=repeats)
        ours = core.replay_rays(log, bare=False, repeats=repeats)
        key = "robust" if robust else "fast"
        row[key] = {
            "rays": len(log), "shadow_rays": log.shadow_rays, "render_s": best,
            "render_mrays_per_s": len(log) / best / 1e6,
            "bare_embree_s": bare, "bare_mrays_per_s": len(log) / bare / 1e6,
            "through_scene_s": ours, "through_scene_mrays_per_s": len(log) / ours / 1e6,
            "of_limit": bare / best, "wrapper_overhead": ours / bare - 1.0,
            "image_mean": float(r.image.mean()),
        }
    core.set_robust(True)
    row["robust_cost_bare"] = row["robust"]["bare_embree_s"] / row["fast"]["bare_embree_s"] - 1.0
    row["robust_cost_render"] = row["robust"]["render_s"] / row["fast"]["render_s"] - 1.0
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=CASES, help="estimator:scene, comma-separated")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=str(record.default_path("embree_limit")))
    a = ap.parse_args(argv)
    rows = []
    print(f"{'case':<24}{'mode':<8}{'rays':>10}{'render Mray/s':>15}{'Embree Mray/s':>15}{'of limit':>10}"
          f"{'wrapper':>9}")
    for case in a.cases.split(","):
        est, scene = case.split(":")
        row = measure(est, scene, a.res, a.spp, a.repeats)
        rows.append(row)
        for mode in ("robust", "fast"):
            m = row[mode]
            print(f"{case:<24}{mode:<8}{m['rays']:>10}{m['render_mrays_per_s']:>15.2f}{m['bare_mrays_per_s']:>15.2f}"
                  f"{m['of_limit']:>10.1%}{m['wrapper_overhead']:>9.1%}", flush=True)
        print(f"{'':<24}robust mode costs {row['robust_cost_bare']:+.1%} of Embree's time, "
              f"{row['robust_cost_render']:+.1%} of the render's")
    path = record.write("embree_limit", record.params_of(a), {"rows": rows}, out=a.out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
