"""vcm, bpm and ppm (renderer/estimators/vcm.cpp): the MIS weights against
a brute force from full-path densities, with a mutation each that the check
must catch; vcm without merging against bdpt and without connections
against bpm (z-tests of 4 x 4 block means, each channel at ALPHA / 3, with
a power check); the bias of the merges shrinking with the iterations;
stability (no NaN, Inf or negative pixel; the same bytes whatever the
thread count; effects summing to the image) and the refusals of bad
parameters and of media. Every estimator against the canonical scenes:
tests/test_estimator_matrix.py."""
from __future__ import annotations

import math

import numpy as np
import pytest

import radiometer as rm
from radiometer import _core
from radiometer.render import _core_integrator, _integrator_desc

from refcompare import assert_clean, assert_same_bytes_whatever_threads, blocked_z, check_mirror_caustic
from test_bdpt import AREA, CORNELL, GLOSSY, MIRROR_BALL, SPHERE_LIGHT, _rgb, small_scene

ALPHA = 0.01


def _mis_check(scene, integ, n=3000, iteration=0, mutation=0):
    spec = _integrator_desc(integ, scene.desc.integrator)
    return _core.vcm_mis_check(scene.core(), _core_integrator(spec), 7, n, iteration, mutation)


SCENES = {
    "cornell": lambda: rm.load_file(CORNELL, res=8, rfilter="box"),
    "glossy_area": lambda: small_scene(AREA, res=8, extra=GLOSSY),
    "mirror_ball_point": lambda: small_scene({"type": "point", "position": [0.6, -0.5, 1.5],
                                              "intensity": _rgb(3.0)}, res=8, extra=MIRROR_BALL),
    "environment_glossy": lambda: small_scene({"type": "constant", "radiance": _rgb(1.0)}, res=8, extra=GLOSSY),
    "sphere_light_glossy": lambda: small_scene(SPHERE_LIGHT, res=8, extra=GLOSSY),
    "directional_glossy": lambda: small_scene({"type": "directional", "direction": [0.3, 0.5, -0.8],
                                               "irradiance": _rgb(1.0)}, res=8, extra=GLOSSY),
}
# radius 0.2: merges that take a real share of the weights (at the default
# 0.01 their weights are ~1e-4 on these 8 x 8 films).
CONFIGS = {"vcm": {"type": "vcm", "radius": 0.2}, "vcm-default": {"type": "vcm"},
           "bpm": {"type": "bpm", "radius": 0.2}, "vcm-no-merging": {"type": "vcm", "merging": False}}


@pytest.mark.parametrize("mis", ["power", "balance", "uniform"])
@pytest.mark.parametrize("config", list(CONFIGS))
@pytest.mark.parametrize("which", list(SCENES))
def test_mis_weights_match_brute_force(which, config, mis):
    """Every connection (s, t) of random subpath pairs, every length, gives a
    full path; each technique that can make it (connections s' = 0 .. k,
    merges at its non-delta surface vertices) is weighted by the renderer's
    recursion (the path split into the technique's subpaths) and by brute
    force from each technique's full-path density (merges: pi r^2 n_L times
    the light-path density). They agree, the renderer's weights of one path
    sum to 1, and the renderer's weight of each pair's own connection on its
    walked subpaths matches too. Delta vertices (mirror, plastic's coat,
    point and directional lights) and emitters at infinity included."""
    scene = SCENES[which]()
    fast, brute, tech, sums, own_fast, own_brute = _mis_check(scene, {**CONFIGS[config], "mis": mis})
    merges = tech >= 500000
    assert len(fast) > 3000 and len(np.unique(tech)) > 20, (len(fast), len(np.unique(tech)))
    if CONFIGS[config].get("merging", True):
        assert merges.sum() > 100
    if config in ("vcm", "bpm"):
        assert brute[merges].max() > 0.1, "merges must take a real share somewhere"
    assert np.all(np.isfinite(fast)) and np.all((fast >= 0) & (fast <= 1 + 1e-6))
    np.testing.assert_allclose(fast, brute, rtol=2e-4, atol=1e-6, err_msg=which)
    np.testing.assert_allclose(sums, 1.0, rtol=0, atol=1e-4, err_msg=f"{which}: weights of one path")
    np.testing.assert_allclose(own_fast, own_brute, rtol=2e-4, atol=1e-6, err_msg=f"{which}: walked subpaths")


