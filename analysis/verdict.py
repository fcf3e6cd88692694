"""What a benchmark result means for a user: the error terms of each render,
a verdict against a target relMSE, and the winning estimator per scene and
effect. The report (analysis/report.py) and the terminal table
(analysis/tables.py) both read these; the runner stores each job's terms
and verdict in its record.

Error terms of one render, in relMSE units against the scene's reference,
each estimated as its `how` says:
  * noise: mean(Var[pixel] / (ref^2 + eps)), from the render's own
    per-pixel variance of its estimate (what relMSE would be for an unbiased
    render with that variance). An estimator whose samples are heavy-tailed
    underestimates it when its few seeds miss the rare paths.
  * reference: the reference's own noise, `relmse_floor` (0 for an analytic
    reference): relMSE against a noisy reference is raised by it.
  * bias: what is left, relMSE - noise - reference, clamped at 0. It is the
    squared bias (truncation, photon radius, missing paths) plus whatever the
    noise estimate missed, so it is labelled "remainder", not bias measured
    on its own (the report's bias table measures it over seeds).
The verdict compares the render's own error, relMSE - reference, with the
target: "usable" when it is at most the target, "not usable" when above,
and "cannot tell" when the reference's own noise alone is at least the
target (the measurement cannot resolve the target then).

Winners: per scene and effect (and "total"), among the estimators of one
budget (the largest seconds budget when the run has one: equal time; else
the largest spp budget), the one with the highest efficiency
1 / (relMSE x seconds) (Veach 1997, section 2.4), a geometric mean over
seeds with its 95 % Student-t interval (benchmarks/compare.log_ci). The
ratio is the winner's efficiency over the runner-up's; "resolved" says
whether the two intervals are disjoint (the rule `radiometer compare`
flags changes with), so a ratio within the noise of the seeds reads as a
tie.
"""
from __future__ import annotations

import math

from typing import Optional

import numpy as np

TERMS = ("noise", "bias", "reference")
TERM_HOW = {
    "noise": "the render's own per-pixel variance: mean(var / (ref^2 + 0.01))",
    "bias": "remainder: relMSE - noise - reference, clamped at 0 (squared bias plus what the noise estimate misses)",
    "reference": "the reference's own noise (relMSE floor; 0 for an analytic reference)",
}
# Efficiency of a render with zero error (an exact furnace): the error is
# floored here so ratios stay finite.
ERROR_FLOOR = 1e-30
# Below this relMSE a render is exact to float32 rounding (an exact furnace
# measures about 1e-13): two such renders tie, whatever their efficiency ratio.
EXACT_RELMSE = 1e-10


def noise_relmse(variance, ref, eps: float | None = None) -> float:
    """The noise term of one render: mean(variance / (ref^2 + eps))."""
    from .metrics import RELMSE_EPS

    ref = np.asarray(ref, np.float64)
    return float(np.mean(np.asarray(variance, np.float64) / (ref * ref + (RELMSE_EPS if eps is None else eps))))


def error_terms(rec: dict) -> dict | None:
    """{term: value} of a job record (noise, bias, reference), or None when
    it has no relMSE. A record made before the noise term was stored has
    noise None, and its bias term then holds everything but the reference."""
    m = rec.get("metrics") or {}
    total = m.get("relmse")
    if total is None or rec.get("status", "ok") != "ok":
        return None
    ref = float(m.get("relmse_floor") or 0.0)
    noise = m.get("relmse_noise")
    rest = total - ref - (noise or 0.0)
    return {"noise": None if noise is None else float(noise), "bias": max(0.0, float(rest)), "reference": ref}


def verdict(rec: dict, target: float) -> dict | None:
    """The verdict of one job record against `target` (relMSE): {usable:
    True / False / None (cannot tell), own_error, dominant, terms, target}."""
    terms = error_terms(rec)
    if terms is None:
        return None
    total = float(rec["metrics"]["relmse"])
    own = max(0.0, total - terms["reference"])
    if terms["reference"] >= target:
        usable = None
    else:
        usable = own <= target
    known = {k: v for k, v in terms.items() if v is not None}
    dominant = max(known, key=lambda k: known[k]) if any(v > 0 for v in known.values()) else "none"
    return {"usable": usable, "own_error": own, "dominant": dominant, "terms": terms, "target": float(target)}


def verdict_word(usable) -> str:
    return {True: "usable", False: "not usable", None: "cannot tell"}[usable]


