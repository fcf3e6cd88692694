"""Where Metropolis wins: error against time of path, bdpt, pssmlt (over
bdpt and over path) and mmlt on ajar_door and keyhole, the two scenes in
which light reaches the camera's room only through a narrow passage. A
benchmark, not a timed test.

    nice -n 10 python -m radiometer.benchmarks.studies.mlt_wins [--results out/mltwins_results] [--run RUN]
        [--long [--long-run RUN]]

Runs (or, with --run, reads) the benchmark matrix benchmarks/mlt_wins.toml
through the harness (`radiometer bench`: equal wall time per job, power-of-
two checkpoints, relMSE against each scene's reference at every
checkpoint, the HTML report with one error-against-time plot per scene),
then copies those plots to benchmarks/results/mlt_wins_<scene>.png and
writes to benchmarks/results/mlt_wins.json the curves, a table of each
estimator's relMSE at the times TIMES (log-log interpolation of each seed's
checkpoint curve, geometric mean over seeds), the stuck-chain counts of
the Metropolis jobs (res.stats mlt_stuck_chains) and, per Metropolis
estimator and scene, the time from which its relMSE stays below bdpt's
(`overtakes_bdpt_s`: None when it never does within the budget). With
--long it also runs (or reads) benchmarks/mlt_wins_long.toml, bdpt and mmlt
on keyhole at 128 s, and keeps its summary under "long".
"""
from __future__ import annotations

import argparse
import math
import shutil
from pathlib import Path

import numpy as np

from radiometer.benchmarks.studies import record
from radiometer.benchmarks.studies.vcm_wins import _at

MATRIX = record.REPO / "benchmarks" / "mlt_wins.toml"
LONG = record.REPO / "benchmarks" / "mlt_wins_long.toml"
TIMES = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
METROPOLIS = ("pssmlt", "pssmlt_path", "mmlt")


def _label(r):
    return r["estimator"]  # the matrix's label (pssmlt_path: pssmlt over path)


def _geo(xs):
    xs = [x for x in xs if x]
    return float(np.exp(np.mean(np.log(xs)))) if xs else None


def relmse_at(curves, t):
    """Geometric mean over seeds of the relMSE at time t; None unless every
    seed's curve reaches t (a mean over some seeds only would favour the
    ones that got there)."""
    at = [_at(c, t) for c in curves]
    return None if not at or any(x is None for x in at) else _geo(at)


def overtakes(mlt, ref, n=64):
    """The earliest time on a log grid of n points over the span both
    estimators' curves (every seed) cover from which the geometric-mean
    relMSE of `mlt` stays below that of `ref`: (time, span); time None when
    it is not below at the span's end. The span runs from the latest first
    checkpoint to the earliest last one over every seed of both."""
    pts = [[p for p in c if p[1] > 0 and p[2] > 0] for c in list(mlt) + list(ref)]
    if not all(pts):
        return None, (None, None)
    lo, hi = max(p[0][1] for p in pts), min(p[-1][1] for p in pts)
    if not hi > lo > 0:
        return None, (lo, hi)
    grid = np.clip(np.exp(np.linspace(math.log(lo), math.log(hi), n)), lo, hi)  # ends exact, not rounded past
    below = [relmse_at(mlt, t) < relmse_at(ref, t) for t in grid]
    if not below[-1]:
        return None, (float(lo), float(hi))
    k = len(below) - 1
    while k > 0 and below[k - 1]:
        k -= 1
    return float(grid[k]), (float(lo), float(hi))


