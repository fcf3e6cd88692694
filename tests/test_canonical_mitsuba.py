"""The canonical scenes against their committed Mitsuba 3 references
(reference_scenes/<name>/reference.exr, 64 x 64, mean of 32 independent
llvm_ad_rgb runs and the variance of that mean; parameters, budgets and
known exclusions in reference_scenes/registry.py, what each scene isolates
in its card.md).

Surface scenes (glass_sphere_caustic, veach_mis, ajar_door): our `path` at
a CI budget (about 2-4 s each on 2 shared cores) against the reference, with the
blocked z-test of tests/refcompare.py (4 x 4 block means, each channel at
alpha / 3, alpha = 0.01 in all; see test_cornell_reference.py for why blocks),
and a power check: the reference scaled by 1.01 (ajar_door: its effect region
scaled by 1.05, see below) must be rejected.

One addition to the Cornell box's test, measured on these scenes: the
variance of each of our blocks is the larger of our render's own estimate
and the per-sample variance the reference measured, scaled to our sample
count (`reference_variance_floor`). These scenes are built around rare
paths (a caustic of a small light seen through or reflected by a glass
sphere, light through a door gap), which a render at CI budget mostly
misses, and when it misses them its own variance estimate misses them too:
the estimate is low exactly where its variance is underestimated. With our
own variance only, 20 of 20 glass_sphere_caustic renders at 1024 spp
(independent seeds) failed against Mitsuba (mean z -60.9, 125 of 256
blocks rejected per channel), and 4 of 4 failed the same way against our
own 16384 spp render (mean z about -11), while the mean of 8 renders agreed
with it: the failure is the estimate of the variance, not a disagreement.
With the floor (never smaller than our own estimate, so a block can only be
judged more leniently where the reference saw more spread than our render
did), 20 of 20 passed and 20 of 20 with a 1 % bias were rejected; numbers
for each scene, including the floor's measured false-alarm rates, in the
scene's card.md.

Media and subsurface scenes (homogeneous_slab, fog_room, vandehulst_slab,
translucent_slab, translucent_object, volumetric_caustic): our `volpath`
(the same estimator as `path` on a scene with media, tests/test_media.py)
against the reference with the same blocked z-test and reference variance
floor, at the budgets and block sizes of MEDIA (measured per scene in its
card.md); their references are also checked for form, and the two with an
independent answer (Beer-Lambert; the slab's diffuse transmittance) against
it. `ptracer` against these references: tests/test_ptracer_media.py; `bdpt`:
tests/test_bdpt_media.py (van de Hulst's irradiancemeter scenes:
tests/test_irradiancemeter.py).
"""
import math

import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.stats import z_test
from radiometer.reference_scenes import registry

from refcompare import blocked_z_test, reference_variance_floor, region_mask, scale_region

RES = 64
ALPHA = 0.01

