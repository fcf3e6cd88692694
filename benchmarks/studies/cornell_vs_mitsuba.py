"""Performance benchmark (not a test): the Cornell box at 256 x 256, 64 spp,
max_depth 8, our `path` against Mitsuba 3's `path` in llvm_ad_rgb and
scalar_rgb, in one process, on all cores.

    python -m radiometer.benchmarks.studies.cornell_vs_mitsuba [--repeats 3]
        [--samplers independent,sobol] [--mitsuba-samplers independent,multijitter]

`--samplers` renders ours with each of our samplers (radiometer.samplers),
`--mitsuba-samplers` Mitsuba with each of its (the scene's sampler type
replaced in a copy of the XML); time to error = relMSE x time, each row's
relative to the best Mitsuba row's.

For each renderer: scene load, the first render, then `repeats` timed
renders with fresh seeds. Each Mitsuba variant runs in its own process with
an empty drjit kernel cache (HOME pointed at a temporary folder, since drjit
caches compiled kernels in $HOME/.drjit), so the first llvm_ad_rgb render
includes tracing and the JIT compile of the render kernel, reported
separately as compile_s = first render - median render. Mitsuba's timings include the final
evaluation and the conversion to numpy (`np.array(mi.render(...))`), since
the LLVM backend only records the computation until something reads the
result. Accuracy: relMSE (eps 1e-2: mean over pixels and channels of
(a - r)^2 / (r^2 + eps)) against a long reference rendered once with Mitsuba
llvm_ad_rgb (64 runs x 64 spp = 4096 spp) and cached under out/. The
reference's own variance adds the same ~1/64 of a 64 spp render's error to
every contender's relMSE.

Writes a table to stdout and benchmarks/results/cornell_vs_mitsuba.json (the
studies' layout, studies/record.py).
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

from radiometer.benchmarks.runner import now as _now
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry

ROOT = record.REPO
SCENE = registry.get("cornell_box").xml
OUT_DIR = ROOT / "out"
RESULTS = record.default_path("cornell_vs_mitsuba")
EPS = 1e-2


def rel_mse(a, ref, eps=EPS) -> float:
    a = np.asarray(a, np.float64)
    r = np.asarray(ref, np.float64)
    return float(np.mean((a - r) ** 2 / (r * r + eps)))


def long_reference(res: int, max_depth: int, runs: int, spp: int, rfilter: str = "gaussian"):
    """Mitsuba llvm_ad_rgb reference, made once and cached under out/."""
    path = OUT_DIR / f"cornell_box_ref_mitsuba_{res}px_d{max_depth}_{rfilter}_{runs}x{spp}spp.exr"
    import radiometer as rm

    if not path.exists():
        from radiometer.reference_scenes.make_reference import make_mitsuba_reference

        OUT_DIR.mkdir(exist_ok=True)
        print(f"making the long reference ({runs} x {spp} spp, Mitsuba llvm_ad_rgb) -> {path}", file=sys.stderr)
        make_mitsuba_reference(SCENE, path, runs=runs, spp=spp, variant="llvm_ad_rgb", res=res, max_depth=max_depth,
                               rfilter=rfilter)
    ref = rm.read_exr(path)
    return ref, path


def bench_ours(res, spp, max_depth, repeats, ref, rfilter="gaussian", sampler="independent"):
    import radiometer as rm

    t0 = time.perf_counter()
    scene = rm.load_file(SCENE, res=res, spp=spp, max_depth=max_depth, rfilter=rfilter)
    load_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    scene.core()  # builds the Embree scene (cached by the Scene)
    build_s = time.perf_counter() - t0
    integ = {"type": "path", "max_depth": max_depth}
    t0 = time.perf_counter()
    r = rm.render(scene, integrator=integ, spp=spp, seed=0, sampler=sampler)
    first_s = time.perf_counter() - t0
    walls, drivers, errs = [], [], []
    threads = r.stats.get("threads")
    for i in range(repeats):
        t0 = time.perf_counter()
        r = rm.render(scene, integrator=integ, spp=spp, seed=1 + i, sampler=sampler)
        walls.append(time.perf_counter() - t0)
        drivers.append(float(r.seconds))
        errs.append(rel_mse(r.image, ref))
    return {"renderer": "radiometer path", "variant": "C++ (Embree, FIS)", "sampler": sampler, "threads": threads,
            "load_s": load_s, "scene_build_s": build_s, "first_render_s": first_s, "compile_s": None,
            "render_s": walls, "render_driver_s": drivers, "relmse": errs}


def bench_mitsuba(variant, res, spp, max_depth, repeats, ref, rfilter="gaussian", sampler="independent"):
    import mitsuba as mi

    mi.set_variant(variant)
    xml = SCENE
    if sampler != "independent":
        text = SCENE.read_text()
        if text.count('<sampler type="independent">') != 1:
            raise RuntimeError(f"{SCENE}: expected one independent sampler to replace")
        tmp = Path(tempfile.mkdtemp(prefix="cornell_sampler_"))
        xml = tmp / "scene.xml"
        xml.write_text(text.replace('<sampler type="independent">', f'<sampler type="{sampler}">'))
        mi.Thread.thread().file_resolver().prepend(str(SCENE.parent))
    t0 = time.perf_counter()
    scene = mi.load_file(str(xml), res=res, spp=spp, max_depth=max_depth, rfilter=rfilter)
    load_s = time.perf_counter() - t0
    # Warm-up: for llvm this traces and JIT-compiles the kernel; the later
    # renders reuse it from drjit's kernel cache.
    t0 = time.perf_counter()
    np.array(mi.render(scene, seed=0, spp=spp))
    first_s = time.perf_counter() - t0
    walls, errs = [], []
    for i in range(repeats):
        t0 = time.perf_counter()
        img = np.array(mi.render(scene, seed=1 + i, spp=spp))  # includes dr.eval and the copy
        walls.append(time.perf_counter() - t0)
        errs.append(rel_mse(img[..., :3], ref))
    try:
        import drjit as dr

        threads = dr.thread_count() if hasattr(dr, "thread_count") else None
    except Exception:
        threads = None
    med = statistics.median(walls)
    return {"renderer": "mitsuba path", "variant": variant, "sampler": sampler, "threads": threads, "load_s": load_s,
            "scene_build_s": None, "first_render_s": first_s,
            "compile_s": (first_s - med) if variant.startswith("llvm") else None,
            "render_s": walls, "render_driver_s": None, "relmse": errs}


def _run_worker(variant, args, ref_path, sampler="independent"):
    """Runs bench_mitsuba in a fresh interpreter whose drjit kernel cache is
    empty, and returns its result row."""
    with tempfile.TemporaryDirectory(prefix="drjit_home_") as home:
        env = dict(os.environ, HOME=home)
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", variant, "--worker-ref", str(ref_path),
               "--res", str(args.res), "--spp", str(args.spp), "--max-depth", str(args.max_depth),
               "--repeats", str(args.repeats), "--rfilter", args.rfilter, "--worker-sampler", sampler]
        p = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"Mitsuba {variant} worker failed (exit {p.returncode})")
    return json.loads(p.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m radiometer.benchmarks.studies.cornell_vs_mitsuba", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--max-depth", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3, help="timed renders per renderer (median reported)")
    ap.add_argument("--ref-runs", type=int, default=64)
    ap.add_argument("--ref-spp", type=int, default=64, help="spp per reference run")
    ap.add_argument("--no-scalar", action="store_true", help="skip Mitsuba scalar_rgb (slow)")
    ap.add_argument("--rfilter", default="gaussian", choices=["gaussian", "box", "tent"],
                    help="reconstruction filter for every renderer (box: both estimators are the same per "
                         "pixel; gaussian: Mitsuba splats, ours importance-samples the filter)")
    ap.add_argument("-o", "--out", type=Path,
                    help="results JSON (default: benchmarks/results/cornell_vs_mitsuba[_FILTER].json)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)  # internal: one Mitsuba variant, JSON row on stdout
    ap.add_argument("--worker-ref", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--worker-sampler", default="independent", help=argparse.SUPPRESS)
    ap.add_argument("--samplers", default="independent", help="our samplers, comma-separated")
    ap.add_argument("--mitsuba-samplers", default="independent",
                    help="Mitsuba's samplers for llvm_ad_rgb, comma-separated (scalar_rgb: independent)")
    args = ap.parse_args(argv)
    if args.out is None:
        args.out = (RESULTS if args.rfilter == "gaussian"
                    else RESULTS.with_name(f"cornell_vs_mitsuba_{args.rfilter}.json"))

    if args.worker:
        import radiometer as rm

        ref = rm.read_exr(args.worker_ref).image.astype(np.float64)
        row = bench_mitsuba(args.worker, args.res, args.spp, args.max_depth, args.repeats, ref, args.rfilter,
                            args.worker_sampler)
        print(json.dumps(row))
        return row

    import mitsuba as mi
    import radiometer as rm

    started = _now()
    ref, ref_path = long_reference(args.res, args.max_depth, args.ref_runs, args.ref_spp, args.rfilter)
    r = ref.image.astype(np.float64)
    rows = []
    for smp in args.samplers.split(","):
        print(f"running radiometer path, sampler {smp} ...", file=sys.stderr, flush=True)
        rows.append(bench_ours(args.res, args.spp, args.max_depth, args.repeats, r, args.rfilter, smp))
    runs = [("llvm_ad_rgb", smp) for smp in args.mitsuba_samplers.split(",")]
    runs += [] if args.no_scalar else [("scalar_rgb", "independent")]
    for v, smp in runs:
        print(f"running Mitsuba {v}, sampler {smp} (own process, empty kernel cache) ...", file=sys.stderr,
              flush=True)
        rows.append(_run_worker(v, args, ref_path, smp))
    finished = _now()

    ours_s = statistics.median(rows[0]["render_s"])
    for row in rows:
        row["render_s_median"] = statistics.median(row["render_s"])
        row["relmse_mean"] = float(np.mean(row["relmse"]))
        row["time_vs_ours"] = row["render_s_median"] / ours_s
        row["msamples_per_s"] = args.res * args.res * args.spp / row["render_s_median"] / 1e6
        # Efficiency (DESIGN section 4): 1 / (error x time).
        row["efficiency"] = 1.0 / (row["relmse_mean"] * row["render_s_median"])
    e_ours = rows[0]["efficiency"]
    best_mitsuba = min(row["relmse_mean"] * row["render_s_median"] for row in rows
                       if row["renderer"].startswith("mitsuba"))
    for row in rows:
        row["efficiency_vs_ours"] = row["efficiency"] / e_ours
        # Time to a given error, relMSE x time, against Mitsuba's best row (the goal: <= 0.5).
        row["time_to_error_vs_best_mitsuba"] = row["relmse_mean"] * row["render_s_median"] / best_mitsuba

    hdr = (f"{'renderer':<16} {'variant':<20} {'sampler':<12} {'load s':>7} {'first s':>8} {'JIT s':>6} "
           f"{'render s':>9} {'x ours':>7} {'Msamp/s':>8} {'relMSE':>9} {'eff. x ours':>11} {'t2e/best M':>10}")
    print(f"\nCornell box {args.res}x{args.res}, {args.spp} spp, max_depth {args.max_depth}, {args.rfilter} filter; "
          f"median of {args.repeats} renders; relMSE (eps {EPS:g}) against {ref_path.name}")
    print(hdr)
    print("-" * len(hdr))
    for row in rows:
        jit = f"{row['compile_s']:.2f}" if row["compile_s"] is not None else "-"
        print(f"{row['renderer']:<16} {row['variant']:<20} {row['sampler']:<12} {row['load_s']:>7.2f} "
              f"{row['first_render_s']:>8.2f} {jit:>6} {row['render_s_median']:>9.3f} {row['time_vs_ours']:>7.2f} "
              f"{row['msamples_per_s']:>8.2f} {row['relmse_mean']:>9.3e} {row['efficiency_vs_ours']:>11.2f} "
              f"{row['time_to_error_vs_best_mitsuba']:>10.2f}")

    params = {"res": args.res, "spp": args.spp, "max_depth": args.max_depth, "repeats": args.repeats,
              "rfilter": args.rfilter, "ref_runs": args.ref_runs, "ref_spp": args.ref_spp, "no_scalar": args.no_scalar,
              "samplers": args.samplers, "mitsuba_samplers": args.mitsuba_samplers}
    out = {
        "scene": str(SCENE.relative_to(ROOT)),
        "metric": f"relMSE, eps {EPS:g}: mean over pixels and channels of (a - r)^2 / (r^2 + eps)",
        "reference": {"path": str(ref_path.relative_to(ROOT)) if ref_path.is_relative_to(ROOT) else str(ref_path),
                      "made_with": "mitsuba", **{k: ref.metadata.get(k) for k in
                                                 ("variant", "runs", "spp_per_run", "total_spp", "mitsuba_version",
                                                  "date")}},
        "timing": "wall seconds (time.perf_counter); Mitsuba's include the evaluation and numpy conversion; "
                  "each Mitsuba variant ran in a fresh process with an empty drjit kernel cache, so "
                  "first_render_s of llvm_ad_rgb includes tracing and the JIT compile; compile_s = first - median",
        "versions": {"radiometer": rm.__version__, "mitsuba": mi.__version__,
                     "drjit": __import__("drjit").__version__, "numpy": np.__version__},
        "started": started,
        "finished": finished,
        "results": rows,
    }
    record.write("cornell_vs_mitsuba", params, out, out=args.out)
    print(f"\nwrote {args.out}")
    return out


if __name__ == "__main__":
    main()
