"""`ptracer` (light tracing, Mitsuba 3's plugin semantics) against `path` and
against analytic images.

Every comparison is a two-sided z-test (radiometer.analysis.stats.z_test) at
ALPHA = 0.01, each channel at ALPHA / 3, on 4 x 4 block means (per-pixel
samples are heavy-tailed: see tests/test_cornell_reference.py). Block
variances are sums of pixel variances / 16^2 on both sides: `path`'s pixels
are independent (filter importance sampling); `ptracer`'s are correlated
only through light paths that splat into two pixels of one block, rare with a
box filter (the spread of z measured on the Cornell box, 32 x 32, 256 spp,
was 1.01). ptracer's variance is a batch-means estimate with 31 degrees of
freedom (light_render.cpp).

Light tracing cannot produce the `specular` class (a specular vertex next to
the camera) nor see delta-position emitters, so the scenes here have no
specular surface in view and no point or spot light in view.
"""
from pathlib import Path

import numpy as np
import pytest

import radiometer as rm
from refcompare import (_rgb, assert_clean, assert_same_bytes_whatever_threads, blocked_z, lookat)

ALPHA = 0.01
ROOT = Path(__file__).resolve().parents[1] / "reference_scenes"
CORNELL = ROOT / "cornell_box" / "scene.xml"


