"""Scenes of the light-selection tests (tests/test_light_sampler.py) and the
stress cases: emitters of very different power in one box."""
import numpy as np


def frame(u, v, t):
    """to_world of a rectangle ([-1, 1]^2, normal +z) spanned by u and v
    (half-extents included) at t; its normal is cross(u, v)."""
    u, v, t = (np.asarray(a, float) for a in (u, v, t))
    n = np.cross(u, v)
    n = n / np.linalg.norm(n)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u, v, n, t
    return m


def rgb(v):
    return {"type": "rgb", "value": list(map(float, v)) if np.ndim(v) else [float(v)] * 3}


def diffuse(r):
    return {"type": "diffuse", "reflectance": rgb(r)}


X, Y, Z = np.eye(3)


def box(res=12, rfilter="box"):
    """An open box (no front wall) seen from the front, diffuse walls."""
    return {
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 45,
                   "to_world": np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 3.6], [0, 0, 0, 1]], float),
                   "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": rfilter}}},
        "floor": {"type": "rectangle", "to_world": frame(Z, X, -Y), "bsdf": diffuse(0.6)},
        "ceiling": {"type": "rectangle", "to_world": frame(X, Z, Y), "bsdf": diffuse(0.6)},
        "back": {"type": "rectangle", "to_world": frame(X, Y, -Z), "bsdf": diffuse([0.5, 0.6, 0.4])},
        "left": {"type": "rectangle", "to_world": frame(Y, Z, -X), "bsdf": diffuse([0.6, 0.2, 0.2])},
        "right": {"type": "rectangle", "to_world": frame(Z, Y, X), "bsdf": diffuse([0.2, 0.6, 0.2])},
    }


def many_powers(res=12, rfilter="box", env=True):
    """Six emitters whose powers span four decades: a bright small ceiling
    light, a dim large wall light, two point lights (intensities 0.05 and
    3), a spot and (env) a faint constant sky through the open front."""
    d = box(res, rfilter)
    d["lamp"] = {"type": "rectangle", "to_world": frame(0.2 * X, 0.2 * Z, 0.98 * Y), "bsdf": diffuse(0.0),
                 "emitter": {"type": "area", "radiance": rgb([40.0, 36.0, 30.0])}}
    d["panel"] = {"type": "rectangle", "to_world": frame(0.3 * Y, 0.3 * Z, [-0.98, 0.0, -0.3]),
                  "bsdf": diffuse(0.0), "emitter": {"type": "area", "radiance": rgb([0.2, 0.25, 0.3])}}
    d["dim_point"] = {"type": "point", "position": [0.5, -0.5, 0.2], "intensity": rgb(0.05)}
    d["bright_point"] = {"type": "point", "position": [-0.4, 0.2, -0.3], "intensity": rgb([3.0, 2.5, 2.0])}
    d["spot"] = {"type": "spot", "intensity": rgb(6.0), "cutoff_angle": 30.0,
                 "to_world": np.array([[1, 0, 0, 0.4], [0, 0, -1, 0.9], [0, 1, 0, -0.4], [0, 0, 0, 1]], float)}
    if env:
        d["sky"] = {"type": "constant", "radiance": rgb(0.05)}
    return d


def grid_of_points(n_side, intensity, bright=None, res=8, coincident=False):
    """n_side^2 point lights on a grid under the ceiling (all at one point
    when `coincident`); `bright`: the intensity of one more at the centre."""
    d = box(res)
    k = 0
    for i in range(n_side):
        for j in range(n_side):
            p = [0.0, 0.9, 0.0] if coincident else [-0.9 + 1.8 * (i + 0.5) / n_side, 0.9,
                                                      -0.9 + 1.8 * (j + 0.5) / n_side]
            d[f"p{k}"] = {"type": "point", "position": p, "intensity": rgb(intensity)}
            k += 1
    if bright is not None:
        d["bright"] = {"type": "point", "position": [0.05, 0.5, 0.05], "intensity": rgb(bright)}
    return d
