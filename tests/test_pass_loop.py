"""The one pass loop under every driver: the camera driver (path, direct), the
light driver (ptracer, bdpt) and the estimators with passes of their own
(photonmapper: photon maps before the camera passes; sppm: a photon pass in
every pass) all get checkpoints, progress, time budgets and Ctrl-C from it."""
import _thread
import signal
import threading
import time

import numpy as np
import pytest

import radiometer as rm

# Every registered estimator, and so every driver; small photon budgets so
# that a pass takes milliseconds (the others at their defaults).
ESTIMATORS = sorted(rm.estimators())
FAST = {
    "photonmapper": {"global_photons": 5000, "caustic_photons": 5000, "direct_samples": 1, "gather_rays": 2},
    "sppm": {"photon_count": 2000},
    # its solve (the whole setup) counts against the budget: ~0.05 s at 100 patches
    "radiosity": {"max_patches": 100},
}


def _integrator(name):
    return {"type": name, **FAST.get(name, {})}


def test_every_kind_of_driver_is_covered():
    drivers = {e["capabilities"]["driver"] for e in rm.estimators().values()}
    assert {"camera", "light", "own"} <= drivers


@pytest.fixture(scope="module")
def tiny_cornell(cornell_path):
    return rm.load_file(cornell_path, res=16, spp=4)


@pytest.fixture(scope="module")
def tiny_sky():
    """A diffuse ball on a floor under a constant sky, 16 x 16: the scene of
    the estimators that refuse the Cornell box's area light (prt)."""
    diffuse = {"type": "diffuse"}
    cam = np.array([[-1, 0, 0, 0], [0, 0, 1, -3], [0, 1, 0, 1], [0, 0, 0, 1.0]])
    return rm.load_dict({"type": "scene", "sky": {"type": "constant"},
                         "floor": {"type": "rectangle", "to_world": np.diag([3.0, 3.0, 1.0, 1.0]), "bsdf": diffuse},
                         "ball": {"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5, "bsdf": diffuse},
                         "cam": {"type": "perspective", "to_world": cam,
                                 "film": {"type": "hdrfilm", "width": 16, "height": 16}}})


@pytest.fixture
def scene_for(tiny_cornell, tiny_sky):
    """The Cornell box, or the sky scene for an estimator that refuses it
    by its own check (radiometer.refusal)."""
    return lambda name: tiny_sky if rm.refusal(tiny_cornell, name) else tiny_cornell


@pytest.mark.parametrize("name", ESTIMATORS)
def test_checkpoints_and_progress_on_every_driver(scene_for, name):
    calls = []
    scene = scene_for(name)
    res = rm.render(scene, integrator=_integrator(name), spp=4, seed=1, checkpoints=[1, 2, 4],
                    threads=2, progress=lambda d, t: calls.append((d, t)))
    assert res.spp == 4
    assert [c[0] for c in res.checkpoints] == [1, 2, 4]
    secs = [c[1] for c in res.checkpoints]
    assert secs == sorted(secs) and secs[-1] <= res.seconds
    np.testing.assert_array_equal(res.checkpoints[-1][2], res.image)
    np.testing.assert_array_equal(res.checkpoints[-1][3], res.variance)
    total = 4 * scene.width * scene.height
    assert calls and calls[-1] == (total, total)
    assert all(b[0] >= a[0] for a, b in zip(calls, calls[1:]))


@pytest.mark.parametrize("name", ESTIMATORS)
def test_time_budget_on_every_driver(scene_for, name):
    t0 = time.monotonic()
    res = rm.render(scene_for(name), integrator=_integrator(name), seconds=0.3, seed=1, threads=2)
    wall = time.monotonic() - t0
    assert res.spp >= 1
    assert res.seconds < 1.2 and wall < 2.0  # a budget, not a wish (generous: 4x)
    capped = rm.render(scene_for(name), integrator=_integrator(name), seconds=30, spp=3, seed=1, threads=2)
    assert capped.spp == 3


def _interrupt_after(seconds, render):
    """Runs render() with a SIGINT to the main thread after `seconds`; the
    RenderCancelled it must raise, and the wall time to it."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(seconds, _thread.interrupt_main)
    try:
        timer.start()
        t0 = time.monotonic()
        with pytest.raises(rm.RenderCancelled) as info:
            render()
        return info.value.result, time.monotonic() - t0
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_ctrl_c_keeps_finished_passes_on_every_driver(scene_for, name):
    """Ctrl-C once the first pass is in (the progress callback says so; a
    fixed delay left a loaded machine with no pass yet): the render stops
    within a few seconds and returns what it finished."""
    sent = []

    def on_progress(done, total):
        if done > 0 and not sent:
            sent.append(time.monotonic())
            _thread.interrupt_main()  # the real signal path: the next poll, or this callback, sees it

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    fallback = threading.Timer(120, _thread.interrupt_main)  # no pass in 2 min: fail, do not hang
    try:
        fallback.start()
        with pytest.raises(rm.RenderCancelled) as info:
            rm.render(scene_for(name), integrator=_integrator(name), spp=1 << 20, seed=1, threads=2,
                      progress=on_progress)
        stopped = time.monotonic()
    finally:
        fallback.cancel()
        signal.signal(signal.SIGINT, previous)
    r = info.value.result
    assert sent, f"{name}: no pass finished within 120 s"
    assert stopped - sent[0] < 10, f"{name}: took {stopped - sent[0]:.1f} s to stop after Ctrl-C"
    assert 0 < r.spp < 1 << 20
    assert np.isfinite(r.image).all() and r.image.mean() > 0


def test_photon_passes_count_against_the_budget_and_the_checkpoint_times(tiny_cornell):
    """photonmapper's photon maps are the loop's setup: its time is in
    res.seconds and in every checkpoint's seconds (error-vs-time curves)."""
    integ = {"type": "photonmapper", "global_photons": 200000, "caustic_photons": 1000,
             "direct_samples": 1, "gather_rays": 1}
    res = rm.render(tiny_cornell, integrator=integ, spp=2, checkpoints=[1, 2], seed=1, threads=2)
    photon_seconds = sum(m["trace_seconds"] + m["build_seconds"] for m in res.stats["photon_maps"].values())
    assert photon_seconds > 0
    assert res.checkpoints[0][1] >= photon_seconds
    assert res.seconds >= res.checkpoints[-1][1]


def test_ctrl_c_during_the_photon_passes(tiny_cornell):
    """A cancel before the first camera pass returns no samples: a zero image
    with NaN variance."""
    integ = {"type": "photonmapper", "global_photons": 50_000_000, "caustic_photons": 1000}
    r, wall = _interrupt_after(0.3, lambda: rm.render(tiny_cornell, integrator=integ, spp=4, seed=1, threads=2))
    assert wall < 10
    assert r.spp == 0
    assert not r.image.any() and np.isnan(r.variance).all()
