"""Textured emitters and the mesh textures, against closed forms and Mitsuba 3
itself (scalar_rgb).

1. The projector (Mitsuba 3 src/emitters/projector.cpp): its intensity
   towards a direction of local cosine c inside the image is
   scale pi E(uv) / c^3, zero outside the image and behind; checked as
   next event estimation sees it (radiance x distance^2) against that
   closed form for a plain irradiance, and against Mitsuba's own
   Projector.sample_direction for a bitmap of another aspect ratio with
   fov_axis y (the uv orientation, the aspect and fov conversion). Power:
   the image upside down is rejected.
2. Estimators on a projector scene and on textured area lights (a bitmap
   radiance on a rectangle and on a sphere): path (next event estimation,
   emission hits), ptracer (light paths, the s = 1 connection) and bdpt
   (all of them and the MIS densities) against Mitsuba 3's path (eight
   renders), blocked z-test with both variances. Power: the textures
   upside down are rejected.
3. mesh_attribute (Mitsuba 3 src/textures/mesh_attribute.cpp) at hit points
   of a PLY mesh with vertex_color, face_color and face_weight against
   Mitsuba's Texture.eval at the same rays; rawconstant against Mitsuba's
   eval, eval_1 and mean. Power: the vertex colours rolled by one vertex
   are told apart.
4. Mitsuba's own suite scenes these bring (projector, mesh_attributes,
   various_emitters) under Mitsuba's protocol, each with a power check.
5. Bad input: SceneError naming the plugin, the parameter and the place.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import radiometer as rm
from radiometer import _core
from radiometer._build import _texture, build_scene
from radiometer.loader import SceneError, load_dict, load_file

mi = pytest.importorskip("mitsuba", reason="mitsuba (the reference renderer) is not installed")
mi.set_variant("scalar_rgb")

SUITE = Path(__file__).resolve().parents[1].parent / "shared" / "peers" / "mitsuba-data" / "tests" / "scenes"


def _lookat(origin, target, up):
    """Mitsuba's look_at as a numpy 4x4 (z towards the target)."""
    return np.array(mi.ScalarTransform4f().look_at(origin=origin, target=target, up=up).matrix, np.float64)


def _image(path, rng, w, h):
    from PIL import Image

    img = (rng.random((h, w, 3)) * 255).astype(np.uint8)
    Image.fromarray(img).save(path / "pattern.png")
    Image.fromarray(img[::-1].copy()).save(path / "flipped.png")
    return path / "pattern.png", path / "flipped.png"


def _nee(scene_dict, refs):
    """What next event estimation receives from the scene's one emitter at
    each reference point: radiance (N, 3) and direction (N, 3)."""
    core = rm.load_dict({"type": "scene", **scene_dict}).core()
    n = len(refs)
    s = core.sample_emitter_direction(refs.astype(np.float32), np.full((n, 4), 0.5, np.float32))
    return s["radiance"].astype(np.float64), s["d"]


# ---------------------------------------------------------------------------
# 1. the projector's intensity


