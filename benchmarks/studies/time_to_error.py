"""Performance benchmark (not a test): time to a target error, ours against
Mitsuba 3, side by side in one run (issue 13 point 4).

    python -m radiometer.benchmarks.studies.time_to_error
        [--scenes cornell_box,veach_mis,glass_sphere_caustic,fog_room]
        [--spp 4,16,64,256] [--repeats 3] [--samplers independent,multijitter,sobol,zsobol]
        [--mitsuba-samplers independent,stratified,multijitter,ldsampler] [--no-scalar]
        [--ours-params '' --ours-params equiangular=true]

Each scene is rendered at its reference's resolution with a box filter on
both sides and the scene's own max_depth and integrator (`path`; `volpath`
on fog_room), by our `path` with each of our samplers and by Mitsuba 3's
llvm_ad_rgb with each of its samplers (and scalar_rgb, independent), at
every spp of the ladder, `repeats` seeds each. Error: relMSE (eps 1e-2,
analysis/metrics.py) against the scene's committed Mitsuba reference (its
box-filtered 64 x 64 one; the Cornell box's is Gaussian-filtered, so a
box-filtered Mitsuba reference is made once and cached under out/), minus
the floor the reference's own variance adds (relmse_floor). Time: wall
seconds of the render alone (the median over seeds; Mitsuba's include the
evaluation and the copy to numpy; each Mitsuba variant and sampler runs in
its own process after an untimed render that JIT-compiles its kernel).

Time to error: on each contender's own error-against-time curve (the
ladder's points, log-log, piecewise linear), the time at which it reaches
the scene's target relMSE (default: what our independent sampler reaches
at the ladder's middle spp); a target outside a curve is extrapolated along
its end segment and marked. The ratio is our best contender's time over
Mitsuba's best (the issue's goal: <= 0.5). Thread scaling: samples per
second of ours (path, independent) and of Mitsuba llvm_ad_rgb on 1 thread
and on all, at the middle spp.

Caveat recorded with the results: Mitsuba's reference of veach_mis is
itself up to 0.74 % too bright on its small far lights (its float32 cone
sampling; reference_scenes/veach_mis/card.md), which Mitsuba's own renders
share and ours do not, so that scene's relMSE floor favours Mitsuba.

Writes benchmarks/results/time_to_error.json and .png (studies/record.py).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from radiometer.benchmarks.studies import record

SCENES = "cornell_box,veach_mis,glass_sphere_caustic,fog_room"
OUT_DIR = record.REPO / "out"


def _spec(name):
    from radiometer.reference_scenes import registry

    return registry.get(name)


def reference(name: str):
    """(image, variance, path) of the box-filtered reference of `name`."""
    import radiometer as rm

    spec = _spec(name)
    xml = spec.xml.read_text()
    if '<rfilter type="box"/>' in xml:
        ref = rm.read_exr(spec.reference_exr)
        return ref.image, ref.variance, spec.reference_exr
    path = OUT_DIR / f"{name}_ref_mitsuba_box_64px_16x1024spp.exr"
    if not path.exists():
        from radiometer.reference_scenes.make_reference import make_mitsuba_reference

        OUT_DIR.mkdir(exist_ok=True)
        print(f"making {name}'s box-filtered reference (Mitsuba llvm_ad_rgb, 16 x 1024 spp) -> {path}",
              file=sys.stderr, flush=True)
        make_mitsuba_reference(spec.xml, path, runs=16, spp=1024, variant="llvm_ad_rgb", res=64, rfilter="box")
    ref = rm.read_exr(path)
    return ref.image, ref.variance, path


def _scene_params(name):
    xml = _spec(name).xml.read_text()
    return {"res": 64, **({"rfilter": "box"} if 'name="rfilter"' in xml else {})}


def parse_params(text: str) -> dict:
    """`--ours-params` text, KEY=VALUE[,KEY=VALUE...], as integrator
    parameters: true/false as booleans, numbers as numbers ('' : none)."""
    out = {}
    for item in filter(None, (t.strip() for t in text.split(","))):
        if "=" not in item:
            raise SystemExit(f"--ours-params: expected KEY=VALUE, got {item!r}")
        k, v = (x.strip() for x in item.split("=", 1))
        if v.lower() in ("true", "false"):
            out[k] = v.lower() == "true"
        else:
            try:
                out[k] = int(v)
            except ValueError:
                try:
                    out[k] = float(v)
                except ValueError:
                    out[k] = v
    return out


def variant_label(params: dict) -> str:
    """Our contenders' `variant`: "path", or "path" and its extra parameters."""
    return " ".join(["path"] + [f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in params.items()])


