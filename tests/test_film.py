"""Reconstruction filters, sampled by filter importance sampling: the
sampled pixel offsets follow the filter (Pearson chi-square), also when
restricted to the film near its border."""
import numpy as np
import pytest
from scipy import integrate, stats

from radiometer import _core

ALPHA = 0.01  # significance of each chi-square test


def _chi2_against_filter(kind, radius, stddev, lo, hi, n=200_000, bins=40, seed=0):
    u = np.random.default_rng(seed).random(n, dtype=np.float32)
    x = _core.filter_sample(kind, radius, stddev, u, lo, hi)
    a, b = max(lo, -radius), min(hi, radius)
    assert x.min() >= a - 1e-6 and x.max() <= b + 1e-6
    edges = np.linspace(a, b, bins + 1)

    def f(t):
        return _core.filter_eval(kind, radius, stddev, t)

    mass = np.array([integrate.quad(f, edges[i], edges[i + 1])[0] for i in range(bins)])
    expected = n * mass / mass.sum()
    observed, _ = np.histogram(x, edges)
    keep = expected >= 5  # pool cells under 5 expected into one
    obs = np.append(observed[keep], observed[~keep].sum())
    exp = np.append(expected[keep], expected[~keep].sum())
    if exp[-1] == 0:
        obs, exp = obs[:-1], exp[:-1]
    return stats.chisquare(obs, exp).pvalue


@pytest.mark.parametrize("kind,radius,stddev", [("box", 0.5, 0.5), ("tent", 1.0, 0.5), ("gaussian", 2.0, 0.5)])
@pytest.mark.parametrize("lo,hi", [(-1e30, 1e30), (-0.5, 1e30), (-1.3, 0.7)])
def test_filter_sampling_follows_filter(kind, radius, stddev, lo, hi):
    assert _chi2_against_filter(kind, radius, stddev, lo, hi) > ALPHA


def test_chi_square_can_fail():
    """A tent sampled where a box was expected is rejected."""
    u = np.random.default_rng(1).random(100_000, dtype=np.float32)
    x = _core.filter_sample("tent", 1.0, 0.5, u, -0.5, 0.5)
    observed, _ = np.histogram(x, np.linspace(-0.5, 0.5, 21))
    assert stats.chisquare(observed).pvalue < 1e-6


def test_filters_match_mitsuba_shapes():
    # Mitsuba 3's gaussian reaches exactly 0 at its radius (4 stddev) and is
    # shifted down by exp(-8) everywhere.

    def g(x):
        return _core.filter_eval("gaussian", 2.0, 0.5, x)

    assert g(2.0) == 0.0 and g(0.0) == pytest.approx(1 - np.exp(-8), rel=1e-6)
    assert _core.filter_eval("tent", 1.0, 0.5, 0.25) == pytest.approx(0.75)
    with pytest.raises(ValueError, match="unknown type"):
        _core.filter_sample("lanczos", 1.0, 0.5, np.zeros(1, np.float32))
