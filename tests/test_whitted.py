"""`whitted` (Whitted 1980): exactly the paths L E, L D E and L D? S+ E.

Checked where those are the whole answer or a known part of it, each at
level ALPHA with a power check on the same render:
- area lights (all direct light): against the exact image, 4 x 4 blocks,
  a cell of tests/test_estimator_matrix.py (with the furnace and the
  mirror caustic);
- a glass sphere in a white constant environment: every camera path that
  leaves the glass carries exactly 1 (Fresnel's R + T = 1, the eta^2 of
  entering and leaving cancel), so the image is 1 to rounding: any error in
  the delta chain's weights shows in every pixel;
- Mitsuba's Cornell box: whitted's image against path's emission + direct
  classes (its other classes are zero by construction), both with variance.
"""
import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.blocks import blocked_z_test
from test_canonical_analytic import assert_clean

ALPHA = 0.01


def glass_in_white_sky(res=16):
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 30,
                       "to_world": np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 4], [0, 0, 0, 1]], float),
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
            "ball": {"type": "sphere", "radius": 1.0, "bsdf": {"type": "dielectric", "int_ior": 1.5}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}


def test_glass_in_white_sky_is_exactly_one():
    r = rm.render(rm.load_dict(glass_in_white_sky()), integrator={"type": "whitted", "max_depth": 64}, spp=16,
                  seed=3)
    assert_clean(r)
    assert r.effects["specular"].mean() > 0.5  # most pixels see the sky through the glass
    np.testing.assert_allclose(r.image, 1.0, rtol=2e-5)
    # The check can fail: cut at 2 segments, paths that enter the glass end inside it (black).
    cut = rm.render(rm.load_dict(glass_in_white_sky()), integrator={"type": "whitted", "max_depth": 2}, spp=16,
                    seed=3)
    assert not np.allclose(cut.image, 1.0, rtol=2e-5)


def test_cornell_box_equals_path_emission_plus_direct():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    d = mi.cornell_box()
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 32
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    scene = rm.load_dict(d)
    w = rm.render(scene, integrator="whitted", spp=256, seed=21)
    p = rm.render(scene, integrator="path", spp=256, seed=22, effects=["emission", "direct"])
    assert_clean(w)
    for cls in ("indirect", "caustic", "specular", "volume", "subsurface"):
        assert not w.effects[cls].any(), cls
    # path's per-pixel variance covers its whole image, which is emission + direct here
    passed, msg = blocked_z_test(w.image, w.variance, p.image, p.variance, alpha=ALPHA, label="whitted vs path ")
    assert passed, msg
    assert not blocked_z_test(w.image * 1.02, w.variance, p.image, p.variance, alpha=ALPHA)[0], \
        "a 2 % bias went undetected"


def test_media_are_refused_by_capability():
    """Whitted has no media: a scene with them is refused, not rendered as vacuum."""
    from test_media import slab_dict

    scene = rm.load_dict(slab_dict({"type": "homogeneous"}))
    with pytest.raises(ValueError, match="integrator 'whitted' does not support participating media"):
        rm.render(scene, integrator="whitted", spp=1)
