"""Sensors: the directions a perspective camera sends through a uniformly
sampled film follow the projection's density (Pearson chi-square), the
orthographic camera sends parallel rays over its extent, and the
irradiancemeter's directions are cosine-distributed about its normal."""
import math

import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.chi2 import SphereGrid, chi2_test, sidak_level

LEVEL = sidak_level(0.01, 4)  # the four chi-square tests below, overall significance 0.01


def _camera(fov, w, h, to_world=None, axis="x"):
    d = {"type": "scene", "sensor": {"type": "perspective", "fov": fov, "fov_axis": axis,
                                     "film": {"type": "hdrfilm", "width": w, "height": h,
                                              "rfilter": {"type": "box"}}}}
    if to_world is not None:
        d["sensor"]["to_world"] = np.asarray(to_world, float)
    return rm.load_dict(d)


@pytest.mark.parametrize("fov,w,h", [(40.0, 64, 64), (90.0, 64, 32), (120.0, 32, 48)])
def test_perspective_direction_density(fov, w, h):
    """A uniform film position maps to the plane z = 1 uniformly over
    [-tan_x, tan_x] x [-tan_y, tan_y]; the density of the directions is
    therefore 1 / (A cos^3 theta) with A the plane's area (camera frame)."""
    scene = _camera(fov, w, h)
    core = scene.core()
    tan_x = math.tan(math.radians(fov) / 2)
    tan_y = tan_x * h / w
    area = 4 * tan_x * tan_y

    def sample(rng, n):
        film = rng.random((n, 2)) * [w, h]
        r = core.sample_sensor_rays(film.astype(np.float32), rng.random((n, 5), dtype=np.float32))
        # Camera frame: Mitsuba's camera looks along +z with +x to the left;
        # the default to_world is the identity.
        return r["d"]

    def pdf(d):
        d = np.asarray(d, np.float64)
        z = d[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = d[:, 0] / z, d[:, 1] / z
            inside = (z > 0) & (np.abs(x) <= tan_x) & (np.abs(y) <= tan_y)
            return np.where(inside, 1.0 / (area * z ** 3), 0.0)

    r = chi2_test(sample, pdf, n_samples=100_000, grid=SphereGrid(n_theta=24, n_phi=48), seed=3, level=LEVEL,
                  min_depth=4, max_depth=10, rtol=1e-5, atol=1e-4, label=f"fov {fov}")
    assert r.passed, r.summary()


def test_pixel_corners_map_to_the_fov():
    """Film corners and centre land where fov and fov_axis say (Mitsuba's
    conventions: pixel (0, 0) top left, +x of the camera frame to the left)."""
    scene = _camera(60.0, 80, 40, axis="x")
    core = scene.core()
    film = np.array([[0, 0], [80, 40], [40, 20]], np.float32)
    r = core.sample_sensor_rays(film, np.zeros((3, 5), np.float32))
    d = r["d"] / r["d"][:, 2:3]
    t = math.tan(math.radians(30))
    np.testing.assert_allclose(d[0, :2], [t, t / 2], rtol=1e-5)  # top left: +x (left), +y (up)
    np.testing.assert_allclose(d[1, :2], [-t, -t / 2], rtol=1e-5)
    np.testing.assert_allclose(d[2, :2], [0, 0], atol=1e-6)


def test_orthographic_rays_are_parallel_over_the_extent():
    tw = np.array([[2.0, 0, 0, 1], [0, 2.0, 0, 0], [0, 0, 1, -3], [0, 0, 0, 1]])
    scene = rm.load_dict({"type": "scene", "sensor": {"type": "orthographic", "to_world": tw,
                                                      "film": {"type": "hdrfilm", "width": 20, "height": 10}}})
    core = scene.core()
    rng = np.random.default_rng(0)
    film = (rng.random((5000, 2)) * [20, 10]).astype(np.float32)
    r = core.sample_sensor_rays(film, rng.random((5000, 5), dtype=np.float32))
    np.testing.assert_allclose(r["d"], np.broadcast_to([0, 0, 1], (5000, 3)), atol=1e-6)
    o = r["o"]
    # x spans 1 +- 2 (scale 2 of [-1, 1]); y spans +-2 * (10 / 20).
    assert o[:, 0].min() >= -1 - 1e-5 and o[:, 0].max() <= 3 + 1e-5
    assert abs(o[:, 1]).max() <= 1 + 1e-5
    np.testing.assert_allclose(o[:, 2], -3, atol=1e-5)


def test_irradiancemeter_directions_are_cosine_weighted():
    scene = rm.load_dict({"type": "scene",
                          "meter": {"type": "rectangle",
                                    "sensor": {"type": "irradiancemeter",
                                               "film": {"type": "hdrfilm", "width": 1, "height": 1,
                                                        "rfilter": {"type": "box"}}}}})
    core = scene.core()

    def sample(rng, n):
        r = core.sample_sensor_rays(rng.random((n, 2), dtype=np.float32), rng.random((n, 5), dtype=np.float32))
        assert np.allclose(r["weight"], math.pi)
        return r["d"]

    def pdf(d):
        d = np.asarray(d, np.float64)
        return np.where(d[:, 2] > 0, d[:, 2] / math.pi, 0.0)

    r = chi2_test(sample, pdf, n_samples=100_000, grid=SphereGrid(n_theta=16, n_phi=32), seed=5, level=LEVEL,
                  label="irradiancemeter")
    assert r.passed, r.summary()
