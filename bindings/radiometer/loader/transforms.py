"""4x4 transforms: translate, rotate, look_at (Mitsuba's conventions) and
applying them to points and normals."""
from __future__ import annotations

import math

import numpy as np

from ..scene_desc import SceneError


def _translate(t):
    m = np.eye(4)
    m[:3, 3] = t
    return m


def _rotate(axis, angle_deg):
    """Rotation by angle_deg about the unit axis, right-handed (Rodrigues'
    formula)."""
    a = np.asarray(axis, dtype=np.float64)
    th = math.radians(angle_deg)
    c, s = math.cos(th), math.sin(th)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    m = np.eye(4)
    m[:3, :3] = c * np.eye(3) + s * k + (1.0 - c) * np.outer(a, a)
    return m


def _onb_first(n):
    """First tangent of the orthonormal basis around unit n of Duff et al.,
    "Building an Orthonormal Basis, Revisited", JCGT 6(1), 2017, Listing 3
    (Mitsuba's coordinate_system); Mitsuba uses it as the default 'up'."""
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])


def _unit(v):
    """v / |v|, or None for a zero vector. The same arithmetic as v / norm(v)
    wherever the norm neither overflows nor underflows (|v| ~ 1e200 or
    1e-200); there v is first divided by its largest component."""
    v = np.asarray(v, dtype=np.float64)
    with np.errstate(over="ignore", under="ignore"):
        n = np.linalg.norm(v)
    if not (math.isfinite(n) and n > 1e-150):
        s = float(np.abs(v).max())
        if not s > 0:
            return None
        v = v / s
        n = np.linalg.norm(v)
    return v / n


def _look_at(origin, target, up, place):
    """Camera-to-world frame looking from origin to target: columns are left,
    up, forward (+z) and origin, as Mitsuba's Transform4f::look_at."""
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.asarray(target, dtype=np.float64) - origin
    if not np.all(np.isfinite(d)):
        raise SceneError(f"{place}: lookat: origin and target are too far apart for a float")
    d = _unit(d)
    if d is None:
        raise SceneError(f"{place}: lookat: origin and target coincide")
    if up is None:
        up = _onb_first(d)
    elif not 1e-150 < np.abs(up).max() < 1e150:  # keep the cross product in range
        up = np.asarray(up) / np.abs(up).max() if np.abs(up).max() > 0 else np.asarray(up)
    left = np.cross(up, d)
    if not np.linalg.norm(left) > 1e-12:
        raise SceneError(f"{place}: lookat: 'up' is parallel to the viewing direction")
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, origin
    return m


def _frame_along(d):
    """An orthonormal frame (4x4, no translation) whose +z column is d."""
    return _look_at(np.zeros(3), d, None, "<frame>")


# The largest float32: world-space data beyond it cannot be stored.
FLOAT32_MAX = float(np.finfo(np.float32).max)


def _apply_points(m, p, err):
    """Points to world space in float64, stored as float32; `err` (a
    message prefix) names the shape if they leave the float32 range."""
    with np.errstate(over="ignore", invalid="ignore"):
        w = p.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    if not np.all(np.abs(w) <= FLOAT32_MAX):
        raise SceneError(f"{err}: vertices beyond the float32 range (|x| > {FLOAT32_MAX:.3g}) after to_world")
    return w.astype(np.float32)


def _apply_normals(m, n):
    """Normals transform by the inverse transpose of the linear part. Its
    scale does not matter (they are normalised), so a linear part scaled far
    from 1 (1e-300) is first brought near 1, lest its inverse or the lengths
    overflow; ordinary ones are used as they are."""
    a = m[:3, :3]
    s = float(np.abs(a).max())
    if not 1e-100 < s < 1e100:
        a = a / s
    nt = n.astype(np.float64) @ np.linalg.inv(a)
    length = np.linalg.norm(nt, axis=1, keepdims=True)
    length[length == 0] = 1.0
    return (nt / length).astype(np.float32)