def small_scene(light, res=32, rfilter="box", fov=50.0, with_walls=True):
    """A floor, a back wall and a cube under `light`, seen in perspective."""
    def rect(m, rho):
        return {"type": "rectangle", "to_world": m, "bsdf": {"type": "diffuse", "reflectance": _rgb(rho)}}
    floor = np.diag([2.0, 2.0, 1.0, 1.0])
    d = {"type": "scene", "integrator": {"type": "path"},
         "floor": rect(floor, [0.7, 0.6, 0.5]),
         "cube": {"type": "cube", "to_world": np.array([[0.3, 0, 0, -0.3], [0, 0.3, 0, 0.2], [0, 0, 0.3, 0.3],
                                                         [0, 0, 0, 1.0]]),
                  "bsdf": {"type": "diffuse", "reflectance": _rgb([0.3, 0.5, 0.7])}},
         "light": light,
         "sensor": {"type": "perspective", "fov": fov, "to_world": lookat([0.0, -3.2, 2.4], [0, 0, 0.3], (0, 0, 1)),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": rfilter}}}}
    if with_walls:
        wall = np.array([[2.0, 0, 0, 0], [0, 0, 1.0, 2.0], [0, -2.0, 0, 2.0], [0, 0, 0, 1.0]])
        d["wall"] = rect(wall, [0.5, 0.5, 0.5])
    return rm.load_dict(d)


def compare_with_path(scene, spp_path, spp_pt, seed=1, max_depth=None, where="", correlated=False):
    integ = {"max_depth": max_depth} if max_depth is not None else {}
    a = rm.render(scene, integrator={"type": "path", **integ}, spp=spp_path, seed=seed)
    b = rm.render(scene, integrator={"type": "ptracer", **integ}, spp=spp_pt, seed=seed + 1000)
    assert_clean(b, where)
    assert b.image.mean() > 0, f"{where}: ptracer image is black"
    passed, msg = blocked_z(b.image, b.variance, a.image, a.variance, a_correlated=correlated)
    ratio = b.image.sum() / a.image.sum()
    assert passed, f"{where}: ptracer / path = {ratio:.5f}\n{msg}"
    return a, b


# ------------------------------------------------------------------ agreement with path

@pytest.fixture(scope="module")
def cornell_pair():
    scene = rm.load_file(CORNELL, res=32, rfilter="box")
    return scene, compare_with_path(scene, 1024, 1024, where="cornell box")


def test_cornell_ptracer_matches_path(cornell_pair):
    """Cornell box (32 x 32, box filter, max_depth 8): ptracer == path at
    ALPHA, per effect class too."""
    scene, (a, b) = cornell_pair
    for k in ("emission", "direct", "indirect"):
        ea, eb = a.effects[k].mean(), b.effects[k].mean()
        assert eb == pytest.approx(ea, rel=0.03), f"effect {k}: ptracer {eb:.5f} vs path {ea:.5f}"
    for k in ("caustic", "specular", "volume", "subsurface"):
        assert not np.any(b.effects[k]), f"effect {k} must be empty in the Cornell box"


def test_cornell_power_rejects_one_percent(cornell_pair):
    """The comparison has the power to see a 1 % error."""
    scene, (a, b) = cornell_pair
    assert not blocked_z(b.image * 1.01, b.variance, a.image, a.variance)[0], "a 1 % bias went undetected"
    assert not blocked_z(b.image * 0.99, b.variance, a.image, a.variance)[0], "a -1 % bias went undetected"


def test_cornell_gaussian_filter_matches_path():
    """The default gaussian filter: splats spread over the filter footprint,
    normalised by its integral inside the film, match filter importance
    sampling, borders included. Each splat covers ~4 x 4 pixels here, so
    ptracer's block variance is the Cauchy-Schwarz bound (summing its pixel
    variances as if independent rejected 6 of 64 blocks, mean z +0.26)."""
    scene = rm.load_file(CORNELL, res=32)
    a, b = compare_with_path(scene, 512, 512, seed=5, where="cornell box, gaussian filter", correlated=True)
    # Borders: the outermost ring of pixels (normalised by the filter's
    # integral inside the film) agrees in the mean.
    ring = np.ones(a.image.shape[:2], bool)
    ring[2:-2, 2:-2] = False
    assert b.image[ring].mean() == pytest.approx(a.image[ring].mean(), rel=0.02)


def test_cornell_max_depth_2_matches_path():
    scene = rm.load_file(CORNELL, res=32, rfilter="box")
    a, b = compare_with_path(scene, 256, 256, seed=7, max_depth=2, where="cornell box, max_depth 2")
    assert not np.any(b.effects["indirect"])


def test_point_light_matches_path():
    light = {"type": "point", "position": [0.6, -0.5, 1.5], "intensity": _rgb([3.0, 2.5, 2.0])}
    compare_with_path(small_scene(light), 512, 512, where="point light")


def test_spot_light_matches_path():
    to_world = lookat([0.5, -0.8, 1.8], [-0.2, 0.2, 0.0])
    light = {"type": "spot", "to_world": to_world, "cutoff_angle": 35.0, "beam_width": 20.0,
             "intensity": _rgb([6.0, 5.0, 4.0])}
    compare_with_path(small_scene(light), 512, 512, where="spot light")


def test_directional_light_matches_path():
    light = {"type": "directional", "direction": [0.3, 0.5, -0.8], "irradiance": _rgb([1.5, 1.2, 1.0])}
    compare_with_path(small_scene(light), 512, 512, where="directional light")


def test_constant_environment_matches_path():
    """Sky seen directly (the s = 1 connection along directions) and lighting
    the floor, the cube and the wall."""
    light = {"type": "constant", "radiance": _rgb([0.8, 0.9, 1.0])}
    a, b = compare_with_path(small_scene(light, fov=70.0), 256, 512, where="constant environment")
    assert b.effects["emission"].max() > 0.7


def test_area_light_hide_emitters():
    """hide_emitters: the emitter seen directly is black, the rest unchanged."""
    scene = rm.load_file(CORNELL, res=16, rfilter="box")
    b = rm.render(scene, integrator={"type": "ptracer", "hide_emitters": True}, spp=64, seed=2)
    assert not np.any(b.effects["emission"])
    assert b.effects["direct"].mean() > 0


# ------------------------------------------------------------------ film, variance, determinism

def test_effects_sum_to_image(cornell_pair):
    scene, (a, b) = cornell_pair
    np.testing.assert_allclose(sum(b.effects.values()), b.image, rtol=1e-5, atol=1e-7)


def test_effects_mask_simulates_only_those():
    scene = rm.load_file(CORNELL, res=16, rfilter="box")
    full = rm.render(scene, integrator="ptracer", spp=32, seed=4)
    only = rm.render(scene, integrator="ptracer", spp=32, seed=4, effects=["direct"])
    assert not np.any(only.effects["emission"]) and not np.any(only.effects["indirect"])
    # Same light paths, same direct splats (the walk stops earlier, its
    # random numbers are per path).
    np.testing.assert_array_equal(only.effects["direct"], full.effects["direct"])


def test_same_seed_same_bytes_whatever_threads():
    assert_same_bytes_whatever_threads(rm.load_file(CORNELL, res=16), "ptracer", 24)


def test_variance_predicts_spread_across_seeds():
    """res.variance (batch means) estimates the variance of the pixel mean:
    over 24 independent renders its mean matches the sample variance of the
    images (block means, chi-square interval at ALPHA / 3 per channel,
    Bonferroni: the three channels were tested each at ALPHA, and one of them
    fell outside under seed offset 1, observed / predicted 0.40)."""
    scene = rm.load_file(CORNELL, res=8, rfilter="box")
    runs = [rm.render(scene, integrator="ptracer", spp=64, seed=100 + s) for s in range(24)]
    imgs = np.stack([r.image for r in runs]).astype(np.float64)
    vars_ = np.stack([r.variance for r in runs]).astype(np.float64)
    # Whole-image mean per channel: pixels correlate little, so the image
    # mean's variance ~ sum of pixel variances / n^2.
    m = imgs.mean(axis=(1, 2))          # (24, 3)
    pred = vars_.mean(axis=0).sum(axis=(0, 1)) / (imgs.shape[1] * imgs.shape[2]) ** 2
    obs = m.var(axis=0, ddof=1)
    from scipy import stats as st
    n = len(runs) - 1
    a = ALPHA / 3
    lo, hi = st.chi2.ppf(a / 2, n) / n, st.chi2.ppf(1 - a / 2, n) / n
    for c in range(3):
        assert lo <= obs[c] / pred[c] <= hi, f"channel {c}: observed / predicted variance {obs[c] / pred[c]:.3f}"


def test_checkpoints_and_time_budget():
    scene = rm.load_file(CORNELL, res=16, rfilter="box")
    r = rm.render(scene, integrator="ptracer", spp=8, checkpoints=[2, 4], seed=1)
    assert [c[0] for c in r.checkpoints] == [2, 4] and r.spp == 8
    t = rm.render(scene, integrator="ptracer", seconds=0.3, seed=1)
    assert t.spp >= 1 and t.image.mean() > 0


# ------------------------------------------------------------------ errors

def _meter_scene(kind):
    d = {"type": "scene", "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
         "light": {"type": "point", "position": [0, 0, 1]}}
    if kind == "radiancemeter":
        d["sensor"] = {"type": "radiancemeter", "origin": [0, 0, 2], "direction": [0, 0, -1],
                       "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}
    else:
        d["floor"]["sensor"] = {"type": "irradiancemeter",
                                "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}
    return rm.load_dict(d)


@pytest.mark.parametrize("integrator", ["ptracer"])
def test_radiancemeter_is_refused_clearly(integrator):
    """A radiance meter (a delta position and direction) cannot be reached by
    light paths; an irradiancemeter can (tests/test_irradiancemeter.py).
    `bdpt` keeps its other strategies for a radiance meter
    (tests/test_bdpt.py::test_radiancemeter_matches_path)."""
    with pytest.raises(ValueError, match=f"{integrator}.*radiancemeter"):
        rm.render(_meter_scene("radiancemeter"), integrator=integrator, spp=4)
    r = rm.render(_meter_scene("irradiancemeter"), integrator=integrator, spp=4)
    assert r.image.shape[:2] == (1, 1)


def test_orthographic_with_visible_environment_is_refused():
    d = {"type": "scene", "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
         "sky": {"type": "constant"},
         "sensor": {"type": "orthographic", "to_world": lookat([0, 0, 1], [0, 0, 0]),
                    "film": {"type": "hdrfilm", "width": 4, "height": 4}}}
    scene = rm.load_dict(d)
    with pytest.raises(ValueError, match="orthographic.*environment"):
        rm.render(scene, integrator="ptracer", spp=4)
    r = rm.render(scene, integrator={"type": "ptracer", "hide_emitters": True}, spp=4)
    assert r.image.mean() > 0


def test_bad_parameters():
    scene = rm.load_file(CORNELL, res=8)
    with pytest.raises(rm.SceneError, match="max_depth"):
        rm.render(scene, integrator={"type": "ptracer", "max_depth": 0}, spp=1)
    with pytest.raises(rm.SceneError, match="unknown parameter"):
        rm.render(scene, integrator={"type": "ptracer", "emitter_samples": 2}, spp=1)
    rm.render(scene, integrator={"type": "ptracer", "samples_per_pass": 64}, spp=1)  # Mitsuba's, ignored


# ------------------------------------------------------------------ stress scenes

STRESS = ROOT / "stress"
# Scenes whose light ptracer cannot (or, at the sweep's budget, does not)
# find: the camera sees them through specular surfaces only (the `specular`
# class, which light tracing never produces), or, for grazing_angles, the
# directional light must hit a 0.09 x 20 glossy band at 0.25 degrees in a
# scene of radius ~50: ~1e-6 of the light paths (unbiased, but 0 at 16 spp).
NOT_LIT_BY_LIGHT_TRACING = {"glass_sphere_camera_center", "tir_slab_camera_inside", "tir_sphere_camera_offset",
                            "grazing_angles"}


@pytest.mark.parametrize("path", sorted(p for p in STRESS.glob("*.xml") if not p.stem.endswith("_ref")),
                         ids=lambda p: p.stem)
def test_stress_scenes_finite_nonnegative(path):
    """No NaN, Inf or negative value in any image, variance or effect on
    every stress scene; lit where light tracing can light it (the media_*
    scenes: test_stress.py checks where they are lit)."""
    res = rm.render(rm.load_file(path), integrator="ptracer", spp=16, seed=0)
    assert_clean(res, path.stem)
    if path.stem.startswith("media_"):
        return
    if path.stem not in NOT_LIT_BY_LIGHT_TRACING and path.stem != "delta_only_no_smooth":
        assert res.image.mean() > 0, f"{path.stem}: black"
    if path.stem == "delta_only_no_smooth":
        assert not res.image.any()
