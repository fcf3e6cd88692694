"""`radiometer compare A B`: did error or time change beyond run-to-run noise?

For every configuration (scene, estimator, parameters, budget) in both runs,
two quantities are compared, each from its values over the seeds:
  * error: a metric of the total image (relMSE by default);
  * time: seconds per sample per pixel (what a budget of either kind costs).
The way asv compares timings: each side's mean of log(value) gets a 95 %
confidence interval (Student t over the seeds); a change is flagged only if
the two intervals do not overlap AND the ratio of the geometric means is
beyond `factor` (1.1 by default: a 10 % change), so noise within the
intervals and changes too small to matter are both ignored. With fewer
than 2 seeds on a side there is no interval and nothing is flagged (the
table says "n<2"). A configuration that ran in A and fails in B is a
regression too. Exit status: 1 if anything regressed, else 0.

The intervals hold the noise between seeds of one run, not the state of the
machine: a run made while the machine was busy is slower per sample, and
under a seconds budget its error is higher too (measured here: two default
runs, the second beside a test suite on the same 2 cores, flagged 13 time
and error "regressions" of 1.25-3.3x). Compare runs made on the same idle
machine, and compare error under spp budgets when only the estimator's
accuracy is in question.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from .store import Store


@dataclass
class Change:
    scene: str
    estimator: str
    budget: str
    quantity: str  # "error (relmse)", "time (s/spp)", "status"
    a: Optional[tuple]  # (geometric mean, lo, hi, n)
    b: Optional[tuple]
    ratio: Optional[float]
    verdict: str  # "regression", "improvement", "same", "n<2", "only in A", "only in B"


def log_ci(values, level: float = 0.95):
    """(geometric mean, lower, upper, n) of positive values, the interval a
    Student-t one on log(values); lower = upper = mean when n < 2."""
    from scipy import stats

    v = np.log(np.asarray([x for x in values if x is not None and x > 0], np.float64))
    n = int(v.size)
    if n == 0:
        return None
    m = float(v.mean())
    if n < 2:
        return (math.exp(m), math.exp(m), math.exp(m), n)
    h = float(stats.t.ppf(0.5 + level / 2, n - 1) * v.std(ddof=1) / math.sqrt(n))
    return (math.exp(m), math.exp(m - h), math.exp(m + h), n)


def judge(a, b, factor: float, lower_is_better: bool = True) -> tuple:
    """(ratio b/a, verdict) for two log_ci tuples."""
    if a is None or b is None:
        return None, "n<2"
    ratio = b[0] / a[0] if a[0] > 0 else math.inf
    if a[3] < 2 or b[3] < 2:
        return ratio, "n<2"
    disjoint = b[1] > a[2] or b[2] < a[1]
    if not disjoint or (1 / factor <= ratio <= factor):
        return ratio, "same"
    worse = ratio > 1 if lower_is_better else ratio < 1
    return ratio, "regression" if worse else "improvement"


def check_options(metric: str = "relmse", factor: float = 1.1):
    """Refuses a metric or factor that would turn the regression gate off
    silently: a metric no record holds (every configuration then reads
    "n<2"), or a factor below 1 or not finite (1/factor..factor is then
    empty, or everything)."""
    from radiometer.analysis.metrics import METRICS

    if metric not in METRICS:
        raise ValueError(f"--metric: unknown metric {metric!r} (known: {', '.join(METRICS)})")
    if isinstance(factor, bool) or not isinstance(factor, (int, float)) or not math.isfinite(factor) or factor < 1:
        raise ValueError(f"--factor: expected a finite number >= 1 (the smallest ratio B/A that counts as a "
                         f"change), got {factor!r}")


def open_run(arg: str, default_store: Path):
    """A run argument: a store file (its latest run), STORE:RUN, or a run id
    (or unique prefix) in the default store. Returns (label, records)."""
    p = Path(arg)
    store_path, run = None, None
    if p.is_file():
        store_path = p
    elif ":" in arg and Path(arg.rsplit(":", 1)[0]).is_file():
        store_path, run = Path(arg.rsplit(":", 1)[0]), arg.rsplit(":", 1)[1]
    else:
        store_path, run = Path(default_store), arg
        if not store_path.is_file():
            raise FileNotFoundError(f"{arg}: not a store file, and the default store {store_path} does not exist")
    with Store(store_path, readonly=True) as s:
        rid = s.resolve_run(run)
        return f"{store_path}:{rid}", s.jobs(rid)


def _groups(records):
    g = {}
    for r in records:
        g.setdefault(r["config_key"], []).append(r)
    return g


def compare_records(recs_a, recs_b, metric: str = "relmse", factor: float = 1.1) -> list:
    from radiometer.analysis.tables import budget_label

    check_options(metric, factor)
    ga, gb = _groups(recs_a), _groups(recs_b)
    out = []
    for key in sorted(set(ga) | set(gb), key=lambda k: (ga.get(k) or gb.get(k))[0]["scene"] + "/" +
                      (ga.get(k) or gb.get(k))[0]["estimator"]):
        ra, rb = ga.get(key, []), gb.get(key, [])
        first = (ra or rb)[0]
        where = (first["scene"], first["estimator"], budget_label(first["budget"]))
        if not ra or not rb:
            out.append(Change(*where, "configuration", None, None, None, "only in A" if ra else "only in B"))
            continue
        oka = [r for r in ra if r["status"] == "ok"]
        okb = [r for r in rb if r["status"] == "ok"]
        if not oka or not okb:
            if oka and not okb:
                verdict = "regression"
            elif okb and not oka:
                verdict = "improvement"
            else:
                verdict = "same"
            out.append(Change(*where, "status", (len(oka), len(ra)), (len(okb), len(rb)), None, verdict))
            continue
        if len(okb) < len(oka):
            out.append(Change(*where, "status", (len(oka), len(ra)), (len(okb), len(rb)), None, "regression"))
        ea = log_ci([r["metrics"].get(metric) for r in oka])
        eb = log_ci([r["metrics"].get(metric) for r in okb])
        ratio, verdict = judge(ea, eb, factor)
        out.append(Change(*where, f"error ({metric})", ea, eb, ratio, verdict))
        ta = log_ci([r["seconds"] / r["spp"] for r in oka if r.get("spp")])
        tb = log_ci([r["seconds"] / r["spp"] for r in okb if r.get("spp")])
        ratio, verdict = judge(ta, tb, factor)
        out.append(Change(*where, "time (s/spp)", ta, tb, ratio, verdict))
    return out


def _fmt_ci(c, quantity):
    from radiometer.analysis.tables import fmt

    if c is None:
        return "-"
    if quantity == "status":
        return f"{c[0]}/{c[1]} ok"
    if c[3] < 2:
        return f"{fmt(c[0])} (n={c[3]})"
    return f"{fmt(c[0])} [{fmt(c[1])}, {fmt(c[2])}] n={c[3]}"


def table(changes, only_changed: bool = False) -> str:
    head = ["scene", "estimator", "budget", "quantity", "A", "B", "B/A", "verdict"]
    rows = []
    for c in changes:
        if only_changed and c.verdict in ("same",):
            continue
        mark = {"regression": "REGRESSION", "improvement": "improved"}.get(c.verdict, c.verdict)
        rows.append([c.scene, c.estimator, c.budget, c.quantity, _fmt_ci(c.a, c.quantity), _fmt_ci(c.b, c.quantity),
                     "-" if c.ratio is None else f"{c.ratio:.3f}", mark])
    if not rows:
        return "no differences beyond noise"
    widths = [max(len(str(x)) for x in col) for col in zip(head, *rows)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths)), "  ".join("-" * w for w in widths)]
    lines += ["  ".join(str(x).ljust(w) for x, w in zip(r, widths)).rstrip() for r in rows]
    return "\n".join(lines)
