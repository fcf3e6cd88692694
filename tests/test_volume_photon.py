"""`photonmapper` in scenes with participating media and subsurface
scattering: the volume photon map (Jensen & Christensen 1998) and ray marching
along camera rays, and with the same machinery subsurface scattering by the
photon map (the seed's "photon tracing - subsurface scattering").

What is checked (fixed seeds; tolerances from the measurements quoted in
each test, never from this code's own outputs alone):

- the volume map is built only in scenes with media and only when the
  volume/subsurface classes can use it, and reported in
  stats["photon_maps"]["volume"] with its photon count;
- exact answers where the estimate has no density estimation in it: Beer-
  Lambert through absorbing slabs (ray marching's transmittance, exact) and
  single scattering from a point light in an unbounded medium (the airlight
  integral, test_media.py's closed form: max_depth 2 leaves no photon map,
  only the jittered ray marching with light sampling, which is unbiased);
- van de Hulst's slab: where the closed form meets the photon map, its
  boundary bias, measured and shrinking as N^(-1/3);
- fog_room against Mitsuba 3's reference (and volpath per effect class):
  the error over image regions falls as volume photons grow and is within
  a stated tolerance at the largest budget; the estimator without the
  volume map (volume_photons 0, no multiple scattering) and a 10 % scaled
  reference are rejected by the same tolerance;
- subsurface on translucent_slab against volpath and Mitsuba 3's reference:
  the lit half's bias (the volume estimate's sphere pokes out of the slab
  at its top face, where camera rays enter: the estimate is low there) is
  inside the measured band and shrinks with the photon count;
- sppm refuses media with a clear error that names the alternatives;
- determinism across thread counts; bad parameters name themselves.
"""
import math
from pathlib import Path

import numpy as np
import pytest

import radiometer as rm

from refcompare import assert_clean, assert_same_bytes_whatever_threads
from test_media import check_single_scatter_point_light, hot_voxel_grid, small_light_slab

ROOT = Path(__file__).resolve().parents[1] / "reference_scenes"
# Budgets that keep each render about a second on one core.
PM = {"type": "photonmapper", "global_photons": 5000, "caustic_photons": 5000, "direct_samples": 1,
      "gather_rays": 4}


def _pm(**kw):
    return dict(PM, **kw)


# --- maps built only when needed ------------------------------------------------------


@pytest.mark.parametrize("scene,kw,want", [
    ("cornell_box", {}, {"global"}),  # no media: no volume map
    ("fog_room", {}, {"global", "volume"}),
    ("fog_room", {"effects": ["direct", "indirect"]}, {"global"}),  # no V/B class asked for
    ("fog_room", {"integrator_extra": {"max_depth": 2}}, set()),  # single scattering only: no photons needed
    ("fog_room", {"integrator_extra": {"volume_photons": 0}}, {"global"}),
    ("translucent_slab", {"effects": ["subsurface"]}, {"volume"}),
])
def test_volume_map_built_only_with_media(scene, kw, want):
    extra = kw.pop("integrator_extra", {})
    integ = _pm(**dict({"volume_photons": 3000}, **extra))
    res = rm.render(rm.load_file(ROOT / scene / "scene.xml", res=8), integrator=integ, spp=2, seed=0, **kw)
    maps = res.stats["photon_maps"]
    assert set(maps) == want
    if "volume" in maps:
        v = maps["volume"]
        assert v["photons"] >= 3000 and v["target_reached"] and v["paths"] > 0, v
        assert v["bytes_per_photon"] == 40 and v["trace_seconds"] >= 0 and v["build_seconds"] >= 0
    assert_clean(res, scene)


# --- exact answers ---------------------------------------------------------------------


def test_beer_lambert_slabs_exact():
    """reference_scenes/homogeneous_slab (albedo 0: nothing in-scatters):
    every pixel through slab i is exactly exp(-tau_i) (Beer-Lambert over the
    marched segment), beside the slabs exactly 1. No noise at all, so the
    tolerance is float rounding (1e-5); a 1 % error is 1000 times that."""
    res = rm.render(rm.load_file(ROOT / "homogeneous_slab" / "scene.xml", res=64), integrator=_pm(), spp=2, seed=2)
    assert_clean(res, "homogeneous_slab")
    for (x0, y0, x1, y1), tau in [((2, 10, 14, 54), 0.25), ((18, 10, 30, 54), 0.5), ((34, 10, 46, 54), 1.0),
                                  ((50, 10, 62, 54), 2.0)]:
        box = res.image[y0:y1, x0:x1].astype(np.float64)
        assert np.allclose(box, math.exp(-tau), rtol=1e-5), (tau, box.min(), box.max())
        assert not np.allclose(box, 1.01 * math.exp(-tau), rtol=1e-5)
    assert np.all(res.image[0:8] == 1.0) and np.all(res.image[56:64] == 1.0)
    assert "volume" not in res.stats["photon_maps"]  # purely absorbing: no photon could be stored
    assert not res.effects["volume"].any()


