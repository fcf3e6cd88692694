"""Hard cases, first set (reference_scenes/stress/, see its README.md):
scenes that break careless renderers (grazing angles, extreme scales, lights
touching surfaces, degenerate meshes, index-matched glass, total internal
reflection, extreme roughness, delta-only scenes, z-fighting, a camera on a
surface).

For every scene x estimator: no NaN, no Inf, nothing negative in the image,
the variance or any effect image; no NaN/Inf sample counted; light where the
scene must show light (the regions in SCENES). Then the scenes that have an
answer are held to it: the scaled Cornell boxes equal the unscaled one, the
huge floor equals a small floor, index-matched glass is invisible, glass
around the camera shows n^2 Le (or 0 where light is trapped), the narrow spot
delivers its analytic power, and a furnace of rough spheres never exceeds 1.

Every statistical test runs at significance level ALPHA (two-sided z-tests
with both sides' variance, `radiometer.analysis.stats.z_test`, which splits
ALPHA over its three views of the z field).

New estimators are added by name to the lists below.
"""
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as st
from scipy.integrate import quad

import radiometer as rm
from radiometer.analysis.stats import z_test
from radiometer.render import INTEGRATOR_PARAMS

# Every estimator (the core's registry): each must survive every scene.
ESTIMATORS = list(rm.estimators())
ALIASES = [a for e in rm.estimators().values() for a in e["aliases"]]
# Per-estimator settings for the sweep's budget (defaults elsewhere): the
# photon estimators' defaults (250 000 photons, 16 shadow and 32 gather rays)
# cost minutes over the sweep; stability does not depend on them.
SWEEP_PARAMS = {
    "photonmapper": {"global_photons": 20000, "caustic_photons": 20000, "volume_photons": 20000, "direct_samples": 1,
                     "gather_rays": 4},
    "sppm": {"photon_count": 10000},
}
# Estimators that refuse emitters at infinity (constant, directional), with
# a clear error naming the emitter; on such scenes the test asserts that
# refusal instead of an image. None at present (bdpt supports them).
REFUSES_INFINITE = set()
# Estimators whose own check refuses most stress scenes (radiometer.refusal:
# prt takes distant lighting and diffuse surfaces only, radiosity diffuse
# surfaces and area emitters); on those the test asserts that refusal. Their
# stability on their own scenes: tests/test_prt.py, tests/test_radiosity.py.
REFUSES_BY_CHECK = {"prt", "radiosity"}
# Regions an estimator cannot light by construction, with the reason; its
# image there is still checked for NaN, Inf and negative values.
CANNOT_LIGHT = {
    # Light tracing connects light paths to the camera only at non-specular
    # vertices: a camera that sees the light only through specular surfaces
    # (the L S* E class) gets nothing, as in Mitsuba 3's ptracer.
    ("ptracer", "glass_sphere_camera_center"): "camera sees the environment only through glass",
    ("ptracer", "tir_sphere_camera_offset"): "camera sees the environment only through glass",
    ("ptracer", "tir_slab_camera_inside"): "camera sees the environment only through glass",
    ("ptracer", "index_matched_glass"): "the wall is seen through the (invisible) glass only",
    # A directional light reaching a 0.09-wide band at 0.25 degrees in a scene
    # of radius ~50: ~1e-6 of the light paths, none at this budget.
    ("ptracer", "grazing_angles"): "the far grazing band needs ~1e6 light paths per pixel",
}
# Unbiased estimators (of whatever they estimate: `direct` estimates paths of
# at most 2 segments): the scale, huge-floor and narrow-spot tests.
UNBIASED = ["path", "direct"]
# Unbiased estimators of full transport (all path lengths): the tests that
# need light that bounces more than once (glass, invisible glass).
FULL_TRANSPORT = ["path"]

ALPHA = 0.01
SPP = 16  # the robustness sweep's budget
HERE = Path(__file__).resolve().parents[1] / "reference_scenes"
STRESS = HERE / "stress"
CORNELL = HERE / "cornell_box" / "scene.xml"

