"""Per-effect variances (render(effect_variance=True)): the film's sums of
each effect's squares give each effect's variance of the estimate, the
noise term per effect of the error budget. The image is the same with and
without them."""
import numpy as np
import pytest

import radiometer as rm
from conftest import furnace_dict


@pytest.fixture(scope="module")
def furnace():
    # Unbounded depth: Russian roulette makes the indirect light noisy (direct
    # light and emission are exact here: every direction sees the same).
    return rm.load_dict(furnace_dict(le=1.0, rho=0.6, max_depth=-1, res=8))


def test_image_bytes_do_not_change(furnace):
    a = rm.render(furnace, spp=8, seed=3)
    b = rm.render(furnace, spp=8, seed=3, effect_variance=True)
    assert a.effect_variance is None and b.effect_variance is not None
    for x, y in [(a.image, b.image), (a.variance, b.variance)] + [(a.effects[e], b.effects[e]) for e in rm.EFFECTS]:
        assert x.tobytes() == y.tobytes()


def test_one_effect_has_the_variance_of_the_total(furnace):
    """With effects=["indirect"] every sample is indirect light, so its
    variance is the total's, to the bit."""
    res = rm.render(furnace, spp=8, seed=1, effects=["indirect"], effect_variance=True)
    assert res.variance.mean() > 1e-3
    assert np.array_equal(res.effect_variance["indirect"], res.variance)
    assert not np.any(res.effect_variance["direct"])


def test_effect_variance_matches_spread_over_seeds(furnace):
    """Each effect's reported variance equals its estimate's variance across
    16 seeds (mean ratio ~ 1 over 192 pixel-channels of ~15 dof each: its
    relative spread is about 0.03, so 0.85..1.15 is over 4 sigma; fixed
    seeds). Power: a variance off by the spp factor (the variance of one
    sample, not of the mean) is 16x and fails."""
    runs = [rm.render(furnace, spp=16, seed=s, effect_variance=True) for s in range(16)]
    for eff in ("indirect",):
        spread = np.stack([r.effects[eff] for r in runs]).var(axis=0, ddof=1)
        reported = np.mean([r.effect_variance[eff] for r in runs], axis=0)
        ratio = spread.mean() / reported.mean()
        assert 0.85 < ratio < 1.15, (eff, ratio)
        assert not 0.85 < spread.mean() / (16 * reported.mean()) < 1.15
    # The exact effects report (almost) none: direct light is the same in every direction.
    assert np.mean([r.effect_variance["direct"].mean() for r in runs]) < 1e-9 < reported.mean()


def test_light_tracing_keeps_no_effect_variance_and_bad_flag_is_refused(furnace):
    assert rm.render(furnace, integrator="ptracer", spp=2, seed=0, effect_variance=True).effect_variance is None
    with pytest.raises(ValueError, match="effect_variance"):
        rm.render(furnace, spp=2, effect_variance="yes")


def test_error_budget_noise_is_the_spread_of_the_image_mean(furnace, tmp_path):
    """res.error_budget's standard error of the image mean (whole image and
    per effect) equals the spread of that mean over 24 seeds (the ratio of
    the spread's square to the mean reported square: ~23 dof, relative sd
    about 0.3, so 0.4..2.0 is a loose band at fixed seeds). Power: the SE
    of one pixel's mean instead (sqrt(N) = 8 times the image's) fails."""
    runs = [rm.render(furnace, spp=16, seed=100 + s, effect_variance=True) for s in range(24)]
    means = np.array([r.image.reshape(-1, 3).mean(axis=0) for r in runs])
    se = np.array([r.error_budget["noise"]["image_mean_se"] for r in runs])
    ratio = means.var(axis=0, ddof=1).mean() / (se ** 2).mean()
    assert 0.4 < ratio < 2.0, ratio
    assert not 0.4 < means.var(axis=0, ddof=1).mean() / (64 * se ** 2).mean() < 2.0
    ind = np.array([r.effects["indirect"].reshape(-1, 3).mean(axis=0) for r in runs])
    se_ind = np.array([r.error_budget["noise"]["effects_mean_se"]["indirect"] for r in runs])
    assert 0.4 < ind.var(axis=0, ddof=1).mean() / (se_ind ** 2).mean() < 2.0
    # One sample per pixel: no variance, no standard error (not a fake 0).
    assert rm.render(furnace, spp=1, seed=0).error_budget["noise"]["image_mean_se"] is None
    # The EXR carries it.
    import json

    p = tmp_path / "r.exr"
    runs[0].write_exr(p)
    meta = rm.read_exr(p).metadata
    assert json.loads(meta["error_budget"])["noise"]["image_mean_se"] == pytest.approx(
        runs[0].error_budget["noise"]["image_mean_se"])


