"""Block comparisons of a render with a reference that has a variance
(DESIGN section 4), shared by the tests (tests/refcompare.py re-exports
them) and the benchmark harness (per-effect references are accepted only
when their total passes `blocked_z_test` against Mitsuba).

Per-sample radiances are heavy-tailed, so per pixel the z statistic (with
the pixel's own estimated variance) is biased and too wide; a 4 x 4 block
pools 16 pixels and is close enough to normal (measured in
tests/test_cornell_reference.py). Ours samples each pixel independently
(filter importance sampling), so a block's variance is the sum of its
pixels'; Mitsuba's splatting correlates neighbouring pixels, so for its
reference the Cauchy-Schwarz bound (mean of the pixel standard
deviations)^2 is used (conservative).
"""
import numpy as np

from .stats import z_test

BLOCK = 4
ALPHA = 0.01


def block_mean(img, k=BLOCK):
    h, w, c = img.shape
    return np.asarray(img, np.float64).reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def block_var_independent(var, k=BLOCK):
    """Variance of a block mean whose pixels are independent (ours: FIS)."""
    h, w, c = var.shape
    return np.asarray(var, np.float64).reshape(h // k, k, w // k, k, c).sum(axis=(1, 3)) / k ** 4


def block_var_bound(var, k=BLOCK):
    """Upper bound on the variance of a block mean whose pixels may be
    correlated (Mitsuba's splatting): Var(mean) <= (mean of the sd)^2."""
    h, w, c = var.shape
    sd = np.sqrt(np.asarray(var, np.float64)).reshape(h // k, k, w // k, k, c)
    return sd.mean(axis=(1, 3)) ** 2


def blocked_z_test(a, var_a, b, var_b, *, b_splatted, alpha=ALPHA, k=BLOCK, var_a_floor=None):
    """z-tests k x k block means, each channel at alpha / 3; returns
    (passed, message). `var_a_floor` (per pixel, like var_a): a lower bound
    on the variance of a's pixels, see `reference_variance_floor`; a block's
    variance is then the larger of a's own estimate and the floor's."""
    ba, va = block_mean(a, k), block_var_independent(var_a, k)
    if var_a_floor is not None:
        va = np.maximum(va, block_var_independent(var_a_floor, k))
    bb = block_mean(b, k)
    vb = block_var_bound(var_b, k) if b_splatted else block_var_independent(var_b, k)
    results = [z_test(ba[..., c], va[..., c], bb[..., c], vb[..., c], alpha=alpha / 3) for c in range(3)]
    msg = "\n".join(f"{'RGB'[c]} ({k}x{k} blocks): {r.summary()}" for c, r in enumerate(results))
    return all(r.passed for r in results), msg


def reference_variance_floor(ref_variance, ref_total_spp, spp):
    """The variance that `spp` samples per pixel would have if they had the
    per-sample variance the reference measured: var_ref * N_ref / spp.

    Why: where a few rare paths carry much of a pixel's radiance (caustics
    from a small light, light through a narrow gap), a render at CI budget
    mostly misses them, and then its own variance estimate misses them too:
    the estimate is low exactly when its variance is underestimated, so z is
    biased negative (measured below). The reference, with 16 to 128 times
    our samples split over independent runs, sees those paths, so its
    per-sample variance is the better estimate of the variance our
    estimator's samples have on them. It is only a floor: it stands in for
    our estimate only where ours is smaller. Valid for box-filtered images
    (a sample lands in one pixel, pixels independent on both sides)."""
    return np.asarray(ref_variance, np.float64) * float(ref_total_spp) / float(spp)
