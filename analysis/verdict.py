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
# Named parts of the bias remainder, from the render's budget (image mean,
# in relMSE units as the squared relative bias of the image mean).
BIAS_PARTS = ("truncation", "discretisation", "model")
TERM_HOW = {
    "noise": "the render's own per-pixel variance: mean(var / (ref^2 + 0.01))",
    "bias": "remainder: relMSE - noise - reference, clamped at 0 (squared bias plus what the noise estimate misses)",
    "reference": "the reference's own noise (relMSE floor; 0 for an analytic reference)",
    "truncation": "part of the bias: the light max_depth cuts off (the render's own probe), (missing mean / "
                  "reference mean)^2",
    "discretisation": "part of the bias: the method's own bias (photon radius from the same render, else the "
                      "matrix's seeds), (bias of the image mean / reference mean)^2",
    "model": "part of the bias: the model against its known alternative (dipole vs random walk, from the matrix), "
             "(error of the image mean / reference mean)^2",
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
    out = {"noise": None if noise is None else float(noise), "bias": max(0.0, float(rest)), "reference": ref}
    b = rec.get("error_budget") or {}
    rm_ = m.get("reference_mean")
    t = b.get("truncation") if isinstance(b.get("truncation"), dict) else {}
    d = b.get("discretisation") if isinstance(b.get("discretisation"), dict) else {}
    mo = b.get("model") if isinstance(b.get("model"), dict) else {}
    out["truncation"] = _squared_relative(t.get("missing_mean"), rm_)
    out["discretisation"] = _squared_relative(d.get("bias_mean"), rm_)
    out["model"] = _squared_relative(mo.get("error_mean"), rm_)
    return out


def dominant_term(terms: dict) -> str:
    """The largest of noise, bias and reference; when it is the bias, the
    largest of its named parts (truncation, discretisation, model) where that
    part is at least what they leave unexplained (bias - parts), else "bias"."""
    known = {k: terms[k] for k in TERMS if terms.get(k) is not None}
    if not any(v > 0 for v in known.values()):
        return "none"
    top = max(known, key=lambda k: known[k])
    if top != "bias":
        return top
    parts = {k: terms[k] for k in BIAS_PARTS if terms.get(k) is not None and terms[k] > 0}
    if not parts:
        return "bias"
    best = max(parts, key=lambda k: parts[k])
    unexplained = max(0.0, known["bias"] - sum(parts.values()))
    return best if parts[best] >= unexplained else "bias"


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
    return {"usable": usable, "own_error": own, "dominant": dominant_term(terms), "terms": terms,
            "target": float(target)}


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
    for k in TERMS + BIAS_PARTS:
        x = [v["terms"].get(k) for v in vs if v["terms"].get(k) is not None]
        if x:
            means[k] = float(np.mean(x))
    dominant = dominant_term(means)
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
            "discretisation": discretisation_term(res),
            "model": model_term(res),
            "how": {"truncation": TRUNCATION_HOW,
                    "discretisation": DISCRETISATION_HOW,
                    "model": MODEL_HOW,
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


# -- discretisation and estimator bias -----------------------------------------

RADIUS_ASSUMPTION = ("bias ~ c r^2 (Richardson extrapolation between the gather radius r and r / sqrt(2)): holds "
                     "where the radiance is smooth within r; at an edge or a corner the bias is of order r and "
                     "this estimate misses part of it")
DISCRETISATION_HOW = ("the bias of the image mean that the method's own approximation makes (photon radius, cache "
                      "density, clamping, patch size), per channel with its standard error. 'same render': sppm and "
                      "photonmapper estimate their photon radius's bias from the density estimate at r and r / "
                      "sqrt(2) of the same photons (" + RADIUS_ASSUMPTION + "; photonmapper adds the k-nearest rim "
                      "photon's share, its n / (n - 1) overestimate). 'the matrix': the other biased estimators' "
                      "seeds against the reference (the bench fills it: the whole bias of the image mean, "
                      "discretisation and any other); 0 for unbiased estimators")
# The biased estimators without a same-render estimate: what their bias comes from.
NO_SAME_RENDER = {
    "irrcache": "cache density (record spacing and interpolation)",
    "radcache": "cache density (record spacing and interpolation)",
    "vpl": "clamping and the VPL count",
    "rowcolumn": "clamping and the row-column sampling",
    "radiosity": "patch size (piecewise-constant radiosity)",
    "prt": "the spherical-harmonic band limit",
    "ppm": "the merge radius",
    "bpm": "the merge radius",
    "vcm": "the merge radius",
}


def _mean_se(total, sq, n):
    """Mean and standard error of the mean of n values from their sum and sum of squares, per channel."""
    total, sq = np.asarray(total, np.float64), np.asarray(sq, np.float64)
    mean = total / n
    if n < 2:
        return mean, None
    var = np.maximum(sq / n - mean ** 2, 0.0) * n / (n - 1)
    return mean, np.sqrt(var / n)


def discretisation_term(res) -> Optional[dict]:
    """The discretisation term of res.error_budget (see DISCRETISATION_HOW):
    {bias_mean, bias_se, relative (to the image mean), from, batches,
    assumption} from the render's own radius-bias tally (sppm, photonmapper),
    0 for an unbiased estimator, or bias_mean None with the reason and
    from None for a biased estimator the bench fills from the matrix."""
    from .. import estimators

    spec = dict(getattr(res, "integrator", None) or {})
    est = spec.get("type")
    info = estimators().get(est, {})
    bias = (info.get("capabilities") or {}).get("bias")
    st = getattr(res, "stats", None) or {}
    if bias == "unbiased":
        return {"bias_mean": [0.0] * 3, "bias_se": [0.0] * 3, "relative": [0.0] * 3, "from": "unbiased estimator",
                "exact": True}
    img_mean = np.asarray(res.image, np.float64).reshape(-1, 3).mean(axis=0)
    for batch in ("passes", "samples"):
        key = f"radius_bias_{batch}"
        if key in st:
            n = int(st[key] if np.isscalar(st[key]) else st[key][0])
            mean, se = _mean_se(st["radius_bias_sum"], st["radius_bias_sq_sum"], n)
            rel = np.divide(mean, img_mean, out=np.zeros(3), where=img_mean > 0)
            note = ("passes: independent (own camera samples and photons)" if batch == "passes" else
                    "camera samples: they share one photon map, whose own randomness this standard error misses")
            return {"bias_mean": [float(x) for x in mean], "bias_se": None if se is None else [float(x) for x in se],
                    "relative": [float(x) for x in rel], "from": "same render", "kind": "photon radius",
                    "batches": n, "batch": note, "assumption": RADIUS_ASSUMPTION, "exact": False}
    if est in ("sppm", "photonmapper"):
        why = ("no photon map was needed (no photon-mapped light in this scene)" if not st.get("photon_maps")
               else "scenes with media are not tallied")
        if not st.get("photon_maps"):
            return {"bias_mean": [0.0] * 3, "bias_se": [0.0] * 3, "relative": [0.0] * 3, "from": why, "exact": True}
        return {"bias_mean": None, "bias_se": None, "from": None,
                "reason": f"{est}: {why}; the bench fills it from the matrix's seeds against the reference"}
    what = NO_SAME_RENDER.get(est, "its approximation")
    return {"bias_mean": None, "bias_se": None, "from": None,
            "reason": f"{est}: no same-render estimate of the bias from {what}; the bench fills it from the "
                      f"matrix's seeds against the reference"}


MODEL_HOW = ("the error of the scene's physical model where it has one known alternative (the dipole BSSRDF against "
             "the random-walk subsurface): from the matrix, the model's renders (seeds) against the alternative's "
             "reference, image mean per channel with its standard error (the seeds' spread and the reference's "
             "variance); None where the scene has no known alternative")


def model_term(res) -> Optional[dict]:
    """The model term a render knows about itself: None (no known
    alternative), or a placeholder naming the alternative, which the bench
    fills from the matrix (matrix_terms)."""
    feats = (getattr(res, "stats", None) or {}).get("features") or {}
    if dict(feats).get("has_dipole"):
        return {"error_mean": None, "error_se": None, "from": None, "model": "dipole BSSRDF",
                "alternative": "random-walk subsurface",
                "reason": "the dipole is an approximation of the random walk; its model error comes from the matrix "
                          "(the dipole scene's seeds against the random walk's reference)"}
    return None


def _image_mean_se(rec_seeds: list, ref_mean, ref_se):
    """(mean, se) per channel of (image mean - reference mean) over seeds:
    se from the seeds' spread (None with one seed) and the reference's own."""
    x = np.array([r["metrics"]["image_mean"] for r in rec_seeds], np.float64) - np.asarray(ref_mean, np.float64)
    mean = x.mean(axis=0)
    rs = np.asarray(ref_se if ref_se is not None else [0.0] * 3, np.float64)
    if len(x) < 2:
        return mean, None
    return mean, np.sqrt(x.var(axis=0, ddof=1) / len(x) + rs ** 2)


def matrix_terms(recs: list) -> list:
    """Fills, in place, the terms of the records' error budgets that come
    from the matrix: `discretisation` where the render has no same-render
    estimate (its seeds, records of one configuration, against the
    reference) and `model` of a scene with a known alternative (model_of).
    Returns the records it changed. Seeds: the ok records of one
    config_key with image and reference means (metrics image_mean,
    reference_mean, reference_mean_se)."""
    groups = {}
    for r in recs:
        m = r.get("metrics") or {}
        if r.get("status") != "ok" or m.get("image_mean") is None or m.get("reference_mean") is None:
            continue
        groups.setdefault(r.get("config_key") or r["key"], []).append(r)
    changed = []
    for grp in groups.values():
        ref_mean = grp[0]["metrics"]["reference_mean"]
        ref_se = grp[0]["metrics"].get("reference_mean_se")
        mean, se = _image_mean_se(grp, ref_mean, ref_se)
        ref_m = np.asarray(ref_mean, np.float64)
        rel = np.divide(mean, ref_m, out=np.zeros(3), where=ref_m > 0)
        label = f"the matrix: {len(grp)} seed(s) against the reference"
        for r in grp:
            b = r.get("error_budget")
            if not isinstance(b, dict):
                continue
            touched = False
            d = b.get("discretisation")
            if isinstance(d, dict) and (d.get("bias_mean") is None or str(d.get("from")).startswith("the matrix")):
                b["discretisation"] = dict(d, bias_mean=[float(x) for x in mean],
                                           bias_se=None if se is None else [float(x) for x in se],
                                           relative=[float(x) for x in rel], **{"from": label}, seeds=len(grp),
                                           note="the whole bias of the image mean (discretisation and any other "
                                                "bias of the estimator), not the discretisation alone")
                touched = True
            if r.get("model_of"):
                mdl = dict(b.get("model") or {})
                mdl.update(error_mean=[float(x) for x in mean], error_se=None if se is None else [float(x) for x in se],
                           relative=[float(x) for x in rel], seeds=len(grp), alternative_scene=r["model_of"],
                           **{"from": f"the matrix: {len(grp)} seed(s) of {r['scene']} against {r['model_of']}'s "
                                      f"reference (the alternative model)"})
                b["model"] = mdl
                touched = True
            if touched:
                changed.append(r)
    return changed


def _squared_relative(values, ref_mean) -> Optional[float]:
    """mean over channels of (value / reference mean)^2: a term of the image
    mean in relMSE units (the squared relative bias of the image mean)."""
    if values is None or ref_mean is None:
        return None
    v, m = np.asarray(values, np.float64), np.asarray(ref_mean, np.float64)
    ok = m > 0
    if not np.any(ok):
        return None
    return float(np.mean((v[ok] / m[ok]) ** 2))
