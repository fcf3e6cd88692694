"""Many lights: error against time of path under the
uniform, power and tree light samplers, and of bdpt, vpl and rowcolumn
(light tree), on reference_scenes/many_lights (10 000 emitters). A
benchmark, not a timed test.

    nice -n 10 python -m radiometer.benchmarks.studies.many_lights [--results out/manylights_results] [--run RUN]

Runs (or, with --run, reads) the benchmark matrix benchmarks/many_lights.toml
through the harness (`radiometer bench`: equal wall time per job, one
thread each, power-of-two checkpoints, relMSE against the Mitsuba reference
at every checkpoint, the HTML report with its error-against-time plot),
then writes benchmarks/results/many_lights.json (the curves; per estimator
the relMSE at each of TIMES by log-log interpolation of each seed's curve,
geometric mean over seeds; the final relMSE and spp) and
benchmarks/results/many_lights.png (relMSE against seconds, log-log, every
seed's curve). relMSE as the harness computes it (analysis/metrics.py,
eps 1e-2): the reference's own noise adds its relative variance of the mean
(recorded here as `reference_relvar`) to every figure.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from radiometer.benchmarks.studies import record
from radiometer.benchmarks.studies.vcm_wins import _at

MATRIX = record.REPO / "benchmarks" / "many_lights.toml"
SCENE = "many_lights"
TIMES = (1.0, 2.0, 4.0, 8.0, 16.0)
ORDER = ("path_uniform", "path_power", "path_tree", "bdpt", "vpl", "rowcolumn")


def summarise(recs):
    rs = [r for r in recs if r["scene"] == SCENE and r["status"] == "ok" and r.get("curve")]
    out = {}
    for e in sorted({r["estimator"] for r in rs}, key=lambda e: ORDER.index(e) if e in ORDER else 99):
        cs = [r["curve"] for r in rs if r["estimator"] == e]
        at = {}
        for t in TIMES:
            v = [x for x in (_at(c, t) for c in cs) if x]
            at[f"{t:g}"] = float(np.exp(np.mean(np.log(v)))) if len(v) == len(cs) else None
        js = [r for r in rs if r["estimator"] == e]
        ratio = [np.mean(r["metrics"]["image_mean"]) / np.mean(r["metrics"]["reference_mean"]) for r in js]
        out[e] = {"relmse_at_seconds": at,
                  # the whole render at the matrix's budget (its last sample, past the last checkpoint)
                  "budget_relmse_geomean": float(np.exp(np.mean(np.log([r["metrics"]["relmse"] for r in js])))),
                  "budget_spp": int(np.median([r["spp"] for r in js])),
                  "budget_seconds": float(np.median([r["seconds"] for r in js])),
                  "image_mean_over_reference": [float(x) for x in ratio],
                  "final_relmse_geomean": float(np.exp(np.mean(np.log([c[-1][2] for c in cs])))),
                  "final_seconds": float(np.median([c[-1][1] for c in cs])),
                  "final_spp": int(np.median([c[-1][0] for c in cs])),
                  "seeds": len(cs)}
    return out


def reference_relvar():
    """The reference's mean relative variance of its mean, var / (ref^2 +
    eps), the floor its noise puts under every relMSE here."""
    import radiometer as rm
    from radiometer.analysis.metrics import relmse_floor
    from radiometer.reference_scenes import registry

    ref = rm.read_exr(registry.get(SCENE).reference_exr)
    return relmse_floor(ref.image, ref.variance)


def plot(recs, png):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
    colours = dict(zip(ORDER, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    seen = set()
    for r in sorted(recs, key=lambda r: (r["estimator"], r["seed"])):
        if r["scene"] != SCENE or r["status"] != "ok" or not r.get("curve"):
            continue
        c = np.array([(p[1], p[2]) for p in r["curve"] if p[1] > 0 and p[2] > 0])
        e = r["estimator"]
        ax.loglog(c[:, 0], c[:, 1], "-o", ms=2.5, lw=1.2, color=colours.get(e), label=None if e in seen else e)
        seen.add(e)
    ax.set_xlabel("seconds (one thread)")
    ax.set_ylabel("relMSE against the Mitsuba reference")
    ax.set_title("many_lights: 10 000 emitters, 64 x 64, max_depth 4")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default="out/manylights_results")
    ap.add_argument("--run", default=None, help="read this run of the store instead of running the matrix")
    a = ap.parse_args(argv)
    root = Path(a.results)
    rid, recs = record.run_matrix(MATRIX, root, a.run, workers=2)
    summary = summarise(recs)
    floor = reference_relvar()
    print(f"{SCENE}: relMSE (geometric mean over seeds) at " + ", ".join(f"{t:g}" for t in TIMES)
          + f" s; the reference's own relative variance {floor:.2e}")
    for e, v in summary.items():
        row = " ".join(f"{x:9.5f}" if x else "        -" for x in v["relmse_at_seconds"].values())
        ratio = " ".join(f"{x:.4f}" for x in v["image_mean_over_reference"])
        print(f"  {e:12s} {row}   at the budget {v['budget_relmse_geomean']:.5f} ({v['budget_seconds']:.1f} s, "
              f"{v['budget_spp']} spp; mean / reference {ratio})")
    curves = [{"scene": r["scene"], "estimator": r["estimator"], "seed": r["seed"], "status": r["status"],
               "integrator": r.get("integrator"), "curve": r.get("curve")} for r in recs]
    record.write("many_lights", {"matrix": str(MATRIX.relative_to(record.REPO)), "run": rid},
                 {"summary": summary, "times_s": list(TIMES), "reference_relvar": floor, "curves": curves},
                 plot=lambda png: plot(recs, png))


if __name__ == "__main__":
    main()
