"""Texture coordinates and textures against Mitsuba 3 itself (scalar_rgb).

1. uv at hit points: the same shape dict loaded by `mitsuba.load_dict` and by
   ours, the same rays; our Interaction::uv (Scene.intersect_rays, the hit
   record every estimator reads) equals Mitsuba's `si.uv` to UV_TOL, per
   shape: rectangle, cube, disk, sphere (rotated, and mirrored), OBJ and
   PLY with vertex uvs. Periodic coordinates (the sphere's u, the disk's v)
   are compared modulo 1, and sphere hits within 1e-3 of a pole, where u is
   undefined, are skipped. Power check: a sphere rotated 1 degree further
   than Mitsuba's is told apart.
"""
from __future__ import annotations

import math
import zlib

import numpy as np
import pytest

import radiometer as rm
from radiometer import _core
from radiometer._build import build_scene
from radiometer.loader import load_dict

mi = pytest.importorskip("mitsuba", reason="mitsuba (the reference renderer) is not installed")
mi.set_variant("scalar_rgb")

UV_TOL = 1e-5
N_RAYS = 300


def _T():
    return mi.ScalarTransform4f()


def _rays(lo, hi, n, seed):
    """n rays from a sphere around the box [lo, hi] towards points inside it."""
    rng = np.random.default_rng(seed)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) + 1.0
    d = rng.normal(size=(n, 3))
    o = c + r * d / np.linalg.norm(d, axis=1, keepdims=True)
    target = lo + (hi - lo) * rng.random((n, 3))
    v = target - o
    return o, v / np.linalg.norm(v, axis=1, keepdims=True)


def _hits(shape, o, d):
    """(ours, theirs): per ray t, uv, and for Mitsuba the shape-local point."""
    scene = {"type": "scene", "s": shape}
    ours = build_scene(load_dict(scene)).intersect_rays(o.astype(np.float32), d.astype(np.float32))
    ref = mi.load_dict(scene)
    t_ref = np.full(len(o), np.inf)
    uv_ref = np.zeros((len(o), 2))
    for i in range(len(o)):
        si = ref.ray_intersect(mi.Ray3f(mi.Point3f(*o[i].astype(np.float32)), mi.Vector3f(*d[i].astype(np.float32))))
        if si.is_valid():
            t_ref[i] = si.t
            uv_ref[i] = np.array(si.uv)
    return ours, t_ref, uv_ref


def _write_obj(path):
    # A quad in two triangles and a triangle off to the side, with uvs
    # outside [0, 1] (Mitsuba keeps them as written, v flipped).
    path.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0.2\nv -1 1 0\nv 2 0 0\nv 3 0 0.5\nv 2 1 0\n"
                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 2.5 -0.5\nvt 3 0\nvt 2 1.5\n"
                    "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\nf 5/5 6/6 7/7\n")


def _write_ply(path):
    verts = [(-1, -1, 0, 0.1, 0.2), (1, -1, 0, 0.9, 0.1), (1, 1, 0.3, 0.8, 0.95), (-1, 1, 0, 0.05, 0.7)]
    lines = ["ply", "format ascii 1.0", f"element vertex {len(verts)}", "property float x", "property float y",
             "property float z", "property float u", "property float v", "element face 2",
             "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(str(x) for x in v) for v in verts] + ["3 0 1 2", "3 0 2 3"]
    path.write_text("\n".join(lines) + "\n")


def _shapes(tmp_path):
    obj, ply = tmp_path / "m.obj", tmp_path / "m.ply"
    _write_obj(obj)
    _write_ply(ply)
    rot = _T().rotate([0, math.sqrt(0.5), math.sqrt(0.5)], 40)
    return {
        "rectangle": {"type": "rectangle", "to_world": _T().translate([0.2, 0, 0]) @ rot @ _T().scale([2, 1, 1])},
        "cube": {"type": "cube", "to_world": rot @ _T().scale([1, 0.5, 2])},
        "disk": {"type": "disk", "to_world": rot @ _T().scale(1.5)},
        "sphere": {"type": "sphere", "center": [0.3, 0, 0], "radius": 0.7, "to_world": rot},
        "sphere_mirrored": {"type": "sphere", "to_world": _T().translate([0, 1, 0]) @ rot @ _T().scale([-1, 1, 1])},
        "obj": {"type": "obj", "filename": str(obj), "to_world": rot},
        "ply": {"type": "ply", "filename": str(ply), "to_world": rot},
    }


PERIODIC = {"sphere": (True, False), "sphere_mirrored": (True, False), "disk": (False, True)}


def _uv_error(name, ours, t_ref, uv_ref):
    both = np.isfinite(ours["t"]) & np.isfinite(t_ref)
    # The two renderers agree on which rays hit (up to a grazing few).
    assert np.mean(np.isfinite(ours["t"]) != np.isfinite(t_ref)) < 0.01
    np.testing.assert_allclose(ours["t"][both], t_ref[both], rtol=1e-4, atol=1e-5)
    diff = ours["uv"][both].astype(np.float64) - uv_ref[both]
    for k, periodic in enumerate(PERIODIC.get(name, (False, False))):
        if periodic:
            diff[:, k] -= np.round(diff[:, k])
    keep = np.ones(len(diff), bool)
    if name.startswith("sphere"):
        keep = np.sin(np.pi * uv_ref[both][:, 1]) > 1e-3
    return np.abs(diff[keep]).max(), int(both.sum())


@pytest.mark.parametrize("name", ["rectangle", "cube", "disk", "sphere", "sphere_mirrored", "obj", "ply"])
def test_uv_matches_mitsuba(name, tmp_path):
    shape = _shapes(tmp_path)[name]
    bbox = mi.load_dict({"type": "scene", "s": shape}).bbox()
    o, d = _rays(np.array(bbox.min), np.array(bbox.max), N_RAYS, seed=zlib.crc32(name.encode()))
    err, n = _uv_error(name, *_hits(shape, o, d))
    assert n > N_RAYS // 4, f"only {n} rays hit"
    assert err < UV_TOL, f"{name}: max |uv - Mitsuba's| = {err:.3g} over {n} hits"


def test_uv_power(tmp_path):
    """A sphere rotated 1 degree further than Mitsuba's one gives uvs the test rejects."""
    rot = _T().rotate([0, math.sqrt(0.5), math.sqrt(0.5)], 40)
    theirs = {"type": "sphere", "to_world": rot}
    o, d = _rays(np.array([-1.0] * 3), np.array([1.0] * 3), N_RAYS, seed=7)
    ref = _hits(theirs, o, d)
    ours = _hits({"type": "sphere", "to_world": _T().rotate([0, math.sqrt(0.5), math.sqrt(0.5)], 41)}, o, d)[0]
    err, _ = _uv_error("sphere", ours, ref[1], ref[2])
    assert err > 100 * UV_TOL