def config_verdict(recs: list, target: float) -> dict | None:
    """The verdict of a configuration from its seeds' records: usable when
    every seed is, not usable when any is not (and none cannot tell); the
    dominant term is the one with the largest mean over seeds."""
    vs = [verdict(r, target) for r in recs]
    vs = [v for v in vs if v is not None]
    if not vs:
        return None
    if any(v["usable"] is None for v in vs):
        usable = None
    else:
        usable = all(v["usable"] for v in vs)
    means = {}
    for k in TERMS:
        x = [v["terms"][k] for v in vs if v["terms"][k] is not None]
        if x:
            means[k] = float(np.mean(x))
    dominant = max(means, key=lambda k: means[k]) if any(x > 0 for x in means.values()) else "none"
    return {"usable": usable, "dominant": dominant, "terms": means, "target": float(target),
            "own_error": float(np.mean([v["own_error"] for v in vs])), "n": len(vs)}


def budget_label(b: dict) -> str:
    return f"{b['spp']} spp" if "spp" in b else f"{b['seconds']:g} s"


def comparison_budget(recs: list):
    """(budget dict, equal_time) the winners are judged at: the largest
    seconds budget of the records, else the largest spp budget."""
    bs = {tuple(sorted(r["budget"].items())) for r in recs}
    secs = [dict(b) for b in bs if dict(b).keys() == {"seconds"}]
    if secs:
        return max(secs, key=lambda b: b["seconds"]), True
    spps = [dict(b) for b in bs if dict(b).keys() == {"spp"}]
    return (max(spps, key=lambda b: b["spp"]), False) if spps else (None, False)


def effect_error(rec: dict, effect: str):
    """relMSE of `effect` ("total" for the whole image) in a job record."""
    if effect == "total":
        return (rec.get("metrics") or {}).get("relmse")
    return ((rec.get("effect_metrics") or {}).get(effect) or {}).get("relmse")


def winners(recs: list) -> list:
    """One dict per (scene, effect) with at least one estimator measured:
    scene, effect, budget (label), equal_time, winner, runner_up, ratio
    (winner's efficiency over the runner-up's; None without a runner-up or
    when both are exact to rounding), resolved ("yes", "no", "n<2", or
    "exact": both exact), candidates [(estimator, efficiency
    geometric mean, lo, hi, seeds, mean relMSE)], best first."""
    from radiometer.benchmarks.compare import log_ci

    out = []
    for scene in sorted({r["scene"] for r in recs}):
        srecs = [r for r in recs if r["scene"] == scene]
        b, equal_time = comparison_budget(srecs)
        if b is None:
            continue
        ok = [r for r in srecs if r["status"] == "ok" and r["budget"] == b]
        effects = ["total"] + sorted({e for r in ok for e in (r.get("effect_metrics") or {})}, key=_effect_key)
        for eff in effects:
            cands = []
            for est in sorted({r["estimator"] for r in ok}):
                errs, effs = [], []
                for r in ok:
                    if r["estimator"] != est:
                        continue
                    e = effect_error(r, eff)
                    if e is None or not r.get("seconds"):
                        continue
                    errs.append(float(e))
                    effs.append(1.0 / (max(float(e), ERROR_FLOOR) * float(r["seconds"])))
                ci = log_ci(effs)
                if ci is not None:
                    cands.append((est, ci[0], ci[1], ci[2], ci[3], float(np.mean(errs))))
            if not cands:
                continue
            cands.sort(key=lambda c: -c[1])
            w = cands[0]
            ratio, resolved, runner = None, "n<2", None
            if len(cands) > 1:
                runner = cands[1]
                ratio = w[1] / runner[1] if runner[1] > 0 else math.inf
                if w[5] < EXACT_RELMSE and runner[5] < EXACT_RELMSE:
                    ratio, resolved = None, "exact"
                elif w[4] >= 2 and runner[4] >= 2:
                    resolved = "yes" if w[2] > runner[3] else "no"
            out.append({"scene": scene, "effect": eff, "budget": budget_label(b), "equal_time": equal_time,
                        "winner": w[0], "runner_up": runner[0] if runner else None, "ratio": ratio,
                        "resolved": resolved, "candidates": cands})
    return out


def _effect_key(e):
    from .tables import EFFECT_ORDER

    return (EFFECT_ORDER.index(e) if e in EFFECT_ORDER else len(EFFECT_ORDER), e)


def effect_budget_over_seeds(layers: list, ref, eps: float | None = None) -> dict:
    """The noise and bias terms of one effect layer of a configuration, from
    its seeds (k >= 2 renders of one configuration with independent seeds,
    `layers`) against that effect's reference `ref`, in relMSE units:
    noise = mean(s^2 / (ref^2 + eps)) with s^2 the per-pixel variance across
    seeds (one render's variance), bias = mean((mean - ref)^2 - s^2 / k) /
    (ref^2 + eps)), clamped at 0 (the squared bias, less the seeds' mean's
    own variance, which would otherwise count as bias). The reference's own
    noise is not included (a per-effect reference keeps no variance)."""
    from .metrics import RELMSE_EPS
    from .stats import bias_variance

    bv = bias_variance(layers, ref)
    k = len(layers)
    d = np.asarray(ref, np.float64) ** 2 + (RELMSE_EPS if eps is None else eps)
    noise = float(np.mean(bv["variance"] / d))
    bias = float(np.mean((bv["bias"] ** 2 - bv["variance"] / k) / d))
    return {"noise": noise, "bias": max(0.0, bias), "seeds": k}