@pytest.mark.parametrize("g", [None, 0.6], ids=["isotropic", "hg0.6"])
def test_single_scattering_point_light_matches_closed_form(g):
    """test_media.py's radiance meter in an unbounded medium with a point
    light beside the ray, max_depth 2: light -> medium point -> sensor only,
    which photonmapper gets from ray marching with light sampling at the
    jittered steps (unbiased: one uniform offset per ray makes the step sum
    an unbiased quadrature). Measured at 4096 spp: relative standard error
    4e-4 (isotropic) / 6e-4 (hg), z +0.8 both; a 1 % error is ~20 standard
    errors."""
    res = check_single_scatter_point_light(g, "photonmapper", 4096)
    assert res.stats["photon_maps"] == {}


SEEDS = range(1, 7)  # photon maps averaged in the van de Hulst slab test


def test_vandehulst_slab_boundary_bias_shrinks():
    """van de Hulst's slab (tau 2, albedo 0.9, g 0.75; diffuse transmittance
    T_d = 0.52562 from the published tables, test_media.py): the worst case
    of the volume estimate's boundary bias, a slab only two mean free paths
    thick and 100 wide, so that the photons' density is low and the
    estimate's sphere (r ~ 0.9 mean free paths at 400 000 photons, 64 per
    estimate) pokes out of both faces. Measured (16384 samples, seed 1):
    -43 % at 50 000 photons, -19 % at 400 000, -12 % at 1 600 000 (and at
    400 000 with 16 photons per estimate), i.e. the bias scales as
    r ~ N^(-1/3) (predicted ratio 0.5 per factor 8, measured 0.44, 0.62 per
    factor 4): it converges, slowly, and is the reason this scene is not a
    pass/fail reference for photon mapping (with the seed's estimate; the
    boundary correction below takes most of it away). One photon map's
    error is itself noisy: over seeds 1-8 it ran from -14 % to -43 % at
    50 000 photons and -10 % to -24 % at 400 000 (single-seed ratios 0.35 to
    1.48), so the errors are means over SEEDS photon maps (seeds 1-6:
    -30.5 % and -17.0 %, ratio 0.56, its standard error about 0.1; under
    seed offset 2: -27.1 % and -10.2 %, corrected +5.8 %), and the bounds
    allow that spread."""
    pub = 0.66096 - math.exp(-2.0)
    scene = rm.load_file(ROOT / "vandehulst_slab" / "scene.xml")

    def error(**pm):
        errs = []
        for seed in SEEDS:
            r = rm.render(scene, integrator=_pm(global_photons=0, caustic_photons=0, **pm), spp=1 << 14, seed=seed)
            assert_clean(r, "vandehulst_slab")
            errs.append(float(r.image[0, 0, 0]) / pub - 1)
        return float(np.mean(errs))

    err = {n: error(volume_photons=n) for n in (50000, 400000)}
    assert -0.55 < err[50000] < err[400000] < -0.05, err
    assert 0.3 < err[400000] / err[50000] < 0.85, f"bias ratio per factor 8 of photons (N^(-1/3): 0.5): {err}"
    # volume_boundary_rays (off by default): the sphere's volume measured
    # inside the slab with 16 rays. Measured: -23 % at 50 000, -4.3 % at
    # 400 000 (64 rays: -4.4 %); what is left is the blur of the density's
    # gradient, which shrinks as r^2 rather than r.
    corrected = error(volume_photons=400000, volume_boundary_rays=16)
    assert abs(corrected) < abs(err[400000]) and abs(corrected) < 0.08, (corrected, err)


# --- against volpath: fog ---------------------------------------------------------------

FOG_RES = 16


