"""Sensors and emitters against closed-form answers (zero-variance set-ups
where possible, so the comparison is exact up to rounding)."""
import math

import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.stats import z_test

ALPHA = 0.01


def _plane(rho=0.5, size=10.0):
    return {"type": "rectangle", "to_world": np.diag([size, size, 1.0, 1.0]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [rho] * 3}}}


def _radiancemeter_at(origin, target):
    o, t = np.asarray(origin, float), np.asarray(target, float)
    return {"type": "radiancemeter", "origin": list(o), "direction": list((t - o) / np.linalg.norm(t - o)),
            "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}


def test_point_light_radiancemeter_inverse_square():
    """Diffuse plane z=0 (albedo rho) under a point light of intensity I at
    height h: L(x) = rho/pi * I cos(theta) / d^2 at every plane point x."""
    rho, inten, h = 0.6, 5.0, 2.0
    x = np.array([1.0, 0.5, 0.0])
    d2 = x[0] ** 2 + x[1] ** 2 + h ** 2
    cos_t = h / math.sqrt(d2)
    exact = rho / math.pi * inten * cos_t / d2
    scene = rm.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 2}, "plane": _plane(rho),
                          "light": {"type": "point", "position": [0, 0, h],
                                    "intensity": {"type": "rgb", "value": [inten] * 3}},
                          "sensor": _radiancemeter_at([3.0, -1.0, 1.5], x)})
    for integ in ("path", "direct"):
        res = rm.render(scene, integrator=integ if integ == "direct" else None, spp=16)
        np.testing.assert_allclose(res.image[0, 0], exact, rtol=1e-5)


def test_spot_light_falloff_follows_mitsuba():
    """Mitsuba's spot: full intensity inside beam_width, linear in angle to
    zero at cutoff_angle, nothing outside."""
    rho, inten, h = 0.5, 3.0, 1.0
    cutoff, beam = 30.0, 10.0
    to_world = np.eye(4)
    to_world[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looks down -z
    to_world[2, 3] = h
    def radiance_at(angle_deg):
        r = h * math.tan(math.radians(angle_deg))
        x = [r, 0.0, 0.0]
        scene = rm.load_dict({"type": "scene", "integrator": {"type": "direct"}, "plane": _plane(rho),
                              "light": {"type": "spot", "to_world": to_world, "cutoff_angle": cutoff,
                                        "beam_width": beam, "intensity": {"type": "rgb", "value": [inten] * 3}},
                              "sensor": _radiancemeter_at([0.3, 0.2, 0.5], x)})
        return float(rm.render(scene, spp=4).image[0, 0, 0]), r
    for angle, fall in ((5.0, 1.0), (20.0, (30.0 - 20.0) / (30.0 - 10.0)), (35.0, 0.0)):
        got, r = radiance_at(angle)
        d2 = r * r + h * h
        exact = rho / math.pi * inten * fall * (h / math.sqrt(d2)) / d2
        assert got == pytest.approx(exact, rel=1e-4, abs=1e-9), angle


def test_directional_light_orthographic_camera():
    """An orthographic camera sees a tilted-light plane at one radiance:
    L = rho/pi * E cos(theta)."""
    rho, irr, theta = 0.4, 2.0, math.radians(40)
    direction = [math.sin(theta), 0.0, -math.cos(theta)]
    scene = rm.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 3}, "plane": _plane(rho),
                          "sun": {"type": "directional", "direction": direction,
                                  "irradiance": {"type": "rgb", "value": [irr] * 3}},
                          "sensor": {"type": "orthographic",
                                     "to_world": np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 1.0], [0, 0, 0, 1]]),
                                     "film": {"type": "hdrfilm", "width": 8, "height": 8}}})
    res = rm.render(scene, spp=8)
    np.testing.assert_allclose(res.image, rho / math.pi * irr * math.cos(theta), rtol=1e-5)


def test_irradiancemeter_under_constant_sky():
    """E = pi L for an upward meter under a uniform sky of radiance L."""
    sky = 1.7
    scene = rm.load_dict({"type": "scene", "integrator": {"type": "path"},
                          "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [sky] * 3}},
                          "meter": {"type": "rectangle", "to_world": np.diag([0.1, 0.1, 1, 1]),
                                    "sensor": {"type": "irradiancemeter",
                                               "film": {"type": "hdrfilm", "width": 1, "height": 1,
                                                        "rfilter": {"type": "box"}}}}})
    res = rm.render(scene, spp=64)
    np.testing.assert_allclose(res.image[0, 0], math.pi * sky, rtol=1e-5)


def test_irradiance_from_disk_light_analytic():
    """Irradiance at the centre below a coaxial disk light of radius R at
    height h and radiance L: E = pi L R^2 / (R^2 + h^2) (a textbook result).
    A small irradiancemeter disk stands in for the point: its mean irradiance
    differs from the centre value by < 1e-4 relative at this size."""
    L, R, h = 2.0, 0.5, 1.0
    light_tw = np.eye(4)
    light_tw[:3, :3] = np.diag([R, -R, -1.0])  # faces down
    light_tw[2, 3] = h
    scene = rm.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                          "light": {"type": "disk", "to_world": light_tw,
                                    "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [L] * 3}}},
                          "meter": {"type": "disk", "to_world": np.diag([0.005, 0.005, 1, 1]),
                                    "sensor": {"type": "irradiancemeter",
                                               "film": {"type": "hdrfilm", "width": 1, "height": 1,
                                                        "rfilter": {"type": "box"}}}}})
    # 2^20 samples: standard error 0.2 %, so a 1 % error is 5 sigma.
    res = rm.render(scene, spp=1 << 20, seed=1)
    exact = math.pi * L * R * R / (R * R + h * h)
    t = z_test(res.image, res.variance, np.full_like(res.image, exact), None, alpha=ALPHA)
    assert t.passed, t.summary()
    assert not z_test(res.image, res.variance, np.full_like(res.image, exact * 1.01), None, alpha=ALPHA).passed


def test_hide_emitters_and_one_sided_area_light():
    """A camera looking at the back of a one-sided area light sees black; at
    its front, the radiance; hide_emitters hides it."""
    def look(z_cam, hide):
        return rm.load_dict({"type": "scene", "integrator": {"type": "path", "hide_emitters": hide},
                             "light": {"type": "rectangle",
                                       "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [3, 2, 1]}}},
                             "sensor": _radiancemeter_at([0.1, 0.2, z_cam], [0, 0, 0])})
    front = rm.render(look(2.0, False), spp=4).image[0, 0]
    back = rm.render(look(-2.0, False), spp=4).image[0, 0]
    hidden = rm.render(look(2.0, True), spp=4).image[0, 0]
    np.testing.assert_array_equal(front, [3, 2, 1])
    np.testing.assert_array_equal(back, [0, 0, 0])
    np.testing.assert_array_equal(hidden, [0, 0, 0])
