"""A per-pixel test over independent seeds (DESIGN section 4: "a bias can
hide in a few pixels"), shared by the test suite and the benchmark harness.

Why: the block test (blocks.py) compares k x k block means, which dilutes a
bias confined to a few pixels by k^2 (a 10 % error in 4 pixels that fall in
four different 4 x 4 blocks moves each block by 0.6 %). Testing each pixel
needs a variance that can be trusted pixel by pixel, and one render's own
per-pixel variance cannot be (heavy tails: the estimate and its variance
rise together, blocks.py). So the variance comes from n independent renders
(seeds), as batch means: the renders' mean a_bar, their sample variance s^2
(n - 1 degrees of freedom), and per pixel and channel

    t = (a_bar - b) / sqrt(s^2 / n + var_b)

against a reference b whose mean has variance var_b (0 for an analytic
image; for a reference that is itself a mean of independent runs, its
degrees of freedom are its runs - 1). t is referred to Student's t with the
Welch-Satterthwaite degrees of freedom (Welch 1947), and the smallest
two-sided p over the N pixel-channels tested against the Sidak level
1 - (1 - alpha)^(1/N) (Sidak 1967; valid for the positively dependent
channels of one pixel, conservative for them).

Two floors on s^2, each the variance of one render, for what n seeds at a
CI budget cannot see (a floor stands in for s^2 only where it is larger):

* `reference_variance_floor` (blocks.py): the per-sample variance the
  reference measured, scaled to our samples: rare paths (caustics, light
  through a gap) that our n renders mostly missed.
* `position_sampling_floor`: filter importance sampling (render.cpp) draws
  each camera sample's film position from the pixel filter, up to its
  radius away from the pixel centre. By the law of total variance, one
  sample's variance is at least the variance of E[L | film position] over
  that draw. Near a bright edge that is a rare, large event: Mitsuba's
  gaussian (radius 2 pixels) lands a sample of a ceiling pixel next to the
  Cornell box's light on the light itself about once in 1000 samples
  (measured: 8 renders x 512 spp of `bdpt`, every pixel value one of a few
  levels L_e / 512 apart), so at 8 x 64 spp most seeds see none, agree with
  each other, and t reaches -25 with no bias at all (8 x 512 spp: no pixel
  rejected; the box filter at 8 x 64 spp: none either). The floor is the
  variance of the reference image over the filter's footprint, the radiance
  taken as constant over each pixel: an approximation (at a hard edge it
  overestimates the true term about twofold, which only makes the test more
  lenient at such edges), exactly 0 for the box filter. It applies to
  estimators whose camera samples are filter-importance sampled, not to
  splatting ones (ptracer).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats as _st

ALPHA = 0.01


@dataclass
class PixelTestResult:
    passed: bool
    alpha: float
    n: int  # pixel-channels tested
    min_p: float
    level: float  # Sidak level per pixel-channel
    rejected: int  # pixel-channels with p below the level
    worst: tuple  # (y, x, channel) of min p
    worst_t: float
    worst_ratio: float  # a_bar / b at the worst pixel
    seeds: int
    t: np.ndarray  # the t field, same shape as the images
    p: np.ndarray

    def summary(self) -> str:
        return (f"{'PASS' if self.passed else 'FAIL'} at alpha={self.alpha:g} over {self.n} pixel-channels, "
                f"{self.seeds} seeds: min p {self.min_p:.3g} (Sidak level {self.level:.3g}) at {self.worst} "
                f"(t {self.worst_t:+.1f}, ratio {self.worst_ratio:.3f}); {self.rejected} rejected")

    __str__ = summary


def sidak_level(alpha: float, n: int) -> float:
    """Per-test level at which n tests have family-wise level alpha."""
    return float(-np.expm1(np.log1p(-alpha) / n))


def seed_t_test(runs, ref, ref_var=None, ref_dof=None, *, alpha: float = ALPHA, var_floor=None, mask=None,
                rounding: float = 1e-5) -> PixelTestResult:
    """Per-pixel Welch t-test of `runs` ((n, H, W, C): n renders with
    independent seeds) against `ref` ((H, W, C)), Sidak over the
    pixel-channels. `ref_var`: variance of the reference's mean (None:
    exact); `ref_dof`: its degrees of freedom (None: known exactly).
    `var_floor` ((H, W, C), the variance of one render): a lower bound on
    s^2 (the module's docstring). `mask` (bool, broadcastable): the pixels
    to test. `rounding`: relative resolution of the images; differences
    within it count as zero (as stats.z_test)."""
    runs = np.asarray(runs, np.float64)
    if runs.ndim < 2 or runs.shape[0] < 2:
        raise ValueError("seed_t_test: need at least 2 renders (independent seeds)")
    n = runs.shape[0]
    b = np.asarray(ref, np.float64)
    if runs.shape[1:] != b.shape:
        raise ValueError(f"seed_t_test: shapes differ: runs {runs.shape}, ref {b.shape}")
    vb = np.zeros_like(b) if ref_var is None else np.asarray(ref_var, np.float64)
    for name, arr in (("runs", runs), ("ref", b), ("ref_var", vb)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"seed_t_test: {name} has NaN or Inf values")
    if np.any(vb < 0):
        raise ValueError("seed_t_test: negative reference variance")
    mean = runs.mean(axis=0)
    s2 = runs.var(axis=0, ddof=1)
    if var_floor is not None:
        s2 = np.maximum(s2, np.asarray(var_floor, np.float64))
    va = s2 / n
    var = va + vb
    diff = mean - b
    tol = rounding * np.maximum(np.abs(mean), np.abs(b))
    diff = np.sign(diff) * np.maximum(np.abs(diff) - tol, 0.0)
    # Welch-Satterthwaite degrees of freedom; a side with unknown dof counts
    # as exact (infinite dof).
    denom = va * va / (n - 1) + (0.0 if ref_dof is None else vb * vb / float(ref_dof))
    with np.errstate(divide="ignore", invalid="ignore"):
        dof = np.where(denom > 0, var * var / np.where(denom > 0, denom, 1.0), np.inf)
        t = np.where(var > 0, diff / np.sqrt(np.where(var > 0, var, 1.0)),
                     np.where(diff == 0, 0.0, np.inf * np.sign(diff)))
    p = 2.0 * _st.t.sf(np.abs(t), np.maximum(dof, 1.0))
    sel = np.ones(b.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), b.shape)
    if not sel.any():
        raise ValueError("seed_t_test: no pixels to test")
    ps = np.where(sel, p, 1.0)
    count = int(sel.sum())
    level = sidak_level(alpha, count)
    iw = np.unravel_index(int(np.argmin(ps)), ps.shape)
    min_p = float(ps[iw])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = float(mean[iw] / b[iw]) if b[iw] != 0 else float("inf")
    return PixelTestResult(min_p >= level, alpha, count, min_p, level, int(np.count_nonzero(ps < level)),
                           tuple(int(i) for i in iw), float(t[iw]), ratio, n, t, p)


def two_sample_t_test(runs_a, runs_b, var_floor_b=None, **kw) -> PixelTestResult:
    """seed_t_test of two sets of independent renders (both sides' variance
    and degrees of freedom from their seeds; `var_floor_b` is `var_floor`
    for b's renders)."""
    b = np.asarray(runs_b, np.float64)
    if b.ndim < 2 or b.shape[0] < 2:
        raise ValueError("two_sample_t_test: need at least 2 renders on each side")
    s2 = b.var(axis=0, ddof=1)
    if var_floor_b is not None:
        s2 = np.maximum(s2, np.asarray(var_floor_b, np.float64))
    return seed_t_test(runs_a, b.mean(axis=0), s2 / b.shape[0], b.shape[0] - 1, **kw)


def filter_masses(rfilter: str, radius: float, stddev: float = 0.5, steps: int = 4096):
    """The pixel filter's mass over each whole-pixel offset d = -D .. D from
    the pixel centre, [d - 1/2, d + 1/2] (D = ceil(radius - 1/2)); filter
    shapes as film.cpp's FilterSampler (Mitsuba 3's). Returns (offsets,
    masses), the masses summing to 1."""
    x = (np.arange(steps) + 0.5) / steps * 2 * radius - radius
    if rfilter == "box":
        f = np.ones_like(x)
    elif rfilter == "tent":
        f = np.maximum(0.0, 1.0 - np.abs(x) / radius)
    elif rfilter == "gaussian":
        a = -1.0 / (2.0 * stddev * stddev)
        f = np.maximum(0.0, np.exp(a * x * x) - np.exp(a * radius * radius))
    else:
        raise ValueError(f"filter_masses: unknown filter '{rfilter}'")
    big = int(np.ceil(radius - 0.5 - 1e-9))
    offsets = np.arange(-big, big + 1)
    masses = np.array([f[(x >= d - 0.5) & (x < d + 0.5)].sum() for d in offsets], np.float64)
    return offsets, masses / masses.sum()


def position_sampling_floor(ref, rfilter: str, radius: float, stddev: float = 0.5, spp: int = 1):
    """Variance of one render of `spp` samples per pixel due to the film
    position each camera sample draws from the filter (the module's
    docstring): with w_k the filter's mass over pixel k (separable,
    renormalised inside the film as FIS is), sum_k w_k ref_k^2 - (sum_k w_k
    ref_k)^2, over spp. 0 for the box filter."""
    img = np.asarray(ref, np.float64)
    offsets, m = filter_masses(rfilter, radius, stddev)
    if len(offsets) == 1:
        return np.zeros_like(img)

    def smooth(a):  # separable weighted sum with masses m, renormalised at the film's borders
        out = a
        for axis in (0, 1):
            acc = np.zeros_like(out)
            norm = np.zeros(out.shape[axis])
            size = out.shape[axis]
            for d, w in zip(offsets, m):
                lo, hi = max(0, -d), min(size, size - d)  # pixels j whose j + d is inside the film
                if hi <= lo:
                    continue
                src = [slice(None)] * out.ndim
                dst = [slice(None)] * out.ndim
                src[axis], dst[axis] = slice(lo + d, hi + d), slice(lo, hi)
                acc[tuple(dst)] += w * out[tuple(src)]
                norm[lo:hi] += w
            shape = [1] * out.ndim
            shape[axis] = size
            out = acc / norm.reshape(shape)
        return out

    mean = smooth(img)
    return np.maximum(smooth(img * img) - mean * mean, 0.0) / float(spp)
