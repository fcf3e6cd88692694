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
   its cost;
5. with `--groups`: the same rays traced by bare Embree in groups, as a
   wavefront renderer would trace them (every sample's k-th closest-hit
   ray in one queue, then every sample's k-th shadow ray, k = 0, 1, ...;
   the render is recorded with one-ray camera rays so each ray knows its
   sample) and in the order traced: 4-, 8- and 16-wide packets
   (rtcIntersectN / rtcOccludedN) and the stream calls (rtcIntersect1M with
   the COHERENT or INCOHERENT flag). This is the ceiling of a wavefront
   renderer on these rays: its samples per second if Embree were its only
   cost.

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


GROUPS = [  # (label, width, wavefront, coherent); width 0 = stream call
    ("1 ray, traced order", 1, False, False),
    ("1 ray, wavefront", 1, True, False),
    ("4-wide, traced order", 4, False, False),
    ("8-wide, traced order", 8, False, False),
    ("16-wide, traced order", 16, False, False),
    ("4-wide, wavefront", 4, True, False),
    ("8-wide, wavefront", 8, True, False),
    ("16-wide, wavefront", 16, True, False),
    ("stream incoherent, wavefront", 0, True, False),
    ("stream coherent, wavefront", 0, True, True),
]


def record_rays(scene, estimator: str, spp: int, seed: int, one_ray: bool = False):
    """Every ray a one-thread render of `scene` traces (`_core.RayLog`);
    with `one_ray` the camera rays are traced one at a time, so the driver
    marks each ray's sample (the wavefront replay needs the marks)."""
    import radiometer as rm
    from radiometer import _core

    log = _core.RayLog()
    _core.set_camera_packets(not one_ray)
    _core.attach_ray_log(log)
    try:
        rm.render(scene, integrator=estimator, spp=spp, seed=seed, threads=1)
    finally:
        _core.attach_ray_log(None)
        _core.set_camera_packets(True)
    return log


def grouped(scene, core, estimator: str, spp: int, repeats: int) -> dict:
    """The render's rays through bare Embree in groups, robust mode on and off."""
    log = record_rays(scene, estimator, spp, seed=7, one_ray=True)  # one-ray camera rays: each knows its sample
    out = {"rays": len(log), "samples": log.samples}
    for robust in (True, False):
        core.set_robust(robust)
        modes, base = [], None
        for label, width, wavefront, coherent in GROUPS:
            if wavefront and log.samples == 0:
                continue  # an estimator outside the camera driver's one-ray loop marks no samples
            t = core.replay_rays_grouped(log, width=width, wavefront=wavefront, coherent=coherent, repeats=repeats)
            if base is None:
                base = t
            modes.append({
                "mode": label, "width": width, "wavefront": wavefront, "coherent": coherent,
                "seconds": t["seconds"], "mrays_per_s": len(log) / t["seconds"] / 1e6,
                "msamples_per_s": log.samples / t["seconds"] / 1e6 if log.samples else None,
                "speedup": base["seconds"] / t["seconds"],
                "closest_seconds": t["closest_seconds"], "shadow_seconds": t["shadow_seconds"],
                "closest_speedup": base["closest_seconds"] / t["closest_seconds"],
                "shadow_speedup": base["shadow_seconds"] / t["shadow_seconds"],
                "calls": t["calls"], "closest_hits": t["closest_hits"], "occluded": t["occluded"],
                # Packets compute hits in another order; the counts should agree to a few rays.
                "hits_vs_one_ray": (t["closest_hits"] + t["occluded"]) - (base["closest_hits"] + base["occluded"]),
            })
        out["robust" if robust else "fast"] = modes
    core.set_robust(True)
    return out


def ceiling_msamples_per_s(row: dict, robust: bool = True) -> float | None:
    """The most samples per second (one thread) bare Embree reaches on a
    row's recorded rays in any grouping (None without `--groups` or sample
    marks)."""
    modes = (row.get("groups") or {}).get("robust" if robust else "fast") or []
    rates = [m["msamples_per_s"] for m in modes if m.get("msamples_per_s")]
    return max(rates) if rates else None


