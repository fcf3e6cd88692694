"""`radiometer compare` on synthetic stores: changes inside run-to-run noise
pass, changes beyond it fail the command (exit 1), as asv does for timings."""
import numpy as np
import pytest

from radiometer.benchmarks import compare as C
from radiometer.benchmarks.store import Store
from radiometer.cli import main


def _record(scene, est, seed, relmse, seconds, spp=100, status="ok"):
    return {"key": f"{scene}-{est}-{seed}", "config_key": f"{scene}-{est}", "scene": scene, "estimator": est,
            "integrator": {"type": est}, "scene_params": {}, "budget": {"seconds": 1.0}, "seed": seed,
            "status": status, "error": None if status == "ok" else "boom", "spp": spp, "seconds": seconds,
            "metrics": {"relmse": relmse} if status == "ok" else {}, "effect_metrics": {}, "curve": []}


def _store(path, rows, run="r1"):
    with Store(path) as st:
        st.add_run(run, "synthetic", "-", "", "abc", {"host": "h"}, "2026-01-01T00:00:00+00:00")
        for r in rows:
            st.add_job(run, r)
    return path


def _rows(scene, est, errs, secs, **kw):
    return [_record(scene, est, i, e, s, **kw) for i, (e, s) in enumerate(zip(errs, secs))]


RNG = np.random.default_rng(7)
BASE_ERR = list(0.01 * np.exp(0.05 * RNG.standard_normal(5)))
BASE_SEC = list(1.0 + 0.01 * RNG.standard_normal(5))


def test_noise_only_is_not_flagged(tmp_path, capsys):
    a = _store(tmp_path / "a.sqlite", _rows("cornell_box", "path", BASE_ERR, BASE_SEC))
    other_err = list(0.01 * np.exp(0.05 * RNG.standard_normal(5)))
    b = _store(tmp_path / "b.sqlite", _rows("cornell_box", "path", other_err, BASE_SEC))
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "REGRESSION" not in out and "same" in out


def test_error_regression_beyond_noise_fails(tmp_path, capsys):
    a = _store(tmp_path / "a.sqlite", _rows("cornell_box", "path", BASE_ERR, BASE_SEC))
    b = _store(tmp_path / "b.sqlite", _rows("cornell_box", "path", [e * 1.5 for e in BASE_ERR], BASE_SEC))
    assert main(["compare", str(a), str(b)]) == 1
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "error (relmse)" in ln)
    assert "REGRESSION" in line and "1.500" in line
    # The other way round it is an improvement, and the command passes.
    assert main(["compare", str(b), str(a)]) == 0
    assert "improved" in capsys.readouterr().out


def test_time_regression_is_seconds_per_sample(tmp_path):
    a = _store(tmp_path / "a.sqlite", _rows("veach_mis", "bdpt", BASE_ERR, BASE_SEC))
    # Same error, same seconds, but 30 % fewer samples in them: slower.
    b = _store(tmp_path / "b.sqlite", _rows("veach_mis", "bdpt", BASE_ERR, BASE_SEC, spp=70))
    changes = C.compare_records(Store(a).jobs("r1"), Store(b).jobs("r1"))
    verdict = {c.quantity: c.verdict for c in changes}
    assert verdict == {"error (relmse)": "same", "time (s/spp)": "regression"}


def test_large_change_inside_wide_noise_is_not_flagged(tmp_path):
    """Intervals that overlap decide 'same' even though the means differ by 30 %."""
    noisy = [0.01, 0.03, 0.005, 0.02, 0.012]
    a = _store(tmp_path / "a.sqlite", _rows("glass_sphere_caustic", "path", noisy, BASE_SEC))
    b = _store(tmp_path / "b.sqlite", _rows("glass_sphere_caustic", "path", [x * 1.3 for x in noisy], BASE_SEC))
    assert main(["compare", str(a), str(b)]) == 0


def test_small_change_below_factor_is_not_flagged():
    """Tight intervals that do not overlap, but a 3 % change: below factor 1.1."""
    a = (1.0, 0.999, 1.001, 5)
    b = (1.03, 1.029, 1.031, 5)
    assert C.judge(a, b, 1.1)[1] == "same"
    assert C.judge(a, b, 1.02)[1] == "regression"


def test_single_seed_is_not_judged(tmp_path, capsys):
    a = _store(tmp_path / "a.sqlite", _rows("furnace", "path", [0.01], [1.0]))
    b = _store(tmp_path / "b.sqlite", _rows("furnace", "path", [0.05], [1.0]))
    assert main(["compare", str(a), str(b)]) == 0
    assert "n<2" in capsys.readouterr().out


def test_job_that_now_fails_is_a_regression(tmp_path, capsys):
    a = _store(tmp_path / "a.sqlite", _rows("ajar_door", "ptracer", BASE_ERR, BASE_SEC))
    b = _store(tmp_path / "b.sqlite", _rows("ajar_door", "ptracer", BASE_ERR, BASE_SEC, status="failed"))
    assert main(["compare", str(a), str(b)]) == 1
    assert "status" in capsys.readouterr().out


def test_runs_in_one_store_and_missing_configurations(tmp_path, capsys):
    path = tmp_path / "s.sqlite"
    _store(path, _rows("furnace", "path", BASE_ERR, BASE_SEC), run="base-1")
    with Store(path) as st:
        st.add_run("cand-2", "synthetic", "-", "", "def", {}, "2026-01-02T00:00:00+00:00")
        for r in _rows("furnace", "path", BASE_ERR, BASE_SEC) + _rows("furnace", "bdpt", BASE_ERR, BASE_SEC):
            st.add_job("cand-2", r)
    assert main(["compare", f"{path}:base", f"{path}:cand"]) == 0
    out = capsys.readouterr().out
    assert "only in B" in out
    assert main(["compare", f"{path}:nope", f"{path}:cand"]) == 2
    assert "no run 'nope'" in capsys.readouterr().err


def test_log_ci():
    m, lo, hi, n = C.log_ci([1.0, 1.0, 1.0])
    assert (m, lo, hi, n) == pytest.approx((1.0, 1.0, 1.0, 3))
    m, lo, hi, n = C.log_ci([1.0, 2.0, 4.0])
    assert m == pytest.approx(2.0) and lo < m < hi and n == 3
    assert C.log_ci([]) is None