# What must be lit, per scene: (rows, cols, what) regions whose mean (over the
# region and the channels) must be > 0 for every estimator; "zero": the exact
# image is 0; "max_at_least": some pixel reaches this value (an emitter seen
# directly, fully covering a pixel). Images are 32 x 32.
ALL = (slice(None), slice(None))
SCENES = {
    "grazing_angles": {"lit": [(slice(r, r + 1), slice(None), f"floor row {r}") for r in range(32)]},
    "cornell_scale_1e-4": {"lit": [(*ALL, "the box")]},
    "cornell_scale_1e4": {"lit": [(*ALL, "the box")]},
    "huge_floor_tiny_object": {"lit": [(*ALL, "floor"), (slice(12, 20), slice(12, 20), "the cube")]},
    "point_light_near_surface": {"lit": [(*ALL, "floor and wall around the lights")]},
    "spot_cutoff_narrow": {"lit": [(slice(12, 20), slice(12, 20), "the lit disk at the centre")]},
    "spot_cutoff_wide": {"lit": [(slice(16, 32), slice(None), "the floor (bottom half)")]},
    "degenerate_triangles": {"lit": [(*ALL, "object and emitter")], "max_at_least": 5.0 * 0.999},
    "index_matched_glass": {"lit": [(*ALL, "floor and wall")]},
    "glass_sphere_camera_center": {"lit": [(*ALL, "environment through the glass")]},
    "tir_sphere_camera_offset": {"lit": [(slice(8, 24), slice(0, 2), "left edge"),
                                         (slice(8, 24), slice(30, 32), "right edge")]},
    "tir_slab_camera_inside": {"lit": [(*ALL, "environment through the slab")]},
    "roughness_extremes_furnace": {"lit": [(*ALL, "furnace")]},
    "roughness_extremes_lit": {"lit": [(*ALL, "floor and objects"), (slice(24, 32), slice(None), "floor")]},
    "tiny_bright_light": {"lit": [(*ALL, "box"), (slice(26, 32), slice(8, 24), "floor")]},
    "delta_only": {"lit": [(slice(24, 32), slice(None), "the floor")]},
    "delta_only_no_smooth": {"zero": True},
    "coplanar_zfighting": {"lit": [(*ALL, "floor"), (slice(6, 14), slice(4, 10), "the red/green square")]},
    "camera_on_surface": {"lit": [(slice(0, 16), slice(None), "above the horizon")]},
}


# Medium stress scenes: what must be lit, as SCENES. Estimators
# without media support must refuse them with the documented error
# (Integrator::supports_media, checked by the render driver) rather than
# render the media as vacuum; the others get the sanity checks above.
MEDIA_SCENES = {
    "media_sigma_t_1e4": {"lit": [(*ALL, "box surface, floor and backlight")]},
    "media_sigma_t_1e-6": {"lit": [(*ALL, "backlight through the (empty) box")]},
    "media_albedo_1": {"lit": [(slice(12, 20), slice(12, 20), "the white medium")]},
    "media_hg_0.99": {"lit": [(slice(12, 20), slice(12, 20), "the forward-scattering medium")]},
    "media_hg_-0.99": {"lit": [(slice(12, 20), slice(12, 20), "the back-scattering medium")]},
    "media_zero_channel": {"lit": [(*ALL, "backlight")]},
    "media_light_inside": {"lit": [(slice(12, 20), slice(12, 20), "fog around the lights")]},
    "media_camera_in_fog": {"lit": [(*ALL, "fog and room")]},
    "media_camera_in_glass": {"lit": [(*ALL, "environment through the medium and the glass")]},
    "media_grid_sparse": {"lit": [(*ALL, "backlight through the cloud")]},
}
SUPPORTS_MEDIA = {n for n in ESTIMATORS + ALIASES if rm.registry.estimator(n)["capabilities"]["media"]}
# Media scenes where light tracing cannot light the checked region (the
# sanity checks still apply): the camera sees it only through glass, and a
# light path never connects to a pinhole through a delta vertex.
MEDIA_CANNOT_LIGHT = {
    ("ptracer", "media_camera_in_glass"): "camera inside glass: everything is seen through the glass",
}
MEDIA_REFUSAL = "does not support participating media"