def test_projector_intensity_closed_form():
    """A plain irradiance E = (2, 1, 0.5), scale 3, fov 70 (horizontal),
    rotated and moved: radiance x d^2 at 400 points equals
    scale pi E / c^3 inside the image (|x| <= z tan(fov/2), |y| likewise:
    a colour's image is square) and 0 outside and behind, to 1e-5."""
    to_world = _lookat([0.3, -0.2, 1.0], [1.0, 0.5, -2.0], [0, 1, 0])
    e = {"type": "projector", "irradiance": {"type": "rgb", "value": [2.0, 1.0, 0.5]}, "scale": 3.0, "fov": 70.0,
         "to_world": to_world}
    rng = np.random.default_rng(1)
    local = rng.normal(size=(400, 3)) + np.array([0.0, 0.0, 1.2])
    refs = (to_world @ np.c_[local, np.ones(len(local))].T).T[:, :3]
    rad, _ = _nee({"light": e}, refs)
    d2 = np.sum(local**2, axis=1)
    c = local[:, 2] / np.sqrt(d2)
    t = math.tan(math.radians(35.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = (local[:, 2] > 0) & (np.abs(local[:, 0]) <= local[:, 2] * t) & (np.abs(local[:, 1]) <= local[:, 2] * t)
        want = np.where(inside[:, None], 3.0 * math.pi * np.array([2.0, 1.0, 0.5]) / c[:, None] ** 3, 0.0)
    got = rad * d2[:, None]
    assert 50 < inside.sum() < 350  # both sides of the image's edge are seen
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    # Power: an inverse-square-of-cosine law (the spot's shape) is told apart.
    assert not np.allclose(got[inside], (want * c[:, None])[inside], rtol=1e-3)


@pytest.mark.parametrize("filter_type", ["nearest", "bilinear"])
def test_projector_texture_matches_mitsuba(tmp_path, filter_type):
    """A 7 x 4 bitmap (aspect 7/4) with fov 50 on the y axis: ours and
    Mitsuba's Projector.sample_direction at 300 points, to 1e-4 relative.
    Power: ours with the image upside down differs."""
    pattern, flipped = _image(tmp_path, np.random.default_rng(2), 7, 4)
    to_world = _lookat([0.1, 0.2, -0.3], [0.4, -0.1, 2.0], [0, 1, 0])

    def proj(path):
        return {"type": "projector", "fov": 50.0, "fov_axis": "y", "scale": 1.5, "to_world": to_world,
                "irradiance": {"type": "bitmap", "filename": str(path), "filter_type": filter_type}}

    rng = np.random.default_rng(3)
    local = rng.normal(size=(300, 3)) * np.array([0.5, 0.3, 0.2]) + np.array([0.0, 0.0, 1.5])
    refs = (to_world @ np.c_[local, np.ones(len(local))].T).T[:, :3]
    ours, _ = _nee({"light": proj(pattern)}, refs)
    theirs = mi.load_dict(proj(pattern) | {"to_world": mi.ScalarTransform4f(to_world.tolist())})
    ref = np.zeros_like(ours)
    for i, p in enumerate(refs):
        it = mi.Interaction3f()
        it.p = mi.Point3f(*p.astype(np.float32))
        _, spec = theirs.sample_direction(it, mi.Point2f(0.5, 0.5))
        ref[i] = np.array(spec)
    lit = ref.max(axis=1) > 0
    assert lit.sum() > 100 and (~lit).sum() > 10
    np.testing.assert_allclose(ours, ref, rtol=1e-4, atol=1e-6)
    wrong, _ = _nee({"light": proj(flipped)}, refs)
    assert not np.allclose(wrong, ref, rtol=1e-2, atol=1e-4)


# ---------------------------------------------------------------------------
# 2. estimators on textured emitters, against Mitsuba's path


def _projector_scene(tf, image):
    """A projector throwing a bitmap onto a diffuse wall at an angle, with a
    second wall catching the bounce."""
    wall = np.array([[-2.0, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, -1.0, 1.5], [0, 0, 0, 1]])  # z = 1.5, facing -z
    side = np.array([[0, 0, 1.0, -1.2], [0, 2.0, 0, 0], [-2.0, 0, 0, 0.5], [0, 0, 0, 1]])  # x = -1.2, facing +x
    cam = np.eye(4)
    cam[:3, 3] = (0.3, 0.0, -2.5)
    return {"type": "scene",
            "integrator": {"type": "path", "max_depth": 4},
            "proj": {"type": "projector", "fov": 40.0, "scale": 0.6,
                     "to_world": tf(_lookat([0.2, 0.1, -0.5], [0.0, 0.0, 1.5], [0, 1, 0])),
                     "irradiance": {"type": "bitmap", "filename": str(image), "filter_type": "nearest"}},
            "wall": {"type": "rectangle", "to_world": tf(wall), "bsdf": {"type": "diffuse", "reflectance": 0.8}},
            "side": {"type": "rectangle", "to_world": tf(side), "bsdf": {"type": "diffuse", "reflectance": 0.6}},
            "cam": {"type": "perspective", "fov": 50, "to_world": tf(cam),
                    "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": 64}}}


def _area_scene(tf, image):
    """A rectangle light and a sphere light with a bitmap radiance over a
    diffuse floor (their uvs: the rectangle's and Mitsuba's sphere map)."""
    rect = _lookat([-0.6, 0.8, 0.6], [-0.2, 0.0, 1.2], [0, 0, 1]) @ np.diag([0.5, 0.4, 1.0, 1.0])
    floor = _lookat([0, 0, 1], [0, 1, 1], [0, 0, 1]) @ np.diag([3.0, 3.0, 1.0, 1.0])  # y = 0, facing +y
    cam = _lookat([0.0, 1.5, -2.0], [0.0, 0.3, 1.0], [0, 1, 0])
    tex = {"type": "bitmap", "filename": str(image), "filter_type": "nearest"}
    return {"type": "scene",
            "integrator": {"type": "path", "max_depth": 3},
            "rect": {"type": "rectangle", "to_world": tf(rect), "emitter": {"type": "area", "radiance": tex}},
            "ball": {"type": "sphere", "center": [0.6, 0.6, 1.0], "radius": 0.3,
                     "emitter": {"type": "area", "radiance": dict(tex)}},
            "floor": {"type": "rectangle", "to_world": tf(floor), "bsdf": {"type": "diffuse", "reflectance": 0.7}},
            "cam": {"type": "perspective", "fov": 55, "to_world": tf(cam),
                    "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": 64}}}