# Per surface scene: our CI budget and the power check; every scene renders
# with its reference's parameters (res, max_depth: the registry). Regions
# are card.md's pixel boxes (x0, y0, x1, y1), half-open, at 64 x 64.
AJAR_DOORWAY = (28, 15, 40, 41)  # the view through the doorway into the lit room
AJAR_BEAM = (54, 18, 64, 40)  # the lamp's strip through the gap on the near room's right wall
SURFACE = {
    "glass_sphere_caustic": {"spp": 1024, "power": None},
    "veach_mis": {"spp": 512, "power": None},
    # At 512 spp a 1 % overall bias is near the mean z's noise here
    # (measured: rejected for 1 of seeds 1-3), so the check scales the region
    # the scene is about, the near room lit only through the gap (every
    # pixel outside the doorway and the lamp's strip), by 5 % (rejected for
    # 3 of 3; the unscaled reference passed 3 of 3).
    "ajar_door": {"spp": 512, "power": ("near room, indirect only", 1.05)},
}
# Our volpath's budget per media scene, the block size of the comparison and
# the bias its power check must reject (the reference scaled by it). Budgets:
# the block test's mean z is biased negative for a heavy-tailed estimator
# (a render that misses the rare paths is low and estimates its own variance
# low too), so each scene gets the budget at which independent seeds pass
# (measured, card.md). volumetric_caustic's L S S V E paths are found only by
# phase sampling through the glass sphere onto a small light: at 1024 spp
# 2 of 3 seeds failed with 4 x 4 blocks (mean z -3.7, -4.8) while 4 pooled
# renders (4096 spp) matched (image mean ratio 1.0035 +- 0.0043, mean z
# -2.4 shrinking with budget: skew, not bias); 16 x 16 blocks (256 pixels x
# 1024 samples each) pass 3 of 3 and see a 2 % bias in 2 of 3 seeds (the
# reference's own noise, 10 % per pixel, limits what any budget can see).
# Its power check is therefore 10 %: under fresh seed offsets 0-2 the mean z
# at 1.0 ran from -1.94 to +0.51 and moved by -0.67 per 1 % of bias, so 2 %
# was missed under 2 of 3 (5 % under 1 of 3), while 10 % moves the worst of
# them to about -6.2, well beyond the level's 3.26.
MEDIA_CI = {
    "homogeneous_slab": {"spp": 512, "k": 4, "power": 1.01},
    "fog_room": {"spp": 1024, "k": 4, "power": 1.01},
    "vandehulst_slab": {"spp": 1 << 18, "k": 1, "power": 1.02},
    # 2 %: 1 % was missed under seed offset 2 and both its reruns (the
    # strongest channel's mean z -2.98 against 3.26 under offsets 0-3: 1 %
    # moves it by about 2.5 to 3.4); 2 % reaches -5.8 to -8.6.
    "translucent_slab": {"spp": 512, "k": 4, "power": 1.02},
    "translucent_object": {"spp": 512, "k": 4, "power": 1.01},
    "volumetric_caustic": {"spp": 1024, "k": 16, "power": 1.10},
}
MEDIA = list(MEDIA_CI)


def _load(name):
    """The scene with its reference's XML parameters."""
    spec = registry.get(name)
    return rm.load_file(spec.xml, **spec.fixed_params)


def _max_depth(name):
    """The max_depth the scene's reference was made with."""
    return registry.max_depth(registry.get(name))


def _reference(name, shape=(RES, RES, 3), min_spp=16384):
    path = registry.get(name).reference_exr
    assert path.exists(), (f"{path} is missing: regenerate it with "
                           f"python -m radiometer.reference_scenes.make_reference {name}")
    ref = rm.read_exr(path)
    assert ref.variance is not None, f"{path} has no variance layer"
    assert ref.image.shape == shape, ref.image.shape
    assert np.all(np.isfinite(ref.image)) and np.all(ref.variance >= 0), path
    assert int(ref.metadata.get("runs", 0)) >= 16, ref.metadata
    assert int(ref.metadata.get("total_spp", 0)) >= min_spp, ref.metadata
    return ref


def _effect_mask(name):
    if name == "ajar_door":
        return ~region_mask((RES, RES), [AJAR_DOORWAY, AJAR_BEAM])
    raise KeyError(name)


_ours = {}


def _render_ours(name):
    """Our `path` on the scene, once per session (the comparison and the
    power check use the same render)."""
    if name not in _ours:
        cfg = SURFACE[name]
        scene = _load(name)
        _ours[name] = rm.render(scene, integrator={"type": "path", "max_depth": _max_depth(name)},
                                spp=cfg["spp"], seed=1)
    return _ours[name]


def _compare(res, ref_image, ref_variance, total_spp):
    floor = reference_variance_floor(ref_variance, total_spp, res.spp)
    return blocked_z_test(res.image, res.variance, ref_image, ref_variance, b_splatted=False, alpha=ALPHA,
                          var_a_floor=floor)


@pytest.mark.parametrize("name", sorted(SURFACE))
def test_path_matches_mitsuba_reference(name):
    ref = _reference(name)
    res = _render_ours(name)
    assert res.spp == SURFACE[name]["spp"]
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0, res.stats
    passed, msg = _compare(res, ref.image, ref.variance, int(ref.metadata["total_spp"]))
    assert passed, f"{name}: ours ({res.spp} spp) differs from Mitsuba's reference:\n{msg}"