def test_scene_list_matches_folder():
    """Every stress scene in the folder is tested (the *_ref.xml files are
    references, not stress scenes) and the README card lists each."""
    on_disk = {p.stem for p in STRESS.glob("*.xml") if not p.stem.endswith("_ref")}
    assert on_disk == set(SCENES) | set(MEDIA_SCENES)
    card = (STRESS / "README.md").read_text()
    for name in list(SCENES) + list(MEDIA_SCENES):
        assert f"{name}.xml" in card, name


def spec(estimator, max_depth=None, rr_depth=None):
    """An integrator dict for `estimator`, with max_depth / rr_depth where it
    takes them (an estimator not in INTEGRATOR_PARAMS yet is assumed to)."""
    d = {"type": estimator, **SWEEP_PARAMS.get(estimator, {})}
    known = INTEGRATOR_PARAMS.get(estimator, {"max_depth": None, "rr_depth": None})
    for k, v in (("max_depth", max_depth), ("rr_depth", rr_depth)):
        if v is not None and k in known:
            d[k] = v
    return d


_cache = {}


class Refused(Exception):
    """The estimator refused the scene with its documented error."""


def render(path, estimator, spp, seed, max_depth=None, rr_depth=None, **params):
    key = (str(path), estimator, spp, seed, max_depth, rr_depth, tuple(sorted(params.items())))
    if key not in _cache:
        scene = rm.load_file(path, **params)
        try:
            _cache[key] = rm.render(scene, integrator=spec(estimator, max_depth, rr_depth), spp=spp, seed=seed)
        except ValueError as e:
            if estimator in REFUSES_INFINITE and "at infinity" in str(e) and "emitter" in str(e):
                raise Refused(str(e)) from None
            if estimator in REFUSES_BY_CHECK and str(e) == rm.refusal(scene, spec(estimator, max_depth, rr_depth)):
                raise Refused(str(e)) from None
            raise
    return _cache[key]


def assert_sane(res, where):
    arrays = {"image": res.image, "variance": res.variance}
    arrays.update({f"effects['{k}']": v for k, v in res.effects.items()})
    for name, a in arrays.items():
        a = np.asarray(a)
        assert a.shape == res.image.shape, f"{where}: {name} has shape {a.shape}"
        n_nan, n_inf = int(np.isnan(a).sum()), int(np.isinf(a).sum())
        assert n_nan == 0 and n_inf == 0, f"{where}: {name} has {n_nan} NaN and {n_inf} Inf values"
        neg = a < 0
        assert not neg.any(), (f"{where}: {name} has {int(neg.sum())} negative values, min {a.min():g} "
                               f"at {tuple(int(i) for i in np.argwhere(neg)[0])}")
    assert res.stats["nan_samples"] == 0, f"{where}: {res.stats['nan_samples']} NaN samples"
    assert res.stats["inf_samples"] == 0, f"{where}: {res.stats['inf_samples']} Inf samples"


@pytest.mark.parametrize("estimator", ESTIMATORS)
@pytest.mark.parametrize("name", sorted(SCENES))
def test_finite_nonnegative_and_lit(name, estimator):
    try:
        res = render(STRESS / f"{name}.xml", estimator, SPP, 0)
    except Refused:
        return  # the documented, clear refusal (REFUSES_INFINITE)
    where = f"{name} / {estimator}"
    assert_sane(res, where)
    exp = SCENES[name]
    if (estimator, name) in CANNOT_LIGHT:
        return  # sanity asserted above; see CANNOT_LIGHT for why nothing must be lit
    if exp.get("zero"):
        assert not res.image.any(), f"{where}: must be exactly 0, max {res.image.max():g}"
    for rows, cols, what in exp.get("lit", []):
        m = float(res.image[rows, cols].mean())
        assert m > 0, f"{where}: {what} must be lit, mean {m:g}"
    if "max_at_least" in exp:
        assert res.image.max() >= exp["max_at_least"], f"{where}: max {res.image.max():g}"


