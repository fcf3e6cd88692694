"""What caching buys: error against time of path, photonmapper (final
gathering), irrcache and radcache on the Cornell box, ajar_door and
corner_room, the bias
floor of each biased estimator, and the time path tracing needs to reach
it. A benchmark, not a timed test.

    nice -n 10 python -m radiometer.benchmarks.studies.cache_wins [--results out/cachewins_results] [--run RUN]

Runs (or, with --run, reads) the benchmark matrix benchmarks/cache_wins.toml
through the harness (`radiometer bench`: equal wall time per job, power-of-
two checkpoints, relMSE against each scene's reference at every checkpoint,
the HTML report), then:

* the floor. A biased estimator's relMSE after n samples per pixel is
  B + V / n: its squared bias B (relative, plus the reference's own noise,
  which every curve shares) and its noise V / n. The two are fitted to each
  seed's checkpoints by least squares in relative error (each checkpoint
  weighted 1 / e_k^2), B and V at least 0. The floor of an estimator is the
  mean of its seeds' B (an MSE: seeds average arithmetically). The curve has
  "stopped falling" at n* = V / B, where its noise has fallen to its bias;
  each seed records n*, the spp it reached, and the ratio of its last two
  checkpoints (1/2 for pure noise, 1 at the floor) as a check of the fit;
  from those ratios the floor is called "flat", "bending" or "falling"
  (resolved(): only a flat one is seen rather than extrapolated).
* the times. Path tracing's time to reach the floor B (and 2 B) on each
  seed's curve (analysis.metrics.time_to_error: log-log interpolation
  between checkpoints); where a curve ends above it, extrapolated from its
  last checkpoint at slope -1 (path is unbiased; marked "extrapolated").
  The biased estimator's own time to 2 B (its noise equal to its bias)
  beside it: at the error 2 B, which one is there first.

Writes benchmarks/results/cache_wins.json (studies/record.py's layout) with
the curves, fits and times, benchmarks/results/cache_wins.png (per scene the
seeds' curves, each floor as a dashed line and path's crossing of it), and
copies the report's convergence plots to benchmarks/results/cache_wins_<scene>.png
and its 3D views of irrcache's records and its bias maps to
cache_wins_<scene>_irrcache_records.png and cache_wins_<scene>_irrcache_bias.png.
"""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from radiometer.analysis.metrics import time_to_error
from radiometer.benchmarks.studies import record

MATRIX = record.REPO / "benchmarks" / "cache_wins.toml"
UNBIASED = "path"


def fit_floor(curve):
    """(B, V) with e ~ B + V / n over the checkpoints [(spp, seconds, e)],
    least squares in relative error, B, V >= 0."""
    pts = [(float(n), float(e)) for n, t, e in curve if n > 0 and e > 0]
    if len(pts) < 2:
        return None
    n = np.array([p[0] for p in pts])
    e = np.array([p[1] for p in pts])
    a = np.stack([np.ones_like(n), 1.0 / n], axis=1) / e[:, None]
    b = np.ones_like(e)
    (bb, vv), *_ = np.linalg.lstsq(a, b, rcond=None)
    if bb < 0 or vv < 0:  # one of the two terms alone: the better of the two one-parameter fits
        cands = []
        for col in (0, 1):
            x = float(np.dot(a[:, col], b) / np.dot(a[:, col], a[:, col]))
            cands.append((float(np.sum((a[:, col] * x - b) ** 2)), col, max(x, 0.0)))
        _, col, x = min(cands)
        bb, vv = (x, 0.0) if col == 0 else (0.0, x)
    return float(bb), float(vv)


def time_to(curve, target):
    """(seconds, extrapolated) at which an unbiased curve reaches `target`:
    on the curve where it gets there, else from its last checkpoint at
    slope -1 in log-log."""
    t = time_to_error(curve, target)
    if t is not None:
        return t, False
    n, t_last, e_last = curve[-1]
    return float(t_last * e_last / target), True


def resolved(seeds):
    """How well the checkpoints show the floor, from the last doubling of
    spp of every seed (e(2n) / e(n) = (1 + x / 2) / (1 + x), x = V / (n B):
    1/2 for pure noise, 1 at the floor): "flat" when every ratio is at least
    0.9 (the noise at most a quarter of the bias), "bending" when every one
    is at least 0.55, else "falling" (the noise still dominates: B is an
    extrapolation of the fit)."""
    r = [s["last_doubling_ratio"] for s in seeds]
    if any(x is None for x in r):
        return "falling"
    return "flat" if min(r) >= 0.9 else "bending" if min(r) >= 0.55 else "falling"


