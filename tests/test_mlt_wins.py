"""The study of where Metropolis wins (benchmarks/studies/mlt_wins.py,
benchmarks/mlt_wins.toml): its matrix parses to the jobs it names, and its
crossover time is read from the curves as documented."""
import math

import pytest


def test_mlt_wins_matrix_parses():
    from radiometer.benchmarks import matrix as MX
    from radiometer.benchmarks.studies import mlt_wins

    m = MX.load(str(mlt_wins.MATRIX))
    assert {j.scene for j in m.jobs} == {"ajar_door", "keyhole"}
    assert {j.estimator for j in m.jobs} == {"path", "bdpt", "pssmlt", "pssmlt_path", "mmlt"}
    assert len(m.jobs) == 2 * 5 * 2
    j = {j.estimator: j for j in m.jobs if j.scene == "keyhole" and j.seed == 0}
    assert j["pssmlt"].integrator["type"] == "pssmlt" and j["pssmlt"].integrator["bidirectional"] is True
    assert j["pssmlt_path"].integrator["type"] == "pssmlt" and j["pssmlt_path"].integrator["bidirectional"] is False
    assert all(x.integrator["max_depth"] == 10 for x in j.values() if "max_depth" in x.integrator)
    assert all(x.budget == {"seconds": 32.0} and x.threads == 1 for x in m.jobs)
    long = MX.load(str(mlt_wins.LONG))
    assert {(j.scene, j.estimator) for j in long.jobs} == {("keyhole", "bdpt"), ("keyhole", "mmlt")}
    assert len(long.jobs) == 2 * 2 and all(x.budget == {"seconds": 128.0} for x in long.jobs)


def _curve(c, start, end, spp0=1):
    """relMSE = c / t at power-of-two spp from `start` to `end` seconds."""
    out, t, spp = [], start, spp0
    while t <= end * (1 + 1e-9):
        out.append((spp, t, c / t))
        t, spp = 2 * t, 2 * spp
    return out


@pytest.mark.parametrize("c_mlt, start, expect", [
    # both fall as 1 / t: below everywhere (from the common span's start), or never
    (0.5, 0.5, 0.5), (2.0, 0.5, None),
])
def test_overtakes_on_parallel_curves(c_mlt, start, expect):
    from radiometer.benchmarks.studies.mlt_wins import overtakes

    bdpt = [_curve(1.0, 0.5, 32.0), _curve(1.1, 0.5, 32.0)]
    mlt = [_curve(c_mlt, start, 32.0), _curve(c_mlt * 1.1, start, 32.0)]
    t, span = overtakes(mlt, bdpt)
    assert span == pytest.approx((0.5, 32.0))
    assert t == (None if expect is None else pytest.approx(expect))


def test_overtakes_finds_a_crossing():
    """Metropolis with a start-up cost: relMSE 4 / t^2 (falls faster) against
    bdpt's 1 / t; they cross at t = 4, and the grid time returned is the
    first grid point past it."""
    from radiometer.benchmarks.studies.mlt_wins import overtakes, relmse_at

    bdpt = [[(2 ** k, 0.5 * 2 ** k, 1 / (0.5 * 2 ** k)) for k in range(7)]]
    mlt = [[(2 ** k, 0.5 * 2 ** k, 4 / (0.5 * 2 ** k) ** 2) for k in range(7)]]
    t, _ = overtakes(mlt, bdpt, n=257)
    grid_step = math.log(64) / 256
    assert 4.0 <= t <= 4.0 * math.exp(grid_step) * (1 + 1e-9)
    assert relmse_at(mlt, 8.0) == pytest.approx(4 / 64) and relmse_at(bdpt, 8.0) == pytest.approx(1 / 8)
    # a curve that ends before t is not averaged in
    assert relmse_at(mlt + [[(1, 0.5, 1.0), (2, 1.0, 0.5)]], 8.0) is None
