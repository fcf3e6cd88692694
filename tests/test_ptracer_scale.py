"""`ptracer` under a constant (environment) emitter is independent of the
scene's scale: light paths from infinity start on a disk just wider than the
scene's bounding sphere (emitter.h's infinite_disk_radius), and that margin
must shrink with the scene (an absolute 1e-6 made a scene of size 1e-8 start
them on a disk 35 times its width: 1 path in 1200 reached it, and the image
read 6-14 % dark with effects swapped between classes).

The same scene (a diffuse floor and sphere, 16 x 16, box filter) at scale 1
and 1e-8, camera and clip planes scaled with it: ptracer against path,
4 x 4 block z-test (refcompare.assert_agrees, its level ALPHA), with a power
check (a 5 % error in path's image is rejected at both scales); and, with
the same seed, the same light paths at both scales: the images agree to
float rounding.
"""
import numpy as np
import pytest

import radiometer as rm
from refcompare import _rgb, assert_agrees, assert_clean, lookat

SCALES = (1.0, 1e-8)


def scaled_scene(scale, res=16):
    s = np.diag([scale, scale, scale, 1.0])
    return rm.load_dict({
        "type": "scene",
        "floor": {"type": "rectangle", "to_world": s @ np.diag([2.0, 2.0, 1.0, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": _rgb([0.5, 0.5, 0.5])}},
        "ball": {"type": "sphere", "center": [0, 0, 0.5 * scale], "radius": 0.5 * scale,
                 "bsdf": {"type": "diffuse", "reflectance": _rgb([0.7, 0.6, 0.5])}},
        "sky": {"type": "constant", "radiance": _rgb([1.0, 0.9, 0.8])},
        "sensor": {"type": "perspective", "fov": 60, "near_clip": 1e-2 * scale, "far_clip": 1e3 * scale,
                   "to_world": lookat([0, -3 * scale, 3 * scale], [0, 0, 0], (0, 0, 1)),
                   "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}})


@pytest.fixture(scope="module")
def renders():
    out = {}
    for scale in SCALES:
        scene = scaled_scene(scale)
        out[scale] = (rm.render(scene, integrator="path", spp=256, seed=1),
                      rm.render(scene, integrator="ptracer", spp=256, seed=2))
    return out


@pytest.mark.parametrize("scale", SCALES)
def test_ptracer_matches_path_at_any_scale(renders, scale):
    path, pt = renders[scale]
    assert_clean(pt, f"scale {scale}")
    assert_agrees(pt, path, power=0.95, what=f"constant emitter at scale {scale}: ptracer vs path")


def test_same_light_paths_at_both_scales(renders):
    """Same seed at scale 1 and 1e-8: the light paths are the same up to
    rounding, so the images (and their effect classes) agree closely; with
    the old absolute margin the small scene's were a different, far noisier
    estimate."""
    big, small = renders[1.0][1], renders[1e-8][1]
    np.testing.assert_allclose(small.image.mean(), big.image.mean(), rtol=1e-3)
    for k in ("emission", "direct", "indirect"):
        np.testing.assert_allclose(small.effects[k].mean(), big.effects[k].mean(), rtol=1e-3, err_msg=k)