@pytest.mark.parametrize("name", sorted(SURFACE))
def test_power_scaled_reference_is_rejected(name):
    """The reference with a bias the test must see (1 % overall, or 5 % on
    the scene's effect region) must fail: the test can fail."""
    ref = _reference(name)
    res = _render_ours(name)
    power = SURFACE[name]["power"]
    if power is None:
        what, image, var = "1 % overall", ref.image * 1.01, ref.variance * 1.01 ** 2
    else:
        region, s = power
        image, var = scale_region(ref.image, ref.variance, _effect_mask(name), s)
        what = f"{(s - 1) * 100:.0f} % on the {region} region"
    passed, msg = _compare(res, image, var, int(ref.metadata["total_spp"]))
    assert not passed, f"{name}: a bias of {what} went undetected:\n{msg}"


# -- media and subsurface scenes ---------------------------------------------


@pytest.mark.parametrize("name", MEDIA)
def test_media_reference_is_well_formed(name):
    shape = (1, 1, 3) if name == "vandehulst_slab" else (RES, RES, 3)
    ref = _reference(name, shape=shape, min_spp=8192)
    assert float(ref.image.max()) > 0, f"{name}: the reference is black"


@pytest.mark.parametrize("name", MEDIA)
def test_volpath_matches_mitsuba_reference(name):
    """Our volpath against the reference, as the surface scenes above, with
    MEDIA_CI's budget, block size and power check."""
    cfg = MEDIA_CI[name]
    shape = (1, 1, 3) if name == "vandehulst_slab" else (RES, RES, 3)
    ref = _reference(name, shape=shape, min_spp=8192)
    total = int(ref.metadata["total_spp"])
    scene = _load(name)
    res = rm.render(scene, integrator="volpath", spp=cfg["spp"], seed=1)
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0, res.stats
    floor = reference_variance_floor(ref.variance, total, res.spp)
    s = cfg["power"]
    if name == "vandehulst_slab":  # one pixel: no blocks
        r = z_test(res.image, np.maximum(res.variance, floor), ref.image, ref.variance, alpha=ALPHA)
        assert r.passed, r.summary()
        r = z_test(res.image, np.maximum(res.variance, floor), ref.image * s, ref.variance * s * s, alpha=ALPHA)
        assert not r.passed, f"a {(s - 1) * 100:.0f} % bias went undetected: {r.summary()}"
        return

    def compare(image, variance):
        return blocked_z_test(res.image, res.variance, image, variance, b_splatted=False, alpha=ALPHA,
                              var_a_floor=floor, k=cfg["k"])

    passed, msg = compare(ref.image, ref.variance)
    assert passed, f"{name}: ours ({res.spp} spp) differs from Mitsuba's reference:\n{msg}"
    passed, msg = compare(ref.image * s, ref.variance * s * s)
    assert not passed, f"{name}: a {(s - 1) * 100:.0f} % bias went undetected:\n{msg}"


# Fully covered pixels of each slab (card.md), and its optical thickness.
SLABS = {"slab_0.25": ((2, 10, 14, 54), 0.25), "slab_0.5": ((18, 10, 30, 54), 0.5),
         "slab_1": ((34, 10, 46, 54), 1.0), "slab_2": ((50, 10, 62, 54), 2.0)}


@pytest.mark.parametrize("slab", sorted(SLABS))
def test_homogeneous_slab_reference_is_beer_lambert(slab):
    """The Mitsuba reference itself against the exact answer exp(-tau)
    (an absorber seen along its normal: no scattering, no boundary effect),
    pixel by pixel over the slab's fully covered pixels (analytic: var_b = 0)."""
    ref = _reference("homogeneous_slab", min_spp=8192)
    box, tau = SLABS[slab]
    m = region_mask((RES, RES), [box])
    exact = np.full(ref.image.shape, math.exp(-tau))
    r = z_test(ref.image, ref.variance, exact, None, alpha=ALPHA, mask=m[..., None])
    assert r.passed, f"{slab}: Mitsuba's reference is not exp(-{tau}) = {math.exp(-tau):.5f}:\n{r.summary()}"
    # And the test would see a 1 % error at this budget.
    r = z_test(ref.image, ref.variance, exact * 1.01, None, alpha=ALPHA, mask=m[..., None])
    assert not r.passed, f"{slab}: a 1 % error went undetected:\n{r.summary()}"


