"""The render driver and the `path` and `direct` estimators, through the
bindings: analytic furnace, truncation, determinism, budgets, checkpoints,
progress, cancellation, effects, stability counters."""
import threading

import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.stats import z_test

from conftest import furnace_dict, furnace_exact

ALPHA = 0.01  # significance level of every statistical test in this file


@pytest.mark.parametrize("integrator", ["path", "direct"])
@pytest.mark.parametrize("rho", [0.3, 0.8])
def test_furnace_max_depth_2_matches_analytic(integrator, rho):
    le = 0.5
    scene = rm.load_dict(furnace_dict(le=le, rho=rho, max_depth=2))
    res = rm.render(scene, integrator={"type": integrator} if integrator == "direct" else None, spp=64, seed=1)
    exact = np.full_like(res.image, furnace_exact(le, rho, 2))
    t = z_test(res.image, res.variance, exact, None, alpha=ALPHA)
    assert t.passed, t.summary()
    # The test can fail: 1 % too much light is rejected.
    assert not z_test(res.image * 1.01, res.variance, exact, None, alpha=ALPHA).passed


@pytest.mark.parametrize("max_depth,rho", [(3, 0.5), (5, 0.7), (-1, 0.5)])
def test_path_furnace_truncation(max_depth, rho):
    """L = Le sum_{k<max_depth} rho^k: the truncation bias of max_depth is
    exactly what the analytic series says (and absent when unbounded)."""
    le = 0.5
    scene = rm.load_dict(furnace_dict(le=le, rho=rho, max_depth=max_depth))
    res = rm.render(scene, spp=128, seed=2)
    exact = furnace_exact(le, rho, max_depth)
    # Every pixel of the furnace estimates the same integral with the same
    # variance, so the variance is pooled over the image: with Russian
    # roulette most paths of a pixel can end at the same depth, and then that
    # pixel's own sample variance (from 128 samples) is near zero although
    # the estimator's is not.
    pooled = np.full_like(res.variance, res.variance.mean())
    t = z_test(res.image, pooled, np.full_like(res.image, exact), None, alpha=ALPHA)
    assert t.passed, t.summary()
    if max_depth > 0:  # the next term of the series is visible: one more bounce is rejected
        longer = furnace_exact(le, rho, max_depth + 1)
        assert not z_test(res.image, pooled, np.full_like(res.image, longer), None, alpha=ALPHA).passed


def test_direct_equals_path_at_max_depth_2(small_cornell):
    a = rm.render(small_cornell, integrator={"type": "path", "max_depth": 2}, spp=64, seed=3)
    b = rm.render(small_cornell, integrator="direct", spp=64, seed=4)
    t = z_test(a.image, a.variance, b.image, b.variance, alpha=ALPHA)
    assert t.passed, t.summary()
    c = rm.render(small_cornell, integrator={"type": "path", "max_depth": 3}, spp=64, seed=5)
    assert not z_test(c.image, c.variance, b.image, b.variance, alpha=ALPHA).passed


@pytest.mark.parametrize("integrator", ["path", "direct"])
def test_same_seed_same_bytes_whatever_threads(small_cornell, integrator):
    a = rm.render(small_cornell, integrator=integrator, spp=8, seed=7, threads=1)
    b = rm.render(small_cornell, integrator=integrator, spp=8, seed=7, threads=2)
    c = rm.render(small_cornell, integrator=integrator, spp=8, seed=7, threads=3)
    assert a.image.tobytes() == b.image.tobytes() == c.image.tobytes()
    assert a.variance.tobytes() == b.variance.tobytes()
    for k in rm.EFFECTS:
        assert a.effects[k].tobytes() == b.effects[k].tobytes()
    d = rm.render(small_cornell, integrator=integrator, spp=8, seed=8, threads=2)
    assert d.image.tobytes() != a.image.tobytes()


def test_effects_sum_to_image_and_are_plausible(small_cornell):
    res = rm.render(small_cornell, spp=16, seed=0)
    total = sum(res.effects[k].astype(np.float64) for k in rm.EFFECTS)
    np.testing.assert_allclose(total, res.image, rtol=1e-5, atol=1e-6)
    # The Cornell box has no specular surface and no media: those classes stay empty...
    for k in ("caustic", "specular", "volume", "subsurface"):
        assert not res.effects[k].any(), k
    # ...and the rest are not.
    for k in ("emission", "direct", "indirect"):
        assert res.effects[k].sum() > 0, k
    assert res.stats["features"]["has_delta_bsdf"] is False


def test_effects_subset_simulates_only_those(small_cornell):
    full = rm.render(small_cornell, spp=32, seed=0)
    only = rm.render(small_cornell, spp=32, seed=1, effects=["direct"])
    for k in rm.EFFECTS:
        if k != "direct":
            assert not only.effects[k].any(), k
    np.testing.assert_array_equal(only.image, only.effects["direct"])
    # Direct alone needs no second bounce: at most the camera ray and one
    # BSDF ray per path, where the full render traces longer paths.
    assert only.stats["rays"] <= 2 * only.stats["paths"] < full.stats["rays"]
    t = z_test(only.image, only.variance, full.effects["direct"], full.variance, alpha=ALPHA)
    assert t.passed, t.summary()
    with pytest.raises(ValueError, match="causti"):
        rm.render(small_cornell, spp=1, effects=["caustics"])


