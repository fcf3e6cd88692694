"""The one results layout of the studies: benchmarks/results/<study>.json,
with a .png of the same name beside it where the study draws one. Each
JSON file holds

    {"study": NAME, "date": ISO 8601 UTC, "commit": "<hash>[-dirty]",
     "machine": {"host", "cpu", "cores", "system", "release", "python",
                 "radiometer", "cores_usable", "memory_gib"},
     "params": {the study's parameters, as given on its command line},
     ...what the study measured (its rows, tables, notes)}

Machine and commit are the benchmark harness's own (benchmarks/runner.py).
Result files written before this layout stay as they were.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "benchmarks" / "results"


def default_path(study: str) -> Path:
    return RESULTS / f"{study}.json"


def machine() -> dict:
    """The harness's machine record, with the cores this process may use
    and the memory."""
    from radiometer.benchmarks.runner import machine_info

    m = machine_info()
    m["cores_usable"] = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    m["memory_gib"] = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                m["memory_gib"] = round(int(line.split()[1]) / 2 ** 20, 1)
                break
    except OSError:
        pass
    return m


def params_of(args) -> dict:
    """An argparse namespace as JSON parameters (paths as strings)."""
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}


def write(study: str, params: dict, results: dict, out=None, plot=None) -> Path:
    """Writes `results` (a dict of what was measured) with the study's name,
    the date, commit, machine and `params` to `out` (default
    benchmarks/results/<study>.json); `plot(png_path)`, when given, draws
    the figure beside it. Returns the JSON's path."""
    from radiometer.benchmarks.runner import commit_id, now

    out = Path(out) if out else default_path(study)
    rec = {"study": study, "date": now(), "commit": commit_id(), "machine": machine(), "params": params}
    clash = set(rec) & set(results)
    if clash:
        raise ValueError(f"{study}: results may not use the layout's keys {sorted(clash)}")
    rec.update(results)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rec, indent=1, default=str) + "\n")
    if plot is not None:
        plot(out.with_suffix(".png"))
    return out


def run_matrix(matrix, results, run=None, workers=2):
    """A benchmark matrix's jobs for an error-against-time study: runs
    `radiometer bench matrix` into the folder `results` (a fresh process,
    `workers` jobs at a time) unless `run` names a run already in its
    store; returns (run id, job records)."""
    import subprocess
    import sys

    from radiometer.benchmarks.store import Store

    root = Path(results)
    if run is None:
        subprocess.run([sys.executable, "-m", "radiometer.cli", "bench", str(matrix), "--workers", str(workers),
                        "--results", str(root)], check=True)
    with Store(root / "bench.sqlite", readonly=True) as st:
        rid = st.resolve_run(run)
        return rid, st.jobs(rid)