# The slab's diffuse transmittance (tau 2, albedo 0.9, Henyey-Greenstein
# g 0.75, normal incidence, index-matched): van de Hulst's tabulated total
# transmittance 0.66096 less the unscattered exp(-2) (half a unit of the last
# digit as its uncertainty). The analog Monte Carlo in
# reference_scenes/vandehulst_slab/independent.py agrees: T_d 0.52561 +- 4e-5,
# R 0.09743 +- 3e-5 (published 0.09739), 4e7 photons.
VDH_TD, VDH_TD_SE = 0.66096 - math.exp(-2.0), 5e-6


def test_vandehulst_reference_matches_independent_transport():
    ref = _reference("vandehulst_slab", shape=(1, 1, 3), min_spp=8192)
    v = ref.image[0, 0].astype(np.float64)
    se = np.sqrt(ref.variance[0, 0].astype(np.float64) + VDH_TD_SE ** 2)
    z = (v - VDH_TD) / se
    from scipy.stats import norm

    p = 2 * norm.sf(np.abs(z))
    assert np.all(p >= ALPHA / 3), (f"Mitsuba's diffuse transmittance {v} differs from the independent "
                                    f"{VDH_TD} +- {VDH_TD_SE}: z {z}")


# -- the veach_mis finding: Mitsuba's small analytic sphere lights ------------

SMALL_SPHERE_XML = """<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="orthographic">
        <transform name="to_world"><lookat origin="5, 5, 0" target="5, 0, 0" up="0, 0, -1"/></transform>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/>
            <rfilter type="box"/></film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><scale value="10"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" x="0" y="1" z="0"/>
        <float name="radius" value="0.01"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0, 0, 0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="10000, 10000, 10000"/></emitter>
    </shape>
</scene>
"""


def _small_sphere_exact(res=32, ss=16, r=0.01, le=1e4, h=1.0, rho=0.5):
    """Pixel means (box filter) of the floor's radiance under a sphere of
    radius r and radiance le at height h, fully above the horizon: E =
    pi le sin^2(alpha) cos(theta) with sin(alpha) = r / d, so L = rho le
    r^2 h / d^3 (exact). Pixels cover world x in [4, 6], z in [-1, 1];
    16 x 16 midpoint samples per pixel (error < 1e-7 relative)."""
    n = res * ss
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    x, z = 5.0 + c[None, :], c[:, None]
    d2 = x * x + z * z + h * h
    lo = rho * le * r * r * h / d2 ** 1.5
    return np.repeat(lo.reshape(res, ss, res, ss).mean(axis=(1, 3))[..., None], 3, axis=-1)


def test_small_sphere_light_matches_analytic(tmp_path):
    """Ours against the exact irradiance of a small sphere light (radius 0.01
    seen from ~5 units, sin^2 alpha ~ 4e-6), the geometry of veach_mis's
    smallest light. Mitsuba 3.9.1 (llvm_ad_rgb, 8 x 4096 spp) renders this
    0.74 % too bright (z +2740; 0.13 % at half the distance, 0.04 % for
    radius 0.04): its cone sampling of the sphere loses 1 - cos(theta_max)
    to float32 rounding. The test must reject that error at our budget."""
    path = tmp_path / "small_sphere.xml"
    path.write_text(SMALL_SPHERE_XML)
    res = rm.render(rm.load_file(path), spp=1024, seed=1)
    exact = _small_sphere_exact()
    r = z_test(res.image, res.variance, exact, None, alpha=ALPHA)
    assert r.passed, f"ours differs from the exact small-sphere irradiance:\n{r.summary()}"
    r = z_test(res.image, res.variance, exact * 1.0074, None, alpha=ALPHA)
    assert not r.passed, f"Mitsuba's +0.74 % went undetected:\n{r.summary()}"


# The slab's diffuse reflectance, van de Hulst's tabulated 0.09739 (half a
# unit of the last digit as its uncertainty).
VDH_R, VDH_R_SE = 0.09739, 5e-6