def block_means(image, variance, b=4):
    """b x b block means and their variances (pixels are independent: box
    filter, or filter importance sampling)."""
    h, w, c = image.shape
    img = np.asarray(image, np.float64).reshape(h // b, b, w // b, b, c).mean(axis=(1, 3))
    var = np.asarray(variance, np.float64).reshape(h // b, b, w // b, b, c).sum(axis=(1, 3)) / b ** 4
    return img, var


@pytest.mark.parametrize("estimator", ESTIMATORS + ALIASES)
@pytest.mark.parametrize("name", sorted(MEDIA_SCENES))
def test_media_finite_nonnegative_and_lit(name, estimator):
    where = f"{name} / {estimator}"
    if estimator not in SUPPORTS_MEDIA:
        with pytest.raises(ValueError, match=f"integrator '{estimator}' {MEDIA_REFUSAL}"):
            render(STRESS / f"{name}.xml", estimator, SPP, 0)
        return
    res = render(STRESS / f"{name}.xml", estimator, SPP, 0)
    assert_sane(res, where)
    if (estimator, name) in MEDIA_CANNOT_LIGHT:
        return
    for rows, cols, what in MEDIA_SCENES[name]["lit"]:
        m = float(res.image[rows, cols].mean())
        assert m > 0, f"{where}: {what} must be lit, mean {m:g}"


def test_media_nearly_empty_equals_no_medium():
    """sigma_t 1e-6 (optical depth 1e-6 across the box): equal to the same
    scene without the medium up to noise (4x4 block means, z-test at ALPHA);
    and nothing is filed as volume scattering beyond ~1e-6 of the image."""
    thin = render(STRESS / "media_sigma_t_1e-6.xml", "volpath", 128, 1)
    plain = render(STRESS / "media_sigma_t_1e-6_ref.xml", "path", 128, 2)
    a, va = block_means(thin.image, thin.variance)
    b, vb = block_means(plain.image, plain.variance)
    t = z_test(a, va, b, vb, alpha=ALPHA)
    assert t.passed, t.summary()
    assert thin.effects["volume"].sum() <= 1e-3 * thin.image.sum()


def test_media_zero_channel_green_sees_the_backlight():
    """sigma_t (2, 0, 2): the green channel neither attenuates nor scatters,
    so every pixel's green is the backlight, 1, in expectation (z-test,
    var_b = 0); red and blue are dimmed where the view crosses the cube."""
    res = render(STRESS / "media_zero_channel.xml", "volpath", 256, 1)
    assert_sane(res, "media_zero_channel")
    t = z_test(res.image[..., 1:2], res.variance[..., 1:2], np.ones_like(res.image[..., 1:2]), None, alpha=ALPHA)
    assert t.passed, t.summary()
    centre = res.image[12:20, 12:20]
    assert centre[..., 0].mean() < 0.9 and centre[..., 2].mean() < 0.9


# --- scale: the whole Cornell box scaled by 1e-4 and 1e4 ----------------------


@pytest.mark.parametrize("estimator", UNBIASED)
@pytest.mark.parametrize("scale", ["1e-4", "1e4"])
def test_scaled_cornell_box_equals_unscaled(scale, estimator):
    """Radiance is scale invariant: the scaled box (camera and every shape
    scaled, radiances unchanged) equals the unscaled one up to noise. 4x4
    block means (64 blocks x 3 channels), independent seeds, z-test at level
    ALPHA."""
    ref = render(CORNELL, estimator, 128, 1, res=32)
    res = render(STRESS / f"cornell_scale_{scale}.xml", estimator, 128, 2)
    assert_sane(res, f"cornell_scale_{scale} / {estimator}")
    a, va = block_means(res.image, res.variance)
    b, vb = block_means(ref.image, ref.variance)
    t = z_test(a, va, b, vb, alpha=ALPHA)
    assert t.passed, f"scale {scale}, {estimator}: {t.summary()}"


# --- a huge floor under a tiny object -----------------------------------------


@pytest.mark.parametrize("estimator", UNBIASED)
def test_huge_floor_equals_small_floor(estimator):
    """Direct light and paths of <= 3 segments: the floor beyond 0.05 is
    unlit and contributes nothing, so a 2e4 floor and a 0.1 floor give the
    same image (the cube's shadow included). 4x4 block means, z-test at ALPHA."""
    big = render(STRESS / "huge_floor_tiny_object.xml", estimator, 64, 1, max_depth=3)
    small = render(STRESS / "huge_floor_tiny_object_ref.xml", estimator, 64, 2, max_depth=3)
    a, va = block_means(big.image, big.variance)
    b, vb = block_means(small.image, small.variance)
    t = z_test(a, va, b, vb, alpha=ALPHA)
    assert t.passed, (f"{estimator}: huge floor {big.image.mean():.5g} vs small floor "
                      f"{small.image.mean():.5g}: {t.summary()}")


# --- index-matched glass is invisible -------------------------------------------


@pytest.mark.parametrize("estimator", FULL_TRANSPORT)
def test_index_matched_glass_is_invisible(estimator):
    glass = render(STRESS / "index_matched_glass.xml", estimator, 128, 1)
    plain = render(STRESS / "index_matched_glass_ref.xml", estimator, 128, 2)
    a, va = block_means(glass.image, glass.variance)
    b, vb = block_means(plain.image, plain.variance)
    t = z_test(a, va, b, vb, alpha=ALPHA)
    assert t.passed, f"{estimator}: {t.summary()}"


# --- glass around the camera: n^2 Le, or 0 where TIR traps the light ---------


def _pinhole_dirs(res, fov_x_deg, ss):
    """Camera-space (x, y) of ss x ss sub-pixel positions per pixel, for a
    square film with fov on x (z = 1). Signs do not matter to the callers."""
    t = np.tan(np.radians(fov_x_deg) / 2)
    u = (np.arange(res * ss) + 0.5) / (res * ss)
    c = (1 - 2 * u) * t
    return np.meshgrid(c, c)


def _tir_sphere_fraction(res=32, ss=64):
    """tir_sphere_camera_offset: camera at (0, 0, -0.9) looking along +x, so
    camera x is world -z; a direction escapes iff b = 0.9 sqrt(1 - dz^2) < 1/1.5."""
    x, y = _pinhole_dirs(res, 120.0, ss)
    dz = np.abs(x) / np.sqrt(1 + x * x + y * y)
    esc = (0.9 * np.sqrt(1 - dz * dz) < 1 / 1.5).astype(np.float64)
    return esc.reshape(res, ss, res, ss).mean(axis=(1, 3))


# scene: (environment radiance, fraction of each pixel that escapes (None:
# all), rr_depth). Where every direction escapes, Russian roulette is pushed
# out of reach: every sample is then exactly 2.25 Le (the Fresnel factors
# cancel against the lobe selection), a zero-variance check of the weights;
# with roulette, a few killed or boosted samples among thousands of exact
# ones make estimated variances unreliable. Trapped light needs roulette.
GLASS = {
    "glass_sphere_camera_center": ((1.0, 0.5, 0.25), None, 1000),
    "tir_slab_camera_inside": ((0.5, 1.0, 0.5), None, 1000),
    "tir_sphere_camera_offset": ((0.25, 0.5, 1.0), _tir_sphere_fraction, None),
}


@pytest.mark.parametrize("estimator", FULL_TRANSPORT)
@pytest.mark.parametrize("name", sorted(GLASS))
def test_camera_inside_glass_sees_n2_le(name, estimator):
    """L = n^2 Le = 2.25 Le in every direction that escapes the glass, 0 in
    trapped ones; per pixel, times the escaping fraction f of its area. The
    estimate's variance under H0 is at least the Bernoulli part
    (2.25 Le)^2 f (1 - f) / spp, which stands in for pixels whose samples all
    fell on one side. 4x4 block means, z-test at level ALPHA."""
    spp = 128
    le, frac, rr_depth = GLASS[name]
    res = render(STRESS / f"{name}.xml", estimator, spp, 3, rr_depth=rr_depth)
    f = np.ones(res.image.shape[:2]) if frac is None else frac(res.image.shape[0])
    full = 2.25 * np.asarray(le)
    exact = f[..., None] * full
    bern = (full ** 2) * (f * (1 - f))[..., None] / spp
    var = np.maximum(res.variance.astype(np.float64), bern)
    # 4x4 blocks: with roulette a pixel's samples are skewed (most give
    # exactly 2.25 Le or 0, a few are killed or boosted), which makes
    # per-pixel z with an estimated variance unreliable.
    a, va = block_means(res.image, var)
    b, _ = block_means(exact, np.zeros_like(exact))
    t = z_test(a, va, b, None, alpha=ALPHA)
    assert t.passed, f"{name}, {estimator}: mean {res.image.mean():.5g} vs exact {exact.mean():.5g}: {t.summary()}"


# --- the narrow spot light ------------------------------------------------------


def _spot_solid_angle(cutoff_deg):
    """Omega = 2 pi int f(theta) sin(theta) dtheta for Mitsuba's falloff: 1
    inside the beam (3/4 of the cutoff), linear in angle to 0 at the cutoff."""
    c = np.radians(cutoff_deg)
    b = 0.75 * c
    ramp = quad(lambda t: (c - t) / (c - b) * np.sin(t), b, c, epsabs=0, epsrel=1e-12)[0]
    return 2 * np.pi * (2 * np.sin(b / 2) ** 2 + ramp)  # 1 - cos(b) without cancellation


@pytest.mark.parametrize("estimator", UNBIASED)
@pytest.mark.parametrize("cutoff,half_extent", [(0.01, 5e-4), (10.0, 0.5)], ids=["cutoff_0.01", "control_10"])
def test_spot_delivers_its_power(cutoff, half_extent, estimator):
    """Mean of the image = rho/pi * I * Omega / A_view (the floor is the only
    surface; the whole lit disk is in view). One z-test on the image mean at
    level ALPHA; cutoff 10 is the control that validates the formula."""
    res = render(STRESS / "spot_cutoff_narrow.xml", estimator, 512, 0, cutoff=cutoff, half_extent=half_extent)
    exact = 0.8 / np.pi * 1.0 * _spot_solid_angle(cutoff) / (2 * half_extent) ** 2
    img = res.image.astype(np.float64)
    n = img[..., 0].size
    mean = img.mean(axis=(0, 1))
    se = np.sqrt(res.variance.astype(np.float64).sum(axis=(0, 1))) / n
    z = (mean - exact) / se
    crit = st.norm.isf(ALPHA / 2)
    assert np.all(np.abs(z) < crit), (f"cutoff {cutoff}, {estimator}: image mean {mean[0]:.6g} vs analytic "
                                      f"{exact:.6g} ({mean[0] / exact:.3f}x, z = {z[0]:+.1f}, "
                                      f"|z| must be < {crit:.2f})")


# --- rough spheres in a furnace never exceed it ----------------------------------


@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_rough_furnace_never_brighter_than_environment(estimator):
    """Passive surfaces in a uniform environment of radiance 1: every 4x4
    block mean <= 1 up to noise (one-sided z-test per block and channel,
    Bonferroni over them, level ALPHA); and clearly lit (> 0.5)."""
    try:
        res = render(STRESS / "roughness_extremes_furnace.xml", estimator, 64, 4)
    except Refused:
        return  # the documented, clear refusal (REFUSES_INFINITE)
    b, vb = block_means(res.image, res.variance)
    z = np.where(vb > 0, (b - 1.0) / np.sqrt(np.where(vb > 0, vb, 1.0)), np.where(b > 1.0 + 1e-5, np.inf, 0.0))
    crit = st.norm.isf(ALPHA / z.size)
    worst = np.unravel_index(np.argmax(z), z.shape)
    assert z.max() < crit, (f"{estimator}: block {worst} mean {b[worst]:.5g} exceeds 1 by "
                            f"z = {z[worst]:.2f} (critical {crit:.2f})")
    assert res.image.mean() > 0.5


# --- an emitter mesh with no area at all ----------------------------------------


def test_zero_area_emitter_mesh_is_refused(tmp_path):
    """An area emitter on a mesh whose triangles all have zero area cannot be
    sampled (a 1/0 pdf); it is refused with a message naming it, as Mitsuba
    refuses it, rather than rendered into NaN."""
    (tmp_path / "zero.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 1 4\nf 4 4 4\n")
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0">\n'
        '  <shape type="obj"><string name="filename" value="zero.obj"/><emitter type="area"/></shape>\n'
        '  <shape type="rectangle"/>\n'
        '  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>'
        '<integer name="height" value="8"/></film></sensor>\n'
        "</scene>\n")
    with pytest.raises(rm.SceneError, match="zero area"):
        rm.render(rm.load_file(tmp_path / "s.xml"), spp=1)
