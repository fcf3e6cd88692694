"""Analytic values of the CIE 171:2006 closed-room case as built here
(closed_room.xml; what is and is not the published case: card.md).

The room: the inside of a cube of side 2 H (H = 2: 4 m, S_T = 24 H^2 =
96 m^2), every surface a grey Lambertian reflector of reflectance rho. The
light: a cube of half side a (`ls`) at the room's centre, each face a
Lambertian emitter of radiance Le facing out, black. Its flux is
Phi = pi Le A_L with A_L = 24 a^2.

1. Direct irradiance at a floor point (the direct-light part). Every face
   of the light whose plane has the point on its front side is seen whole
   (the light is convex and lies above the floor), and each contributes
   Lambert's polygon-to-point configuration factor (Lambert 1760; the
   vector form of Baum, Rushmeier and Winget 1989, eq. 5, and of Arvo
   1994, eq. 2-3):  E = Le / 2 |sum_i Theta_i n . Gamma_i|.
   A box-filtered pixel is the mean of rho / pi E over its square
   (Gauss-Legendre, as area_lights/analytic.py).

2. Mean irradiance over the floor, all bounces (the interreflection).
   The room and the light share the cube's symmetry group, which maps the
   floor onto every wall and the ceiling, so each of the six faces gets the
   same share of every bounce: the floor mean is the mean over all S_T.
   The light's whole flux lands on the room first (nothing of the room lies
   inside the convex light), so the first bounce brings Phi / S_T on
   average. Each reflection returns rho of what a surface receives; of the
   flux leaving the room's surfaces the fraction eps = A_L / S_T falls on
   the black light and is lost (exact for a uniform radiosity: the room
   sends the light B sum A_i F_i,L = B A_L F_L,room = B A_L; the field's
   non-uniformity changes this at order eps times its relative spread,
   below 1e-4 of the answer here). So, for paths of at most `max_depth`
   segments (as `path` counts them: camera -> floor -> ... -> light),

       E_mean = Phi / S_T * sum_{k=0}^{max_depth-2} (rho (1 - eps))^k
              -> Phi / (S_T (1 - rho (1 - eps)))      (max_depth = -1)

   the flux balance of a closed room with one reflectance (Sumpner's
   integrating-sphere result, 1892, there for the sphere's every point; in
   any closed room it holds for the mean over all surfaces). With eps = 0
   (a point source) it is the formula the case's reference is built on,
   E_indirect = rho Phi / (S_T (1 - rho)).

3. The same formula read at a point (the integrating-sphere assumption):
   a uniform indirect irradiance E_ind = E_mean - Phi / S_T everywhere.
   True for a sphere, not for a cube: the point values are measured
   (docs/radiosity.md), not asserted.

Units: the case is in lumens and lux; here Phi is in W and E in W m^-2 of
a grey (all channels equal) quantity. Only the ratios E / Phi enter, so a
case value in lux is ours times (the case's lumens / our Phi): with
le = 1000, ls = 0.05, Phi = pi * 1000 * 0.06 = 188.5 W, and 1 lm of the
case corresponds to 1 / 188.5 of our Phi.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from radiometer.reference_scenes.area_lights.analytic import (_rgb, pixel_average, polygon_irradiance,
                                                             scene_params)

HERE = Path(__file__).resolve().parent
XML = HERE / "closed_room.xml"
H = 2.0  # room half side (m): the room is [-H, H]^2 x [0, 2H]
S_T = 24.0 * H * H  # 96 m^2
CENTRE_Z = H
VIEW = H  # the orthographic camera's half extent (scale 2 in to_world): the whole floor


def light_faces(a: float, cz: float = CENTRE_Z) -> list:
    """The light's six faces as (vertices (4, 3), outward normal (3,))."""
    faces = []
    for axis in range(3):
        for s in (-1.0, 1.0):
            u, v = [k for k in range(3) if k != axis]
            quad = []
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3)
                p[axis], p[u], p[v] = s * a, du * a, dv * a
                quad.append(p + np.array([0.0, 0.0, cz]))
            n = np.zeros(3)
            n[axis] = s
            faces.append((np.array(quad), n))
    return faces