def curve_ours(name, sampler, ladder, repeats, ref, floor, threads=0, params=None):
    """Our `path` (the scene's own integrator and its parameters, updated
    by `params`) at each spp of the ladder."""
    import radiometer as rm
    from radiometer.analysis.metrics import relmse

    spec = _spec(name)
    scene = rm.load_file(spec.xml, **_scene_params(name))
    integ = None
    if params:
        own = scene.desc.integrator
        integ = {"type": own.type, **dict(own.params), **params}
    rm.render(scene, integrator=integ, spp=1, seed=99, threads=threads)  # first-touch costs out of the timings
    points = []
    for spp in ladder:
        secs, errs = [], []
        for k in range(repeats):
            t0 = time.perf_counter()
            r = rm.render(scene, integrator=integ, spp=spp, seed=1 + k, threads=threads, sampler=sampler)
            secs.append(time.perf_counter() - t0)
            errs.append(relmse(r.image, ref) - floor)
        points.append({"spp": spp, "seconds": statistics.median(secs), "relmse": float(np.mean(errs))})
    return points


def curve_mitsuba(name, variant, sampler, ladder, repeats, ref, floor, threads=0):
    import mitsuba as mi

    from radiometer.analysis.metrics import relmse

    mi.set_variant(variant)
    if threads:
        import drjit as dr

        dr.set_thread_count(threads)
    spec = _spec(name)
    xml = spec.xml
    if sampler != "independent":
        text = xml.read_text()
        if text.count('<sampler type="independent">') != 1:
            raise RuntimeError(f"{xml}: expected one independent sampler to replace")
        tmp = Path(tempfile.mkdtemp(prefix="t2e_sampler_"))
        (tmp / "scene.xml").write_text(text.replace('<sampler type="independent">', f'<sampler type="{sampler}">'))
        mi.Thread.thread().file_resolver().prepend(str(spec.xml.parent))
        xml = tmp / "scene.xml"
    points = []
    for spp in ladder:
        scene = mi.load_file(str(xml), spp=spp, **_scene_params(name))
        np.array(mi.render(scene, seed=0, spp=spp))  # traces and compiles the kernel for this spp
        secs, errs = [], []
        for k in range(repeats):
            t0 = time.perf_counter()
            img = np.array(mi.render(scene, seed=1 + k, spp=spp))
            secs.append(time.perf_counter() - t0)
            errs.append(relmse(img[..., :3], ref) - floor)
        points.append({"spp": spp, "seconds": statistics.median(secs), "relmse": float(np.mean(errs))})
    return points


def time_to(points, target):
    """Seconds at which a log-log piecewise-linear error curve reaches
    `target`, and whether that was extrapolated."""
    pts = sorted((p["seconds"], p["relmse"]) for p in points if p["relmse"] > 0)
    if len(pts) < 2:
        return float("nan"), True
    lt = np.log([p[0] for p in pts])
    le = np.log([p[1] for p in pts])
    lg = np.log(target)
    for i in range(len(pts) - 1):
        if (le[i] - lg) * (le[i + 1] - lg) <= 0 and le[i] != le[i + 1]:
            f = (lg - le[i]) / (le[i + 1] - le[i])
            return float(np.exp(lt[i] + f * (lt[i + 1] - lt[i]))), False
    i = 0 if lg > le[0] else len(pts) - 2  # extrapolate along the nearer end segment
    slope = (lt[i + 1] - lt[i]) / (le[i + 1] - le[i]) if le[i + 1] != le[i] else float("nan")
    return float(np.exp(lt[i] + slope * (lg - le[i]))), True