@pytest.fixture(scope="module")
def fog_ref():
    """fog_room from volpath, 16 x 16 at 4096 spp, for the effect classes
    (Mitsuba's reference holds only the total)."""
    scene = rm.load_file(ROOT / "fog_room" / "scene.xml", res=FOG_RES)
    return scene, rm.render(scene, integrator="volpath", spp=4096, seed=1)


@pytest.fixture(scope="module")
def fog_mitsuba():
    """Mitsuba 3's fog_room reference, block-averaged to 16 x 16: relative
    standard error of the top / bottom half's mean 0.17 % / 0.09 %. Our
    volpath at 4096 spp is no good reference for the bias here: next event
    estimation to the spot light from fog right next to it has a 1 / d^2
    tail, so most renders are low and a rare one high (measured: the top
    half of one such render 4.3 % below Mitsuba's)."""
    scene = rm.load_file(ROOT / "fog_room" / "scene.xml", res=FOG_RES)
    ref = rm.read_exr(ROOT / "fog_room" / "reference.exr").image.astype(np.float64)
    f = ref.shape[0] // FOG_RES
    return scene, ref.reshape(FOG_RES, f, FOG_RES, f, 3).mean(axis=(1, 3))


def _halves(img):
    h = img.shape[0] // 2
    return np.array([img[:h].mean(), img[h:].mean()], np.float64)


def _errors(renders, ref, regions):
    """Per budget: the relative error of each region's mean, per seed
    (array seeds x regions)."""
    return {n: np.array([regions(r.image) / regions(ref) - 1 for r in rs]) for n, rs in renders.items()}


def _rms(e):
    """RMS over seeds and regions: sqrt(bias^2 + variance) of the estimate
    with its photon map's noise (shared by all pixels of one render, which
    the per-pixel variance does not show)."""
    return float(np.sqrt(np.mean(e ** 2)))


# Measured (16 x 16, 8 spp, seeds 0-2; relative error of the top / bottom
# half's mean against Mitsuba's reference), mean over seeds +- their spread:
#   volume_photons      0: -54 % / -38 %  (no multiple scattering at all)
#                    1000: -5.8 +- 6.3 % / -3.1 +- 1.1 %
#                   16000: -2.1 +- 1.7 % / -1.3 +- 1.3 %
#                  128000: -1.5 +- 1.5 % / -0.9 +- 0.9 %
# The bottom half (the floor's lit disc and the fog above it) shows the
# bias itself: negative (the estimate's sphere reaches past the floor and
# walls, where no fog is, and blurs the lit cone) and shrinking.
# The camera pass's own noise is heavy-tailed (light sampling of the spot
# light from fog right beside it: a 1 / d^2 tail), and the same for every
# map size with the same seed: over seeds 0-17, seed 15's bottom half is
# +46 to +49 % at every budget and seed 5's top +13 to +14 % at 16000 and
# 128000 photons. An RMS over 3 seeds (the test's statistic before) was
# 1.8 % at 128000 photons for seeds 0-2 but 5.2 % and 8.3 % under fresh
# seed offsets 2 and 3. So the statistic is the median over 6 seeds and both
# halves of |relative error|, which such spikes do not move: at 128000
# photons 2.0 / 2.0 / 1.2 % for seeds 0-5 / 6-11 / 12-17, at 1000 photons
# 4.5 / 8 / 5.2 %; against a reference 10 % too bright about 8 %.
FOG_TOL = 0.04
FOG_BUDGETS = (1000, 16000, 128000)
FOG_SEEDS = range(6)


def _median_abs(e):
    return float(np.median(np.abs(e)))


def test_fog_room_error_falls_against_mitsuba(fog_mitsuba):
    """The volume map's error against Mitsuba falls as the map grows, to
    within FOG_TOL (median |error| over seeds and halves, see above). The
    bottom half's bias (-3.1 % at 1000 photons, -0.9 % at 128000) is below
    what 6 seeds at 8 spp resolve under fresh noise, so the test asks for
    the total error to fall, not the bias alone."""
    scene, ref = fog_mitsuba
    renders = {n: [rm.render(scene, integrator=_pm(volume_photons=n), spp=8, seed=s) for s in FOG_SEEDS]
               for n in FOG_BUDGETS}
    for rs in renders.values():
        assert_clean(rs[0], "fog_room")
    err = _errors(renders, ref, _halves)
    med = {n: _median_abs(e) for n, e in err.items()}
    lo, hi = FOG_BUDGETS[0], FOG_BUDGETS[-1]
    assert med[hi] <= FOG_TOL, med
    assert med[lo] > med[hi], f"the error must fall as the volume map grows: {med}"
    # Power: the same tolerance rejects the estimator without multiple
    # scattering (no volume map) and a reference 10 % too bright.
    none = _errors({0: [rm.render(scene, integrator=_pm(volume_photons=0), spp=8, seed=0)]}, ref, _halves)
    assert _median_abs(none[0]) > 5 * FOG_TOL
    assert _median_abs(_errors({hi: renders[hi]}, 1.1 * ref, _halves)[hi]) > FOG_TOL