def test_rounding_term_bounds_what_the_exact_furnace_shows():
    """res.error_budget's rounding term: the accumulation and storage bounds,
    and the furnace whose every sample is exact in real arithmetic (le 0.5,
    rho 0.5, max_depth 3: 0.875, no Russian roulette before depth 5) lands
    within one float32 ulp of 0.875 in every pixel, under every seed. The
    check can fail: before the emitter-hit MIS weight took both densities
    from the shading point (transport/scatter_origin.h), one grazing sample
    in about 10^5 left its pixel 1,700 ulps low (0.8748992)."""
    from conftest import furnace_dict, furnace_exact

    scene = rm.load_dict(furnace_dict(le=0.5, rho=0.5, max_depth=3))
    exact = furnace_exact(0.5, 0.5, 3)
    ulp = float(np.spacing(np.float32(exact)))
    for seed in range(4):
        res = rm.render(scene, spp=128, seed=seed)
        term = res.error_budget["rounding"]
        assert term["accumulation_rel_bound"] == pytest.approx(127 * 2.0 ** -53)
        assert term["storage_rel_bound"] == 2.0 ** -24
        dev = float(np.abs(res.image.astype(np.float64) - exact).max())
        assert dev <= ulp, (seed, dev / ulp)
        # The power of the check: one pixel two ulps lower is seen.
        bad = res.image.copy()
        bad[0, 0] = np.nextafter(np.nextafter(bad[0, 0], np.float32(0)), np.float32(0))
        assert float(np.abs(bad.astype(np.float64) - exact).max()) > ulp
    assert "rounding" in res.error_budget["how"]


def test_truncation_term_is_the_light_max_depth_cuts_off():
    """res.error_budget's truncation term on the closed furnace, where the
    light max_depth D cuts off is exact: le rho^D / (1 - rho) everywhere.
    Every path continued (truncation_probe 1), 16 seeds: the mean of their
    estimates passes a two-sided t-test (15 dof) at ALPHA = 0.01 (the
    channels are equal: one test), and 3 % more (or less) missing light is
    rejected. A t-test over seeds, not a z-test with each render's own
    standard error: past the roulette depth the tail is heavy (Mitsuba's
    rule keeps 3 % of the paths at depth 5, weighted 32), so one render's
    variance estimate is itself noisy; it must still agree with the spread
    over seeds within a factor of 2. With the default probe (1/16) the
    image keeps its bytes, and an unbounded render says nothing is missing."""
    from scipy import stats as st

    from conftest import furnace_dict

    alpha = 0.01
    le, rho, depth = 0.5, 0.5, 3
    exact = le * rho ** depth / (1.0 - rho)
    scene = rm.load_dict(furnace_dict(le=le, rho=rho, max_depth=depth))
    integ = {"type": "path", "max_depth": depth, "truncation_probe": 1.0}
    terms = [rm.render(scene, integrator=integ, spp=32, seed=s).error_budget["truncation"] for s in range(16)]
    m = np.array([np.mean(t["missing_mean"]) for t in terms])
    own_se = np.array([np.mean(t["missing_se"]) for t in terms])
    assert all(t["probes"] > 0 and not t["exact"] for t in terms)
    assert st.ttest_1samp(m, exact).pvalue > alpha, (m.mean(), exact)
    for wrong in (1.03 * exact, 0.97 * exact):
        assert st.ttest_1samp(m, wrong).pvalue < alpha, (m.mean(), wrong)
    assert 0.5 < np.median(own_se) / m.std(ddof=1) < 2.0, (np.median(own_se), m.std(ddof=1))
    res = rm.render(scene, integrator=integ, spp=4, seed=1)
    term = res.error_budget["truncation"]
    assert np.mean(term["relative"]) == pytest.approx(np.mean(term["missing_mean"]) / float(res.image.mean()),
                                                      rel=1e-6)

    plain = rm.render(scene, integrator={"type": "path", "max_depth": depth, "truncation_probe": 0.0}, spp=8, seed=4)
    probed = rm.render(scene, integrator={"type": "path", "max_depth": depth}, spp=8, seed=4)
    assert plain.image.tobytes() == probed.image.tobytes()
    assert plain.error_budget["truncation"] is None
    assert probed.error_budget["truncation"]["probes"] > 0
    unbounded = rm.render(scene, integrator={"type": "path", "max_depth": -1}, spp=2, seed=4)
    assert unbounded.error_budget["truncation"]["exact"] and unbounded.error_budget["truncation"]["missing_mean"] == [
        0.0, 0.0, 0.0]
    # estimators without a probe say so
    assert rm.render(scene, integrator="direct", spp=2, seed=4).error_budget["truncation"] is None
