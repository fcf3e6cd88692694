"""Helpers shared by the scene and estimator tests. The block z-test itself
lives in radiometer.analysis.blocks (why blocks: its docstring)."""
import numpy as np

from radiometer.analysis.blocks import (ALPHA, BLOCK, block_mean, block_var_bound, block_var_independent,  # noqa: F401
                                        blocked_z_test, reference_variance_floor, region_mask, scale_region)
from radiometer.analysis.stats import z_test  # noqa: F401


# --- shared by the estimator tests (test_ptracer.py, test_bdpt.py) -----------


def blocked_z(a, var_a, b, var_b=None, alpha=ALPHA, a_correlated=False):
    """Two renders of ours (or ours against an exact image, var_b None);
    a_correlated: a's pixels share splats (a filter wider than a pixel)."""
    return blocked_z_test(a, var_a, b, var_b, a_correlated=a_correlated, alpha=alpha)


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
