"""Scenes built for the caching estimators (irrcache, radcache), as
scene dicts for radiometer.load_dict; used by tests/test_irrcache.py,
tests/test_radcache.py and benchmarks/studies/irrcache_bias.py. Not in the
registry: thin_wall's lit side and glossy_box have no exact answer, and no
Mitsuba reference was made for them (their references are long `path`
renders where they are used). corner_room is a registered scene (its XML
and Mitsuba reference in reference_scenes/corner_room); corner_room()
loads it.

- thin_wall: light leaks through a thin wall (docs/irrcache.md).
- glossy_box: a rough metal floor reflecting coloured walls, for
  radcache's error against the harmonics' order.
- corner_room: a diffuse room full of concave corners (a staircase and
  boxes against its walls), for irrcache's interpolation bias.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def thin_wall(res=32, thickness=0.01):
    """A floor split by a thin wall (1 high): an area light low on the left
    lights the left half; nothing can reach the right half (no ceiling, no
    environment, the wall higher than the light), so its exact radiance is
    0. Camera above, seeing both halves."""
    def m(scale=(1, 1, 1), flip=False, at=(0, 0, 0)):
        a = np.diag([scale[0], scale[1] * (-1 if flip else 1), scale[2] * (-1 if flip else 1), 1.0])
        a[:3, 3] = at
        return a

    cam = np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 4], [0, 0, 0, 1]], float)
    white = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}}
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 36, "to_world": cam,
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
            "floor": {"type": "rectangle", "to_world": m(), "bsdf": white},
            "wall": {"type": "cube", "to_world": m((thickness / 2, 1, 0.5), at=(0, 0, 0.5)), "bsdf": white},
            "light": {"type": "rectangle", "to_world": m((0.15, 0.15, 1), flip=True, at=(-0.5, 0, 0.3)),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [20.0, 20.0, 20.0]}}}}


def look_at(o, t):
    """Camera-to-world matrix from o towards t, z up (Mitsuba's lookat:
    columns left, up, forward, origin)."""
    f = (t - o) / np.linalg.norm(t - o)
    left = np.cross([0, 0, 1.0], f)
    left /= np.linalg.norm(left)
    cam = np.eye(4)
    cam[:3, 0], cam[:3, 1], cam[:3, 2], cam[:3, 3] = left, np.cross(f, left), f, o
    return cam


def _rect(scale, rot, at):
    a = np.eye(4)
    a[:3, :3] = rot @ np.diag(scale)
    a[:3, 3] = at
    return a


def _rx(d):
    return np.array([[1, 0, 0], [0, np.cos(d), -np.sin(d)], [0, np.sin(d), np.cos(d)]])


def _ry(d):
    return np.array([[np.cos(d), 0, np.sin(d)], [0, 1, 0], [-np.sin(d), 0, np.cos(d)]])


def _diffuse(c):
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": c}}


def glossy_box(res=24, alpha=0.2):
    """A glossy floor (roughconductor, alpha 0.2, eta 0.2, k 3.9: a bright
    metal) with a grey back wall and red and green side walls, lit by a
    square light under the open top; camera above the front edge. About a
    third of the image's light is indirect, most of it the walls seen in
    the floor."""
    o, t = np.array([0, -2.6, 1.6]), np.array([0, 0, 0.3])
    cam = look_at(o, t)
    metal = {"type": "roughconductor", "alpha": alpha, "eta": {"type": "rgb", "value": [0.2] * 3},
             "k": {"type": "rgb", "value": [3.9] * 3}}
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 45, "to_world": cam,
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
            "floor": {"type": "rectangle", "to_world": _rect((1, 1, 1), np.eye(3), (0, 0, 0)), "bsdf": metal},
            "back": {"type": "rectangle", "to_world": _rect((1, 0.5, 1), _rx(np.pi / 2), (0, 1, 0.5)),
                     "bsdf": _diffuse([0.7, 0.7, 0.7])},
            "left": {"type": "rectangle", "to_world": _rect((0.5, 1, 1), _ry(np.pi / 2), (-1, 0, 0.5)),
                     "bsdf": _diffuse([0.7, 0.1, 0.1])},
            "right": {"type": "rectangle", "to_world": _rect((0.5, 1, 1), _ry(-np.pi / 2), (1, 0, 0.5)),
                      "bsdf": _diffuse([0.1, 0.7, 0.1])},
            "light": {"type": "rectangle", "to_world": _rect((0.2, 0.2, 1), _rx(np.pi), (0, 0.3, 0.95)),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [15.0, 15.0, 15.0]}}}}


def corner_room(res=32):
    """corner_room (reference_scenes/corner_room/scene.xml, a registered
    scene with a Mitsuba reference; its card.md), loaded at res x res."""
    import radiometer as rm

    return rm.load_file(Path(__file__).resolve().parent / "corner_room" / "scene.xml", res=res)