def test_fog_room_classes_match_volpath(fog_ref):
    """Light that scattered in the fog is filed under `volume`, also when a
    surface photon of the global map carried it (L V D E), as volpath files
    it: each class's image mean, the median over 5 seeds, within 8 % of
    volpath's. Measured over seeds 0-11 (one render each): direct -1.8 to
    +2.3 %, indirect -11.3 to +7.5 %, volume -3.4 to +7.6 % (the 4096 spp
    volpath reference's own volume class moves by up to 4.7 % between
    seeds: the same 1 / d^2 tail as above); medians of seeds 0-4 / 5-9:
    indirect +2.6 / -1.4 %, volume +0.2 / +5.9 %. Light filed in the
    wrong class moves two classes by far more: multiple scattering in the
    fog is 38 to 54 % of the image (the estimator without a volume map,
    measured above)."""
    scene, ref = fog_ref
    rs = [rm.render(scene, integrator=_pm(volume_photons=64000), spp=8, seed=s) for s in range(5)]
    for k in ("direct", "indirect", "volume"):
        ratio = float(np.median([float(r.effects[k].mean()) for r in rs])) / float(ref.effects[k].mean())
        assert abs(ratio - 1) < 0.08, (k, ratio)
    for k in ("caustic", "specular", "subsurface", "emission"):
        assert not any(r.effects[k].any() for r in rs), k


def test_fog_room_global_map_seen_directly(fog_mitsuba):
    """final_gather off: the global map (its photons attenuated through the
    fog, those that scattered in it filed as volume light) read at the
    camera's first surface, no gather rays through the fog. One render's
    halves carry the camera pass's 1 / d^2 tail (FOG_TOL's note): against
    Mitsuba (64 000 volume and 50 000 global photons, seeds 0-14, one render
    each) the top half is -5.1 to +14.1 %, the bottom -2.3 to +1.6 %; a
    single render under seed offset 5 was 7.5 % off. So the statistic is
    the median over 5 seeds, per half: seeds 0-4 / 5-9 / 10-14 gave
    +0.3 / +2.2 / -2.4 % (top) and -0.9 / -0.5 / -0.3 % (bottom); held to
    5 %, and a reference 10 % too bright must fall outside it."""
    scene, ref = fog_mitsuba
    rs = [rm.render(scene, integrator=_pm(volume_photons=64000, global_photons=50000, final_gather=False), spp=8,
                    seed=s) for s in range(5)]
    assert_clean(rs[0], "fog_room, final_gather off")
    med = np.median(_errors({0: rs}, ref, _halves)[0], axis=0)
    assert np.all(np.abs(med) < 0.05), med
    med_s = np.median(_errors({0: rs}, 1.1 * ref, _halves)[0], axis=0)
    assert np.all(np.abs(med_s) > 0.05), f"a reference 10 % too bright went undetected: {med_s}"
    assert all(r.effects["volume"].mean() > 0.5 * r.image.mean() for r in rs)


# --- subsurface: translucent_slab ---------------------------------------------------------


def _lit_dark(img):
    """Means over the lit half (x > 0, light enters below it) and the dark half."""
    w = img.shape[1] // 2
    return np.array([img[:, w:].mean(), img[:, :w].mean()], np.float64)