def _worker(args) -> int:
    import radiometer as rm

    ref = rm.read_exr(args.worker_ref)
    from radiometer.analysis.metrics import relmse_floor

    floor = relmse_floor(ref.image, ref.variance)
    ladder = [int(x) for x in args.spp.split(",")]
    pts = curve_mitsuba(args.worker_scene, args.worker, args.worker_sampler, ladder, args.repeats, ref.image, floor,
                        args.worker_threads)
    print(json.dumps(pts))
    return 0


def _run_worker(scene, variant, sampler, ref_path, args, threads=0):
    with tempfile.TemporaryDirectory(prefix="drjit_home_") as home:
        cmd = [sys.executable, "-m", "radiometer.benchmarks.studies.time_to_error", "--worker", variant,
               "--worker-scene", scene, "--worker-sampler", sampler, "--worker-ref", str(ref_path),
               "--worker-threads", str(threads), "--spp", args.spp, "--repeats", str(args.repeats)]
        p = subprocess.run(cmd, env=dict(os.environ, HOME=home), stdout=subprocess.PIPE, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"Mitsuba {variant}/{sampler} on {scene}: worker failed (exit {p.returncode})")
    return json.loads(p.stdout.strip().splitlines()[-1])


def _plot(results, png):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.8), squeeze=False)
    for ax, name in zip(axes[0], names):
        for c in results[name]["contenders"]:
            pts = c["points"]
            style = "-o" if c["renderer"] == "radiometer" else "--s"
            ax.loglog([p["seconds"] for p in pts], [max(p["relmse"], 1e-9) for p in pts], style, ms=3,
                      label=f"{'ours' + c['variant'][4:] if c['renderer'] == 'radiometer' else c['variant'][:4]} "
                            f"{c['sampler']}")
        ax.axhline(results[name]["target_relmse"], color="grey", lw=0.8, ls=":")
        ax.set_title(f"{name}: ratio {results[name]['ratio']:.2f}")
        ax.set_xlabel("seconds")
        ax.set_ylabel("relMSE")
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=SCENES)
    ap.add_argument("--spp", default="4,16,64,256")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--samplers", default="independent,multijitter,sobol,zsobol")
    ap.add_argument("--mitsuba-samplers", default="independent,stratified,multijitter,ldsampler")
    ap.add_argument("--no-scalar", action="store_true", help="skip Mitsuba scalar_rgb")
    ap.add_argument("--ours-params", action="append", metavar="KEY=VALUE[,...]",
                    help="extra integrator parameters for our contenders (e.g. equiangular=true); repeat the option "
                         "for several variants of ours, '' for the scene's own: each variant renders with every "
                         "sampler, the target comes from the first variant's independent sampler, and "
                         "ratio_by_variant gives each variant's best over Mitsuba's best (default: the scene's "
                         "own integrator only)")
    ap.add_argument("--out", default=str(record.default_path("time_to_error")))
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--worker-scene", help=argparse.SUPPRESS)
    ap.add_argument("--worker-sampler", help=argparse.SUPPRESS)
    ap.add_argument("--worker-ref", help=argparse.SUPPRESS)
    ap.add_argument("--worker-threads", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        return _worker(args)

    import mitsuba as mi

    import radiometer as rm
    from radiometer.analysis.metrics import relmse_floor

    ladder = [int(x) for x in args.spp.split(",")]
    mid = ladder[len(ladder) // 2]
    variants = [parse_params(t) for t in (args.ours_params or [""])]
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    results = {}
    for name in args.scenes.split(","):
        ref, var, ref_path = reference(name)
        floor = relmse_floor(ref, var)
        contenders = []
        for params in variants:
            for smp in args.samplers.split(","):
                print(f"{name}: ours, {variant_label(params)}, {smp} ...", file=sys.stderr, flush=True)
                contenders.append({"renderer": "radiometer", "variant": variant_label(params), "sampler": smp,
                                   "points": curve_ours(name, smp, ladder, args.repeats, ref, floor,
                                                        params=params)})
        runs = [("llvm_ad_rgb", s) for s in args.mitsuba_samplers.split(",")]
        runs += [] if args.no_scalar else [("scalar_rgb", "independent")]
        for v, smp in runs:
            print(f"{name}: Mitsuba {v}, {smp} ...", file=sys.stderr, flush=True)
            contenders.append({"renderer": "mitsuba", "variant": v, "sampler": smp,
                               "points": _run_worker(name, v, smp, ref_path, args)})
        base = next(c for c in contenders if c["renderer"] == "radiometer" and c["sampler"] == "independent"
                    and c["variant"] == variant_label(variants[0]))
        target = next((p["relmse"] for p in base["points"] if p["spp"] == mid), base["points"][-1]["relmse"])
        for c in contenders:
            c["time_to_target_s"], c["extrapolated"] = time_to(c["points"], target)
            p = next(p for p in c["points"] if p["spp"] == mid)
            c["msamples_per_s"] = 64 * 64 * mid / p["seconds"] / 1e6
        best_ours = min((c for c in contenders if c["renderer"] == "radiometer"), key=lambda c: c["time_to_target_s"])
        best_m = min((c for c in contenders if c["renderer"] == "mitsuba"), key=lambda c: c["time_to_target_s"])
        by_variant = {}
        if len(variants) > 1 or variants[0]:
            for params in variants:
                label = variant_label(params)
                best_v = min((c for c in contenders if c["renderer"] == "radiometer" and c["variant"] == label),
                             key=lambda c: c["time_to_target_s"])
                by_variant[label] = best_v["time_to_target_s"] / best_m["time_to_target_s"]
        scaling = {}
        for t in sorted({1, cores}):
            po = curve_ours(name, "independent", [mid], 1, ref, floor, threads=t)[0]
            pm = _run_worker(name, "llvm_ad_rgb", "independent", ref_path,
                             argparse.Namespace(spp=str(mid), repeats=1), threads=t)[0]
            scaling[t] = {"ours_msamples_per_s": 64 * 64 * mid / po["seconds"] / 1e6,
                          "mitsuba_llvm_msamples_per_s": 64 * 64 * mid / pm["seconds"] / 1e6}
        results[name] = {"reference": str(ref_path), "relmse_floor": floor, "target_relmse": target,
                         "contenders": contenders, "best_ours": best_ours["sampler"],
                         "best_mitsuba": f"{best_m['variant']} {best_m['sampler']}",
                         "ratio": best_ours["time_to_target_s"] / best_m["time_to_target_s"],
                         "thread_scaling": scaling,
                         **({"ratio_by_variant": by_variant, "best_ours_variant": best_ours["variant"]}
                            if by_variant else {})}
        print(f"\n{name}: target relMSE {target:.3e} (ours, independent, {mid} spp)")
        print(f"  {'contender':<34}{'t to target s':>14}{'Msamples/s':>12}")
        for c in contenders:
            label = f"{c['renderer']} {c['variant']} {c['sampler']}"
            mark = " (extrapolated)" if c["extrapolated"] else ""
            print(f"  {label:<34}{c['time_to_target_s']:>14.3f}{c['msamples_per_s']:>12.2f}{mark}")
        which = f"{best_ours['variant']} {best_ours['sampler']}" if by_variant else best_ours["sampler"]
        print(f"  ratio ours best ({which}) / Mitsuba best ({results[name]['best_mitsuba']}): "
              f"{results[name]['ratio']:.2f}   threads: " + ", ".join(
                  f"{t}: ours {s['ours_msamples_per_s']:.2f} / Mitsuba {s['mitsuba_llvm_msamples_per_s']:.2f} Ms/s"
                  for t, s in scaling.items()), flush=True)
        for label, ratio in by_variant.items():
            print(f"  ratio ours best ({label}) / Mitsuba best: {ratio:.2f}", flush=True)
    extra = {"versions": {"radiometer": rm.__version__, "mitsuba": mi.__version__}, "scenes": results,
             "goal": "ratio <= 0.5 on every scene"}
    path = record.write("time_to_error", record.params_of(args), extra, out=args.out,
                        plot=lambda png: _plot(results, png))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
