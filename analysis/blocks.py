"""Block z-tests of a render against a reference (DESIGN section 4), shared
by the test suite and the benchmark harness.

Why blocks: per-sample radiances are heavy-tailed, so per pixel at a CI
budget the z statistic (with the pixel's own estimated variance) is biased
and too wide: the estimate and its variance rise together, which inflates
|z| exactly in the pixels that missed a rare path. A k x k block mean pools
k^2 x spp samples and is close enough to normal (measured on the Cornell
box, tests/test_cornell_reference.py). Our renderer samples each pixel
independently (filter importance sampling), so a block's variance is the sum
of its pixels'; Mitsuba's splatting correlates neighbouring pixels, so for
its references the Cauchy-Schwarz bound (mean of the pixel standard
deviations)^2 is used (conservative). Each channel is tested at alpha / 3
(one path sample feeds R, G and B, so channels are not pooled).
"""
from __future__ import annotations

import numpy as np

from .stats import z_test

BLOCK = 4
ALPHA = 0.01


def block_mean(img, k=BLOCK):
    h, w, c = np.shape(img)
    return np.asarray(img, np.float64).reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def block_var_independent(var, k=BLOCK):
    """Variance of a block mean whose pixels are independent (ours: FIS)."""
    h, w, c = np.shape(var)
    return np.asarray(var, np.float64).reshape(h // k, k, w // k, k, c).sum(axis=(1, 3)) / k ** 4


def block_var_bound(var, k=BLOCK):
    """Upper bound on the variance of a block mean whose pixels may be
    correlated (splatting): Var(mean) <= (mean of the sd)^2."""
    h, w, c = np.shape(var)
    sd = np.sqrt(np.asarray(var, np.float64)).reshape(h // k, k, w // k, k, c)
    return sd.mean(axis=(1, 3)) ** 2


def region_mask(shape, boxes):
    """Boolean (H, W) mask of the pixel boxes (x0, y0, x1, y1), half-open
    [x0, x1) x [y0, y1), as a scene's card.md lists them."""
    m = np.zeros(shape[:2], bool)
    for x0, y0, x1, y1 in boxes:
        m[y0:y1, x0:x1] = True
    return m


def scale_region(img, var, mask, s):
    """`img` with the pixels under `mask` scaled by s (a bias confined to an
    effect region), and its variance scaled by s^2 there."""
    f = np.where(np.asarray(mask, bool)[..., None], s, 1.0)
    return img * f, var * f * f


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


def blocked_z_test(a, var_a, b, var_b=None, *, b_splatted=False, a_correlated=False, a_common_mode=False,
                   alpha=ALPHA, k=BLOCK, var_a_floor=None, exclude=(), block_mask=None, label=""):
    """z-tests k x k block means of `a` against `b`, each channel at
    alpha / 3; returns (passed, message). var_b None: b is exact (analytic).
    b_splatted / a_correlated: that side's pixels share samples (a filter
    wider than a pixel), so its block variance is the Cauchy-Schwarz bound.
    a_common_mode: a's blocks may share one error across the whole image
    (Metropolis' normalisation b), so the mean-z statistic takes its
    Cauchy-Schwarz bound too (z_test's `common_mode`).
    `var_a_floor` (per pixel, like var_a): a lower bound on the variance of
    a's pixels (`reference_variance_floor`); a block's variance is the larger
    of a's own estimate and the floor's, the floor's taken by a's own rule
    (a_correlated: the Cauchy-Schwarz bound, as it stands in for a's pixels,
    whose errors a chain shares; measured on mmlt's glass_sphere_caustic
    cell, docs/mlt.md). `exclude`: pixel boxes (x0, y0, x1,
    y1); every block that touches one is left out. `block_mask`: (H/k, W/k)
    booleans, the blocks to test. The Sidak level counts the blocks tested.
    Images whose sides k does not divide (a 1 x 1 irradiance meter) use the
    largest block side below k that divides both."""
    h, w = np.shape(a)[:2]
    while k > 1 and (h % k or w % k):
        k -= 1
    ba = block_mean(a, k)
    a_rule = block_var_bound if a_correlated else block_var_independent
    va = a_rule(var_a, k)
    if var_a_floor is not None:
        va = np.maximum(va, a_rule(var_a_floor, k))
    bb = block_mean(b, k)
    if var_b is None:
        vb = np.zeros_like(bb)
    else:
        vb = block_var_bound(var_b, k) if b_splatted else block_var_independent(var_b, k)
    keep = np.ones(ba.shape[:2], bool) if block_mask is None else np.asarray(block_mask, bool).copy()
    if exclude:
        keep &= ~(block_mean(region_mask(np.shape(a), exclude)[..., None].astype(float), k)[..., 0] > 0)
    results = [z_test(ba[..., c], va[..., c], bb[..., c], vb[..., c], alpha=alpha / 3, mask=keep,
                      common_mode=a_common_mode) for c in range(3)]
    msg = "\n".join(f"{label}{'RGB'[c]} ({k}x{k} blocks): {r.summary()}" for c, r in enumerate(results))
    return all(r.passed for r in results), msg
