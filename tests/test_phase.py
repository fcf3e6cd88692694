"""Phase functions (isotropic, Henyey-Greenstein) as components: sampled
directions follow the density (Pearson chi-square, analysis/chi2.py), the
density integrates to 1 over the sphere, weight == eval / pdf, the mean
cosine equals g, and extreme g stays finite."""
import numpy as np
import pytest

from radiometer import _core
from radiometer.analysis.chi2 import SphereGrid, chi2_test, sidak_level

CASES = [("isotropic", 0.0), ("hg", -0.9), ("hg", -0.3), ("hg", 0.0005), ("hg", 0.5), ("hg", 0.9)]
WI = [(0.0, 0.0, 1.0), (0.6, 0.0, 0.8), (0.36, -0.48, -0.8)]
LEVEL = sidak_level(0.01, len(CASES) * len(WI))  # overall significance 0.01 over the chi-square tests


@pytest.mark.parametrize("wi", WI)
@pytest.mark.parametrize("kind,g", CASES)
def test_phase_sampling_chi2(kind, g, wi):
    ph = _core.Phase(kind, g)
    wi = np.asarray(wi, np.float32)

    def sample(rng, n):
        s = ph.sample(np.broadcast_to(wi, (n, 3)), rng.random((n, 2), dtype=np.float32))
        return s["wo"]

    def pdf(d):
        d = np.asarray(d, np.float32)
        return ph.eval(np.broadcast_to(wi, d.shape), d)

    r = chi2_test(sample, pdf, n_samples=100_000, grid=SphereGrid(n_theta=20, n_phi=40), seed=11, level=LEVEL,
                  label=f"{kind} g={g}", min_depth=3, max_depth=9, rtol=1e-5, atol=1e-4)
    assert r.passed, r.summary()


@pytest.mark.parametrize("kind,g", CASES + [("hg", 0.99), ("hg", -0.999)])
def test_weight_pdf_mean_cosine_and_stability(kind, g):
    ph = _core.Phase(kind, g)
    rng = np.random.default_rng(2)
    n = 200_000
    wi = np.broadcast_to(np.array([0.0, 0.6, -0.8], np.float32), (n, 3))
    s = ph.sample(wi, rng.random((n, 2), dtype=np.float32))
    assert np.isfinite(s["wo"]).all() and np.isfinite(s["pdf"]).all() and (s["pdf"] > 0).all()
    np.testing.assert_allclose(np.linalg.norm(s["wo"], axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(s["weight"], 1.0)
    np.testing.assert_allclose(ph.eval(wi, s["wo"]), s["pdf"], rtol=2e-3)
    # g is the mean cosine between the propagation direction -wi and wo.
    mu = -(s["wo"] * wi).sum(axis=1)
    assert abs(mu.mean() - g) < 5 * mu.std() / np.sqrt(n) + 1e-4


@pytest.mark.parametrize("g", [-0.9, 0.0, 0.7])
def test_hg_integrates_to_one(g):
    ph = _core.Phase("hg", g)
    # Stratified over the cosine to the z axis (wi = +z) and phi.
    m = 4000
    mu = (np.arange(m) + 0.5) / m * 2 - 1
    wo = np.stack([np.sqrt(1 - mu * mu), np.zeros(m), mu], axis=1).astype(np.float32)
    p = ph.eval(np.broadcast_to(np.array([0, 0, 1], np.float32), (m, 3)), wo)
    assert abs(2 * np.pi * p.mean() * 2 - 1) < 1e-3


def test_wrong_pdf_is_rejected():
    """The test can fail: HG g = 0.5 samples judged against g = 0.45."""
    ph, wrong = _core.Phase("hg", 0.5), _core.Phase("hg", 0.45)
    wi = np.array([0, 0, 1], np.float32)
    r = chi2_test(lambda rng, n: ph.sample(np.broadcast_to(wi, (n, 3)), rng.random((n, 2), dtype=np.float32))["wo"],
                  lambda d: wrong.eval(np.broadcast_to(wi, np.shape(d)), np.asarray(d, np.float32)),
                  n_samples=100_000, grid=SphereGrid(n_theta=20, n_phi=40), seed=1, level=0.01)
    assert not r.passed


@pytest.mark.parametrize("kind,g,match", [("hg", 1.0, "'g'"), ("hg", -1.5, "'g'"), ("rayleigh", 0.0, "unknown type")])
def test_bad_phase_parameters(kind, g, match):
    with pytest.raises(ValueError, match=match):
        _core.Phase(kind, g)