SCENES = {"projector": _projector_scene, "area": _area_scene}


@pytest.fixture(scope="module")
def mitsuba_refs(tmp_path_factory):
    """Per scene: (folder with the images, Mitsuba's mean, its variance)
    over eight scalar_rgb path renders of 256 spp."""
    out = {}
    for k, (name, make) in enumerate(sorted(SCENES.items())):
        d = tmp_path_factory.mktemp(name)
        pattern, _ = _image(d, np.random.default_rng(10 + k), 6, 5)
        theirs = mi.load_dict(make(lambda m: mi.ScalarTransform4f(np.asarray(m).tolist()), pattern))
        runs = np.stack([np.array(mi.render(theirs, spp=256, seed=s)) for s in range(8)])
        out[name] = (d, runs.mean(axis=0), runs.var(axis=0, ddof=1) / len(runs))
    return out


@pytest.mark.parametrize("scene", sorted(SCENES))
@pytest.mark.parametrize("estimator,spp", [("path", 1024), ("ptracer", 256), ("bdpt", 256), ("vcm", 64)])
def test_textured_emitters_match_mitsuba(mitsuba_refs, scene, estimator, spp):
    """Textured projector and area-light radiance in next event estimation
    and emission hits (path), light paths and their s = 1 connections
    (ptracer), all of them with bdpt's MIS densities, and vcm's engine
    (merging off: its own light-vertex store and recursive MIS quantities)
    against Mitsuba 3's path: blocked z-test, both variances
    (refcompare.ALPHA). Power: the texture upside down is rejected.
    (Measured once on the projector scene at 64 spp: vcm with merging
    0.9994, photonmapper 1.0024, sppm 1.0006 and bpm 1.018 of Mitsuba's
    mean, each within the blocked test.)"""
    from refcompare import blocked_z

    d, mean, var = mitsuba_refs[scene]
    make = SCENES[scene]
    integrator = {"type": estimator, "max_depth": 4 if scene == "projector" else 3}
    if estimator == "vcm":
        integrator["merging"] = False
    res = rm.render(rm.Scene(load_dict(make(lambda m: m, d / "pattern.png"))), integrator=integrator, spp=spp,
                    seed=4)
    passed, msg = blocked_z(res.image, res.variance, mean, var)
    assert passed, f"{scene}/{estimator}: ours / mitsuba = {res.image.sum() / mean.sum():.5f}\n{msg}"
    flipped = rm.render(rm.Scene(load_dict(make(lambda m: m, d / "flipped.png"))), integrator=integrator, spp=spp,
                        seed=4)
    assert not blocked_z(flipped.image, flipped.variance, mean, var)[0]


def test_untextured_projector_equals_constant_texture(tmp_path):
    """A plain irradiance and a one-colour bitmap of the same value (the
    same aspect, 1) render the same image bytes with ptracer and bdpt: the
    texture's sampling grid of equal weights samples uv uniformly, as the
    plain colour does."""
    from PIL import Image

    Image.fromarray(np.full((4, 4, 3), 255, np.uint8)).save(tmp_path / "white.png")
    base = _projector_scene(lambda m: m, tmp_path / "white.png")
    plain = dict(base, proj=dict(base["proj"], irradiance={"type": "rgb", "value": [1.0, 1.0, 1.0]}))
    for est in ("path", "ptracer", "bdpt"):
        a = rm.render(rm.Scene(load_dict(base)), integrator=est, spp=4, seed=1).image
        b = rm.render(rm.Scene(load_dict(plain)), integrator=est, spp=4, seed=1).image
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7, err_msg=est)


