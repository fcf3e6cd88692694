"""Comparing a render of ours with a Mitsuba 3 reference: 4 x 4 block means
per channel, z-tested with both sides' variance (DESIGN section 4).

The Cornell box test (tests/test_cornell_reference.py) uses them; its
docstring measures why: per-sample radiances are heavy-tailed, so per pixel
the z statistic (with the pixel's own estimated variance) is biased and too
wide; a 4 x 4 block pools 16 pixels and is close enough to normal. Ours
samples each pixel independently (filter importance sampling), so a block's
variance is the sum of its pixels'; Mitsuba's splatting correlates
neighbouring pixels, so for its reference the Cauchy-Schwarz bound
(mean of the pixel standard deviations)^2 is used (conservative).
`region_mask` turns the pixel boxes a card.md lists into a block mask.
"""
import numpy as np

from radiometer.analysis.stats import z_test

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


def region_mask(shape, boxes):
    """Boolean (H, W) mask of the pixel boxes (x0, y0, x1, y1), half-open
    [x0, x1) x [y0, y1), as card.md lists them at the default resolution."""
    m = np.zeros(shape[:2], bool)
    for x0, y0, x1, y1 in boxes:
        m[y0:y1, x0:x1] = True
    return m


def scale_region(img, var, mask, s):
    """`img` with the pixels under `mask` scaled by s (a bias confined to the
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


# --- shared by the estimator tests (test_ptracer.py, test_bdpt.py) -----------


def blocked_z(a, var_a, b, var_b=None, alpha=ALPHA, a_correlated=False):
    """a_correlated: a's pixels share splats (a filter wider than a pixel
    spreads each splat over its footprint), so its block variance is bounded
    by Cauchy-Schwarz instead of summed."""
    vb = None if var_b is None else block_var_independent(var_b)
    va = block_var_bound(var_a) if a_correlated else block_var_independent(var_a)
    r = z_test(block_mean(a), va, block_mean(b), vb, alpha=alpha)
    return r.passed, r.summary() + "\n" + "\n".join(getattr(r, "channel_lines", []))


def assert_clean(res, where=""):
    for name, a in [("image", res.image), ("variance", res.variance)] + list(res.effects.items()):
        a = np.asarray(a)
        assert np.all(np.isfinite(a)), f"{where}: {name} has NaN/Inf"
        assert not np.any(a < 0), f"{where}: {name} has negative values"
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0, where


def lookat(origin, target, up=(0, 1, 0)):
    """Mitsuba's lookat: local +z forward, +x left, +y up."""
    o, t, u = (np.asarray(v, float) for v in (origin, target, up))
    d = (t - o) / np.linalg.norm(t - o)
    left = np.cross(u, d)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, o
    return m


def _rgb(v):
    return {"type": "rgb", "value": list(v) if np.ndim(v) else [v] * 3}
