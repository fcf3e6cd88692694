"""Helpers shared by the scene and estimator tests. The block z-test itself
lives in radiometer.analysis.blocks (why blocks: its docstring)."""
import numpy as np

from radiometer.analysis.blocks import (ALPHA, BLOCK, block_mean, block_var_bound, block_var_independent,  # noqa: F401
                                        blocked_z_test, reference_variance_floor, region_mask, scale_region)
from radiometer.analysis.stats import z_test  # noqa: F401


# --- shared by the estimator tests (test_ptracer.py, test_bdpt*.py) ----------


def blocked_z(a, var_a, b, var_b=None, alpha=ALPHA, a_correlated=False):
    """Two renders of ours (or ours against an exact image, var_b None);
    a_correlated: a's pixels share splats (a filter wider than a pixel)."""
    return blocked_z_test(a, var_a, b, var_b, a_correlated=a_correlated, alpha=alpha)


def check_mirror_caustic(estimator, spp, res=32, seed=3, power=1.01):
    """An estimator on the mirror caustic (orthographic camera, L S D E and
    direct light) against the method-of-images solution (zero variance):
    blocks at ALPHA with a power check (`power` x the solution rejected,
    default 1 %), the direct and caustic classes
    to 3 % each (their own variances are not reported; the total's bounds
    each, so only the total is tested strictly), nothing in other classes."""
    import radiometer as rm
    from radiometer.reference_scenes.mirror_caustic import analytic as mirror

    b = rm.render(rm.load_file(mirror.XML, res=res), integrator={"type": estimator, "max_depth": 3}, spp=spp,
                  seed=seed)
    assert_clean(b, "mirror caustic")
    ref = mirror.effects(res=res)
    for k in ("direct", "caustic"):
        assert abs(b.effects[k].sum() / ref[k].sum() - 1) <= 0.03, (k, b.effects[k].sum(), ref[k].sum())
    total = ref["direct"] + ref["caustic"]
    passed, msg = blocked_z(b.image, b.variance, total)
    assert passed, f"mirror caustic: {estimator} / exact = {b.image.sum() / total.sum():.5f}\n{msg}"
    assert not blocked_z(b.image, b.variance, total * power)[0], (
        f"mirror caustic: a {(power - 1) * 100:.0f} % bias went undetected")
    for k in ("emission", "indirect", "specular"):
        assert not np.any(b.effects[k]), k


def assert_same_bytes_whatever_threads(scene, integrator, spp):
    """Same seed: identical image, variance and effect bytes on 1, 2 and 3
    threads; another seed: a different image."""
    import radiometer as rm

    r = [rm.render(scene, integrator=integrator, spp=spp, seed=9, threads=t) for t in (1, 2, 3)]
    for x in r[1:]:
        assert x.image.tobytes() == r[0].image.tobytes()
        assert x.variance.tobytes() == r[0].variance.tobytes()
        for k in x.effects:
            assert x.effects[k].tobytes() == r[0].effects[k].tobytes()
    other = rm.render(scene, integrator=integrator, spp=spp, seed=10, threads=2)
    assert other.image.tobytes() != r[0].image.tobytes()


def assert_strategies_estimate_their_depth(runs):
    """`runs`: renders with strategy_images, one seed each. Unweighted, every
    strategy (s, t) of a depth d = s + t - 1 >= 2 is an unbiased estimate of
    that depth's light (Veach 1997, sec. 10.2): its image mean minus the
    MIS-weighted depth total is tested for zero mean over the runs
    (one-sample t, alpha = 0.01 Bonferroni over the strategies tested).
    Power: the same test must reject the strategies scaled by 1.1."""
    from scipy import stats as st

    keys = [k for k in runs[0].strategies_unweighted if sum(k) - 1 >= 2]
    alpha = 0.01 / len(keys)
    for scale in (1.0, 1.1):
        worst = 1.0
        for s, t in keys:
            d = s + t - 1
            diffs = [scale * r.strategies_unweighted[(s, t)].mean() -
                     sum(v.mean() for (a, b), v in r.strategies.items() if a + b - 1 == d) for r in runs]
            p = st.ttest_1samp(diffs, 0.0).pvalue
            worst = min(worst, p)
            if scale == 1.0:
                assert p >= alpha, f"strategy ({s}, {t}) disagrees with its depth's total: p {p:.2e}"
        if scale != 1.0:
            assert worst < alpha, f"strategies scaled by {scale} went undetected (smallest p {worst:.2e})"


def assert_agrees(a, b, power=None, what=""):
    """Render `a` against render `b` (images with variances), blocked
    z-test; with `power`, the same test must reject b scaled by it (that
    it would notice such an error)."""
    passed, msg = blocked_z(a.image, a.variance, b.image, b.variance)
    assert passed, f"{what} a / b = {a.image.sum() / b.image.sum():.5f}\n{msg}"
    if power is None:
        return
    passed, msg = blocked_z(a.image, a.variance, b.image * power, b.variance * power ** 2)
    assert not passed, f"{what}: a {(power - 1) * 100:.0f} % error went undetected:\n{msg}"


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
