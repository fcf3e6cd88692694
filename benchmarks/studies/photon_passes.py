"""Performance benchmark (not a test): passes per second of the photon
mapping estimators (issue 13, point 3: "photon mapping is not stalled by its
set-up"). For every scene of the main matrix (benchmarks/default.toml, at
its resolution) a render of `photonmapper` and of `sppm` under a time budget
(3 s by default), with the estimators' default parameters, on all threads;
each render runs in a fresh process.

    python -m radiometer.benchmarks.studies.photon_passes [--base /path/to/base/pkg] \
        [--this PKG] [--seconds 3] [--threads 0] [--scenes a,b] [--estimators photonmapper,sppm] \
        [--repeats 1] [--study NAME]

Reported per (scene, estimator): spp (for sppm the passes: one photon pass
per spp; for photonmapper the camera passes over the image after its one
set of photon maps), passes per second of wall time, the process's CPU
seconds (all threads) per pass (on a loaded machine the wall clock
measures the load more than the work), and where the time went: photon tracing and kd-tree builds of each
map (res.stats["photon_maps"]), and, where the build reports them
(res.stats "phase_seconds"), the camera and gather phases; otherwise the
rest of the wall time after tracing and building. `--base` runs the same
renders on an earlier build too (a folder holding its `radiometer` package
with its compiled `_core`, as cpu_time_vs_base takes it), alternating this
tree and the base render by render, so that load from other processes hits
both alike; the table then shows the ratio of passes per second (this /
base). Writes benchmarks/results/<study>.json (studies/record.py).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tomllib

from radiometer.benchmarks.studies import record

ESTIMATORS = ("photonmapper", "sppm")

CHILD = r"""
import sys, json, time
base = sys.argv[1]
if base != "-":
    # Run the base package: drop this environment's editable finder so the
    # import resolves to `base` first.
    sys.meta_path = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
    sys.path.insert(0, base)
import radiometer as rm
from radiometer.reference_scenes import registry as sc
spec = sc.get(sys.argv[2])
params = sc.scene_params(spec, json.loads(sys.argv[3]))
scene = rm.load_file(spec.xml, **params)
try:
    c0 = time.process_time()
    r = rm.render(scene, integrator={"type": sys.argv[4]}, seconds=float(sys.argv[5]), seed=0,
                  threads=int(sys.argv[6]))
    cpu = time.process_time() - c0
except Exception as e:  # an estimator that refuses the scene (sppm and media)
    print(json.dumps({"error": f"{type(e).__name__}: {e}"[:200]}))
    sys.exit(0)
st = r.stats
out = {"spp": r.spp, "seconds": r.seconds, "cpu_seconds": cpu,
       "photon_maps": {k: {f: v[f] for f in ("photons", "paths", "trace_seconds", "build_seconds")}
                       for k, v in st.get("photon_maps", {}).items()},
       "phase_seconds": {k[len("phase_seconds_"):]: st[k] for k in st if str(k).startswith("phase_seconds_")},
       "file": rm.__file__}
print(json.dumps(out))
"""


def matrix_scenes():
    """(scene, its XML parameters) of the main matrix, in its order."""
    from radiometer.benchmarks.matrix import resolve_path

    d = tomllib.loads(resolve_path("default").read_text(encoding="utf-8"))
    return [(name, t.get("params", {})) for name, t in d["scenes"].items()]


def _run(pkg, scene, params, estimator, seconds, threads):
    out = subprocess.run([sys.executable, "-c", CHILD, pkg, scene, json.dumps(params), estimator, str(seconds),
                          str(threads)], capture_output=True, text=True)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1][:200] if out.stderr.strip() else "failed"}
    r = json.loads(out.stdout.strip().splitlines()[-1])
    if "error" in r:
        return r
    maps = r["photon_maps"].values()
    r["trace_seconds"] = sum(m["trace_seconds"] for m in maps)
    r["build_seconds"] = sum(m["build_seconds"] for m in maps)
    r["passes_per_second"] = r["spp"] / r["seconds"] if r["seconds"] > 0 else 0.0
    # On a loaded machine the wall clock mostly measures the load; the
    # process's CPU seconds (every thread) per pass measure the work.
    r["cpu_seconds_per_pass"] = r["cpu_seconds"] / r["spp"] if r["spp"] > 0 else None
    return r


def _cell(r):
    if "error" in r:
        return f"{'refused':>8}"
    return (f"{r['spp']:5d} {r['passes_per_second']:7.2f}/s cpu/pass {r['cpu_seconds_per_pass']:6.2f} "
            f"tr {r['trace_seconds']:5.2f} bu {r['build_seconds']:5.2f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="an earlier build's package folder, measured side by side")
    ap.add_argument("--this", default="-", help="this side's package folder (default: this environment's build)")
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--threads", type=int, default=0, help="render threads (0: all)")
    ap.add_argument("--scenes", help="comma-separated subset of the matrix's scenes")
    ap.add_argument("--estimators", default=",".join(ESTIMATORS))
    ap.add_argument("--repeats", type=int, default=1, help="renders per side and cell (the median is reported)")
    ap.add_argument("--study", default="photon_passes")
    ap.add_argument("--out")
    a = ap.parse_args(argv)
    scenes = matrix_scenes()
    if a.scenes:
        want = a.scenes.split(",")
        scenes = [s for s in scenes if s[0] in want]
    sides = [("this", a.this)] + ([("base", a.base)] if a.base else [])
    rows = []
    for scene, params in scenes:
        for est in a.estimators.split(","):
            runs = {side: [] for side, _ in sides}
            for i in range(a.repeats):
                # Alternating the order of the sides (A B, B A, ...) so that neither always runs first.
                order = sides if i % 2 == 0 else sides[::-1]
                for side, pkg in order:
                    runs[side].append(_run(pkg, scene, params, est, a.seconds, a.threads))
            row = {"scene": scene, "params": params, "estimator": est}
            for side, rs in runs.items():
                ok = [r for r in rs if "error" not in r]
                if not ok:
                    row[side] = rs[0]
                    continue
                ok.sort(key=lambda r: r["passes_per_second"])
                row[side] = dict(ok[len(ok) // 2], repeats=[r["passes_per_second"] for r in ok])
            if a.base and "error" not in row["this"] and "error" not in row["base"] and row["base"]["spp"] > 0:
                row["ratio_passes_per_second"] = row["this"]["passes_per_second"] / row["base"]["passes_per_second"]
            rows.append(row)
            line = f"{scene:28s} {est:12s} this {_cell(row['this'])}"
            if a.base:
                line += f" | base {_cell(row['base'])}"
                if "ratio_passes_per_second" in row:
                    line += f" | x{row['ratio_passes_per_second']:.2f}"
            print(line, flush=True)
            # Written after every row, so that a run stopped early keeps what it measured.
            path = record.write(a.study, record.params_of(a), {"rows": rows}, out=a.out)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