# ---------------------------------------------------------------------------
# 3. mesh_attribute and rawconstant against Mitsuba


def _attribute_ply(path, roll=0):
    """A bumpy 6 x 6 grid of 50 triangles with vertex_color (3), face_color
    (3) and face_weight (1) as Mitsuba's PLY writer names them
    (color_0.., weight_0); roll: the vertex colours moved by that many
    vertices (the power check)."""
    rng = np.random.default_rng(7)
    g = np.linspace(-1, 1, 6)
    x, y = np.meshgrid(g, g)
    z = 0.2 * np.sin(3 * x) * np.cos(2 * y)
    verts = np.c_[x.ravel(), y.ravel(), z.ravel()]
    faces = []
    for j in range(5):
        for i in range(5):
            a = j * 6 + i
            faces += [(a, a + 1, a + 7), (a, a + 7, a + 6)]
    vc = np.roll(rng.random((len(verts), 3)), roll, axis=0)
    fc = rng.random((len(faces), 3))
    fw = rng.random(len(faces))
    lines = ["ply", "format ascii 1.0", f"element vertex {len(verts)}"]
    lines += [f"property float {n}" for n in ("x", "y", "z", "color_0", "color_1", "color_2")]
    lines += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    lines += [f"property float {n}" for n in ("color_0", "color_1", "color_2", "weight_0")]
    lines += ["end_header"]
    lines += [" ".join(f"{v:.6f}" for v in (*p, *c)) for p, c in zip(verts, vc)]
    lines += [f"3 {a} {b} {c} " + " ".join(f"{v:.6f}" for v in (*col, w)) for (a, b, c), col, w in zip(faces, fc, fw)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("name", ["vertex_color", "face_color", "face_weight"])
def test_mesh_attribute_matches_mitsuba(tmp_path, name):
    """Our mesh_attribute (scale 1.5) at the hits of 400 rays on a PLY mesh
    equals Mitsuba's Texture.eval at its hits of the same rays, to 2e-5;
    the vertex colours rolled by one vertex are told apart."""
    ply = _attribute_ply(tmp_path / "m.ply")
    shape = {"type": "ply", "filename": str(ply), "to_world": _lookat([0, 0, 0.3], [0.2, 0.1, 2], [0, 1, 0])}
    rng = np.random.default_rng(5)
    o = np.c_[rng.uniform(-0.9, 0.9, (400, 2)), np.full(400, -3.0)]
    d = np.c_[rng.normal(0, 0.05, (400, 2)), np.ones(400)]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = (shape["to_world"] @ np.c_[o, np.ones(400)].T).T[:, :3]
    d = (shape["to_world"][:3, :3] @ d.T).T
    tex = {"type": "mesh_attribute", "name": name, "scale": 1.5}
    desc = load_dict({"type": "scene", "s": {**shape, "bsdf": {"type": "diffuse", "reflectance": tex}}})
    ours = build_scene(desc).intersect_rays(o.astype(np.float32), d.astype(np.float32),
                                            texture=_texture(desc.shapes[0].bsdf.textures["reflectance"]))
    ref_scene = mi.load_dict({"type": "scene", "s": shape | {"to_world": mi.ScalarTransform4f(
        shape["to_world"].tolist())}})
    ref_tex = mi.load_dict(tex)
    ref = np.zeros((400, 3))
    hit = np.zeros(400, bool)
    for i in range(400):
        si = ref_scene.ray_intersect(mi.Ray3f(mi.Point3f(*o[i].astype(np.float32)),
                                              mi.Vector3f(*d[i].astype(np.float32))))
        if si.is_valid():
            hit[i] = True
            ref[i] = np.array(ref_tex.eval(si))
    assert hit.sum() > 300 and np.array_equal(hit, np.isfinite(ours["t"]))
    np.testing.assert_allclose(ours["tex"][hit], ref[hit], rtol=2e-5, atol=2e-6)
    if name == "vertex_color":
        _attribute_ply(tmp_path / "m.ply", roll=1)
        desc = load_dict({"type": "scene", "s": {**shape, "bsdf": {"type": "diffuse", "reflectance": tex}}})
        wrong = build_scene(desc).intersect_rays(o.astype(np.float32), d.astype(np.float32),
                                                 texture=_texture(desc.shapes[0].bsdf.textures["reflectance"]))
        assert not np.allclose(wrong["tex"][hit], ref[hit], rtol=1e-2, atol=1e-3)


@pytest.mark.parametrize("value", [0.3, [0.2, 0.5, 0.9]])
def test_rawconstant_matches_mitsuba(value):
    """rawconstant: eval (no colour conversion), mean and, for one value,
    eval_1, as Mitsuba's."""
    desc = load_dict({"type": "scene", "s": {"type": "sphere", "bsdf": {
        "type": "diffuse", "reflectance": {"type": "rawconstant", "value": value}}}})
    t = desc.shapes[0].bsdf.textures["reflectance"]
    ev, ev1, mean, _ = _core.texture_eval(_texture(t), np.random.default_rng(0).random((5, 2), dtype=np.float32))
    ref = mi.load_dict({"type": "rawconstant", "value": value})
    si = mi.SurfaceInteraction3f()
    np.testing.assert_allclose(ev, np.broadcast_to(np.array(ref.eval(si)), ev.shape), rtol=1e-7)
    assert mean == pytest.approx(ref.mean(), rel=1e-6)
    if np.isscalar(value):
        np.testing.assert_allclose(ev1, ref.eval_1(si), rtol=1e-7)


# ---------------------------------------------------------------------------
# 4. Mitsuba's own suite scenes, under Mitsuba's protocol


def _flip_textures(d):
    """Every bitmap of the scene upside down (emitters' and BSDFs')."""
    texs = [t for e in d.emitters for t in e.textures.values()]
    texs += [t for s in d.shapes for t in (s.emitter.textures.values() if s.emitter is not None else ())]
    for t in texs:
        if t.type == "bitmap":
            t.data = np.ascontiguousarray(t.data[::-1])
    return d


def _dim_projector(d):
    for e in d.emitters:
        if e.type == "projector":
            e.scale *= 0.97
    return d


def _swap_attribute_channels(d):
    for s in d.shapes:
        for name, a in s.attributes.items():
            s.attributes[name] = np.ascontiguousarray(a[:, ::-1])
    return d


def _roll_vertex_attributes(d):
    for s in d.shapes:
        for name, a in s.attributes.items():
            if name.startswith("vertex_"):
                s.attributes[name] = np.ascontiguousarray(np.roll(a, 1, axis=0))
    return d


def _invert_face_weights(d):
    """1_face's blendbsdf weights (a one-channel face attribute) read as 1 - w."""
    for s in d.shapes:
        for name, a in s.attributes.items():
            if name.startswith("face_") and a.shape[1] == 1:
                s.attributes[name] = np.ascontiguousarray(1.0 - a)
    return d


@pytest.mark.skipif(not SUITE.is_dir(), reason="../shared/peers/mitsuba-data absent")
@pytest.mark.parametrize("scene,spoil", [
    ("projector/test_projector_constant_direct.xml", _dim_projector),
    ("mesh_attributes/test_mesh_attributes_1_face_direct.xml", _invert_face_weights),
    ("projector/test_projector_textured_direct.xml", _flip_textures),
    ("mesh_attributes/test_mesh_attributes_3_face_direct.xml", _swap_attribute_channels),
    ("mesh_attributes/test_mesh_attributes_3_vertex_direct.xml", _roll_vertex_attributes),
    ("various_emitters/test_various_emitters_ptracer.xml", _flip_textures),
])
def test_suite_emitter_texture_scenes_pass_mitsubas_test(scene, spoil):
    """Mitsuba 3's own scenes with projectors (a constant one and a PNG),
    face and vertex colours (PLY attributes through mesh_attribute) and
    various_emitters (textured area lights on a rectangle, an OBJ quad and
    an OBJ sphere, spots, a textured projector, a point; rendered by
    ptracer) under Mitsuba's test protocol (benchmarks/studies/
    mitsuba_suite.py: 2e6 samples, seed 0, XYZ, Sidak 0.01, at most 0.75 %
    of the pixel-channels rejected). Measured: 0, 0, 0, 0 rejected of 17.3
    allowed, and 73 of 245.8 for various_emitters (ptracer's noise against
    a path-traced reference's variance). Power: the constant projector 3 %
    dimmer, the textures upside down, the face colours' channels reversed,
    the vertex colours rolled by one vertex, each fails the protocol."""
    from radiometer.benchmarks.studies import mitsuba_suite as ms

    r = ms.protocol(SUITE / scene, threads=2)
    assert r["passes"], r
    assert not ms.protocol(SUITE / scene, threads=2, change=spoil)["passes"]


# ---------------------------------------------------------------------------
# 5. bad input


def _ply_file(tmp_path):
    return _attribute_ply(tmp_path / "m.ply")


@pytest.mark.parametrize("body,expected", [
    # an attribute the mesh lacks: the texture's 'name', at its line, and the shape's place
    ('<shape type="ply"><string name="filename" value="m.ply"/>\n<bsdf type="diffuse">\n'
     '<texture type="mesh_attribute" name="reflectance">\n<string name="name" value="vertex_normal"/>'
     '</texture></bsdf></shape>',
     r"s.xml:5: texture 'mesh_attribute': parameter 'name': the shape 'ply' at .*s.xml:2 has no attribute "
     r"'vertex_normal' \(its attributes: face_color, face_weight, vertex_color"),
    # on a shape that carries none
    ('<shape type="rectangle"><bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">\n'
     '<string name="name" value="face_color"/></texture></bsdf></shape>',
     r"s.xml:3: texture 'mesh_attribute': parameter 'name': the shape 'rectangle' .* has no attribute "
     r"'face_color' \(its attributes: none"),
    ('<texture type="mesh_attribute" id="t">\n<string name="name" value="color"/></texture>',
     r"s.xml:3: texture 'mesh_attribute': parameter 'name' must start with \"vertex_\" or \"face_\""),
    ('<texture type="rawconstant" id="t"/>', r"s.xml:2: texture 'rawconstant': missing parameter 'value'"),
    ('<texture type="rawconstant" id="t">\n<vector name="value" value="0.5, -1, 0"/></texture>',
     r"s.xml:3: texture 'rawconstant': parameter 'value': negative value -1.0"),
    ('<texture type="rawconstant" id="t">\n<string name="value" value="x"/></texture>',
     r"s.xml:3: texture 'rawconstant': parameter 'value' must be a float or a 3D vector"),
    ('<emitter type="projector">\n<float name="fov" value="190"/></emitter>',
     r"s.xml:3: emitter 'projector': fov 190.0 must lie in \(0, 180\)"),
    ('<emitter type="projector">\n<float name="scale" value="-1"/></emitter>',
     r"s.xml:3: emitter 'projector': parameter 'scale': negative value"),
    ('<emitter type="projector"><transform name="to_world">\n<scale value="2"/></transform></emitter>',
     r"s.xml:2: emitter 'projector': scale factors in the projector's to_world are not allowed"),
    ('<emitter type="projector"><rgb name="irradiance" value="1"/>\n'
     '<texture type="checkerboard" name="irradiance"/></emitter>',
     r"s.xml:3: emitter 'projector': parameter 'irradiance' given both as a value and as a texture"),
    ('<emitter type="projector"><texture type="mesh_attribute" name="irradiance">\n'
     '<string name="name" value="face_color"/></texture></emitter>',
     r"s.xml:2: emitter 'projector': parameter 'irradiance': a mesh_attribute texture has no value"),
    ('<shape type="sphere"><emitter type="area"><rgb name="radiance" value="1"/>\n'
     '<texture type="checkerboard" name="radiance"/></emitter></shape>',
     r"s.xml:3: emitter 'area': parameter 'radiance' given both as a value and as a texture"),
    ('<emitter type="point">\n<texture type="checkerboard" name="intensity"/></emitter>',
     r"s.xml:3: emitter 'point': parameter 'intensity' cannot take a texture"),
])
def test_errors(tmp_path, body, expected):
    _ply_file(tmp_path)
    path = tmp_path / "s.xml"
    path.write_text(f'<scene version="3.0.0">\n{body}\n</scene>\n')
    with pytest.raises(SceneError, match=expected):
        load_file(path)


def test_radiosity_refuses_a_textured_area_light():
    """A radiosity patch has one emission: a textured radiance is refused by
    name, not rendered as its value at one uv."""
    scene = rm.Scene(load_dict({"type": "scene", "light": {"type": "rectangle", "emitter": {
        "type": "area", "radiance": {"type": "checkerboard"}}}}))
    with pytest.raises(ValueError, match="integrator 'radiosity' cannot render emitter .*: its radiance is textured"):
        rm.render(scene, integrator="radiosity", spp=1)


def _vertex_colour_light(ply):
    """A bumpy PLY grid emitting its vertex colours (mesh_attribute radiance,
    scale 3) over a diffuse floor, its emitting side seen from below."""
    light = _lookat([0, 1.2, 1.0], [0, 0, 1.0], [0, 0, 1]) @ np.diag([0.4, 0.4, 0.4, 1.0])
    floor = _lookat([0, 0, 1], [0, 1, 1], [0, 0, 1]) @ np.diag([3.0, 3.0, 1.0, 1.0])
    cam = _lookat([0.0, 0.6, -2.0], [0.0, 0.4, 1.0], [0, 1, 0])
    return {"type": "scene",
            "light": {"type": "ply", "filename": str(ply), "to_world": light, "emitter": {
                "type": "area", "radiance": {"type": "mesh_attribute", "name": "vertex_color", "scale": 3.0}}},
            "floor": {"type": "rectangle", "to_world": floor, "bsdf": {"type": "diffuse", "reflectance": 0.7}},
            "cam": {"type": "perspective", "fov": 55, "to_world": cam,
                    "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"}}}}