# Measured (16 x 16, 4 spp, 6 seeds; relative error of the lit / dark
# half's mean against volpath at 2048 spp, standard error 0.3 % / 1.4 %):
#   volume_photons  10000: -6.5 +- 5.4 % / -14 +- 14 %
#                   40000: -5.5 +- 3.6 % / -14 +- 10 %
#                  160000: -5.7 +- 1.7 % / -12 +- 7 %
#                  640000: -3.9 +- 1.2 % / -8 +- 2 %
# and with this test's seeds 0-2 (volpath at 1024 spp / Mitsuba), the lit
# half: 10000 -10.6 % / -10.7 % (RMS 12.0 %), 80000 -7.6 % / -7.7 %
# (7.8 %), 640000 -4.8 % / -4.9 % (5.0 %). (The 6-seed rows above were
# taken with half the default step; the step moves noise, not the mean.)
# The lit half's bias is the boundary bias of the volume estimate: camera
# rays enter through the top face, where the in-scattered light is
# largest and the estimate's sphere is half outside the slab; it shrinks
# with r ~ N^(-1/3). With 16 photons per estimate instead of 64 it is
# +1.3 % (320 000 photons), with 4: +30 % (n / (n - 1) = 4/3 of the n-th
# photon on the sphere's rim takes over): a density-estimation bias, not
# one of the photon tracing. The dark half is lit only by light diffusing
# across the shadow edge, in clumps of photons from a few long light paths:
# far noisier. volpath against Mitsuba 3's reference: lit +0.5 %, dark -1 %.
SLAB_LIT_BAND = (-0.08, 0.02)
SLAB_BUDGETS = (10000, 80000, 640000)
# All diffuse surfaces of translucent_slab are black: no surface maps needed.
SLAB_PM = {"global_photons": 0, "caustic_photons": 0}


def test_translucent_slab_against_volpath_and_mitsuba():
    scene = rm.load_file(ROOT / "translucent_slab" / "scene.xml", res=16)
    ref = rm.render(scene, integrator="volpath", spp=1024, seed=1)
    mitsuba = rm.read_exr(ROOT / "translucent_slab" / "reference.exr")
    m = mitsuba.image.reshape(16, 4, 16, 4, 3).mean(axis=(1, 3))
    renders = {n: [rm.render(scene, integrator=_pm(volume_photons=n, **SLAB_PM), spp=4, seed=s) for s in (0, 1, 2)]
               for n in SLAB_BUDGETS}
    r = renders[SLAB_BUDGETS[-1]][0]
    assert_clean(r, "translucent_slab")
    assert set(r.stats["photon_maps"]) == {"volume"}
    assert r.effects["subsurface"].mean() > 0.8 * r.image.mean()  # the light under the top face is B
    assert not r.effects["volume"].any()
    lo, hi = SLAB_LIT_BAND
    for name, target in (("volpath", ref.image), ("Mitsuba", m)):
        err = _errors(renders, target, _lit_dark)
        lit = float(err[SLAB_BUDGETS[-1]][:, 0].mean())
        assert lo <= lit <= hi, f"lit half vs {name}: {lit:+.3f} outside {SLAB_LIT_BAND}"
        rms = {n: _rms(e[:, 0]) for n, e in err.items()}
        assert rms[SLAB_BUDGETS[0]] > rms[SLAB_BUDGETS[-1]], f"vs {name}: the error must fall: {rms}"
    # Power: a reference 10 % brighter leaves the band, and without the
    # volume map the slab is dark (only light that crossed it unscattered).
    err = _errors({0: renders[SLAB_BUDGETS[-1]]}, 1.1 * ref.image, _lit_dark)[0]
    assert not lo <= float(err[:, 0].mean()) <= hi
    none = rm.render(scene, integrator=_pm(volume_photons=0, **SLAB_PM), spp=4, seed=0)
    assert _lit_dark(none.image)[0] < 0.2 * _lit_dark(ref.image)[0]


# --- heterogeneous media ------------------------------------------------------------------


def test_grid_medium_matches_homogeneous_volpath(tmp_path):
    """test_ptracer_media.py's constant grid with one hot voxel (sigma_t
    exactly 1 / 2 / 0.5 inside the backlit slab, majorant 6): photons take
    delta-tracking flights, camera rays march with ratio-tracked
    transmittance. Against volpath on the same homogeneous medium (1024
    spp): measured image mean -0.3 to -0.7 % per channel, volume class
    -0.1 to -0.7 % (2 seeds at 100 000 photons); held to 2 % / 3 %."""
    het, hom = hot_voxel_grid(tmp_path)
    ref = rm.render(rm.load_dict(small_light_slab(hom)), integrator="volpath", spp=1024, seed=2)
    a = rm.render(rm.load_dict(small_light_slab(het)),
                  integrator=_pm(volume_photons=100000, global_photons=0, caustic_photons=0), spp=16, seed=0)
    assert_clean(a, "grid slab")
    ratio = a.image.mean(axis=(0, 1)) / ref.image.mean(axis=(0, 1))
    assert np.all(np.abs(ratio - 1) < 0.02), ratio
    vol = float(a.effects["volume"].mean() / ref.effects["volume"].mean())
    assert abs(vol - 1) < 0.03 and ref.effects["volume"].mean() > 0.1 * ref.image.mean(), vol