def test_variance_estimate_matches_spread_over_seeds():
    """The per-pixel variance a render reports equals the variance of its
    estimate across independent seeds (ratio ~ 1, F-test style tolerance
    from 16 seeds: each pixel's ratio has ~15 dof; we test the mean ratio).
    The furnace is unbounded, so Russian roulette makes every sample noisy
    (with a max_depth below the roulette depth every sample is exact, and
    both variances are rounding)."""
    scene = rm.load_dict(furnace_dict(le=1.0, rho=0.6, max_depth=-1, res=8))
    runs = [rm.render(scene, spp=16, seed=s) for s in range(16)]
    imgs = np.stack([r.image for r in runs])
    spread = imgs.var(axis=0, ddof=1)
    reported = np.mean([r.variance for r in runs], axis=0)
    assert reported.mean() > 1e-3  # a noisy estimate, not an exact one
    # The furnace is grey: 64 pixels, each ratio with 15 dof, so the mean
    # ratio's sd is about sqrt(2 / 15 / 64) = 0.046 and +-0.15 is 3.3 sd.
    ratio = spread.mean() / reported.mean()
    assert 0.85 < ratio < 1.15, ratio
    # Power: a variance reported 30 % too large (or small) is rejected.
    assert not 0.85 < spread.mean() / (1.3 * reported.mean()) < 1.15
    assert not 0.85 < spread.mean() / (0.7 * reported.mean()) < 1.15


def test_checkpoints_and_progress(small_cornell):
    calls = []
    res = rm.render(small_cornell, spp=16, seed=0, checkpoints=[1, 4, 16], progress=lambda d, t: calls.append((d, t)))
    assert [c[0] for c in res.checkpoints] == [1, 4, 16]
    secs = [c[1] for c in res.checkpoints]
    assert secs == sorted(secs)
    np.testing.assert_array_equal(res.checkpoints[-1][2], res.image)
    # One sample has no variance estimate (NaN, not a fake 0); fewer samples, more variance.
    assert np.isnan(res.checkpoints[0][3]).all()
    assert res.checkpoints[1][3].mean() > res.checkpoints[2][3].mean()
    assert calls and calls[-1][0] == calls[-1][1] == 16 * small_cornell.width * small_cornell.height
    assert all(b[0] >= a[0] for a, b in zip(calls, calls[1:]))


def test_seconds_budget_is_wall_clock(small_cornell):
    res = rm.render(small_cornell, seconds=0.5, seed=0)
    assert res.spp >= 1
    assert res.seconds < 2.0  # a budget, not a wish (generous: 4x)
    capped = rm.render(small_cornell, seconds=30, spp=4, seed=0)
    assert capped.spp == 4


def test_progress_exception_propagates_and_cancels(small_cornell):
    def boom(done, total):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        rm.render(small_cornell, spp=4096, progress=boom)


def test_keyboard_interrupt_keeps_finished_passes(small_cornell):
    """Ctrl-C (a SIGINT to the main thread) cancels cleanly; the finished
    passes come back on the exception."""
    import _thread
    import signal
    import time

    # A shell starts background jobs with SIGINT ignored, and Python then
    # installs no handler (interrupt_main would do nothing): give the main
    # thread Python's own for the test.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(1.0, _thread.interrupt_main)
    try:
        timer.start()
        t0 = time.monotonic()
        with pytest.raises(rm.RenderCancelled) as info:
            rm.render(small_cornell, spp=1 << 20, seed=0)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - t0 < 10
    r = info.value.result
    assert 0 < r.spp < 1 << 20
    assert np.isfinite(r.image).all() and r.image.mean() > 0


def test_gil_released_during_render(small_cornell):
    """Another Python thread keeps running while a render is in progress."""
    ticks = []
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            ticks.append(1)
            stop.wait(0.01)

    t = threading.Thread(target=spin)
    t.start()
    rm.render(small_cornell, spp=256, threads=1)
    stop.set()
    t.join()
    assert len(ticks) > 5


def test_no_nan_and_counters_present(small_cornell):
    res = rm.render(small_cornell, spp=4)
    assert np.isfinite(res.image).all() and np.isfinite(res.variance).all()
    assert (res.image >= 0).all()
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0
    assert res.stats["paths"] == 4 * small_cornell.width * small_cornell.height


@pytest.mark.parametrize("kwargs,match", [
    ({"spp": -1}, "spp"),
    ({"spp": 1.5}, "spp"),
    ({"seconds": -2}, "seconds"),
    ({"seconds": float("nan")}, "seconds"),
    ({"seed": -1}, "seed"),
    ({"threads": -3}, "threads"),
    ({"checkpoints": [0]}, "checkpoints"),
    ({"effects": []}, "effects"),
])
def test_bad_render_arguments(small_cornell, kwargs, match):
    with pytest.raises(ValueError, match=match):
        rm.render(small_cornell, **kwargs)