def test_vandehulst_reflectance_reference_matches_published():
    ref = _reference("vandehulst_slab_reflectance", shape=(1, 1, 3), min_spp=8192)
    v = ref.image[0, 0].astype(np.float64)
    se = np.sqrt(ref.variance[0, 0].astype(np.float64) + VDH_R_SE ** 2)
    from scipy.stats import norm

    p = 2 * norm.sf(np.abs((v - VDH_R) / se))
    assert np.all(p >= ALPHA / 3), f"Mitsuba's diffuse reflectance {v} differs from the published {VDH_R}"
    # The check has the resolution to see a 1 % error.
    assert np.all(2 * norm.sf(np.abs((v - VDH_R * 1.01) / se)) < ALPHA / 3)


def test_volpath_matches_vandehulst_reflectance():
    """Our volpath against the published reflectance (tests/test_media.py
    also holds it, and T_d, to Mitsuba's references)."""
    scene = _load("vandehulst_slab_reflectance")
    res = rm.render(scene, integrator="volpath", spp=1 << 16, seed=1)
    v, se = float(res.image[0, 0, 0]), float(np.sqrt(res.variance[0, 0, 0]) + VDH_R_SE)
    from scipy.stats import norm

    assert 2 * norm.sf(abs(v - VDH_R) / se) >= ALPHA, f"volpath R {v} +- {se} vs published {VDH_R}"


# -- the other unbiased estimators on the surface scenes ----------------------
# `bdpt` estimates every path class, so it must match every surface reference
# (same budget and comparison as `path`).
#
# `ptracer` (light tracing) is held to each scene except the pixels where it
# cannot work (the registry's known exclusions), left out of the test
# (every 4 x 4 block touching them):
# - glass_sphere_caustic: the sphere itself (card.md box (16, 14, 41, 39)).
#   The camera sees it through a delta BSDF (L ... S E); a light path can
#   never connect to a pinhole through a delta vertex, so ptracer renders
#   those paths as 0 (it has no `specular` effect).
# - veach_mis: the plates of alpha 0.005 and 0.02 (boxes (0, 28, 64, 34) and
#   (0, 34, 64, 39)). There the camera sees a near-mirror reflecting the
#   indirectly lit floor and wall: a light path contributes only when its
#   last bounce arrives inside a lobe of width ~alpha, so the estimate is
#   carried by rare huge samples. Measured (512 spp, 64 x 64, 40 seeds,
#   the alpha-0.005 plate's pixels (27..33, 29..32)): median 0.30 of the
#   reference, 6 of 40 renders above it, up to 3.6x; every seed failed the
#   comparison there, and 8192 spp failed worse (one block p 3e-58), the
#   signature of a heavy tail rather than a bias. The same scene with that
#   plate's alpha set to 0.05 (nothing else changed) gives ptracer's
#   indirect light on the plate at 1.013 +- 0.017 of `path`'s (24 seeds x
#   512 spp against 8192 spp), median equal to mean; and the plates' direct
#   highlights (light -> plate -> camera, the same connection code) agree
#   at alpha 0.005. Outside the two plates, 8 of 8 seeds passed at 512 spp.
# ajar_door is tested whole (seeds 2 and 3 at 1024 spp passed, the near
# room's mean at 0.9975 and 0.9999 of the reference; every surface there is
# diffuse, and Mitsuba's reference is itself a light tracer's, card.md).
PTRACER_EXCLUDE = {name: registry.get(name).exclusions.get("ptracer", []) for name in SURFACE}
PTRACER_SPP = 1024


@pytest.mark.parametrize("estimator,name", [("bdpt", n) for n in sorted(SURFACE)] +
                         [("ptracer", n) for n in sorted(SURFACE)])
def test_other_estimators_match_mitsuba_reference(estimator, name):
    ref = _reference(name)
    cfg = SURFACE[name]
    scene = _load(name)
    spp = PTRACER_SPP if estimator == "ptracer" else cfg["spp"]
    res = rm.render(scene, integrator={"type": estimator, "max_depth": _max_depth(name)}, spp=spp, seed=2)
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0, res.stats
    exclude = PTRACER_EXCLUDE[name] if estimator == "ptracer" else ()
    floor = reference_variance_floor(ref.variance, int(ref.metadata["total_spp"]), res.spp)
    passed, msg = blocked_z_test(res.image, res.variance, ref.image, ref.variance, b_splatted=False, alpha=ALPHA,
                                 var_a_floor=floor, exclude=exclude)
    assert passed, f"{name}: {estimator} ({res.spp} spp) differs from Mitsuba's reference:\n{msg}"