# --- refusals, parameters, determinism -----------------------------------------------------


def test_sppm_refuses_media_naming_the_alternatives():
    scene = rm.load_file(ROOT / "fog_room" / "scene.xml", res=8)
    with pytest.raises(ValueError, match="integrator 'sppm' does not support participating media.*volpath.*"
                                         "photonmapper"):
        rm.render(scene, integrator={"type": "sppm", "photon_count": 1000}, spp=1)


@pytest.mark.parametrize("integrator,param", [
    (_pm(volume_photons=-1), "volume_photons"),
    (_pm(volume_lookup_size=0), "volume_lookup_size"),
    (_pm(volume_lookup_radius=0.0), "volume_lookup_radius"),
    (_pm(step_size=-0.1), "step_size"),
    (_pm(volume_boundary_rays=-1), "volume_boundary_rays"),
    (_pm(volume_photons=10, volumePhotons=10), "volumePhotons"),
])
def test_bad_volume_parameters_name_themselves(integrator, param):
    scene = rm.load_file(ROOT / "fog_room" / "scene.xml", res=8)
    with pytest.raises(rm.SceneError, match=param):
        rm.render(scene, integrator=integrator, spp=1)


def test_core_rejects_bad_volume_parameters():
    from radiometer import _core

    scene = rm.load_file(ROOT / "fog_room" / "scene.xml", res=8)
    for attr, v in [("volume_photons", -1), ("volume_lookup_size", 0), ("volume_lookup_radius", -1.0),
                    ("step_size", -1.0), ("step_size", float("nan")), ("volume_boundary_rays", -1),
                    ("volume_boundary_rays", 5000)]:
        d = _core.IntegratorDesc()
        d.type = "photonmapper"
        setattr(d, attr, v)
        with pytest.raises(ValueError, match=attr):
            _core.render(scene.core(), d, [True] * 7, 1, 0.0, 0, 1, [], None)


def test_mitsuba06_volume_names_and_step_size():
    """volumePhotons / volumeLookupRadius are aliases; an explicit step_size
    changes the quadrature but not its expectation (homogeneous media:
    exact transmittance, jittered steps), so both agree within noise. The
    noise is the camera pass's 1 / d^2 tail near the spot light, so one
    render pair can differ by far more than any bias (measured at 8 x 8,
    1 spp: the pair's ratio 0.94 to 1.31 over seeds 0-7, 100-107, 200-207;
    under seed offset 5 one pair was 38 % apart). The statistic is the
    median over 8 seeds of the pair's ratio (same seed: same photon map):
    0.995 / 0.994 / 1.017 for those seed sets, held to 5 %; a 10 % change of
    the expectation must fall outside it."""
    scene = rm.load_file(ROOT / "fog_room" / "scene.xml", res=8)
    a = rm.render(scene, integrator=_pm(volumePhotons=2000, volumeLookupRadius=0.1), spp=1, seed=1)
    b = rm.render(scene, integrator=_pm(volume_photons=2000, volume_lookup_radius=0.1), spp=1, seed=1)
    assert a.image.tobytes() == b.image.tobytes()
    ratios = []
    for s in range(8):
        b = rm.render(scene, integrator=_pm(volume_photons=2000, volume_lookup_radius=0.1), spp=1, seed=s)
        c = rm.render(scene, integrator=_pm(volume_photons=2000, volume_lookup_radius=0.1, step_size=0.05), spp=1,
                      seed=s)
        assert c.image.tobytes() != b.image.tobytes()
        ratios.append(float(c.image.mean()) / float(b.image.mean()))
    med = float(np.median(ratios))
    assert abs(med - 1) < 0.05, ratios
    assert abs(1.1 * med - 1) > 0.05, f"a 10 % change went undetected: {ratios}"


def test_same_bytes_whatever_threads_on_media():
    scene = rm.load_file(ROOT / "fog_room" / "scene.xml", res=16)
    assert_same_bytes_whatever_threads(scene, _pm(volume_photons=20000), spp=2)