@pytest.mark.parametrize("integrator,match", [
    ("nosuch", "unknown estimator 'nosuch'"),
    ({"type": "path", "max_depth": 0}, "max_depth"),
    ({"type": "path", "maxdepth": 3}, "unknown parameter"),
    ({"type": "path", "max_depth": "3"}, "max_depth"),
    ({"type": "direct", "emitter_samples": 0, "bsdf_samples": 0}, "not both 0"),
    ({"max_depth": 3}, "type"),
])
def test_bad_integrators(small_cornell, integrator, match):
    with pytest.raises(rm.SceneError, match=match):
        rm.render(small_cornell, integrator=integrator, spp=1)


def test_render_rejects_non_scene():
    with pytest.raises(TypeError, match="Scene"):
        rm.render({"type": "scene"}, spp=1)


@pytest.mark.parametrize("integrator,max_depth", [("direct", 2), ("path", 2), ("path", 5)])
def test_closed_cube_furnace_is_unbiased_to_1e4(integrator, max_depth):
    """A closed mesh cube (emission Le, albedo rho inside, camera off-centre)
    has L = Le sum_{k<max_depth} rho^k everywhere. Edges and corners are
    where careless shadow rays and ray offsets lose light: the bias found
    here once (-3e-4 relative, a shadow ray falsely occluded by the light's
    own face at grazing angles) must stay gone. The image mean of k = 8
    independent renders is compared with the analytic value by a two-sided
    t-test (k - 1 dof) at level 0.01, with the spread measured across seeds.
    k = 16: with 8 the 3e-4 power check below missed under fresh noise
    (seed offset 1: t 2.82 against the 7-dof critical 3.50)."""
    le, rho = 0.5, 0.8
    d = {"type": "scene", "integrator": {"type": integrator} if integrator == "direct" else
         {"type": "path", "max_depth": max_depth},
         "box": {"type": "cube", "flip_normals": True,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [rho] * 3}},
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [le] * 3}}},
         "sensor": {"type": "perspective", "fov": 70,
                    "to_world": np.array([[1, 0, 0, 0.3], [0, 1, 0, 0.1], [0, 0, 1, -0.2], [0, 0, 0, 1.0]]),
                    "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}}}}
    scene = rm.load_dict(d)
    means = np.array([rm.render(scene, spp=512, seed=100 + s).image[..., 0].mean(dtype=np.float64)
                      for s in range(16)])
    exact = furnace_exact(le, rho, max_depth)
    from scipy import stats

    t = (means.mean() - exact) / (means.std(ddof=1) / np.sqrt(len(means)))
    p = 2 * stats.t.sf(abs(t), len(means) - 1)
    assert p > 0.01, (f"mean {means.mean():.7f} vs exact {exact:.7f} (relative {means.mean() / exact - 1:+.2e}), "
                      f"t {t:.2f}")
    # The resolution it has: a 3e-4 relative error would be seen.
    t_biased = (means.mean() - exact * (1 - 3e-4)) / (means.std(ddof=1) / np.sqrt(len(means)))
    assert 2 * stats.t.sf(abs(t_biased), len(means) - 1) < 0.01


def test_absurd_resolution_is_a_clear_error(cornell_path):
    scene = rm.load_file(cornell_path, res=16384)
    with pytest.raises(ValueError, match="16384x16384 film needs .* GiB"):
        rm.render(scene, spp=1)
    with pytest.raises(rm.SceneError, match="width"):
        rm.load_file(cornell_path, res=100000)


def test_bias_and_variance_over_seeds():
    """analysis.stats.bias_variance: k renders with independent seeds give the
    variance of one render (matching what each render reports) and the bias
    of their mean against the exact answer (zero within its standard error;
    a 1 % bias injected into the renders is found)."""
    from radiometer.analysis.stats import bias_variance

    scene = rm.load_dict(furnace_dict(le=1.0, rho=0.6, max_depth=4, res=8))
    runs = [rm.render(scene, integrator={"type": "path", "max_depth": 4, "rr_depth": 1}, spp=32, seed=s)
            for s in range(12)]
    exact = np.full_like(runs[0].image, furnace_exact(1.0, 0.6, 4))
    bv = bias_variance([r.image for r in runs], exact)
    se = float(np.sqrt((bv["bias_se"] ** 2).sum()) / bv["bias_se"].size)
    assert abs(bv["mean_bias"]) < 4 * se, (bv["mean_bias"], se)
    assert 0.7 < bv["mean_variance"] / np.mean([r.variance.mean() for r in runs]) < 1.4
    biased = bias_variance([r.image * 1.01 for r in runs], exact)
    assert biased["mean_bias"] > 4 * se
    assert biased["mean_bias"] - bv["mean_bias"] == pytest.approx(0.01 * bv["mean"].mean(), rel=1e-4)
