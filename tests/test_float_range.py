"""Scenes beyond what float32 ray tracing represents are refused with an
error naming the limit, instead of aborting the interpreter in Embree's
`ray.valid()` assertion; a camera whose far clip misses every shape warns."""
import numpy as np
import pytest

import radiometer as rm
from test_dipole import sphere_scene

BOX = {"type": "cube", "bsdf": {"type": "diffuse"}}


def _scene(sensor_to_world, sensor="perspective", shape_scale=1.0, far_clip=None):
    s = {"type": sensor, "to_world": sensor_to_world, "film": {"type": "hdrfilm", "width": 4, "height": 4}}
    if far_clip is not None:
        s["far_clip"] = far_clip
    return {"type": "scene", "sensor": s,
            "box": dict(BOX, to_world=np.diag([shape_scale, shape_scale, shape_scale, 1.0])),
            "light": {"type": "constant"}}


def _at(z, scale=1.0):
    # looking down -z from (0, 0, z); Mitsuba's camera looks along +z locally
    return np.array([[scale, 0, 0, 0], [0, scale, 0, 0], [0, 0, -scale, z], [0, 0, 0, 1]], float)


@pytest.mark.parametrize("integrator", ["path", "bdpt", "ptracer"])
def test_camera_beyond_embree_range_is_refused(integrator):
    with pytest.raises(rm.SceneError, match=r"1\.8e18"):
        rm.render(rm.load_dict(_scene(_at(3e18))), integrator=integrator, spp=1)


def test_camera_inside_range_renders():
    """The control: the same scene with the camera near renders and sees the box."""
    r = rm.render(rm.load_dict(_scene(_at(4.0))), integrator="path", spp=4)
    assert np.isfinite(r.image).all() and r.image.mean() > 0


def test_geometry_beyond_embree_range_is_refused():
    with pytest.raises(rm.SceneError, match=r"geometry reaches .*1\.8e18"):
        rm.render(rm.load_dict(_scene(_at(4.0), shape_scale=3e18)), integrator="path", spp=1)


@pytest.mark.parametrize("scale", [1e-30, 1e30])
def test_degenerate_orthographic_scale_is_refused(scale):
    with pytest.raises(rm.SceneError, match="outside what float32 ray directions represent"):
        rm.render(rm.load_dict(_scene(_at(4.0, scale), sensor="orthographic")), integrator="path", spp=1)


@pytest.mark.parametrize("sigma", [1e-18])
def test_dipole_radius_beyond_range_is_refused(sigma):
    with pytest.raises(rm.SceneError, match="scattering radius"):
        rm.render(rm.load_dict(sphere_scene(sigma, sigma, res=4)), integrator="path", spp=1)


def test_scaled_scene_beyond_far_clip_warns():
    """A scene scaled by 1e13 without its clip planes: black for camera paths."""
    big = _scene(_at(4e13), shape_scale=1e13)
    with pytest.warns(rm.SceneWarning, match="far_clip"):
        rm.render(rm.load_dict(big), integrator="path", spp=1)
    ok = _scene(_at(4e13), shape_scale=1e13, far_clip=1e14)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", rm.SceneWarning)
        r = rm.render(rm.load_dict(ok), integrator="path", spp=4)
    assert r.image.mean() > 0