@pytest.mark.parametrize("mutation,what", [(1, "camera d^VCM without the light-path count"),
                                           (2, "light d^VM 50 % off from y_2 on")])
def test_mis_check_catches_a_broken_quantity(mutation, what):
    """Power of the check above: one broken quantity makes weights differ
    from the brute force and the weights of a path no longer sum to 1.
    Mutation 1 is the camera vertex started without the light-path count
    n_L (d^VCM = 1 / p_cam instead of SmallVCM's n_L / p_cam): with n_L = 64
    light paths per iteration its light tracing is weighted as if it had one
    sample, and the check rejects it."""
    scene = SCENES["cornell"]()
    fast, brute, tech, sums, _, _ = _mis_check(scene, {"type": "vcm", "radius": 0.2}, mutation=mutation)
    assert np.max(np.abs(fast - brute)) > 1e-2, what
    assert np.max(np.abs(sums - 1.0)) > 1e-2, what


def _cornell(res=16):
    return rm.load_file(CORNELL, res=res, rfilter="box", max_depth=5)


def test_vcm_without_merging_equals_bdpt():
    """vcm with merging off is bidirectional path tracing with n_L light
    paths per iteration (SmallVCM's kBpt): unbiased, so its image equals
    bdpt's under the block z-test (independent seeds); power: bdpt scaled by
    1.03 is rejected."""
    scene = _cornell()
    a = rm.render(scene, integrator={"type": "vcm", "merging": False, "max_depth": 5}, spp=256, seed=1)
    b = rm.render(scene, integrator={"type": "bdpt", "max_depth": 5}, spp=256, seed=2)
    assert_clean(a, "vcm without merging")
    passed, msg = blocked_z(a.image, a.variance, b.image, b.variance, alpha=ALPHA)
    assert passed, f"vcm (no merging) / bdpt = {a.image.mean() / b.image.mean():.5f}\n{msg}"
    passed, msg = blocked_z(a.image, a.variance, b.image * 1.03, b.variance * 1.03 ** 2, alpha=ALPHA)
    assert not passed, f"a 3 % error went undetected\n{msg}"


def test_vcm_without_connections_is_bpm():
    """vcm with connections off is bpm: the same engine with the same
    techniques, so the same bytes under one seed; and with independent
    seeds the two agree under the block z-test (both biased alike: same
    radius schedule), power: scaled by 1.05 rejected."""
    scene = _cornell()
    integ = {"max_depth": 5, "radius": 0.03, "light_paths": 8192}
    a = rm.render(scene, integrator={"type": "vcm", "connections": False, **integ}, spp=64, seed=1)
    b = rm.render(scene, integrator={"type": "bpm", **integ}, spp=64, seed=1)
    assert a.image.tobytes() == b.image.tobytes()
    c = rm.render(scene, integrator={"type": "bpm", **integ}, spp=64, seed=2)
    assert_clean(c, "bpm")
    passed, msg = blocked_z(a.image, a.variance, c.image, c.variance, alpha=ALPHA)
    assert passed, msg
    passed, msg = blocked_z(a.image, a.variance, c.image * 1.05, c.variance * 1.05 ** 2, alpha=ALPHA)
    assert not passed, f"a 5 % error went undetected\n{msg}"


