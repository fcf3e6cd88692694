"""Image error metrics and convergence measures (DESIGN section 4, "Accuracy
against time").

All metrics take an estimate `a` and a reference `ref`, both (H, W, 3)
linear RGB, and return one float (lower is better):

- `mse`: mean squared error over pixels and channels.
- `relmse`: relative MSE, mean((a - ref)^2 / (ref^2 + eps)), eps = 1e-2
  (the definition of Rousselle et al. 2011 and the denoising literature; eps
  keeps black pixels from dominating).
- `smape`: symmetric mean absolute percentage error,
  mean(|a - ref| / (|a| + |ref| + tiny)) in [0, 1] (a pixel where both are 0
  contributes 0).
- `flip`: mean NVIDIA FLIP error (Andersson et al. 2020; PyPI flip-evaluator)
  of the two images tone-mapped to sRGB with one exposure taken from the
  reference (`display_exposure`), LDR FLIP at its default 67 pixels per degree.
- `ciede2000`: mean CIEDE2000 colour difference (Sharma et al. 2005;
  colour-science) of the same tone-mapped images, through sRGB -> XYZ (D65)
  -> CIE Lab.

A noisy reference biases the squared-error metrics upward by its own
variance: E[(a - r)^2] = (a - L)^2 + Var[r]. `relmse_floor(ref, ref_var)`
is that floor, mean(Var[r] / (r^2 + eps)); it is recorded next to every
relMSE measured against a reference with variance so a reader can see when
the reference, not the estimate, limits the number.

Convergence: `error_curve` evaluates a metric at each checkpoint of one
render, (spp, seconds, error); `loglog_slope` fits log error against log
time by least squares (-1 for an unbiased Monte Carlo estimator of relMSE,
flattening where bias dominates), only to a curve of >= 4 checkpoints
spanning >= 4x in time (`curves_slope`: over several seeds' curves);
`time_to_error` interpolates the curve in
log-log for the time a target error is first reached; `efficiency` is
1 / (error x seconds) (Veach 1997, section 2.4: the inverse of the
variance-time product).
"""
from __future__ import annotations

import math

import numpy as np

RELMSE_EPS = 1e-2
SMAPE_TINY = 1e-8
METRICS = ("relmse", "mse", "smape", "flip", "ciede2000")
DISPLAY_PERCENTILE = 99.0


def _pair(a, ref):
    a = np.asarray(a, np.float64)
    ref = np.asarray(ref, np.float64)
    if a.shape != ref.shape:
        raise ValueError(f"metric: shapes differ: estimate {a.shape}, reference {ref.shape}")
    if a.size == 0:
        raise ValueError("metric: empty images")
    return a, ref


def mse(a, ref) -> float:
    a, ref = _pair(a, ref)
    return float(np.mean((a - ref) ** 2))


def relmse(a, ref, eps: float = RELMSE_EPS) -> float:
    a, ref = _pair(a, ref)
    return float(np.mean((a - ref) ** 2 / (ref * ref + eps)))


def relmse_floor(ref, ref_var, eps: float = RELMSE_EPS) -> float:
    """The relMSE a perfect estimate would show against a reference with
    per-pixel variance `ref_var`: mean(ref_var / (ref^2 + eps))."""
    ref = np.asarray(ref, np.float64)
    return float(np.mean(np.asarray(ref_var, np.float64) / (ref * ref + eps)))


def smape(a, ref) -> float:
    a, ref = _pair(a, ref)
    den = np.abs(a) + np.abs(ref)
    return float(np.mean(np.where(den > SMAPE_TINY, np.abs(a - ref) / np.maximum(den, SMAPE_TINY), 0.0)))


def display_exposure(ref, percentile: float = DISPLAY_PERCENTILE) -> float:
    """Exposure (in stops, for `tonemap.to_srgb`) that maps the reference's
    `percentile`-th percentile of pixel luminance to 1. One exposure per
    reference, shared by every image compared with it."""
    ref = np.asarray(ref, np.float64)
    lum = 0.2126 * ref[..., 0] + 0.7152 * ref[..., 1] + 0.0722 * ref[..., 2]
    top = float(np.percentile(lum, percentile)) if lum.size else 0.0
    if not top > 0 or not math.isfinite(top):
        return 0.0
    return float(-math.log2(top))


def tonemapped(img, exposure: float) -> np.ndarray:
    from radiometer.tonemap import to_srgb

    return to_srgb(img, exposure).astype(np.float32)


def flip(a, ref, exposure: float | None = None) -> float:
    """Mean LDR FLIP of the tone-mapped images (see the module docstring)."""
    a, ref = _pair(a, ref)
    import flip_evaluator

    e = display_exposure(ref) if exposure is None else exposure
    _, mean_err, _ = flip_evaluator.evaluate(tonemapped(ref, e), tonemapped(a, e), "LDR", inputsRGB=True,
                                             applyMagma=False, computeMeanError=True)
    return float(mean_err)


def srgb_to_lab(srgb) -> np.ndarray:
    """sRGB-encoded [0, 1] -> CIE Lab (D65 white), via colour-science."""
    import colour

    xyz = colour.sRGB_to_XYZ(np.asarray(srgb, np.float64))
    return colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])


def delta_e2000(lab_a, lab_b) -> np.ndarray:
    """CIEDE2000 between Lab arrays (..., 3)."""
    import colour

    return np.asarray(colour.delta_E(np.asarray(lab_a, np.float64), np.asarray(lab_b, np.float64),
                                     method="CIE 2000"), np.float64)