def summarise(recs):
    out = {}
    for scene in sorted({r["scene"] for r in recs}):
        rs = [r for r in recs if r["scene"] == scene and r["status"] == "ok" and r.get("curve")]
        labels = sorted({_label(r) for r in rs})
        curves = {e: [r["curve"] for r in rs if _label(r) == e] for e in labels}
        row = {}
        for e in labels:
            cs = curves[e]
            row[e] = {"relmse_at": {f"{t:g}": relmse_at(cs, t) for t in TIMES},
                      "final_relmse_geomean": _geo([c[-1][2] for c in cs]),
                      "final_seconds": float(np.median([c[-1][1] for c in cs])),
                      "final_spp": int(np.median([c[-1][0] for c in cs])),
                      "first_checkpoint_s": float(np.median([c[0][1] for c in cs])),
                      "seeds": len(cs)}
            st = [r.get("stats") or {} for r in rs if _label(r) == e]
            if any("mlt_chains" in s for s in st):
                row[e]["stuck_chains"] = [int(s.get("mlt_stuck_chains") or 0) for s in st]
                row[e]["chains"] = [int(s.get("mlt_chains") or 0) for s in st]
                row[e]["longest_rejection_run"] = [int(s.get("mlt_longest_rejection_run") or 0) for s in st]
                row[e]["acceptance"] = [float(s.get("mlt_acceptance") or 0) for s in st]
        over = {}
        if "bdpt" in curves:
            for e in METROPOLIS:
                if e in curves:
                    t, span = overtakes(curves[e], curves["bdpt"])
                    over[e] = {"overtakes_bdpt_s": t, "compared_over_s": span}
        out[scene] = {"estimators": row, "against_bdpt": over}
    return out


def _print(summary):
    for scene, s in summary.items():
        print(f"{scene}: relMSE (geometric mean over seeds) at " + ", ".join(f"{t:g}" for t in TIMES) +
              " s; final")
        for e, v in s["estimators"].items():
            cells = " ".join("      -  " if x is None else f"{x:9.2e}" for x in v["relmse_at"].values())
            stuck = f"  stuck {v['stuck_chains']} of {v['chains']}" if "stuck_chains" in v else ""
            print(f"  {e:12s}{cells}  {v['final_relmse_geomean']:.2e} at {v['final_seconds']:.1f} s, "
                  f"{v['final_spp']} spp{stuck}")
        for e, o in s["against_bdpt"].items():
            t, (lo, hi) = o["overtakes_bdpt_s"], o["compared_over_s"]
            when = f"from {t:.2f} s" if t else "not at the end"
            print(f"  {e} below bdpt {when} (over {lo or 0:.2f}-{hi or 0:.2f} s)")


def _curves(recs):
    return [{"scene": r["scene"], "estimator": _label(r), "seed": r["seed"], "status": r["status"],
             "curve": r.get("curve")} for r in recs]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default="out/mltwins_results")
    ap.add_argument("--run", default=None, help="read this run of the store instead of running the matrix")
    ap.add_argument("--long", action="store_true", help="also run (or read) benchmarks/mlt_wins_long.toml")
    ap.add_argument("--long-run", default=None, help="read this run of the store for --long")
    a = ap.parse_args(argv)
    root = Path(a.results)

    def run(matrix, run_id, prefix):
        """The matrix run (or read), summarised, its convergence plots copied to results/<prefix>_<scene>.png."""
        rid, recs = record.run_matrix(matrix, root, run_id, workers=2)
        summary = summarise(recs)
        for scene in summary:
            png = root / "reports" / rid / f"{scene}-convergence.png"
            if png.exists():
                shutil.copy(png, record.RESULTS / f"{prefix}_{scene}.png")
        _print(summary)
        return rid, {"summary": summary, "curves": _curves(recs)}

    rid, out = run(MATRIX, a.run, "mlt_wins")
    params = {"matrix": str(MATRIX.relative_to(record.REPO)), "run": rid}
    if a.long:
        print("--long:")
        lid, out["long"] = run(LONG, a.long_run, "mlt_wins_long")
        params.update(long_matrix=str(LONG.relative_to(record.REPO)), long_run=lid)
    record.write("mlt_wins", params, out)


if __name__ == "__main__":
    main()
