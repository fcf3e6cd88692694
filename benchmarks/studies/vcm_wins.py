"""Where merging wins: error against time of path, bdpt,
sppm, bpm and vcm on caustic_in_mirror, glass_sphere_caustic and the
Cornell box. A benchmark, not a timed test.

    nice -n 10 python -m radiometer.benchmarks.studies.vcm_wins [--results out/vcmwins_results] [--run RUN]

Runs (or, with --run, reads) the benchmark matrix benchmarks/vcm_wins.toml
through the harness (`radiometer bench`: equal wall time per job, power-of-
two checkpoints, relMSE against each scene's reference at every
checkpoint, the HTML report with one error-against-time plot per scene),
then copies those plots to benchmarks/results/vcm_wins_<scene>.png and the
curves with a table of the final relMSE (geometric mean over seeds) and each
estimator's relMSE at the latest time every estimator reached (log-log
interpolation) to benchmarks/results/vcm_wins.json.
"""
from __future__ import annotations

import argparse
import math
import shutil
from pathlib import Path

import numpy as np

from radiometer.benchmarks.studies import record

MATRIX = record.REPO / "benchmarks" / "vcm_wins.toml"


def _at(curve, t):
    """relMSE at time t by log-log interpolation of one checkpoint curve."""
    pts = [(c[1], c[2]) for c in curve if c[1] > 0 and c[2] > 0]
    if not pts or t < pts[0][0] or t > pts[-1][0]:
        return None
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if t0 <= t <= t1:
            if t1 == t0:
                return e1
            w = (math.log(t) - math.log(t0)) / (math.log(t1) - math.log(t0))
            return math.exp((1 - w) * math.log(e0) + w * math.log(e1))
    return pts[-1][1]


def summarise(recs):
    out = {}
    for scene in sorted({r["scene"] for r in recs}):
        rs = [r for r in recs if r["scene"] == scene and r["status"] == "ok" and r.get("curve")]
        ests = sorted({r["estimator"] for r in rs})
        # the latest time every curve reached, and the earliest the first checkpoints all passed
        t_eq = min(r["curve"][-1][1] for r in rs)
        row = {}
        for e in ests:
            cs = [r["curve"] for r in rs if r["estimator"] == e]
            final = [c[-1][2] for c in cs]
            at = [_at(c, t_eq) for c in cs]
            at = [x for x in at if x]
            row[e] = {"final_relmse_geomean": float(np.exp(np.mean(np.log(final)))),
                      "final_seconds": float(np.median([c[-1][1] for c in cs])),
                      "final_spp": int(np.median([c[-1][0] for c in cs])),
                      "relmse_at_equal_time": float(np.exp(np.mean(np.log(at)))) if at else None,
                      "seeds": len(cs)}
        out[scene] = {"equal_time_s": float(t_eq), "estimators": row}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default="out/vcmwins_results")
    ap.add_argument("--run", default=None, help="read this run of the store instead of running the matrix")
    a = ap.parse_args(argv)
    root = Path(a.results)
    rid, recs = record.run_matrix(MATRIX, root, a.run, workers=2)
    summary = summarise(recs)
    curves = [{"scene": r["scene"], "estimator": r["estimator"], "seed": r["seed"], "status": r["status"],
               "curve": r.get("curve")} for r in recs]
    for scene in summary:
        png = root / "reports" / rid / f"{scene}-convergence.png"
        if png.exists():
            shutil.copy(png, record.RESULTS / f"vcm_wins_{scene}.png")
        print(f"{scene}: relMSE at {summary[scene]['equal_time_s']:.2f} s (geometric mean over seeds) / final")
        for e, v in sorted(summary[scene]["estimators"].items(), key=lambda kv: kv[1]["relmse_at_equal_time"] or 1e9):
            eq = v["relmse_at_equal_time"]
            print(f"  {e:5s} {eq if eq is None else round(eq, 5)!s:>9}   final {v['final_relmse_geomean']:.5f} at "
                  f"{v['final_seconds']:.1f} s, {v['final_spp']} spp")
    record.write("vcm_wins", {"matrix": str(MATRIX.relative_to(record.REPO)), "run": rid},
                 {"summary": summary, "curves": curves})


if __name__ == "__main__":
    main()