def ciede2000(a, ref, exposure: float | None = None) -> float:
    """Mean CIEDE2000 of the tone-mapped images (see the module docstring)."""
    a, ref = _pair(a, ref)
    e = display_exposure(ref) if exposure is None else exposure
    return float(np.mean(delta_e2000(srgb_to_lab(tonemapped(a, e)), srgb_to_lab(tonemapped(ref, e)))))


_FUNCS = {"relmse": relmse, "mse": mse, "smape": smape, "flip": flip, "ciede2000": ciede2000}


def metric(name: str):
    """The metric function called `name` (one of METRICS)."""
    try:
        return _FUNCS[name]
    except KeyError:
        raise ValueError(f"unknown metric '{name}' (known: {', '.join(METRICS)})") from None


def all_metrics(a, ref, ref_var=None, which=METRICS) -> dict:
    """{metric: value} for `which`, plus `relmse_floor` when the reference has
    a variance. The perceptual metrics share one exposure (the reference's)."""
    a, ref = _pair(a, ref)
    e = display_exposure(ref)
    out = {}
    for m in which:
        out[m] = float(metric(m)(a, ref, exposure=e)) if m in ("flip", "ciede2000") else float(metric(m)(a, ref))
    if ref_var is not None:
        out["relmse_floor"] = relmse_floor(ref, ref_var)
    return out


def pixel_error_map(a, ref, eps: float = RELMSE_EPS) -> np.ndarray:
    """Per-pixel relative squared error, averaged over channels (H, W): the
    heat map whose mean is relMSE."""
    a, ref = _pair(a, ref)
    return np.mean((a - ref) ** 2 / (ref * ref + eps), axis=-1)


# -- convergence ------------------------------------------------------------


def error_curve(checkpoints, ref, name: str = "relmse") -> list:
    """[(spp, seconds, error)] for one render's checkpoints
    [(spp, seconds, image, variance)], in increasing spp; checkpoints with
    zero time are dropped (no point on a log axis)."""
    f = metric(name)
    out = []
    for spp, seconds, image, _ in sorted(checkpoints, key=lambda c: c[0]):
        if seconds > 0:
            out.append((int(spp), float(seconds), float(f(image, ref))))
    return out


# A log-log slope is fitted only to a curve of at least this many
# checkpoints spanning at least this factor in time: two checkpoints of a
# photon-map render a few per cent apart in time gave a "slope" of -160.
SLOPE_MIN_CHECKPOINTS = 4
SLOPE_MIN_SPAN = 4.0
TOO_FEW_CHECKPOINTS = (f"too few checkpoints (a slope needs >= {SLOPE_MIN_CHECKPOINTS} spanning a factor >= "
                       f"{SLOPE_MIN_SPAN:g} in time)")


def _usable(times, errors):
    t = np.asarray(times, np.float64)
    e = np.asarray(errors, np.float64)
    ok = (t > 0) & (e > 0) & np.isfinite(t) & np.isfinite(e)
    return t[ok], e[ok]


def slope_fits(times, errors, min_points: int = SLOPE_MIN_CHECKPOINTS, min_span: float = SLOPE_MIN_SPAN) -> bool:
    """True when one curve's usable points (positive time and error) are
    enough for a slope: `min_points` of them, max time / min time >= `min_span`."""
    t, _ = _usable(times, errors)
    return t.size >= min_points and t.size > 0 and float(t.max()) >= min_span * float(t.min())


def loglog_slope(times, errors, min_points: int = SLOPE_MIN_CHECKPOINTS, min_span: float = SLOPE_MIN_SPAN):
    """Least-squares slope of log(error) against log(time) of one curve;
    None unless `slope_fits` (too few points, or too short a span in time)."""
    if not slope_fits(times, errors, min_points, min_span):
        return None
    t, e = _usable(times, errors)
    slope, _ = np.polyfit(np.log(t), np.log(e), 1)
    return float(slope)


def curves_slope(curves, min_points: int = SLOPE_MIN_CHECKPOINTS, min_span: float = SLOPE_MIN_SPAN):
    """One slope over several renders' curves [(spp, seconds, error)] (the
    seeds of a configuration): fitted to the pooled points of the curves
    that each `slope_fits`; None when none does."""
    keep = [c for c in curves if c and slope_fits([p[1] for p in c], [p[2] for p in c], min_points, min_span)]
    if not keep:
        return None
    t, e = _usable([p[1] for c in keep for p in c], [p[2] for c in keep for p in c])
    if np.ptp(np.log(t)) == 0:
        return None
    slope, _ = np.polyfit(np.log(t), np.log(e), 1)
    return float(slope)


def time_to_error(curve, target: float):
    """The time at which the curve [(spp, seconds, error)] first reaches
    `target`, interpolated linearly in log-log between the two checkpoints
    that bracket it; the first checkpoint's time if it is already below, and
    None if the curve never gets there."""
    prev = None
    for _, t, e in curve:
        if e <= target:
            if prev is None:
                return float(t)
            t0, e0 = prev
            if e0 <= 0 or e <= 0 or t0 <= 0 or e0 == e:
                return float(t)
            w = (math.log(target) - math.log(e0)) / (math.log(e) - math.log(e0))
            return float(math.exp(math.log(t0) + w * (math.log(t) - math.log(t0))))
        prev = (t, e)
    return None


def efficiency(error: float, seconds: float):
    """1 / (error x seconds); None where undefined (zero or missing)."""
    if error is None or seconds is None or not error > 0 or not seconds > 0:
        return None
    return float(1.0 / (error * seconds))