def test_merging_bias_shrinks_with_iterations():
    """ppm and bpm with a large radius (0.2 of the scene's radius, so that
    the bias dominates the error) on a 16 x 16 Cornell box, emitters hidden
    (their edge pixels' camera noise is not the merges'): the squared bias
    b2 = mean over pixels of (image - ref)^2 - var - var_ref, ref vcm
    without merging (unbiased, 1024 spp), at 16 and 256 iterations of 2048
    light paths. With r_i = r_1 i^((alpha - 1) / 2) it shrinks; measured
    (seeds 3, 4): b2(16) / b2(256) = 1.64 .. 1.76 at alpha 0.75 (|bias| ~
    N^-0.10, the O(r) bias at the box's edges and corners: mean r_i ~
    N^-0.125), 0.97 .. 1.04 with alpha 0.999, the radius kept. Asked: above
    1.35, and (power) below 1.2 with the radius kept."""
    scene = _cornell()
    hide = {"max_depth": 5, "hide_emitters": True}
    ref = rm.render(scene, integrator={"type": "vcm", "merging": False, **hide}, spp=1024, seed=5)
    for est in ("ppm", "bpm"):
        b2 = {}
        for alpha, n in ((0.75, 16), (0.75, 256), (0.999, 16), (0.999, 256)):
            integ = {"type": est, "radius": 0.2, "alpha": alpha, "light_paths": 2048, **hide}
            r = rm.render(scene, integrator=integ, spp=n, seed=3)
            b2[alpha, n] = float(np.mean((r.image - ref.image) ** 2 - r.variance - ref.variance))
        assert b2[0.75, 256] > 0, b2
        assert b2[0.75, 16] / b2[0.75, 256] > 1.35, f"{est}: squared bias at 16 and 256 iterations: {b2}"
        assert b2[0.999, 16] / b2[0.999, 256] < 1.2, f"{est}: power: radius kept, squared bias {b2}"


def test_vcm_caustic_bias_shrinks_with_iterations():
    """vcm on glass_sphere_caustic (its Mitsuba reference; the caustic under
    the sphere is made by merges), radius 0.02, 8192 light paths per
    iteration: the squared bias (as above, against the reference with its
    variance) at 8 and 128 iterations. Measured (seeds 3, 4): ratio 3.7 and
    2.3 at alpha 0.75 (|bias| ~ N^-0.24 over 8, 32, 128: the O(r^2) bias of
    a smooth caustic, mean r_i^2 ~ N^-0.25), 1.07 and 0.92 with the radius
    kept (alpha 0.999). Asked: above 1.5, and below 1.3 with the radius
    kept (power)."""
    from radiometer.reference_scenes import references, registry

    spec = registry.get("glass_sphere_caustic")
    params = dict(spec.fixed_params)  # the reference's
    scene = rm.load_file(spec.xml, **params)
    ref = references.reference("glass_sphere_caustic", params)
    md = registry.max_depth(spec, params)
    b2 = {}
    for alpha, n in ((0.75, 8), (0.75, 128), (0.999, 8), (0.999, 128)):
        integ = {"type": "vcm", "radius": 0.02, "alpha": alpha, "light_paths": 8192, "max_depth": md}
        r = rm.render(scene, integrator=integ, spp=n, seed=3)
        b2[alpha, n] = float(np.mean((r.image - ref.image) ** 2 - r.variance - ref.variance))
    assert b2[0.75, 128] > 0, b2
    assert b2[0.75, 8] / b2[0.75, 128] > 1.5, f"squared bias at 8 and 128 iterations: {b2}"
    assert b2[0.999, 8] / b2[0.999, 128] < 1.3, f"power: radius kept, squared bias {b2}"


