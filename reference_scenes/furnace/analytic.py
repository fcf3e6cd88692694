"""Exact image of furnace/scene.xml: the white furnace.

Inside a closed sphere whose wall emits Le and reflects diffusely with albedo
rho, the radiance is the same at every point and in every direction, so the
rendering equation L = Le + T L (Kajiya 1986) reduces to the scalar equation
L = Le + rho L (a diffuse BRDF rho / pi integrated against cos over the
hemisphere gives rho). Its Neumann series, truncated where the estimator stops
(max_depth = the number of path segments, Mitsuba 3's convention: 1 is the
emitter seen directly, 2 adds direct light, ...), is

    L = Le * sum_{k=0}^{max_depth-1} rho^k,   Le / (1 - rho) for max_depth -1.

Every pixel of any camera inside the sphere, with any filter, sees exactly L.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from radiometer.reference_scenes.area_lights.analytic import _rgb, scene_params

HERE = Path(__file__).resolve().parent
XML = HERE / "scene.xml"


def radiance(le, rho, max_depth) -> np.ndarray:
    """L = Le sum_{k < max_depth} rho^k per channel (Le / (1 - rho) for -1)."""
    le, rho, md = _rgb(le), _rgb(rho), int(max_depth)
    if md == -1:
        if np.any(rho >= 1):
            raise ValueError("furnace: rho >= 1 with unbounded depth has no finite solution")
        return le / (1.0 - rho)
    if md < 1:
        raise ValueError(f"furnace: max_depth must be -1 or >= 1, got {md}")
    return le * sum(rho ** k for k in range(md))


def reference(**params):
    """(image, variance) of scene.xml with `params` overriding its defaults
    (le, rho, max_depth, res, spp): the constant image L (float64,
    (res, res, 3)) and zeros."""
    p = scene_params(XML, **params)
    res = int(p["res"])
    img = np.broadcast_to(radiance(p["le"], p["rho"], p["max_depth"]), (res, res, 3)).copy()
    return img, np.zeros_like(img)