def direct_irradiance(x, y, a: float, le: float = 1.0, cz: float = CENTRE_Z):
    """Irradiance at floor points (x, y, 0) from the cube light (radiance le):
    the sum of Lambert's formula over the faces the point is in front of."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    e = np.zeros(np.broadcast(x, y).shape)
    p = np.stack(np.broadcast_arrays(x, y, np.zeros_like(x)), axis=-1)
    for quad, n in light_faces(a, cz):
        front = ((p - quad[0]) @ n) > 0.0
        if front.any():
            e = e + np.where(front, polygon_irradiance(x, y, quad), 0.0)
    return le * e


def flux(le: float, a: float) -> float:
    """Phi = pi Le A_L, A_L = 24 a^2."""
    return math.pi * le * 24.0 * a * a


def eps_loss(a: float) -> float:
    """The fraction of the room's outgoing flux that falls on the black light."""
    return 24.0 * a * a / S_T


def floor_mean_irradiance(rho: float, le: float, a: float, max_depth: int = -1, point_source: bool = False):
    """(total, direct, indirect) mean irradiance over the floor, section 2 of
    the docstring; point_source: eps = 0 (the case's own formula)."""
    md = int(max_depth)
    if md == 0 or md < -1:
        raise ValueError(f"max_depth must be -1 or >= 1, got {md}")
    phi = flux(le, a)
    q = rho * (1.0 - (0.0 if point_source else eps_loss(a)))
    direct = phi / S_T if md != 1 else 0.0
    if md == -1:
        total = direct / (1.0 - q)
    else:
        total = direct * sum(q ** k for k in range(max(0, md - 1)))
    return total, direct, total - direct


def params(**overrides) -> dict:
    p = scene_params(XML, **overrides)
    rho = _rgb(p["rho"])
    if not np.all(rho == rho[0]):
        raise ValueError("closed_room: the analytic values need a grey rho (the symmetry argument is per channel, "
                         "but the docs quote one number)")
    out = {"res": int(p["res"]), "max_depth": int(p["max_depth"]), "rho": float(rho[0]),
           "le": float(_rgb(p["le"])[0]), "ls": float(p["ls"]), "cam_h": float(p["cam_h"])}
    if not out["cam_h"] < CENTRE_Z - out["ls"]:
        raise ValueError("closed_room: the camera must sit below the light (cam_h < 2 - ls)")
    return out


def direct_image(order: int = 6, **overrides) -> np.ndarray:
    """The exact image at max_depth 2 (direct light only): rho / pi times the
    pixel mean of the direct irradiance, (res, res, 3) float64."""
    p = params(**overrides)
    e = pixel_average(lambda x, y: direct_irradiance(x, y, p["ls"], p["le"]), p["res"], order, VIEW)
    return np.repeat((p["rho"] / math.pi * e)[..., None], 3, axis=2)


def image_mean(**overrides) -> float:
    """The exact mean of the image (any max_depth): rho / pi E_mean."""
    p = params(**overrides)
    return p["rho"] / math.pi * floor_mean_irradiance(p["rho"], p["le"], p["ls"], p["max_depth"])[0]


def direct_floor_mean_by_quadrature(a: float, le: float = 1.0, n: int = 64) -> float:
    """The floor mean of direct_irradiance by Gauss-Legendre (n x n nodes on
    each of 16 x 16 cells): an independent check of the symmetry argument
    (it must equal Phi / S_T)."""
    t, w = np.polynomial.legendre.leggauss(n)
    cells = 16
    h = 2.0 * H / cells
    nodes = np.concatenate([-H + h * (k + 0.5 * (t + 1.0)) for k in range(cells)])
    wts = np.tile(0.5 * h * w, cells)
    X, Y = np.meshgrid(nodes, nodes, indexing="ij")
    return float((direct_irradiance(X, Y, a, le) * wts[:, None] * wts[None, :]).sum() / (2.0 * H) ** 2)


def point_values(rho: float, le: float, a: float, points=((0.0, 0.0), (1.0, 1.0), (1.75, 1.75))) -> list:
    """At each floor point: (x, y, direct E, integrating-sphere indirect E,
    their sum): the case's way of reading the formula at a point."""
    _, _, ind = floor_mean_irradiance(rho, le, a)
    out = []
    for x, y in points:
        d = float(direct_irradiance(x, y, a, le))
        out.append((x, y, d, ind, d + ind))
    return out
