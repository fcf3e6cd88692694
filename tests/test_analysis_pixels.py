"""radiometer.analysis.pixels on synthetic data with known answers: the
per-pixel seed t-test holds its level under H0 and rejects a biased pixel,
the Welch degrees of freedom, and the position-sampling floor against a
simulation of filter importance sampling. Significance: stated per test;
fixed seeds."""
import numpy as np
import pytest
from scipy import stats

from radiometer.analysis.pixels import (filter_masses, position_sampling_floor, seed_t_test, sidak_level,
                                        two_sample_t_test)


def _runs(rng, n=16, shape=(8, 8, 3), mean=1.0, sd=0.1):
    return mean + sd * rng.standard_normal((n,) + shape)


def test_level_under_h0_and_a_biased_pixel_is_rejected():
    """Under H0 (normal noise, reference exact) a test at alpha = 0.05 over
    192 pixel-channels rejects in about 5 % of 400 repetitions (binomial
    bounds at 0.001); one pixel off by 8 standard errors of the mean is
    rejected."""
    rng = np.random.default_rng(1)
    ref = np.ones((8, 8, 3))
    rejections = sum(not seed_t_test(_runs(rng), ref, alpha=0.05).passed for _ in range(400))
    lo, hi = stats.binom.ppf([0.0005, 0.9995], 400, 0.05)
    assert lo <= rejections <= hi, rejections
    runs = _runs(rng)
    runs[:, 3, 4, 1] += 8 * 0.1 / 4  # 8 standard errors of a 16-seed mean
    r = seed_t_test(runs, ref, alpha=0.01)
    assert not r.passed and r.worst == (3, 4, 1), r.summary()


def test_welch_degrees_of_freedom_and_two_samples():
    """Two-sample t over seeds equals scipy's Welch t-test pixel by pixel."""
    rng = np.random.default_rng(2)
    a, b = _runs(rng, 8, sd=0.1), _runs(rng, 12, sd=0.3)
    r = two_sample_t_test(a, b, rounding=0.0)
    w = stats.ttest_ind(a, b, axis=0, equal_var=False)
    np.testing.assert_allclose(r.t, w.statistic, rtol=1e-9)
    np.testing.assert_allclose(r.p, w.pvalue, rtol=1e-6)
    assert sidak_level(0.01, 1) == pytest.approx(0.01)


def test_floor_and_mask_and_errors():
    rng = np.random.default_rng(3)
    runs = _runs(rng)
    runs[:, 0, 0, 0] = 1.0  # no spread at all: any difference would be infinite t
    ref = np.ones((8, 8, 3))
    ref[0, 0, 0] = 1.1
    assert not seed_t_test(runs, ref).passed
    assert seed_t_test(runs, ref, var_floor=np.full(ref.shape, 0.1)).passed  # floor: 0.1 / 16 per mean
    mask = np.ones((8, 8), bool)
    mask[0, 0] = False
    assert seed_t_test(runs, ref, mask=mask[..., None]).passed
    with pytest.raises(ValueError, match="at least 2"):
        seed_t_test(runs[:1], ref)
    with pytest.raises(ValueError, match="NaN"):
        seed_t_test(runs, ref * np.nan)


def test_filter_masses():
    off, m = filter_masses("box", 0.5)
    assert off.tolist() == [0] and m.tolist() == [1.0]
    off, m = filter_masses("gaussian", 2.0, 0.5)
    assert off.tolist() == [-2, -1, 0, 1, 2] and m.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(m, m[::-1])
    # Mitsuba's gaussian: [-0.5, 0.5] holds about P(|Z| < 1) of it
    assert 0.65 < m[2] < 0.72
    off, m = filter_masses("tent", 1.0)
    np.testing.assert_allclose(m, [0.125, 0.75, 0.125], atol=1e-3)
    with pytest.raises(ValueError):
        filter_masses("mitchell", 2.0)


def test_position_floor_matches_simulated_filter_importance_sampling():
    """An image constant over each pixel with a bright edge: the variance
    of one sample's value when its film position is drawn from the
    gaussian filter about the pixel centre (truncated at the film's
    borders, as render.cpp's filter importance sampling) equals the floor,
    within 4 standard errors of the simulated variance (about 1.2 M
    simulated samples per pixel). The tolerance was a fixed 3 % on 200 000
    samples before: where the bright edge is rare ((3, 2): about 1 sample in
    900) that is half a standard error, and seed offset 4 failed it (0.2305
    against 0.2187). Power: the floor 10 % off is rejected at (3, 3), where
    the edge is common enough (at (3, 2) the standard error is 3.7 %). The
    box filter's floor is 0."""
    img = np.full((6, 7, 3), 0.05)
    img[:, 4:] = 14.0  # a light two pixels away from column 2
    floor = position_sampling_floor(img, "gaussian", 2.0, 0.5, spp=1)
    rng = np.random.default_rng(4)
    x = rng.uniform(-2, 2, 4_000_000)
    keep = rng.uniform(0, 1, x.size) < np.maximum(0, np.exp(-2 * x * x) - np.exp(-8)) / (1 - np.exp(-8))
    u = x[keep]
    m = u.size // 2
    for py, px in ((3, 2), (3, 3), (0, 6), (2, 0)):
        perm = rng.permutation(u.size)
        dx, dy = u[perm[:m]], u[perm[m:2 * m]]
        fx, fy = px + 0.5 + dx, py + 0.5 + dy
        inside = (fx >= 0) & (fx < img.shape[1]) & (fy >= 0) & (fy < img.shape[0])
        v = img[fy[inside].astype(int), fx[inside].astype(int), 0]
        var = v.var()
        # Standard error of a sample variance: sqrt((mu4 - var^2) / n).
        se = np.sqrt(max(np.mean((v - v.mean()) ** 4) - var ** 2, 0.0) / v.size)
        tol = 4 * se + 1e-6
        assert abs(floor[py, px, 0] - var) <= tol, ((py, px), floor[py, px, 0], var, se)
        if (py, px) == (3, 3):
            assert abs(1.1 * floor[py, px, 0] - var) > tol, f"a floor 10 % off went undetected at {(py, px)}"
    assert not np.any(position_sampling_floor(img, "box", 0.5))
