"""vpl (instant radiosity) and rowcolumn (matrix row-column sampling),
renderer/estimators/vpl.cpp and rowcolumn.cpp; docs/vpl.md.

Statistics: the pixels of one pass share its VPLs, so they are correlated
(each pixel's res.variance is its own, honest, but a test that treats
pixels or blocks as independent is not valid here: measured, the image
mean's z-scores of the compensated furnace spread twice as wide as N(0,
1)). The expectation tests therefore compare the image means of SEEDS
independent renders with the exact value: a t-test per channel (SEEDS - 1
degrees of freedom) at ALPHA / 3 each, ALPHA = 0.01, fixed seeds, with a
power check (the exact value scaled by 1.01 must be rejected). Scene: the
white furnace (a closed diffuse emitting sphere, exact image L = Le
sum_{k < max_depth} rho^k), rho = (0.3, 0.5, 0.7), max_depth 4, Russian
roulette from the first bounce (rr_depth 1, so that the VPL sets vary): its
geometry term is bounded (G = 1/4 between any two points of a unit
sphere), so the unclamped estimate's variance is finite, and clamping
still bites (near points of the wall). Measured figures: docs/vpl.md."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import radiometer as rm
from radiometer.reference_scenes.furnace import analytic as furnace

from refcompare import assert_clean, assert_same_bytes_whatever_threads
from test_bdpt import AREA, CORNELL, MIRROR_BALL, small_scene

ALPHA = 0.01
SEEDS = 12
MD = 4  # furnace depth: emission, direct and two bounces of indirect light
FURNACE = dict(le=0.5, rho="0.3, 0.5, 0.7", max_depth=MD)
BASE = {"vpl_count": 64, "max_depth": MD, "rr_depth": 1}


def _furnace(res=16):
    scene = rm.load_file(furnace.XML, res=res, **FURNACE)
    ref, _ = furnace.reference(res=res, **FURNACE)
    return scene, ref[0, 0]


def _seed_means(integ, spp=16, seed0=0):
    """(relative error of the image mean per channel, one row per seed, and the renders)."""
    scene, exact = _furnace()
    runs = [rm.render(scene, integrator={**BASE, **integ}, spp=spp, seed=seed0 + k) for k in range(SEEDS)]
    for r in runs:
        assert_clean(r, integ["type"])
    return np.array([r.image.mean(axis=(0, 1)) for r in runs]) / exact - 1, runs


def _t(rel, bias=0.0):
    """t per channel of the mean relative error against `bias`, and the critical value."""
    t = (rel.mean(0) - bias) / (rel.std(0, ddof=1) / np.sqrt(len(rel)))
    return t, stats.t.ppf(1 - ALPHA / 6, len(rel) - 1)


@pytest.mark.parametrize("integ", [
    {"type": "vpl", "clamping": 0.0},
    {"type": "vpl", "clamping": 0.5, "compensate": True},
    {"type": "rowcolumn", "clamping": 0.0, "rows": 16, "columns": 24},
], ids=["vpl-unclamped", "vpl-compensated", "rowcolumn-unclamped"])
def test_furnace_unbiased(integ):
    """Unclamped, compensated, and row-column sampled with fewer clusters
    than VPLs: the mean over seeds agrees with the exact furnace (measured:
    |t| <= 2.2 over seeds 0-11 and 100-111); power: a 1 % bias is rejected
    (measured sd of one render's mean: 0.04 .. 0.33 %)."""
    rel, runs = _seed_means(integ)
    t, crit = _t(rel)
    assert np.all(np.abs(t) < crit), f"{integ}: mean relative error {rel.mean(0)}, t {t} (critical {crit:.2f})"
    t1, _ = _t(rel, 0.01)
    assert np.all(np.abs(t1) > crit), f"{integ}: a 1 % bias went undetected: t {t1}"
    if integ["type"] == "rowcolumn":
        assert runs[0].stats["photon_maps"]["vpl"]["photons"] > 16 * 24, "fewer VPLs than clusters: none clustered"
    # res.variance is the variance of each pixel's estimate: the pixels'
    # spread over the seeds agrees with it on average (measured ratios 0.82 ..
    # 1.25 over seeds 0-11, 100-111, 200-211; pixels correlate within a pass,
    # so the ratio is noisy); the bound rejects a variance off by 2x either
    # way (and one pass's variance, not divided by the 16 passes).
    images, variances = np.array([r.image for r in runs]), np.array([r.variance for r in runs])
    ratio = images.var(axis=0, ddof=1).mean() / variances.mean()
    assert 0.5 < ratio < 2.0, f"{integ}: spread over seeds / res.variance = {ratio:.3f}"


def test_clamping_bias_has_its_sign_and_compensation_removes_it():
    """Clamping only removes light: without compensation the furnace is
    darker than exact, by many standard errors (measured, seeds 0-11:
    -1.2 %, -3.0 %, -4.9 % per channel at clamping 0.5, t -60 .. -83); the
    compensated renders of the same seeds are not (test_furnace_unbiased),
    and share their emission and direct light byte for byte (the clamp
    changes only VPL light)."""
    rel, runs = _seed_means({"type": "vpl", "clamping": 0.5})
    t, crit = _t(rel)
    assert np.all(t < -crit), f"clamping must darken: mean relative error {rel.mean(0)}, t {t}"
    scene, exact = _furnace()
    c = rm.render(scene, integrator={**BASE, "type": "vpl", "clamping": 0.5, "compensate": True}, spp=16, seed=0)
    for k in ("emission", "direct"):
        assert runs[0].effects[k].tobytes() == c.effects[k].tobytes(), k
    assert runs[0].effects["indirect"].mean() < c.effects["indirect"].mean()


def test_rowcolumn_with_a_cluster_per_vpl_is_the_full_vpl_sum():
    """With at least as many clusters as VPLs every VPL is its own cluster
    (weight 1), so rowcolumn renders exactly vpl's full sum from the same
    VPLs and camera samples (same seed): the same bytes. With fewer clusters
    the image differs from the full sum, and its error against it (relative
    MSE per pixel, eps 1e-2) shrinks as the clusters grow."""
    scene = rm.load_file(CORNELL, res=16, rfilter="box", max_depth=4)
    base = {"vpl_count": 64, "max_depth": 4}
    full = rm.render(scene, integrator={"type": "vpl", **base}, spp=4, seed=5)
    rc = rm.render(scene, integrator={"type": "rowcolumn", **base, "columns": 1 << 20}, spp=4, seed=5)
    assert rc.image.tobytes() == full.image.tobytes()
    n_vpl = full.stats["photon_maps"]["vpl"]["photons"] / 4
    err = {}
    for c in (2, 8, 32):
        r = rm.render(scene, integrator={"type": "rowcolumn", **base, "rows": 32, "columns": c}, spp=4, seed=5)
        assert_clean(r, f"rowcolumn columns={c}")
        err[c] = float(np.mean((r.image - full.image) ** 2 / (full.image ** 2 + 1e-2)))
    # measured (seeds 0-5, about 90 VPLs per pass): 0.030 .. 0.089, 0.005 .. 0.021, 0.0005 .. 0.0023
    assert n_vpl > 32, n_vpl
    assert err[2] > err[8] > err[32] > 0, err


@pytest.mark.parametrize("integ", [
    {"type": "vpl", "compensate": True, "vpl_count": 32},
    {"type": "rowcolumn", "vpl_count": 32, "rows": 8, "columns": 8},
], ids=["vpl", "rowcolumn"])
def test_same_bytes_whatever_threads_and_effects_sum(integ):
    """Threads 1, 2, 3: the same bytes (each light path, pixel and the
    clustering on their own streams, sums in a fixed order); effects sum to
    the image; through the mirror ball the specular class is lit."""
    scene = small_scene(AREA, res=16, extra=MIRROR_BALL)
    integ = {**integ, "max_depth": 5}
    assert_same_bytes_whatever_threads(scene, integ, 2)
    r = rm.render(scene, integrator=integ, spp=2, seed=3)
    assert_clean(r, integ["type"])
    np.testing.assert_allclose(sum(r.effects.values()), r.image, rtol=1e-5, atol=1e-7)
    for k in ("direct", "indirect", "specular"):
        assert r.effects[k].sum() > 0, k
    assert not r.effects["caustic"].any(), "no VPL connection makes a caustic"


def test_effects_restricted_and_max_depth():
    """effects=['direct'] skips the VPLs (none traced); max_depth 2 (direct
    light at most) has no indirect light at all."""
    scene, _ = _furnace(8)
    r = rm.render(scene, integrator={"type": "vpl", "max_depth": MD}, spp=2, seed=1, effects=["direct"])
    assert "vpl" not in r.stats["photon_maps"] and r.effects["direct"].sum() > 0
    r = rm.render(scene, integrator={"type": "vpl", "max_depth": 2}, spp=2, seed=1)
    assert not r.effects["indirect"].any() and "vpl" not in r.stats["photon_maps"]
    exact, _ = furnace.reference(res=8, **{**FURNACE, "max_depth": 2})
    np.testing.assert_allclose(r.image.mean(axis=(0, 1)), exact[0, 0], rtol=0.02)


@pytest.mark.parametrize("est", ["vpl", "rowcolumn"])
def test_bad_parameters_and_media_refused(est):
    scene = small_scene(AREA, res=8)
    bad = [("vpl_count", 0), ("clamping", 1.5), ("clamping", -0.1), ("max_depth", 0)]
    if est == "rowcolumn":
        bad += [("rows", 0), ("columns", 0)]
    else:
        bad += [("compensate", "yes")]
    for param, value in bad:
        with pytest.raises(rm.SceneError, match=param):
            rm.render(scene, integrator={"type": est, param: value}, spp=1)
    with pytest.raises(rm.SceneError, match="unknown parameter"):
        rm.render(scene, integrator={"type": est, "gather_rays": 2}, spp=1)
    if est == "vpl":  # Mitsuba 0.6's shadow-map size is accepted and changes nothing (shadow rays here)
        a = rm.render(scene, integrator={"type": est, "shadowMapResolution": 512}, spp=1, seed=2)
        b = rm.render(scene, integrator={"type": est}, spp=1, seed=2)
        assert a.image.tobytes() == b.image.tobytes()
    from radiometer.reference_scenes import registry

    spec = registry.get("homogeneous_slab")
    media = rm.load_file(spec.xml, **spec.fixed_params)
    with pytest.raises((rm.SceneError, ValueError), match="participating media"):
        rm.render(media, integrator={"type": est}, spp=1)


@pytest.mark.parametrize("est", ["vpl", "rowcolumn"])
def test_cancel_keeps_finished_passes(est):
    scene, _ = _furnace(8)

    def progress(done, total):
        if done >= 2 * 64:
            raise KeyboardInterrupt

    with pytest.raises(rm.RenderCancelled) as e:
        rm.render(scene, integrator={"type": est, "max_depth": MD}, spp=1 << 16, seed=0, threads=1,
                  progress=progress)
    r = e.value.result
    assert 0 < r.spp < 1 << 16 and np.isfinite(r.image).all() and r.image.mean() > 0
