"""analysis/metrics.py on inputs with known answers."""
import math

import numpy as np
import pytest

from radiometer.analysis import metrics as M


def _ref(seed=0, shape=(16, 16, 3)):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.05, 2.0, shape)


def test_relmse_of_a_scaled_image():
    ref = _ref()
    s = 1.1
    expected = np.mean((s - 1) ** 2 * ref ** 2 / (ref ** 2 + 1e-2))
    assert M.relmse(ref * s, ref) == pytest.approx(expected, rel=1e-12)
    assert M.relmse(ref, ref) == 0.0
    # eps keeps a black reference finite: (0.1)^2 / 1e-2 = 1.
    assert M.relmse(np.full((2, 2, 3), 0.1), np.zeros((2, 2, 3))) == pytest.approx(1.0)


def test_mse_and_smape():
    ref = _ref(1)
    assert M.mse(ref + 0.5, ref) == pytest.approx(0.25)
    # a = 2 ref: |a - r| / (|a| + |r|) = 1/3 everywhere.
    assert M.smape(2 * ref, ref) == pytest.approx(1 / 3)
    # both zero: contributes 0, not NaN.
    assert M.smape(np.zeros((2, 2, 3)), np.zeros((2, 2, 3))) == 0.0
    with pytest.raises(ValueError, match="shapes differ"):
        M.mse(np.zeros((2, 2, 3)), np.zeros((3, 2, 3)))


def test_relmse_floor_is_the_reference_noise():
    ref = _ref(2)
    var = np.full_like(ref, 1e-4)
    assert M.relmse_floor(ref, var) == pytest.approx(np.mean(1e-4 / (ref ** 2 + 1e-2)))


def test_flip_zero_for_identical_and_grows_with_noise():
    ref = _ref(3, (32, 32, 3)) * 0.4
    rng = np.random.default_rng(4)
    small = ref * (1 + 0.05 * rng.standard_normal(ref.shape))
    large = ref * (1 + 0.5 * rng.standard_normal(ref.shape))
    assert M.flip(ref, ref) == pytest.approx(0.0, abs=1e-6)
    f_small, f_large = M.flip(np.abs(small), ref), M.flip(np.abs(large), ref)
    assert 0 < f_small < f_large <= 1


def test_ciede2000_known_pair_and_images():
    # Sharma, Wu and Dalal (2005), table 1, pair 1: dE00 = 2.0425.
    d = M.delta_e2000([50.0, 2.6772, -79.7751], [50.0, 0.0, -82.7485])
    assert float(d) == pytest.approx(2.0425, abs=1e-4)
    ref = _ref(5) * 0.3
    assert M.ciede2000(ref, ref) == pytest.approx(0.0, abs=1e-9)
    tinted = ref * np.array([1.0, 0.7, 0.7])
    assert M.ciede2000(tinted, ref) > 1.0


def test_all_metrics_names_every_metric():
    ref = _ref(6)
    m = M.all_metrics(ref * 1.2, ref, ref_var=np.zeros_like(ref))
    assert set(m) == set(M.METRICS) | {"relmse_floor"}
    assert all(v >= 0 for v in m.values())
    with pytest.raises(ValueError, match="unknown metric"):
        M.metric("psnr")


def test_loglog_slope_of_monte_carlo_rate():
    t = np.array([0.1, 0.2, 0.4, 0.8, 1.6])
    assert M.loglog_slope(t, 3.0 / t) == pytest.approx(-1.0)
    assert M.loglog_slope(t, 3.0 / np.sqrt(t)) == pytest.approx(-0.5)
    assert M.loglog_slope([1, 2], [1, 0.5]) is None  # too few points


def test_time_to_error_interpolates_in_log_log():
    curve = [(1, 1.0, 1.0), (2, 2.0, 0.5), (4, 4.0, 0.25)]  # error = 1 / t
    assert M.time_to_error(curve, 0.35) == pytest.approx(1 / 0.35)
    assert M.time_to_error(curve, 2.0) == 1.0  # already there at the first checkpoint
    assert M.time_to_error(curve, 0.1) is None  # never reached


def test_efficiency_and_error_curve():
    assert M.efficiency(0.5, 4.0) == pytest.approx(0.5)
    assert M.efficiency(0.0, 4.0) is None
    ref = _ref(7)
    cps = [(4, 0.4, ref * 1.1, None), (1, 0.1, ref * 1.4, None), (2, 0.0, ref, None)]
    curve = M.error_curve(cps, ref)
    assert [c[0] for c in curve] == [1, 4]  # sorted, the zero-time point dropped
    assert curve[0][2] > curve[1][2]


def test_display_exposure_maps_percentile_to_one():
    ref = np.full((4, 4, 3), 4.0)
    assert M.display_exposure(ref) == pytest.approx(-2.0)
    assert M.display_exposure(np.zeros((4, 4, 3))) == 0.0
    assert math.isfinite(M.display_exposure(ref))