def test_vertex_colour_emitter_estimators_agree(tmp_path):
    """mesh_attribute radiance on an area light reaches every estimator the
    same way: the attribute at the barycentrics of hits (path's emission
    hits), of next event estimation's area samples (path) and of light-path
    origins (ptracer, bdpt). ptracer and bdpt against path (2048 spp), blocked
    z-test with both variances. Power: path with the vertex colours rolled
    by one vertex is rejected against path. (Mitsuba 3.9.1 gives no
    reference here: its scalar_rgb render of this scene ends in a
    segmentation fault.)"""
    from refcompare import blocked_z

    ply, rolled = _attribute_ply(tmp_path / "m.ply"), _attribute_ply(tmp_path / "r.ply", roll=1)

    def render(path, est, spp, seed):
        return rm.render(rm.Scene(load_dict(_vertex_colour_light(path))),
                         integrator={"type": est, "max_depth": 3}, spp=spp, seed=seed)

    ref = render(ply, "path", 2048, 1)
    for est in ("ptracer", "bdpt"):
        res = render(ply, est, 512, 2)
        passed, msg = blocked_z(res.image, res.variance, ref.image, ref.variance)
        assert passed, f"{est}: ours / path = {res.image.sum() / ref.image.sum():.5f}\n{msg}"
    wrong = render(rolled, "path", 512, 2)
    assert not blocked_z(wrong.image, wrong.variance, ref.image, ref.variance)[0]


