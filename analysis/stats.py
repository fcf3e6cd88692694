"""Statistical tests that decide correctness (DESIGN section 4).

`z_test(a, var_a, b, var_b)`: per pixel and channel z = (a - b) / sqrt(var_a + var_b)
with both sides' variance (var_b = 0 against an analytic solution). Three
views of the same z field, each at level alpha / 3 (Bonferroni), so the whole
test has significance level alpha:
  * Sidak: the smallest two-sided p against 1 - (1 - alpha/3)^(1/N), which
    catches a few pixels that are far off;
  * rejected fraction: how many pixels have p < `pixel_level`, against the
    binomial count that level predicts under H0 (one-sided), which catches a
    region that is moderately off;
  * mean z: sum(z) / sqrt(N) ~ N(0, 1) under H0 for independent pixels,
    which catches a small bias spread over the whole image.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats as _st


@dataclass
class ZTestResult:
    passed: bool
    alpha: float
    n: int  # pixel-channels tested
    min_p: float
    sidak_level: float
    rejected: int  # pixel-channels with p < pixel_level
    expected_rejected: float
    p_rejected: float  # binomial tail probability of that many rejections
    mean_z: float  # sum(z) / sqrt(n)
    p_mean: float
    worst_pixel: tuple  # (y, x, channel) of min p
    z: np.ndarray  # the z field, same shape as the images

    channel_lines: list = None  # per-channel summaries when channels were tested separately

    def summary(self) -> str:
        if self.channel_lines:
            return (f"{'PASS' if self.passed else 'FAIL'} at alpha={self.alpha:g}, channels tested separately at "
                    f"alpha/3:\n" + "\n".join(self.channel_lines))
        return (f"{'PASS' if self.passed else 'FAIL'} at alpha={self.alpha:g} over {self.n} pixel-channels: "
                f"min p {self.min_p:.3g} (Sidak level {self.sidak_level:.3g}) at {self.worst_pixel}; "
                f"{self.rejected} rejected at the per-pixel level (expected {self.expected_rejected:.1f}, "
                f"p {self.p_rejected:.3g}); mean z {self.mean_z:+.2f} (p {self.p_mean:.3g})")

    __str__ = summary


def z_test(a, var_a, b, var_b=None, alpha: float = 0.01, pixel_level: float = 0.01, mask=None,
           rounding: float = 1e-5, per_channel: bool = True, common_mode: bool = False) -> ZTestResult:
    """Tests H0: E[a] == E[b] pixel by pixel. For (H, W, 3) images the
    channels are tested separately, each at alpha / 3 (Bonferroni): one path
    sample feeds R, G and B, so the channels of a pixel are correlated and
    pooling them would make the rejected-count and mean-z statistics too
    wide (measured on the Cornell box: the pooled mean z spread 1.66, not 1).
    The result is that of the worst channel, with every channel's line in its
    summary. `mask` (bool, broadcastable)
    restricts the test to a region. `rounding` is the relative resolution of
    the images (float32 arithmetic along a path, ~10 ulp): differences within
    rounding * max(|a|, |b|) count as zero, so a zero-variance estimate that
    agrees to rounding is neither an infinite z nor, summed over many pixels,
    a spurious bias. `common_mode`: every pixel of `a` may carry one shared
    error (Metropolis: each chain's normalisation b scales all its splats,
    wherever they land), so the z's are not independent and the mean-z
    statistic sum(z) / sqrt(n) is too wide; its Cauchy-Schwarz bound
    Var(sum z) <= n^2 gives mean z = sum(z) / n instead (conservative). The
    per-pixel tests (Sidak, rejected count) are unchanged."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    var_a = np.asarray(var_a, np.float64)
    var_b = np.zeros_like(b) if var_b is None else np.asarray(var_b, np.float64)
    if per_channel and a.ndim == 3 and a.shape[-1] == 3 and a.shape == b.shape == var_a.shape == var_b.shape:
        m = None if mask is None else np.broadcast_to(np.asarray(mask, bool), a.shape)
        parts = [z_test(a[..., c], var_a[..., c], b[..., c], var_b[..., c], alpha / 3.0, pixel_level,
                        None if m is None else m[..., c], rounding, per_channel=False, common_mode=common_mode)
                 for c in range(3)]
        worst = min(parts, key=lambda r: (r.passed, min(r.min_p / r.sidak_level, r.p_rejected, r.p_mean)))
        z = np.stack([r.z for r in parts], axis=-1)
        lines = [f"  {'RGB'[c]}: {r.summary()}" for c, r in enumerate(parts)]
        res = ZTestResult(all(r.passed for r in parts), alpha, sum(r.n for r in parts), worst.min_p,
                          worst.sidak_level, sum(r.rejected for r in parts), sum(r.expected_rejected for r in parts),
                          worst.p_rejected, worst.mean_z, worst.p_mean, worst.worst_pixel, z)
        res.channel_lines = lines
        return res
    if a.shape != b.shape or var_a.shape != a.shape or var_b.shape != b.shape:
        raise ValueError(f"z_test: shapes differ: a {a.shape}, var_a {var_a.shape}, b {b.shape}, var_b {var_b.shape}")
    for name, arr in (("a", a), ("var_a", var_a), ("b", b), ("var_b", var_b)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"z_test: {name} has NaN or Inf values")
    if np.any(var_a < 0) or np.any(var_b < 0):
        raise ValueError("z_test: negative variance")
    var = var_a + var_b
    diff = a - b
    tol = rounding * np.maximum(np.abs(a), np.abs(b))
    diff = np.sign(diff) * np.maximum(np.abs(diff) - tol, 0.0)
    sel = np.ones(a.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), a.shape)
    # Zero variance on both sides: equal values agree; different values are
    # an infinite z (a deterministic disagreement).
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(var > 0, diff / np.sqrt(np.where(var > 0, var, 1.0)),
                     np.where(diff == 0, 0.0, np.inf * np.sign(diff)))
    zs = z[sel]
    n = int(zs.size)
    if n == 0:
        raise ValueError("z_test: no pixels to test")
    p = 2.0 * _st.norm.sf(np.abs(zs))
    a3 = alpha / 3.0
    sidak = 1.0 - (1.0 - a3) ** (1.0 / n)
    imin = int(np.argmin(p))
    min_p = float(p[imin])
    worst = tuple(int(i) for i in np.argwhere(sel)[imin])
    rejected = int(np.count_nonzero(p < pixel_level))
    p_rej = float(_st.binom.sf(rejected - 1, n, pixel_level))
    finite = np.isfinite(zs)
    mean_z = float(zs[finite].sum() / (n if common_mode else np.sqrt(n))) if finite.all() else float("inf")
    p_mean = float(2.0 * _st.norm.sf(abs(mean_z)))
    passed = (min_p >= sidak) and (p_rej >= a3) and (p_mean >= a3)
    return ZTestResult(passed, alpha, n, min_p, sidak, rejected, n * pixel_level, p_rej, mean_z, p_mean, worst, z)


def bias_variance(images, reference, reference_var=None):
    """From k renders with independent seeds: per-pixel mean, the variance of
    one render (across seeds), and the bias of the mean against `reference`
    with its standard error. Returns a dict of arrays and scalar summaries."""
    imgs = np.asarray(images, np.float64)
    if imgs.ndim < 2 or imgs.shape[0] < 2:
        raise ValueError("bias_variance: need at least 2 renders")
    k = imgs.shape[0]
    mean = imgs.mean(axis=0)
    var = imgs.var(axis=0, ddof=1)
    ref = np.asarray(reference, np.float64)
    bias = mean - ref
    se2 = var / k + (0 if reference_var is None else np.asarray(reference_var, np.float64))
    return {"mean": mean, "variance": var, "bias": bias, "bias_se": np.sqrt(se2),
            "mean_bias": float(bias.mean()), "mean_variance": float(var.mean()),
            "rel_bias": float(bias.mean() / max(abs(ref.mean()), 1e-30))}