@pytest.mark.parametrize("est", ["vcm", "bpm", "ppm"])
def test_same_bytes_whatever_threads_and_effects_sum(est):
    scene = small_scene(AREA, res=16, extra=GLOSSY)
    integ = {"type": est, "max_depth": 5, "radius": 0.05}
    assert_same_bytes_whatever_threads(scene, integ, 4)
    # 64 spp: the caustic or the indirect class was still empty at 4 spp in
    # 12 (vcm) and 15 (bpm) of 40 seeds, at 16 spp in 1 and 2 of 40
    # (measured 2026-12-03), so 4 spp made this a chance outcome.
    r = rm.render(scene, integrator={**integ, "range_search": "kd_tree"}, spp=64, seed=9)
    assert_clean(r, est)
    total = sum(r.effects[k] for k in r.effects)
    np.testing.assert_allclose(total, r.image, rtol=1e-5, atol=1e-7)
    assert r.effects["caustic"].sum() > 0 and r.effects["indirect"].sum() > 0
    # the hash grid and the kd-tree find the same light vertices (sums in another order)
    g = rm.render(scene, integrator=integ, spp=64, seed=9)
    np.testing.assert_allclose(g.image, r.image, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("est", ["vcm", "bpm", "ppm"])
def test_effect_classes_against_the_mirror_caustic(est):
    """Each technique's contribution under its class: on the mirror caustic
    (L S D E by light tracing, merging and the camera hitting the light
    through the mirror; L D E by every technique) the direct and caustic
    images match the method-of-images solution's to 3 % each, the total
    passes the block z-test with a 1 % power check, and no other class
    gets anything (refcompare.check_mirror_caustic). bpm and ppm: a 2 %
    power check, as in test_vcm_reference (their radius bias here is about
    -0.7 % at this budget, and under seed offset 1 both missed 1 %)."""
    check_mirror_caustic(est, 256, power=1.01 if est == "vcm" else 1.02)


@pytest.mark.parametrize("est", ["vcm", "bpm", "ppm"])
def test_technique_images_sum_to_the_image(est, tmp_path):
    """strategy_images = D (D = max_depth): one image per technique, the
    connections (s, t) and the merges ("merge", i, t) of light vertex y_i at
    camera vertex z_{t-1}; they sum to the image, each has its depth's keys
    only, asking for them changes no byte of the image, and the strategy
    pyramid draws the connections."""
    from radiometer.analysis.strategies import strategy_pyramid

    scene = small_scene(AREA, res=16, extra=GLOSSY)
    integ = {"type": est, "max_depth": 4, "radius": 0.05}
    r = rm.render(scene, integrator={**integ, "strategy_images": 4}, spp=4, seed=1)
    merges = sorted(k for k in r.strategies if k[0] == "merge")
    assert merges == sorted(("merge", i, d + 1 - i) for d in range(2, 5) for i in range(1, d))
    assert len(r.strategies) == 14 + 6 and set(r.strategies) == set(r.strategies_unweighted)
    np.testing.assert_allclose(sum(r.strategies.values()), r.image, rtol=1e-5, atol=1e-6)
    assert sum(float(r.strategies[k].sum()) for k in merges) > 0
    plain = rm.render(scene, integrator=integ, spp=4, seed=1)
    assert plain.image.tobytes() == r.image.tobytes()
    assert strategy_pyramid(r, tmp_path / "p.png").exists()


def test_effects_subset_renders_its_classes():
    """An effects subset renders the classes it keeps: vcm's caustic alone
    equals the caustic class of the full render (same seed: the same paths;
    merges and connections filed per technique)."""
    scene = small_scene(AREA, res=16, extra=GLOSSY)
    integ = {"type": "vcm", "max_depth": 5, "radius": 0.05}
    full = rm.render(scene, integrator=integ, spp=4, seed=3)
    part = rm.render(scene, integrator=integ, spp=4, seed=3, effects=["caustic"])
    np.testing.assert_allclose(part.image, full.effects["caustic"], rtol=1e-4, atol=1e-7)


@pytest.mark.parametrize("param,value", [("radius", 0.0), ("radius", -0.1), ("radius", math.inf),
                                         ("radius", math.nan), ("radius", 5.0), ("alpha", 0.0), ("alpha", 1.0),
                                         ("alpha", 1.5), ("light_paths", -3),
                                         ("light_paths", 1 << 30)])
@pytest.mark.parametrize("est", ["vcm", "bpm", "ppm"])
def test_bad_parameters_refused(est, param, value):
    scene = small_scene(AREA, res=8)
    with pytest.raises(rm.SceneError, match=param):
        rm.render(scene, integrator={"type": est, param: value}, spp=1)


def test_both_off_refused_and_media_refused():
    scene = small_scene(AREA, res=8)
    with pytest.raises(rm.SceneError, match="merging"):
        rm.render(scene, integrator={"type": "vcm", "merging": False, "connections": False}, spp=1)
    from radiometer.reference_scenes import registry
    spec = registry.get("homogeneous_slab")
    media = rm.load_file(spec.xml, **spec.fixed_params)
    for est in ("vcm", "bpm", "ppm"):
        with pytest.raises((rm.SceneError, ValueError), match="bdpt"):
            rm.render(media, integrator={"type": est}, spp=1)
