"""Scenes built for the Metropolis estimators (pssmlt, mmlt), as scene dicts
for radiometer.load_dict; used by tests/test_mlt.py. Not in the registry:
they have no Mitsuba reference (bdpt is their reference where one is
needed).

- tiny_caustic: a glass ball under a tiny bright sphere light, over a
  diffuse floor, under a dim sky. The caustic under the ball is
  L S S D E: a unidirectional path tracer finds it only when a BSDF sample
  through the ball happens to hit the light, a rare sample with a huge
  contribution, so a chain of pssmlt over path that lands on it stays
  there for hundreds of proposals (the stuck-chain artefact).
"""
from __future__ import annotations

import numpy as np

from .caching import look_at


def tiny_caustic(res=32, light_radius=0.02, power=50.0, sky=0.02, fov=40.0):
    """The light is a sphere of `light_radius` at height 1.6 emitting
    `power` (radiance power / (4 pi^2 r^2)); the ball (glass, ior 1.5,
    radius 0.3) sits at height 0.5 above a 4 x 4 floor of albedo 0.7;
    camera in front, above, looking at the ball's foot."""
    def sq(scale, at):
        a = np.diag([scale, scale, scale, 1.0])
        a[:3, 3] = at
        return a

    o, t = np.array([0, -2.5, 2.0]), np.array([0, 0, 0.2])
    cam = look_at(o, t)
    radiance = power / (4 * np.pi ** 2 * light_radius ** 2)
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": fov, "to_world": cam,
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
            "floor": {"type": "rectangle", "to_world": sq(2, (0, 0, 0)),
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7] * 3}}},
            "ball": {"type": "sphere", "center": [0, 0, 0.5], "radius": 0.3,
                     "bsdf": {"type": "dielectric", "int_ior": 1.5}},
            "light": {"type": "sphere", "center": [0, 0, 1.6], "radius": light_radius,
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [sky] * 3}}}
