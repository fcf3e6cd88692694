"""Scenes built for the caching estimators (irrcache, radcache), as
scene dicts for radiometer.load_dict; used by tests/test_irrcache.py,
tests/test_radcache.py and benchmarks/studies/irrcache_bias.py. Not in the
registry: thin_wall's lit side, glossy_box and corner_room have no exact
answer, and no Mitsuba reference was made for them (their references are
long `path` renders where they are used).

- thin_wall: light leaks through a thin wall (docs/irrcache.md).
- glossy_box: a rough metal floor reflecting coloured walls, for
  radcache's error against the harmonics' order.
- corner_room: a diffuse room full of concave corners (a staircase and
  boxes against its walls), for irrcache's interpolation bias.
"""
from __future__ import annotations

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


def _box(lo, hi):
    """A cube shape's to_world for the axis-aligned box [lo, hi]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    a = np.diag(list((hi - lo) / 2) + [1.0])
    a[:3, 3] = (hi + lo) / 2
    return a


def corner_room(res=32):
    """Many concave corners, diffuse only: a room (2 x 2, 1.5 high, open
    towards the camera) with a four-step staircase against the back and
    right walls, two stacked boxes in the back left corner, one box in the
    front left corner and a small one on the floor, lit by a square light
    under the ceiling facing down. Walls grey (0.7), the left wall red and
    the right one green for colour bleeding; boxes pale (0.6). Each box
    stands 1e-3 off the walls it touches (no coincident faces)."""
    e = 0.999
    grey, box = _diffuse([0.7, 0.7, 0.7]), _diffuse([0.6, 0.6, 0.6])
    o, t = np.array([0, -2.4, 1.1]), np.array([0, 0.2, 0.45])
    cam = look_at(o, t)
    scene = {"type": "scene",
             "sensor": {"type": "perspective", "fov": 45, "to_world": cam,
                        "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
             "floor": {"type": "rectangle", "to_world": _rect((1, 1, 1), np.eye(3), (0, 0, 0)), "bsdf": grey},
             "ceiling": {"type": "rectangle", "to_world": _rect((1, 1, 1), _rx(np.pi), (0, 0, 1.5)), "bsdf": grey},
             "back": {"type": "rectangle", "to_world": _rect((1, 0.75, 1), _rx(np.pi / 2), (0, 1, 0.75)),
                      "bsdf": grey},
             "left": {"type": "rectangle", "to_world": _rect((0.75, 1, 1), _ry(np.pi / 2), (-1, 0, 0.75)),
                      "bsdf": _diffuse([0.7, 0.15, 0.15])},
             "right": {"type": "rectangle", "to_world": _rect((0.75, 1, 1), _ry(-np.pi / 2), (1, 0, 0.75)),
                       "bsdf": _diffuse([0.15, 0.7, 0.15])},
             "light": {"type": "rectangle", "to_world": _rect((0.25, 0.25, 1), _rx(np.pi), (0, -0.1, 1.499)),
                       "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [12.0, 12.0, 12.0]}}}}
    boxes = {f"step{k}": ((0.1, 0.2 + 0.2 * k, 0), (e, min(0.4 + 0.2 * k, e), 0.25 * (k + 1)))
             for k in range(4)}  # the staircase, rising towards the back wall
    boxes.update(box_back=((-e, 0.4, 0), (-0.5, e, 0.6)), box_top=((-e, 0.7, 0.6), (-0.7, e, 0.9)),
                 box_front=((-e, -0.6, 0), (-0.6, -0.2, 0.3)), box_floor=((-0.3, -0.1, 0), (0, 0.2, 0.3)))
    for name, (lo, hi) in boxes.items():
        scene[name] = {"type": "cube", "to_world": _box(lo, hi), "bsdf": box}
    return scene