def summarise(recs):
    out = {}
    for scene in sorted({r["scene"] for r in recs}):
        rs = [r for r in recs if r["scene"] == scene and r["status"] == "ok" and r.get("curve")]
        paths = [r for r in rs if r["estimator"] == UNBIASED]
        floors = {}
        for est in sorted({r["estimator"] for r in rs} - {UNBIASED}):
            seeds = []
            for r in sorted((r for r in rs if r["estimator"] == est), key=lambda r: r["seed"]):
                c = r["curve"]
                f = fit_floor(c)
                if f is None:
                    continue
                bb, vv = f
                seeds.append({"seed": r["seed"], "floor": bb, "noise_v": vv,
                              "spp_noise_equals_bias": (vv / bb) if bb > 0 else None,
                              "spp_reached": int(c[-1][0]), "seconds_reached": float(c[-1][1]),
                              "final_relmse": float(c[-1][2]),
                              "last_doubling_ratio": float(c[-1][2] / c[-2][2]) if len(c) > 1 else None,
                              "checkpoints": len(c),
                              "time_to_twice_floor": time_to_error(c, 2 * bb) if bb > 0 else None})
            if not seeds:
                continue
            floor = float(np.mean([s["floor"] for s in seeds]))
            row = {"floor": floor, "seeds": seeds, "resolved": resolved(seeds)}
            own = [s["time_to_twice_floor"] for s in seeds if s["time_to_twice_floor"] is not None]
            row["time_to_twice_floor"] = float(np.median(own)) if own else None
            for key, target in (("path_time_to_floor", floor), ("path_time_to_twice_floor", 2 * floor)):
                ts = [time_to(p["curve"], target) for p in paths] if floor > 0 else []
                row[key] = float(np.median([t for t, _ in ts])) if ts else None
                row[key + "_seeds"] = [{"seed": p["seed"], "seconds": t, "extrapolated": x}
                                       for p, (t, x) in zip(paths, ts)]
            floors[est] = row
        ref_floor = [r["metrics"].get("relmse_floor") for r in rs if r["metrics"].get("relmse_floor") is not None]
        out[scene] = {"reference_relmse_floor": float(np.mean(ref_floor)) if ref_floor else None,
                      "path_final": [{"seed": p["seed"], "spp": int(p["curve"][-1][0]),
                                      "seconds": float(p["curve"][-1][1]), "relmse": float(p["curve"][-1][2])}
                                     for p in paths],
                      "biased": floors}
    return out


def plot(summary, recs, png: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(summary)
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.6 * len(scenes), 4.2), dpi=100, squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, scene in zip(axes[0], scenes):
        rs = [r for r in recs if r["scene"] == scene and r["status"] == "ok" and r.get("curve")]
        ests = [UNBIASED] + sorted({r["estimator"] for r in rs} - {UNBIASED})
        for i, est in enumerate(ests):
            c = colours[i % len(colours)]
            for j, r in enumerate(sorted((r for r in rs if r["estimator"] == est), key=lambda r: r["seed"])):
                ax.plot([p[1] for p in r["curve"]], [p[2] for p in r["curve"]], "-o", color=c, ms=2.5, lw=1.1,
                        alpha=1.0 if j == 0 else 0.55, label=est if j == 0 else None)
            f = summary[scene]["biased"].get(est)
            if f and f["floor"] > 0:
                ax.axhline(f["floor"], color=c, ls="--", lw=0.9)
                t = f["path_time_to_floor"]
                if t:
                    ext = any(s["extrapolated"] for s in f["path_time_to_floor_seeds"])
                    ax.plot([t], [f["floor"]], "D", color=c, mec="k", ms=6, mfc="none" if ext else c)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall seconds (one thread per job)")
        ax.set_ylabel("relMSE against the reference")
        ax.set_title(f"{scene}: dashed = fitted bias floor B,\n diamond = path reaches B (open: extrapolated)",
                     fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default="out/cachewins_results")
    ap.add_argument("--run", default=None, help="read this run of the store instead of running the matrix")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    root = Path(a.results)
    rid, recs = record.run_matrix(MATRIX, root, a.run, workers=a.workers)
    summary = summarise(recs)
    curves = [{"scene": r["scene"], "estimator": r["estimator"], "seed": r["seed"], "status": r["status"],
               "curve": r.get("curve"), "stats": {k: v for k, v in (r.get("stats") or {}).items()
                                                  if "overture_seconds" in k or k.endswith("_computed")}}
              for r in recs]
    for scene, s in summary.items():
        png = root / "reports" / rid / f"{scene}-convergence.png"
        if png.exists():
            shutil.copy(png, record.RESULTS / f"cache_wins_{scene}.png")
        for what in ("records", "bias"):  # the report's 3D view of irrcache's records and its bias map
            png = root / "reports" / rid / f"{scene}-irrcache-{what}.png"
            if png.exists():
                shutil.copy(png, record.RESULTS / f"cache_wins_{scene}_irrcache_{what}.png")
        print(f"{scene}: reference's own relMSE floor {s['reference_relmse_floor']}")
        for p in s["path_final"]:
            print(f"  path seed {p['seed']}: {p['relmse']:.3g} at {p['seconds']:.1f} s, {p['spp']} spp")
        for est, f in s["biased"].items():
            def secs(x):
                return "never" if x is None else f"{x:.3g} s"

            ext = " (extrapolated)" if any(q["extrapolated"] for q in f["path_time_to_floor_seeds"]) else ""
            per_seed = ", ".join("%.3g" % q["floor"] for q in f["seeds"])
            print(f"  {est:12s} floor {f['floor']:.3g} ({f['resolved']}; seeds {per_seed});"
                  f" itself at 2 B: {secs(f['time_to_twice_floor'])}; path at 2 B: "
                  f"{secs(f['path_time_to_twice_floor'])}, at B: {secs(f['path_time_to_floor'])}{ext}")
            for q in f["seeds"]:
                nstar, ratio = q["spp_noise_equals_bias"], q["last_doubling_ratio"]
                print(f"      seed {q['seed']}: noise = bias at {'-' if nstar is None else f'{nstar:.3g}'} spp, "
                      f"reached {q['spp_reached']} spp in {q['seconds_reached']:.1f} s, last doubling x"
                      f"{ratio if ratio is None else round(ratio, 3)}")
    out = record.write("cache_wins", {"matrix": str(MATRIX.relative_to(record.REPO)), "run": rid,
                                      "results": str(root)},
                       {"method": {"floor": "e = B + V / n fitted per seed (least squares in relative error, "
                                            "B, V >= 0); floor = mean over seeds of B",
                                   "path_time": "analysis.metrics.time_to_error on each path seed's curve "
                                                "(median over seeds); extrapolated at slope -1 from the last "
                                                "checkpoint where the curve ends above"},
                        "summary": summary, "curves": curves},
                       plot=lambda png: plot(summary, recs, png))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