def zero_shading_ratio(tte_scene: dict, row: dict, robust: bool = True) -> float | None:
    """time_to_error's ratio for one scene as it would be if our renderer
    cost nothing but Embree's fastest grouping of the same rays, with the
    samples it has (the best sampler's error per sample): the ratio times
    our best contender's samples per second over the ceiling on all the
    threads the study used (perfect scaling assumed, which favours us)."""
    ceiling = ceiling_msamples_per_s(row, robust)
    ours = next((c for c in tte_scene.get("contenders", [])
                 if c.get("renderer") == "radiometer" and c.get("sampler") == tte_scene.get("best_ours")), None)
    threads = max((int(t) for t in tte_scene.get("thread_scaling", {})), default=0)
    if not ceiling or ours is None or not ours.get("msamples_per_s") or not threads:
        return None
    return tte_scene["ratio"] * ours["msamples_per_s"] / (threads * ceiling)


def measure(estimator: str, scene_name: str, res: int, spp: int, repeats: int, groups: bool = False) -> dict:
    import radiometer as rm
    from radiometer.reference_scenes import registry

    spec = registry.get(scene_name)
    scene = rm.load_file(spec.xml, **registry.scene_params(spec, {"res": res}))
    core = scene.core()
    row = {"estimator": estimator, "scene": scene_name, "res": res, "spp": spp}
    for robust in (True, False):
        core.set_robust(robust)
        log = record_rays(scene, estimator, spp, seed=7)
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
    if groups:
        row["groups"] = grouped(scene, core, estimator, spp, repeats)
    row["robust_cost_bare"] = row["robust"]["bare_embree_s"] / row["fast"]["bare_embree_s"] - 1.0
    row["robust_cost_render"] = row["robust"]["render_s"] / row["fast"]["render_s"] - 1.0
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=CASES, help="estimator:scene, comma-separated")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--groups", action="store_true",
                    help="also the rays in packets and streams, queued as a wavefront renderer would")
    ap.add_argument("--out", default=str(record.default_path("embree_limit")))
    a = ap.parse_args(argv)
    rows = []
    print(f"{'case':<24}{'mode':<8}{'rays':>10}{'render Mray/s':>15}{'Embree Mray/s':>15}{'of limit':>10}"
          f"{'wrapper':>9}")
    for case in a.cases.split(","):
        est, scene = case.split(":")
        row = measure(est, scene, a.res, a.spp, a.repeats, a.groups)
        rows.append(row)
        for mode in ("robust", "fast"):
            m = row[mode]
            print(f"{case:<24}{mode:<8}{m['rays']:>10}{m['render_mrays_per_s']:>15.2f}{m['bare_mrays_per_s']:>15.2f}"
                  f"{m['of_limit']:>10.1%}{m['wrapper_overhead']:>9.1%}", flush=True)
        print(f"{'':<24}robust mode costs {row['robust_cost_bare']:+.1%} of Embree's time, "
              f"{row['robust_cost_render']:+.1%} of the render's")
        if "groups" in row:
            g = row["groups"]
            for mode in ("robust", "fast"):
                print(f"{'':<24}bare Embree on the same {g['rays']} rays ({g['samples']} samples), {mode}, one thread:")
                for m in g[mode]:
                    per_sample = f"{m['msamples_per_s']:>8.2f} Msample/s" if m["msamples_per_s"] else ""
                    print(f"{'':<26}{m['mode']:<30}{m['mrays_per_s']:>8.2f} Mray/s{per_sample}{m['speedup']:>7.2f} x"
                          f" (closest {m['closest_speedup']:.2f}, shadow {m['shadow_speedup']:.2f})"
                          f"  hits {m['hits_vs_one_ray']:+d}", flush=True)
    path = record.write("embree_limit", record.params_of(a), {"rows": rows}, out=a.out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