def render_error_budget(res) -> dict:
    """The error terms one render knows about itself, without a reference
    (res.error_budget): the standard error of the image mean per channel,
    sqrt(sum of the pixels' variances) / pixels (pixels are independent
    samples), of the whole image and, where the render kept per-effect
    variances, of each effect. Terms that need a reference or the matrix
    (bias, the reference's noise) are the benchmark's (error_terms)."""

    def se(var):
        v = np.asarray(var, np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(v)):  # one sample per pixel: no variance estimate
            return None
        return [float(x) for x in np.sqrt(v.sum(axis=0)) / v.shape[0]]

    effects = None
    if getattr(res, "effect_variance", None) is not None:
        effects = {e: se(v) for e, v in res.effect_variance.items() if np.any(np.asarray(res.effects[e]) != 0)}
    return {"noise": {"image_mean_se": se(res.variance), "effects_mean_se": effects},
            "rounding": rounding_term(res),
            "truncation": truncation_term(res),
            "how": {"truncation": TRUNCATION_HOW,
                    "noise": "standard error of the image mean per channel, sqrt(sum of per-pixel variances) / "
                             "pixels; per effect from the film's per-effect variances (render(effect_variance=True))",
                    "rounding": ROUNDING_HOW}}


# The film sums samples in float64 and hands the image out in float32; the
# samples themselves are float32 arithmetic. The first two are bounded here
# (Higham 2002, sec. 4.2: a recursive sum of n terms is within (n - 1) u of
# the exact sum of its terms, u = 2^-53, relative to the sum of magnitudes;
# rounding to float32 is within 2^-24 relative). The third has no useful
# a-priori bound: tests/test_effect_variance.py measures it on the closed
# furnace, whose every sample is exact in real arithmetic.
ROUNDING_HOW = ("relative bounds: float64 accumulation of spp samples per pixel, (spp - 1) 2^-53 (Higham 2002, "
                "sec. 4.2); float32 image storage 2^-24; the samples' own float32 arithmetic is measured by the "
                "test suite on the exact furnace (within one float32 ulp of 0.875 at max_depth 3), not bounded")


def rounding_term(res) -> dict:
    spp = max(int(getattr(res, "spp", 0) or 0), 1)
    return {"accumulation_rel_bound": float((spp - 1) * 2.0 ** -53), "storage_rel_bound": float(2.0 ** -24)}


TRUNCATION_HOW = ("the light max_depth cuts off, per channel, as a mean over the image, estimated in the same render: "
                  "a fraction truncation_probe of the paths that max_depth stops go on past it with Russian roulette, "
                  "weighted 1 / fraction, into a tally of their own (the image is unchanged); mean and standard error "
                  "over the render's camera samples. 0 with an unbounded max_depth; None where the estimator (or "
                  "its media loop) does not probe")


def truncation_term(res) -> Optional[dict]:
    """The truncation term of res.error_budget: the image mean's missing
    light (per channel, its standard error, and relative to the image
    mean), from the render's truncation probe; None where it has none."""
    from .. import estimators

    spec = dict(getattr(res, "integrator", None) or {})
    st = getattr(res, "stats", None) or {}
    params = estimators().get(spec.get("type"), {}).get("params", {})
    if "truncation_probe" not in params:
        return None

    def value(name):
        return spec.get(name, params[name]["default"]) if name in params else None

    if value("max_depth") == -1:
        return {"missing_mean": [0.0] * 3, "missing_se": [0.0] * 3, "relative": [0.0] * 3, "probes": 0,
                "exact": True}
    if "truncated_sum" not in st or value("truncation_probe") == 0 or getattr(st.get("features"), "has_media", False):
        return None
    img = np.asarray(res.image, np.float64)
    n = max(int(res.spp) * img.shape[0] * img.shape[1], 2)  # camera samples, each on one pixel with weight 1
    mean = np.asarray(st["truncated_sum"], np.float64) / n
    var = np.maximum(np.asarray(st["truncated_sq_sum"], np.float64) / n - mean ** 2, 0.0) / (n - 1)
    img_mean = img.reshape(-1, 3).mean(axis=0)
    rel = np.divide(mean, img_mean, out=np.zeros(3), where=img_mean > 0)
    probes = int(st.get("truncation_probes", 0))
    # No path probed (none reached max_depth, or none drawn at this budget):
    # nothing seen missing, and no standard error to say how little.
    se = [float(x) for x in np.sqrt(var)] if probes > 0 else None
    return {"missing_mean": [float(x) for x in mean], "missing_se": se, "relative": [float(x) for x in rel],
            "probes": probes, "exact": False}
