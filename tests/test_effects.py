"""Effect classes (DESIGN section 3) in a scene that has them all: a diffuse
floor, a mirror wall and a small light. Every contribution is filed under
exactly one class; the classes sum to the image; asking for one class
simulates only it."""
import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.stats import z_test

ALPHA = 0.01


def mirror_room(res=24):
    rot_y = np.array([[0, 0, -1, 0.9], [0, 1, 0, 0], [1, 0, 0, 0.8], [0, 0, 0, 1.0]])  # faces -x, at x = 0.9
    light = np.array([[0.2, 0, 0, 0], [0, -0.2, 0, 0], [0, 0, -1, 1.2], [0, 0, 0, 1.0]])  # faces down
    cam = np.array([[-1, 0, 0, 0], [0, 0.1736, 0.9848, -2.0], [0, 0.9848, -0.1736, 0.6], [0, 0, 0, 1.0]])  # 10 deg down
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "floor": {"type": "rectangle", "to_world": np.diag([2.0, 2.0, 1, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.7]}}},
        "mirror": {"type": "rectangle", "to_world": rot_y, "bsdf": {"type": "conductor"}},
        # The light reflects (diffuse 0.5, explicit: an emitter without a
        # BSDF is black, as in Mitsuba 3), so that indirect light exists:
        # light -> floor -> light's face -> floor.
        "light": {"type": "rectangle", "to_world": light,
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}},
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [20, 20, 20]}}},
        "sensor": {"type": "perspective", "fov": 70, "to_world": cam,
                   "film": {"type": "hdrfilm", "width": res, "height": res}},
    }


@pytest.fixture(scope="module")
def scene():
    return rm.load_dict(mirror_room())


def test_every_class_present_and_summing(scene):
    res = rm.render(scene, spp=64, seed=0)
    total = sum(res.effects[k].astype(np.float64) for k in rm.EFFECTS)
    np.testing.assert_allclose(total, res.image, rtol=1e-5, atol=1e-6)
    for k in ("emission", "direct", "indirect", "caustic", "specular"):
        assert res.effects[k].sum() > 0, k
    for k in ("volume", "subsurface"):
        assert not res.effects[k].any(), k
    assert res.stats["features"]["has_delta_bsdf"] is True


@pytest.mark.parametrize("effect", ["caustic", "specular", "direct", "indirect"])
def test_one_effect_alone_matches_its_share_of_the_full_render(scene, effect):
    full = rm.render(scene, spp=128, seed=1)
    alone = rm.render(scene, spp=128, seed=2, effects=[effect])
    for k in rm.EFFECTS:
        if k != effect:
            assert not alone.effects[k].any()
    # Compare the class images; the variance of a class image is bounded by
    # the variance of the whole-sample estimate, which both renders report.
    t = z_test(alone.image, alone.variance, full.effects[effect], full.variance, alpha=ALPHA)
    assert t.passed, t.summary()
    assert alone.stats["rays"] <= full.stats["rays"]


def test_caustic_is_the_light_through_the_mirror(scene):
    """Remove the mirror: the caustic class vanishes and `direct` is unchanged."""
    d = mirror_room()
    del d["mirror"]
    plain = rm.render(rm.load_dict(d), spp=64, seed=3)
    assert not plain.effects["caustic"].any() and not plain.effects["specular"].any()
    assert plain.stats["features"]["has_delta_bsdf"] is False
    with_mirror = rm.render(scene, spp=64, seed=4, effects=["direct"])
    # The mirror shadows part of the floor from nothing: direct light on the
    # floor is the same with or without it where the mirror is not in view.
    t = z_test(with_mirror.image[:, :8], with_mirror.variance[:, :8], plain.effects["direct"][:, :8],
               plain.variance[:, :8], alpha=ALPHA)
    assert t.passed, t.summary()
