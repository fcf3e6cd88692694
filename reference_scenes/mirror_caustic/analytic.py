"""Exact images of mirror_caustic/scene.xml: direct light plus a caustic,
solved by the method of images.

The floor z = 0 (diffuse, albedo rho) receives
* direct light from the disk light D (radius R, centre (lx, ly, h), facing
  down), and
* light reflected by the perfect mirror in the plane x = m (m = 1, facing -x,
  Fresnel reflectance F = 1: Mitsuba's conductor with material "none", eta 0
  and k 1, for which |r_s|^2 = |r_p|^2 = 1 at every angle). A perfect mirror
  preserves radiance along a ray, so the floor sees, through the mirror, the
  mirror image D' of the light: a disk of the same radius and radiance,
  centred at (2 m - lx, ly, h), still facing down (reflection in a vertical
  plane keeps the vertical normal). This is the classical image method
  (e.g. Modest, Radiative Heat Transfer, chapter 6, "specularly reflecting
  surfaces": the exchange factor through a specular surface is the view
  factor to the image, times its reflectance).

So, with E_disk the closed-form irradiance from a parallel disk (see
reference_scenes/area_lights/analytic.py),

    direct(x)  = rho / pi * L * E_disk(x; lx, ly, R, h)          L D E
    caustic(x) = rho / pi * L * F * E_disk(x; 2m - lx, ly, R, h)  L S D E

each box-filtered over the pixel squares with the Gauss-Legendre rule of
area_lights.analytic (exact to ~1e-15 relative at order 6).

The image method is exact here only if the whole image light is seen through
the mirror from every floor point in view, and the mirror blocks no direct
light; `check_geometry` enforces the conditions for the parameters given:
* the light lies wholly in front of the mirror (lx + R < m), so segments from
  the light to floor points in view (x < m) never cross the mirror plane;
* the segment from a floor point p (x < m, z = 0) to a point q' of the image
  light crosses the plane x = m at a height in (0, h) and at a y between
  p_y and q'_y; the mirror covers z in [0, 2.5] and y in [-2.5, 2.5], so it
  needs h <= 2.5 and max(1, |ly| + R) <= 2.5;
* the light is flat, horizontal and faces down, so no reflected segment
  (all below z = h) can be blocked by it;
* the camera sits between the light and the floor (cam_h < h) and sees the
  mirror edge-on, so it sees the floor only.

Path classes at each max_depth: 1 -> nothing visible (the camera sees no
emitter); 2 -> direct; 3 -> direct + caustic. From 4 on, L D S D E (the
floor lit by the floor's mirror image) joins in, which this module does not
compute: it raises for max_depth > 3 or -1.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from radiometer.reference_scenes.area_lights.analytic import (GL_ORDER, _rgb, disk_irradiance, pixel_average,
                                                               scene_params)

HERE = Path(__file__).resolve().parent
XML = HERE / "scene.xml"

# The mirror, as fixed in scene.xml: the plane x = MIRROR_X, facing -x,
# y in [-MIRROR_HALF_Y, MIRROR_HALF_Y], z in [0, MIRROR_TOP].
MIRROR_X = 1.0
MIRROR_HALF_Y = 2.5
MIRROR_TOP = 2.5
MIRROR_F = 1.0  # conductor, material none
VIEW = 1.0


def check_geometry(p: dict):
    """Raises ValueError unless the image method is exact for parameters `p`."""
    lx, ly, radius, h, cam_h = (float(p[k]) for k in ("lx", "ly", "radius", "h", "cam_h"))
    problems = []
    if not lx + radius < MIRROR_X:
        problems.append(f"the light must lie wholly in front of the mirror (lx + radius = {lx + radius} < {MIRROR_X})")
    if not 0 < h <= MIRROR_TOP:
        problems.append(f"the light height h = {h} must lie in (0, {MIRROR_TOP}] (the mirror's top)")
    if not max(VIEW, abs(ly) + radius) <= MIRROR_HALF_Y:
        problems.append(f"|ly| + radius = {abs(ly) + radius} exceeds the mirror's half width {MIRROR_HALF_Y}")
    if not 0 < cam_h < h:
        problems.append(f"the camera must sit between the floor and the light (0 < cam_h = {cam_h} < h = {h})")
    if problems:
        raise ValueError("mirror_caustic: the image method is not exact here: " + "; ".join(problems))


def effects(order: int = GL_ORDER, **params) -> dict:
    """The exact effect images {"direct": ..., "caustic": ...} (float64,
    (res, res, 3)) of scene.xml with `params` overriding its defaults; every
    other effect class is zero."""
    p = scene_params(XML, **params)
    check_geometry(p)
    md = int(p["max_depth"])
    if md == 0 or md < -1:
        raise ValueError(f"mirror_caustic: max_depth must be -1 or >= 1, got {md}")
    if md == -1 or md > 3:
        raise ValueError(f"mirror_caustic: max_depth {md} adds L D S D E paths (the floor's own mirror image), "
                         "which this analytic solution does not include; use max_depth <= 3")
    res = int(p["res"])
    scale = _rgb(p["rho"]) * _rgb(p["radiance"]) / math.pi
    lx, ly, radius, h = (float(p[k]) for k in ("lx", "ly", "radius", "h"))
    e_direct = pixel_average(lambda x, y: disk_irradiance(x, y, lx, ly, radius, h), res, order)
    e_caustic = MIRROR_F * pixel_average(lambda x, y: disk_irradiance(x, y, 2 * MIRROR_X - lx, ly, radius, h),
                                         res, order)
    direct = scale[None, None, :] * e_direct[..., None] * float(md >= 2)
    caustic = scale[None, None, :] * e_caustic[..., None] * float(md >= 3)
    return {"direct": direct, "caustic": caustic}


def reference(order: int = GL_ORDER, **params):
    """(image, variance) of scene.xml with `params` overriding its defaults:
    the exact box-filtered image direct + caustic (float64, (res, res, 3))
    and zeros. The split is effects(**params)."""
    e = effects(order=order, **params)
    img = e["direct"] + e["caustic"]
    return img, np.zeros_like(img)


def caustic_fraction(**params) -> np.ndarray:
    """caustic / (direct + caustic) per pixel (channel 0; all channels share
    it, the colour being rho * L in both)."""
    e = effects(**params)
    return e["caustic"][..., 0] / (e["direct"][..., 0] + e["caustic"][..., 0])