def test_ply_attributes_grouped_as_mitsuba(tmp_path):
    """The PLY properties beyond position, normal and uv become the same
    attributes, with the same values, as in Mitsuba's PLY reader: NAME_0..
    grouped into vertex_NAME / face_NAME, 8-bit red green blue into
    vertex_color kept as integers (Mitsuba warns and keeps 255)."""
    from radiometer.loader.meshes import _read_ply

    lines = ["ply", "format ascii 1.0", "element vertex 3"]
    lines += [f"property float {n}" for n in "xyz"] + [f"property uchar {n}" for n in ("red", "green", "blue")]
    lines += [f"property float {n}" for n in ("foo_0", "bar_0", "bar_1", "bar_2")]
    lines += ["element face 1", "property list uchar int vertex_indices", "property float w_0", "end_header",
              "0 0 0 255 0 0 0.1 1 2 3", "1 0 0 0 255 0 0.2 4 5 6", "0 1 0 0 0 51 0.3 7 8 9", "3 0 1 2 0.5"]
    path = tmp_path / "a.ply"
    path.write_text("\n".join(lines) + "\n")
    *_, ours = _read_ply(str(path), "test")
    assert sorted(ours) == ["face_w", "vertex_bar", "vertex_color", "vertex_foo"]
    theirs = mi.load_dict({"type": "ply", "filename": str(path)})
    for name, a in ours.items():
        assert theirs.has_attribute(name), name
        np.testing.assert_allclose(a.ravel(), np.array(theirs.attribute_buffer(name)), rtol=1e-7, err_msg=name)
