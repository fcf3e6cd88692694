"""Exact images of the area_lights scenes (disk_light.xml, rect_light.xml).

A diffuse floor z = 0 (albedo rho) under one area light of radiance L facing
straight down, seen by an orthographic camera looking straight down over the
view [-1, 1]^2 with a box filter. At max_depth 2 the floor receives direct
light only (it is flat and alone; the light is black), so the outgoing
radiance is

    L_o(x) = rho / pi * E(x)                                     (Lambertian)

and a pixel, under a box filter, is the average of L_o over its square. E is
in closed form; the pixel average is integrated with an n x n tensor
Gauss-Legendre rule per pixel.

Irradiance formulas (the light's radiance L factored out below):

* Disk of radius R, in a plane parallel to the receiver at height z, its
  centre at horizontal distance r from the receiving point (the form factor
  from a differential element to a parallel disk, Howell's catalog of
  configuration factors, "plane element to parallel circular disk", e.g.
  Howell, Menguc & Siegel, Thermal Radiation Heat Transfer, appendix C; also
  Modest, Radiative Heat Transfer, appendix D):

      E = pi L / 2 * (1 - (z^2 + r^2 - R^2) / sqrt((z^2 + r^2 + R^2)^2 - 4 r^2 R^2))

  evaluated without cancellation as E = 2 pi L R^2 z^2 / (B (A + B)) with
  A = z^2 + r^2 - R^2 and B = sqrt(A^2 + 4 R^2 z^2) (B^2 - A^2 = 4 R^2 z^2).
  On the axis it is pi L R^2 / (z^2 + R^2) = pi L sin^2(half angle).

* Polygon (the rectangle), Lambert's formula (Lambert 1760, Photometria; in
  vector form Arvo, "The Irradiance Jacobian for Partially Occluded Polyhedral
  Sources", SIGGRAPH 1994, eq. 2 and 3): with u_i the unit vectors from the
  receiving point to the vertices, Theta_i the angle between u_i and u_{i+1}
  and Gamma_i = (u_i x u_{i+1}) / |u_i x u_{i+1}|,

      E = L / 2 * | sum_i Theta_i (n . Gamma_i) |

  (the sign only says which way round the vertices go; the polygon lies wholly
  above the receiver's horizon, so no clipping is needed).

Accuracy: E is analytic over each pixel (the light is at height h above
the floor), so Gauss-Legendre converges exponentially. Measured on the
default scenes at res 64 (check_accuracy() below, or python -m
radiometer.reference_scenes.check_analytic): the 6 x 6 rule (default)
differs from the 12 x 12 rule by at most 8.5e-16 relative (disk) and 1.1e-15
(rectangle), i.e. to rounding; order 3 is at 6e-13 and 1.8e-12. So the
reference pixels are exact far beyond the 1e-6 required. The closed forms
themselves agree with scipy's dblquad of L cos cos' / d^2 over the light
(epsrel 1e-12) to 5.6e-16 (disk) and 1.1e-15 (rectangle) at 12 random floor
points (check_analytic.closed_forms_vs_quadrature; asserted to 1e-9 in
tests/test_canonical_analytic.py::test_area_light_formulas_match_quadrature).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DISK_XML = HERE / "disk_light.xml"
RECT_XML = HERE / "rect_light.xml"
GL_ORDER = 6  # Gauss-Legendre nodes per pixel side (see Accuracy above)
VIEW = 1.0  # the orthographic camera's default half extent (no scale in to_world)


# --------------------------------------------------------------------------
# Scene parameters: the XML's <default>s are the one source of truth.

def xml_defaults(xml_path) -> dict:
    """The <default name=... value=...> entries of a scene file, as strings."""
    root = ET.parse(xml_path).getroot()
    return {d.get("name"): d.get("value") for d in root.iter("default")}


def _rgb(v) -> np.ndarray:
    """A scalar, a 3-sequence or an XML string ("0.8, 0.6, 0.4" or "0.5") as
    an RGB float64 array."""
    if isinstance(v, str):
        v = [float(t) for t in v.replace(",", " ").split()]
    a = np.atleast_1d(np.asarray(v, np.float64))
    if a.size == 1:
        a = np.repeat(a, 3)
    if a.shape != (3,):
        raise ValueError(f"expected a scalar or 3 values, got {v!r}")
    return a


def scene_params(xml_path, **overrides) -> dict:
    """The scene's parameters with `overrides` applied (the same keyword
    arguments radiometer.load_file / mitsuba.load_file take)."""
    p = xml_defaults(xml_path)
    unknown = set(overrides) - set(p)
    if unknown:
        raise ValueError(f"{Path(xml_path).name}: unknown parameter(s) {sorted(unknown)} (known: {sorted(p)})")
    p.update({k: v for k, v in overrides.items()})
    return p


# --------------------------------------------------------------------------
# Geometry of the film.

def pixel_nodes(res: int, order: int = GL_ORDER, view: float = VIEW):
    """World (x, y) of the Gauss-Legendre nodes in every pixel and their
    weights (summing to 1 per pixel): arrays x, y of shape (res, res, order^2)
    and w of shape (order^2,).

    The camera looks down -z with up = +y (lookat origin (0,0,c), target 0):
    Mitsuba's camera frame has +x to the left, and film x runs against it, so
    pixel column j covers world x in [-v + 2 v j / res, -v + 2 v (j + 1) / res]
    and row i (from the top) covers y in [v - 2 v (i + 1) / res, v - 2 v i / res]."""
    t, wt = np.polynomial.legendre.leggauss(order)
    t = 0.5 * (t + 1.0)  # nodes on [0, 1]
    wt = 0.5 * wt
    size = 2.0 * view / res
    j = np.arange(res)
    xs = -view + size * (j[:, None] + t[None, :])  # (res, order): column j
    ys = view - size * (j[:, None] + t[None, :])  # (res, order): row i
    x = np.broadcast_to(xs[None, :, None, :], (res, res, order, order)).reshape(res, res, order * order)
    y = np.broadcast_to(ys[:, None, :, None], (res, res, order, order)).reshape(res, res, order * order)
    w = (wt[:, None] * wt[None, :]).reshape(-1)
    return x, y, w


def pixel_average(func, res: int, order: int = GL_ORDER, view: float = VIEW) -> np.ndarray:
    """Box-filtered pixel values of a scalar field func(x, y) on the floor:
    the average over each pixel square, (res, res) float64."""
    x, y, w = pixel_nodes(res, order, view)
    return func(x, y) @ w


# --------------------------------------------------------------------------
# Irradiance per unit radiance.

def disk_irradiance(x, y, cx, cy, radius, h):
    """Irradiance at floor points (x, y, 0) (normal +z) from a disk of unit
    radiance, radius `radius`, centred at (cx, cy, h), facing down."""
    r2 = (np.asarray(x, np.float64) - cx) ** 2 + (np.asarray(y, np.float64) - cy) ** 2
    z2, R2 = float(h) ** 2, float(radius) ** 2
    a = z2 + r2 - R2
    b = np.sqrt(a * a + 4.0 * R2 * z2)  # = sqrt((z^2 + r^2 + R^2)^2 - 4 r^2 R^2)
    return 2.0 * math.pi * R2 * z2 / (b * (a + b))


def polygon_irradiance(x, y, vertices):
    """Irradiance at floor points (x, y, 0) (normal +z) from a planar convex
    polygon of unit radiance whose vertices (k, 3) all lie above the floor
    (Lambert's formula; see the module docstring)."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    v = np.asarray(vertices, np.float64)
    p = np.stack([x, y, np.zeros_like(x)], axis=-1)
    u = v - p[..., None, :]  # (..., k, 3)
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    un = np.roll(u, -1, axis=-2)
    c = np.cross(u, un)
    sin = np.linalg.norm(c, axis=-1)
    cos = np.sum(u * un, axis=-1)
    theta = np.arctan2(sin, cos)  # accurate at every angle, unlike arccos
    nz = c[..., 2] / sin  # n . Gamma_i with n = +z
    return np.abs(0.5 * np.sum(theta * nz, axis=-1))


def rect_vertices(a, b, angle_deg, cx, cy, h):
    """World vertices of the light in rect_light.xml: the rectangle
    [-a, a] x [-b, b], turned upside down (rotate x 180: the vertex set is
    unchanged), rotated by angle_deg about +z (right-handed, as Mitsuba's
    <rotate z="1">), moved to (cx, cy, h). Counter-clockwise seen from above."""
    t = math.radians(float(angle_deg))
    c, s = math.cos(t), math.sin(t)
    local = [(-a, -b), (a, -b), (a, b), (-a, b)]
    return np.array([(cx + c * px - s * py, cy + s * px + c * py, h) for px, py in local], np.float64)


# --------------------------------------------------------------------------
# Reference images.

def _lit(max_depth) -> bool:
    """max_depth 1 is emission only, and the camera sees no emitter: black.
    Any depth >= 2 (or -1) gives the same image, since the light is black
    and the floor flat and alone: no lit surface sees another."""
    md = int(max_depth)
    if md == 0 or md < -1:
        raise ValueError(f"max_depth must be -1 or >= 1, got {md}")
    return md != 1


def reference_disk(order: int = GL_ORDER, **params):
    """(image, variance) of disk_light.xml with `params` overriding its
    defaults: the exact box-filtered image (float64, (res, res, 3)) and zeros."""
    p = scene_params(DISK_XML, **params)
    res = int(p["res"])
    rho, le = _rgb(p["rho"]), _rgb(p["radiance"])
    cx, cy, radius, h = (float(p[k]) for k in ("lx", "ly", "radius", "h"))
    if not float(p["cam_h"]) < h:
        raise ValueError("disk_light: the camera must sit below the light (cam_h < h)")
    e = pixel_average(lambda x, y: disk_irradiance(x, y, cx, cy, radius, h), res, order)
    lit = _lit(p["max_depth"])
    img = (rho * le / math.pi)[None, None, :] * e[..., None] * float(lit)
    return img, np.zeros_like(img)


def reference_rect(order: int = GL_ORDER, **params):
    """(image, variance) of rect_light.xml with `params` overriding its
    defaults: the exact box-filtered image (float64, (res, res, 3)) and zeros."""
    p = scene_params(RECT_XML, **params)
    res = int(p["res"])
    rho, le = _rgb(p["rho"]), _rgb(p["radiance"])
    verts = rect_vertices(float(p["a"]), float(p["b"]), float(p["angle"]), float(p["lx"]), float(p["ly"]),
                          float(p["h"]))
    if not float(p["cam_h"]) < float(p["h"]):
        raise ValueError("rect_light: the camera must sit below the light (cam_h < h)")
    e = pixel_average(lambda x, y: polygon_irradiance(x, y, verts), res, order)
    lit = _lit(p["max_depth"])
    img = (rho * le / math.pi)[None, None, :] * e[..., None] * float(lit)
    return img, np.zeros_like(img)


def reference(light: str = "disk", **params):
    """(image, variance) of disk_light.xml (light="disk") or rect_light.xml
    (light="rect"), `params` overriding the XML's defaults."""
    if light == "disk":
        return reference_disk(**params)
    if light in ("rect", "rectangle"):
        return reference_rect(**params)
    raise ValueError(f"area_lights: light must be 'disk' or 'rect', got {light!r}")


def check_accuracy(res: int = 64, order: int = GL_ORDER):
    """Largest relative difference between the order-n and order-2n
    Gauss-Legendre pixel averages, for both lights at their defaults."""
    out = {}
    for name, f in (("disk", reference_disk), ("rect", reference_rect)):
        a, _ = f(order=order, res=res)
        b, _ = f(order=2 * order, res=res)
        out[name] = float(np.max(np.abs(a - b) / np.abs(b)))
    return out


if __name__ == "__main__":
    print("GL order", GL_ORDER, "vs", 2 * GL_ORDER, "max relative difference:", check_accuracy())
