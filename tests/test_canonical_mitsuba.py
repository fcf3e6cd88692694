"""The canonical scenes' committed Mitsuba 3 references themselves
(reference_scenes/<name>/reference.exr, 64 x 64, mean of 32 independent
llvm_ad_rgb runs and the variance of that mean; parameters, budgets and
known exclusions in reference_scenes/registry.py, what each scene isolates
in its card.md): the two with an independent answer (Beer-Lambert; van de
Hulst's slab) against it, and the veach_mis finding (Mitsuba's small
sphere lights, against the exact answer). Every estimator against every
reference, each with its power check, is a cell of
tests/test_estimator_matrix.py (the blocked z-test of tests/refcompare.py
with the reference variance floor; why the floor, below).

The reference variance floor, measured on these scenes: the variance of
each of our blocks is the larger of our render's own estimate and the
per-sample variance the reference measured, scaled to our sample count
(`reference_variance_floor`). These scenes are built around rare paths (a
caustic of a small light seen through or reflected by a glass sphere,
light through a door gap), which a render at CI budget mostly misses, and
when it misses them its own variance estimate misses them too: the
estimate is low exactly where its variance is underestimated. With our own
variance only, 20 of 20 glass_sphere_caustic renders at 1024 spp
(independent seeds) failed against Mitsuba (mean z -60.9, 125 of 256
blocks rejected per channel), and 4 of 4 failed the same way against our
own 16384 spp render (mean z about -11), while the mean of 8 renders agreed
with it: the failure is the estimate of the variance, not a disagreement.
With the floor (never smaller than our own estimate, so a block can only be
judged more leniently where the reference saw more spread than our render
did), 20 of 20 passed and 20 of 20 with a 1 % bias were rejected; numbers
for each scene, including the floor's measured false-alarm rates, in the
scene's card.md.

Why the budgets differ per estimator and scene (volpath, bdpt, ptracer on
the media scenes, ptracer's known exclusions on the surface scenes): the
comments at the matrix's MITSUBA table and in the registry; the ptracer
exclusions on veach_mis measured below.
"""
import math

import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.stats import z_test
from radiometer.reference_scenes import registry

from refcompare import region_mask

RES = 64
ALPHA = 0.01


def _load(name):
    """The scene with its reference's XML parameters."""
    spec = registry.get(name)
    return rm.load_file(spec.xml, **spec.fixed_params)


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


# -- media and subsurface scenes ---------------------------------------------

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


# -- ptracer's known exclusions on the surface scenes (the registry's) ------
# ptracer (light tracing) is held to each scene except the pixels where it
# cannot work, left out of the comparison (every 4 x 4 block touching them):
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
