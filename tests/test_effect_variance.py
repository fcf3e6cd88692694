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
    return rm.load_dict(furnace_dict(le=1.0, rho=0.6, max_depth=4, res=8))


def test_image_bytes_do_not_change(furnace):
    a = rm.render(furnace, spp=8, seed=3)
    b = rm.render(furnace, spp=8, seed=3, effect_variance=True)
    assert a.effect_variance is None and b.effect_variance is not None
    for x, y in [(a.image, b.image), (a.variance, b.variance)] + [(a.effects[e], b.effects[e]) for e in rm.EFFECTS]:
        assert x.tobytes() == y.tobytes()


def test_one_effect_has_the_variance_of_the_total(furnace):
    """max_depth 2 in the furnace: emission and direct light only; with
    effects=["direct"] every sample is direct light, so its variance is the
    total's, to the bit."""
    res = rm.render(furnace, spp=8, seed=1, effects=["direct"], effect_variance=True)
    assert np.array_equal(res.effect_variance["direct"], res.variance)
    assert not np.any(res.effect_variance["indirect"])


def test_effect_variance_matches_spread_over_seeds(furnace):
    """Each effect's reported variance equals its estimate's variance across
    16 seeds (mean ratio ~ 1 over 192 pixel-channels of ~15 dof each: its
    relative spread is about 0.03, so 0.85..1.15 is over 4 sigma; fixed
    seeds). Power: a variance off by the spp factor (the variance of one
    sample, not of the mean) is 16x and fails."""
    runs = [rm.render(furnace, spp=16, seed=s, effect_variance=True) for s in range(16)]
    for eff in ("direct", "indirect"):
        spread = np.stack([r.effects[eff] for r in runs]).var(axis=0, ddof=1)
        reported = np.mean([r.effect_variance[eff] for r in runs], axis=0)
        ratio = spread.mean() / reported.mean()
        assert 0.85 < ratio < 1.15, (eff, ratio)
        assert not 0.85 < spread.mean() / (16 * reported.mean()) < 1.15


def test_light_tracing_keeps_no_effect_variance_and_bad_flag_is_refused(furnace):
    assert rm.render(furnace, integrator="ptracer", spp=2, seed=0, effect_variance=True).effect_variance is None
    with pytest.raises(ValueError, match="effect_variance"):
        rm.render(furnace, spp=2, effect_variance="yes")
