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
The block functions live in radiometer.analysis.blocks (the benchmark
harness uses them too) and are re-exported here. `region_mask` turns the
pixel boxes a card.md lists into a block mask.
"""
import numpy as np

from radiometer.analysis.blocks import (ALPHA, BLOCK, block_mean, block_var_bound, block_var_independent,  # noqa: F401
                                        blocked_z_test, reference_variance_floor)
from radiometer.analysis.stats import z_test


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
