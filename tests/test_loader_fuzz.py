"""Fuzzing both scene loaders with hypothesis: random scene trees built from
the loader's plugin table (radiometer.loader.PLUGINS) and the parameters
each plugin reads (PARAMS below, the estimators' from the core's registry,
radiometer.registry), with mostly sensible values, some
extreme or mistyped ones and some unknown names, written out as a dict and
as XML (plus XML-only damage: bad number text, truncation, encodings).

The contract: loading gives a SceneDesc or a SceneError whose message starts
with its place (the file, or the dict's key path); never another exception
(no RuntimeWarning from numpy either), never a crash. Every scene that loads
is rendered at 2x2, 1 spp with `path`: it renders, or the renderer refuses
it with a ValueError. The profile is derandomised (a fixed sequence of
examples, no example database), so that CI is reproducible; set
RADIOMETER_FUZZ_EXAMPLES to search longer, RADIOMETER_FUZZ_RANDOM=1 to draw
fresh examples."""
import os
import struct
import warnings
import zlib
from collections import Counter

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import radiometer as rm  # noqa: E402
from radiometer.loader import PLUGINS, SceneWarning, load_dict, load_file  # noqa: E402
from radiometer.registry import estimators  # noqa: E402
from radiometer.scene_desc import SceneError  # noqa: E402

EXAMPLES = int(os.environ.get("RADIOMETER_FUZZ_EXAMPLES", "600"))
PROFILE = settings(max_examples=EXAMPLES, derandomize=not os.environ.get("RADIOMETER_FUZZ_RANDOM"),
                   database=None, deadline=None, print_blob=True,
                   suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                          HealthCheck.filter_too_much])

# -- the schema: parameters each plugin reads, by kind --------------------------------

_MICRO = {"distribution": "distribution", "alpha": "float", "alpha_u": "float", "alpha_v": "float",
          "sample_visible": "bool"}
_DIEL = {"int_ior": "ior", "ext_ior": "ior", "specular_reflectance": "rgb", "specular_transmittance": "rgb"}
_COND = {"material": "material", "eta": "rgb", "k": "rgb", "specular_reflectance": "rgb"}
_MEDIUM = {"sigma_t": "rgb", "albedo": "rgb", "sigma_a": "rgb", "sigma_s": "rgb", "scale": "float",
           "sample_emitters": "bool"}
_PRINCIPLED = {"base_color": "rgb", "roughness": "unit", "anisotropic": "unit", "spec_trans": "unit",
               "spec_tint": "unit", "sheen": "unit", "sheen_tint": "unit", "flatness": "unit"}
PARAMS = {
    "shape": {
        "obj": {"filename": "obj_file", "face_normals": "bool", "flip_normals": "bool", "to_world": "transform",
                "flip_tex_coords": "bool"},
        "ply": {"filename": "ply_file", "face_normals": "bool", "flip_normals": "bool", "to_world": "transform"},
        "rectangle": {"to_world": "transform", "flip_normals": "bool", "face_normals": "bool"},
        "cube": {"to_world": "transform", "flip_normals": "bool", "face_normals": "bool"},
        "disk": {"to_world": "transform", "flip_normals": "bool"},
        "sphere": {"center": "point", "radius": "float", "to_world": "transform", "flip_normals": "bool"},
        "cylinder": {"p0": "point", "p1": "point", "radius": "float", "to_world": "transform",
                     "flip_normals": "bool"},
        "serialized": {"filename": "ser_file", "shape_index": "int", "face_normals": "bool",
                       "flip_normals": "bool", "to_world": "transform"},
        "shapegroup": {},
        "instance": {"to_world": "transform"},
    },
    "bsdf": {
        "diffuse": {"reflectance": "rgb"},
        "conductor": _COND, "roughconductor": {**_COND, **_MICRO},
        "dielectric": _DIEL, "thindielectric": _DIEL, "roughdielectric": {**_DIEL, **_MICRO},
        "plastic": {"diffuse_reflectance": "rgb", "specular_reflectance": "rgb", "int_ior": "ior",
                    "ext_ior": "ior", "nonlinear": "bool"},
        "roughplastic": {"diffuse_reflectance": "rgb", "specular_reflectance": "rgb", "int_ior": "ior",
                         "ext_ior": "ior", "nonlinear": "bool", **_MICRO},
        "twosided": {}, "null": {},
        "principled": {**_PRINCIPLED, "metallic": "unit", "clearcoat": "unit", "clearcoat_gloss": "unit",
                       "specular": "unit", "eta": "float", "main_specular_sampling_rate": "float",
                       "clearcoat_sampling_rate": "float", "diffuse_reflectance_sampling_rate": "float"},
        "principledthin": {**_PRINCIPLED, "eta": "float", "diff_trans": "float",
                           "specular_reflectance_sampling_rate": "float",
                           "specular_transmittance_sampling_rate": "float",
                           "diffuse_reflectance_sampling_rate": "float",
                           "diffuse_transmittance_sampling_rate": "float"},
        "blendbsdf": {"weight": "unit"},
        "mask": {"opacity": "float"},
        "normalmap": {"flip_invalid_normals": "bool", "use_shadowing_function": "bool"},
        "bumpmap": {"scale": "float", "flip_invalid_normals": "bool", "use_shadowing_function": "bool"},
    },
    "emitter": {
        "area": {"radiance": "rgb"}, "constant": {"radiance": "rgb"},
        "point": {"intensity": "rgb", "position": "point", "to_world": "transform"},
        "envmap": {"scale": "float", "to_world": "transform"},
        "spot": {"intensity": "rgb", "cutoff_angle": "angle", "beam_width": "angle", "to_world": "transform"},
        "directional": {"irradiance": "rgb", "direction": "vector", "to_world": "transform"},
        "projector": {"irradiance": "rgb", "scale": "float", "fov": "angle", "fov_axis": "fov_axis",
                      "focal_length": "focal_length", "to_world": "camera"},
    },
    "sensor": {
        "perspective": {"fov": "angle", "fov_axis": "fov_axis", "focal_length": "focal_length",
                        "near_clip": "float", "far_clip": "clip", "to_world": "camera", "focus_distance": "float"},
        "orthographic": {"to_world": "transform", "near_clip": "float", "far_clip": "clip"},
        "radiancemeter": {"to_world": "camera", "origin": "point", "direction": "vector"},
        "irradiancemeter": {},
    },
    "film": {"hdrfilm": {"width": "res", "height": "res", "pixel_format": "pixel_format",
                         "component_format": "component_format"}},
    "rfilter": {"box": {}, "tent": {"radius": "float"}, "gaussian": {"stddev": "float"}},
    "sampler": {"independent": {"sample_count": "spp", "seed": "int"},
                "stratified": {"sample_count": "spp", "seed": "int", "jitter": "bool"},
                "multijitter": {"sample_count": "spp", "seed": "int", "jitter": "bool"},
                "sobol": {"sample_count": "spp", "seed": "int"},
                "zsobol": {"sample_count": "spp", "seed": "int"},
                "ldsampler": {"sample_count": "spp", "seed": "int"}},
    "medium": {"homogeneous": _MEDIUM, "heterogeneous": {**_MEDIUM, "has_spectral_extinction": "bool"}},
    "phase": {"isotropic": {}, "hg": {"g": "g"}},
    "volume": {"gridvolume": {"filename": "vol_file", "to_world": "transform", "use_grid_bbox": "bool",
                              "filter_type": "filter_type", "wrap_mode": "wrap_mode", "raw": "bool",
                              "accel": "bool"},
               "constvolume": {"value": "rgb", "to_world": "transform"}},
    "texture": {"checkerboard": {"color0": "rgb", "color1": "rgb", "to_uv": "transform"},
                "bitmap": {"filename": "img_file", "filter_type": "tex_filter", "wrap_mode": "tex_wrap",
                           "raw": "bool", "to_uv": "transform", "format": "tex_format", "accel": "bool"},
                "rawconstant": {"value": "float"},
                "mesh_attribute": {"name": "attr_name", "scale": "float"}},
    "subsurface": {"dipole": {"sigma_a": "rgb", "sigma_s": "rgb", "sigma_t": "rgb", "albedo": "rgb",
                              "scale": "float", "g": "g", "int_ior": "ior", "ext_ior": "ior"}},
    # The estimators' declarations in the core's registry, Mitsuba 0.6 names included.
    "integrator": {n: {name: {"int": "int", "float": "float", "bool": "bool", "string": "string"}[p["type"]]
                       for k, p in e["params"].items() for name in [k, *p["aliases"]]}
                   for e in estimators().values() for n in [e["name"], *e["aliases"]]} | {"moment": {}},
}
assert {c: set(t) for c, t in PARAMS.items()} == {c: set(t) for c, t in PLUGINS.items()}, \
    "the fuzzer's schema must cover the loader's plugin table"

def _png(mode, shape):
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.arange(int(np.prod(shape)), dtype=np.uint8).reshape(shape), mode).save(buf, "PNG")
    return buf.getvalue()


# Files the scenes may name: valid and broken meshes, volumes and images.
_TRI_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 2 4 3\n"
FILES = {
    "tri.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3 1\n",
    "uv.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1\n",
    "degenerate.obj": b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n",
    "nan.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn nan 0 1\nf 1//1 2//1 3//1\n",
    "bad.obj": b"v 0 0 0\nf 1 2 3\n",
    "tri.ply": (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
    "bad.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n",
    "ok.vol": (b"VOL\x03" + struct.pack("<5i", 1, 2, 2, 2, 1) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
               + np.linspace(0, 2, 8, dtype="<f4").tobytes()),
    "rgb.vol": (b"VOL\x03" + struct.pack("<5i", 1, 1, 1, 2, 3) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
                + np.full(6, 0.5, dtype="<f4").tobytes()),
    "bad.vol": b"VOL\x03" + bytes(20),
    "rgb.png": _png("RGB", (3, 4, 3)),
    "grey.png": _png("L", (1, 5)),
    "bad.png": b"\x89PNG\r\n\x1a\n" + bytes(30),
    # Mitsuba's serialized format (tests/test_shapes.py writes it the same way): one triangle.
    "tri.serialized": (struct.pack("<HH", 0x041C, 4) + zlib.compress(
        struct.pack("<I", 0x1000) + b"tri\0" + struct.pack("<QQ", 3, 1)
        + np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], "<f4").tobytes() + np.array([0, 1, 2], "<u4").tobytes())
        + struct.pack("<QI", 0, 1)),
    "bad.serialized": struct.pack("<HH", 0x041C, 4) + b"not zlib",
}
_OBJ_NAMES = ["tri.obj", "uv.obj", "degenerate.obj", "nan.obj", "bad.obj", "absent.obj", "tri.ply",
              "../outside.obj", "link.obj", "sub/../tri.obj", "", "."]
_PLY_NAMES = ["tri.ply", "bad.ply", "absent.ply", "tri.obj"]
_VOL_NAMES = ["ok.vol", "rgb.vol", "bad.vol", "absent.vol", "../outside.vol", "link.vol"]
_IMG_NAMES = ["rgb.png", "grey.png", "bad.png", "absent.png", "tri.obj", "ok.vol"]
_SER_NAMES = ["tri.serialized", "bad.serialized", "absent.serialized", "tri.obj"]
_FILE_NAMES = set(_OBJ_NAMES + _PLY_NAMES + _VOL_NAMES + _IMG_NAMES + _SER_NAMES)

# -- values ---------------------------------------------------------------------

_EXTREME_FLOATS = [0.0, -0.0, -1.0, 1e-30, 1e-18, 1e18, 1e30, 1e300, float("nan"), float("inf"), -float("inf")]
_EXTREME_INTS = [0, -1, -2, 2**31 - 1, 2**31, -2**31 - 1, 2**63, 10**30]
_WEIRD_DICT = [None, 1j, "1", "1_6", [True, False, True], ["1", "2", "3"], [1j, 0, 0], np.array([True, True, True]),
               10**400, [10**400, 0, 0], {1.0}, [[1.0]], np.float32(0.5), np.int64(3), np.bool_(False), (), b"x"]
# Attribute text the XML front end must refuse (or read as the number it is).
_WEIRD_TEXT = ["1_6", "nan", "inf", "", " 1 ", "0x10", "\u0661", "1e400", "--1", "1,,2", "true", "1 2 3 4",
               "9" * 400, "$undefined", "&amp;", "1e-400", "+.5", "5.", ".", "e5", "1e+"]
_STRINGS = {
    "distribution": ["beckmann", "ggx", "phong"], "material": ["none", "Au"],
    "fov_axis": ["x", "y", "diagonal", "smaller", "larger", "z"], "focal_length": ["50mm", "35mm", "0mm", "abc"],
    "pixel_format": ["rgb", "rgba", "xyz"], "component_format": ["float16", "float32", "uint8"],
    "filter_type": ["trilinear", "nearest"], "wrap_mode": ["clamp", "repeat"],
    "string": ["power", "balance", "uniform", "x"],
    "tex_filter": ["bilinear", "nearest", "trilinear"], "tex_wrap": ["repeat", "mirror", "clamp", "wrap"],
    "tex_format": ["auto", "variant", "fp16", "uint8"],
    "attr_name": ["vertex_color", "face_color", "color", "vertex_normal"],
}


def _finite_floats(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def _matrix(draw, camera=False):
    """Mostly rigid or uniformly scaled maps; sometimes random, singular or
    huge ones."""
    kind = draw(st.sampled_from(["identity", "translate", "scale", "rotate", "random", "singular", "huge", "ops"]))
    if kind == "ops":  # XML's transform operations (a dict gets the identity)
        ops = []
        for op in draw(st.lists(st.sampled_from(["translate", "scale", "rotate", "lookat", "matrix"]), max_size=3)):
            x, y, z = (_text("", v) for v in draw(st.lists(_finite_floats(-2, 2), min_size=3, max_size=3)))
            ops.append({"translate": f'<translate x="{x}" y="{y}" z="{z}"/>',
                        "scale": f'<scale value="{x}"/>',
                        "rotate": f'<rotate {draw(st.sampled_from("xyz"))}="1" angle="{x}"/>',
                        "lookat": f'<lookat origin="{x} {y} {z}" target="0 0 0" up="0 1 0"/>',
                        "matrix": f'<matrix value="{x} 0 0 {y} 0 1 0 0 0 0 1 {z}"/>'}[op])
        return ("ops", ops)
    m = np.eye(4)
    if kind == "translate":
        m[:3, 3] = draw(st.lists(_finite_floats(-5, 5), min_size=3, max_size=3))
        if camera:
            m[2, 3] = -abs(m[2, 3]) - 2.0
    elif kind == "scale":
        m[:3, :3] *= draw(_finite_floats(0.1, 3))
    elif kind == "rotate":
        a = draw(_finite_floats(0, 6.3))
        m[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    elif kind == "random":
        m[:3, :] = np.array(draw(st.lists(_finite_floats(-3, 3), min_size=12, max_size=12))).reshape(3, 4)
    elif kind == "singular":
        m[1, 1] = 0.0
    elif kind == "huge":
        m[:3, :3] *= draw(st.sampled_from([1e-300, 1e-30, 1e-13, 1e13, 1e30, 1e39, 1e300]))
    return ("transform", m.tolist())


def _good_table():
    """Strategies for a sensible value of each kind: (xml tag, python value)."""
    rgb = st.one_of(_finite_floats(0, 1), st.lists(_finite_floats(0, 1), min_size=3, max_size=3))
    table = {
        "float": _finite_floats(0.05, 3).map(lambda x: ("float", x)),
        "unit": _finite_floats(0, 1).map(lambda x: ("float", x)),
        "angle": _finite_floats(1, 120).map(lambda x: ("float", x)),
        "clip": _finite_floats(10, 1e4).map(lambda x: ("float", x)),
        "g": _finite_floats(-0.9, 0.9).map(lambda x: ("float", x)),
        "ior": st.one_of(_finite_floats(1.0, 2.5).map(lambda x: ("float", x)),
                         st.sampled_from(["bk7", "water", "Air", "unobtainium"]).map(lambda s: ("string", s))),
        "int": st.integers(-1, 8).map(lambda x: ("integer", x)),
        "res": st.integers(1, 8).map(lambda x: ("integer", x)),
        "spp": st.integers(1, 4).map(lambda x: ("integer", x)),
        "bool": st.booleans().map(lambda x: ("boolean", x)),
        "rgb": rgb.map(lambda x: ("rgb", x)),
        "point": st.lists(_finite_floats(-3, 3), min_size=3, max_size=3).map(lambda x: ("point", x)),
        "vector": st.lists(_finite_floats(-1, 1), min_size=3, max_size=3).map(lambda x: ("vector", x)),
        "transform": _matrix(),
        "camera": _matrix(camera=True),
        "obj_file": st.sampled_from(_OBJ_NAMES).map(lambda s: ("string", s)),
        "ply_file": st.sampled_from(_PLY_NAMES).map(lambda s: ("string", s)),
        "vol_file": st.sampled_from(_VOL_NAMES).map(lambda s: ("string", s)),
        "img_file": st.sampled_from(_IMG_NAMES).map(lambda s: ("string", s)),
        "ser_file": st.sampled_from(_SER_NAMES).map(lambda s: ("string", s)),
    }
    table.update({k: st.sampled_from(v).map(lambda s: ("string", s)) for k, v in _STRINGS.items()})
    return table


_GOOD = _good_table()


# An extreme or mistyped value.
_BAD = st.one_of(
    st.sampled_from(_EXTREME_FLOATS).map(lambda x: ("float", x)),
    st.sampled_from(_EXTREME_INTS).map(lambda x: ("integer", x)),
    st.sampled_from(["", "x", "1_6"]).map(lambda s: ("string", s)),
    st.booleans().map(lambda x: ("boolean", x)),
    st.sampled_from(_EXTREME_FLOATS).map(lambda x: ("rgb", [x, 0.5, 0.5])),
    st.sampled_from(_WEIRD_DICT).map(lambda x: ("weird", x)),
    st.sampled_from(_WEIRD_TEXT).map(lambda s: ("text", s)),
    st.lists(st.sampled_from(_EXTREME_FLOATS + [1e200, 1e-200, 5e-324, 1e39, 1.0]), min_size=3, max_size=3).map(
        lambda v: ("vector", v)),
    st.sampled_from([1e-300, 1e-200, 1e-100, 1e100, 1e200, 1e300]).map(
        lambda x: ("transform", np.diag([x, x, x, 1.0]).tolist())),
    st.sampled_from([1e-300, 1e300, 1e38]).map(lambda x: ("transform", [[1, 0, 0, x], [0, 1, 0, 0], [0, 0, 1, 0],
                                                                       [0, 0, 0, 1]])),
)


@st.composite
def _value(draw, kind):
    """Mostly a sensible value; one in 12 extreme or mistyped."""
    return draw(_BAD if draw(st.integers(0, 11)) == 0 else _GOOD[kind])


# Parameters a plugin cannot do without, drawn nearly always.
_REQUIRED = {"obj": "filename", "ply": "filename", "serialized": "filename", "gridvolume": "filename",
             "bitmap": "filename", "blendbsdf": "weight", "rawconstant": "value", "mesh_attribute": "name"}
# Plugin types that stand only nested, rarely drawn elsewhere.
_NESTED_ONLY = {"emitter": ["area"], "sensor": ["irradiancemeter"]}


# -- scene trees ------------------------------------------------------------------
# A node: (category, type, name, params [(name, (tag, value))], children [node]);
# name is the dict key / XML name attribute a child is given under, or None.


@st.composite
def _node(draw, category, name=None, depth=0, types=None):
    if types is None:
        types = PLUGINS[category]
        if category in _NESTED_ONLY and draw(st.integers(0, 9)):
            types = [t for t in types if t not in _NESTED_ONLY[category]]
    t = draw(st.sampled_from(types))
    schema = PARAMS[category][t]
    names = draw(st.lists(st.sampled_from(sorted(schema)), unique=True, max_size=4)) if schema else []
    if t in _REQUIRED and _REQUIRED[t] not in names and draw(st.integers(0, 19)):
        names.append(_REQUIRED[t])
    params = [(n, draw(_value(schema[n]))) for n in names]
    if draw(st.integers(0, 15)) == 0:  # an unknown parameter
        params.append(("reflectanse", draw(_value("float"))))
    children = []
    child = (lambda c, n=None, **k: children.append(draw(_node(c, n, depth + 1, **k)))) if depth < 4 else None
    if child is not None:
        if category == "shape" and t == "shapegroup":
            for n in ("a", "b")[:draw(st.integers(0, 2))]:
                child("shape", n)
        elif category == "shape" and t == "instance":
            if draw(st.integers(0, 9)):
                child("shape", "group", types=["shapegroup"] if draw(st.integers(0, 9)) else None)
        elif category == "shape":
            if draw(st.booleans()):
                child("bsdf", "bsdf")
            if draw(st.integers(0, 3)) == 0:
                child("emitter", "emitter", types=["area"] if draw(st.integers(0, 9)) else None)
            if draw(st.integers(0, 5)) == 0:
                child("medium", draw(st.sampled_from(["interior", "exterior", "inside"])))
            if draw(st.integers(0, 9)) == 0:
                child("subsurface", "subsurface")
            if draw(st.integers(0, 19)) == 0:
                child("sensor", "sensor", types=["irradiancemeter"])
        elif category == "bsdf" and t in ("mask", "normalmap", "bumpmap"):
            # a nested bsdf (usually one), and the texture of the map or the mask's opacity
            for n in ("a", "b")[:draw(st.sampled_from([0, 1, 1, 1, 2]))]:
                child("bsdf", n)
            if t != "mask" or draw(st.booleans()):
                child("texture", {"mask": "opacity", "normalmap": "normalmap", "bumpmap": "height"}[t])
        elif category == "bsdf" and t not in ("twosided", "blendbsdf") and draw(st.integers(0, 3)) == 0:
            # a texture on a colour parameter that takes one, or on one that does not
            child("texture", draw(st.sampled_from(["reflectance", "diffuse_reflectance", "specular_reflectance",
                                                   "specular_transmittance", "eta", "alpha", "alpha_u",
                                                   "base_color", "roughness", "diff_trans"])))
        elif category == "emitter" and t in ("area", "spot", "projector") and draw(st.integers(0, 3)) == 0:
            # a texture on the emission parameter that takes one, or on one that does not
            child("texture", draw(st.sampled_from([{"area": "radiance", "spot": "texture",
                                                    "projector": "irradiance"}[t], "intensity"])))
        elif category == "bsdf" and t in ("twosided", "blendbsdf"):
            for n in ("a", "b")[:draw(st.integers(0, 3))] + (("c",) if draw(st.integers(0, 9)) == 0 else ()):
                child("bsdf", n)
        elif category == "sensor":
            if draw(st.booleans()):
                child("film", "film")
            if draw(st.booleans()):
                child("sampler", "sampler")
            if draw(st.integers(0, 5)) == 0:
                child("medium", "medium")
        elif category == "film" and draw(st.booleans()):
            child("rfilter", "rfilter")
        elif category == "medium":
            if draw(st.booleans()):
                child("phase", "phase")
            if t == "heterogeneous" and draw(st.booleans()):
                child("volume", draw(st.sampled_from(["sigma_t", "albedo"])))
    return (category, t, name, params, children)


@st.composite
def scenes(draw):
    top = []
    for category, chance in (("shape", 1), ("shape", 2), ("emitter", 2), ("sensor", 1), ("integrator", 2),
                             ("bsdf", 6), ("medium", 6), ("film", 20), ("subsurface", 20), ("texture", 12)):
        if draw(st.integers(0, chance)) == 0:
            top.append(draw(_node(category)))
    if top and draw(st.integers(0, 7)) == 0:  # a ref: to a node declared on top, or to nothing
        shapes = [n for n in top if n[0] == "shape"]
        if shapes:
            shapes[0][4].append(("ref", draw(st.sampled_from(["n0", "n1", "nowhere"])), "bsdf", [], []))
    return top


# -- writing a tree as a dict and as XML ---------------------------------------------


def _dict_value(tag, value, base):
    if tag == "string" and value in _FILE_NAMES:  # dicts resolve against the current folder: make it absolute
        return os.path.join(base, value)
    if tag == "rgb" and isinstance(value, list) and len(value) == 3 and len(repr(value)) % 2:
        return {"type": "rgb", "value": value}
    if tag == "transform":
        return np.array(value)
    if tag == "ops":
        return np.eye(4)
    if tag == "text":
        return value
    return value


def to_dict(tree, base):
    def node(n, i):
        cat, t, _, params, children = n
        if cat == "ref":
            return {"type": "ref", "id": t}
        d = {"type": t, **{k: _dict_value(tag, v, base) for k, (tag, v) in params}}
        for j, c in enumerate(children):
            d[c[2] if c[2] not in d else f"{c[2]}{j}"] = node(c, j)
        return d

    return {"type": "scene", **{f"n{i}": node(n, i) for i, n in enumerate(tree)}}


def _text(tag, v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return " ".join(_text(tag, x) for x in v)
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _xml_prop(name, tag, v):
    from xml.sax.saxutils import quoteattr

    if tag == "ops":
        return f'<transform name="{name}">{"".join(v)}</transform>'
    if tag == "transform":
        return f'<transform name="{name}"><matrix value="{_text(tag, [x for row in v for x in row])}"/></transform>'
    if tag == "weird":  # a Python object has no XML form; write its text
        return f"<string name={quoteattr(name)} value={quoteattr(str(v)[:60])}/>"
    if tag == "text":
        return f"<float name={quoteattr(name)} value={quoteattr(v)}/>"
    if tag in ("point", "vector") and isinstance(v, list):
        return f'<{tag} name="{name}" x="{_text(tag, v[0])}" y="{_text(tag, v[1])}" z="{_text(tag, v[2])}"/>'
    return f"<{tag} name={quoteattr(name)} value={quoteattr(_text(tag, v))}/>"


def to_xml(tree):
    def node(n, i):
        cat, t, name, params, children = n
        if cat == "ref":
            return f'<ref id="{t}" name="{name}"/>'
        attrs = f' type="{t}"' + (f' name="{name}"' if name else "") + ("" if name else f' id="n{i}"')
        body = "\n".join([_xml_prop(k, tag, v) for k, (tag, v) in params] + [node(c, j) for j, c in
                                                                               enumerate(children)])
        return f"<{cat}{attrs}>\n{body}\n</{cat}>"

    return '<scene version="3.0.0">\n' + "\n".join(node(n, i) for i, n in enumerate(tree)) + "\n</scene>\n"


# -- the contract -------------------------------------------------------------------


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    for name, data in FILES.items():
        (root / name).write_bytes(data)
    # Files outside the scene's folder, directly and through links in it.
    (root.parent / "outside.obj").write_bytes(FILES["tri.obj"])
    (root.parent / "outside.vol").write_bytes(FILES["ok.vol"])
    (root / "link.obj").symlink_to(root.parent / "outside.obj")
    (root / "link.vol").symlink_to(root.parent / "outside.vol")
    (root / "sub").mkdir()
    return root


def _load(load, place):
    """desc, or None after a SceneError whose message starts with `place`."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # numpy maths on an unchecked value
        warnings.simplefilter("ignore", SceneWarning)
        try:
            return load()
        except SceneError as e:
            assert str(e).startswith(place), f"message without its place: {e}"
            return None


def _renders(desc):
    """Renders at 2x2 (a point sensor keeps its 1x1), 1 spp, with `path`:
    True, or False after a ValueError (a scene the renderer refuses)."""
    if desc.sensor.type in ("perspective", "orthographic"):
        desc.sensor.width = desc.sensor.height = 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # warnings about what the scene will look like
        try:
            res = rm.render(rm.Scene(desc), integrator="path", spp=1, threads=1)
        except ValueError:
            return False
    # An irradiancemeter measures one value whatever its film (a SceneWarning says so).
    shape = (1, 1) if desc.sensor.type == "irradiancemeter" else (desc.sensor.height, desc.sensor.width)
    assert res.image.shape[:2] == shape
    return True


def _check_stats(stats):
    """The search is only worth its time if it reaches both outcomes."""
    print(f"fuzz outcomes: {dict(stats)}")
    assert stats["error"] >= EXAMPLES // 10, stats
    assert stats["rendered"] >= EXAMPLES // 20, stats


def test_dict_loader_fuzz(files):
    stats = Counter()

    @PROFILE
    @given(tree=scenes())
    def run(tree):
        desc = _load(lambda: load_dict(to_dict(tree, str(files))), ("scene", "<dict>"))
        stats["error" if desc is None else "rendered" if _renders(desc) else "refused"] += 1

    run()
    _check_stats(stats)


_DAMAGE = ["none"] * 12 + ["truncate", "encoding", "tag", "text", "doctype", "nul", "default", "undefined"]


@st.composite
def xml_documents(draw):
    text = to_xml(draw(scenes()))
    damage = draw(st.sampled_from(_DAMAGE))
    if damage == "truncate":
        text = text[:draw(st.integers(0, len(text)))]
    elif damage == "encoding":
        enc = draw(st.sampled_from(["utf-8", "latin-1", "utf-16", "ascii", "klingon", "ebcdic"]))
        text = f'<?xml version="1.0" encoding="{enc}"?>\n' + text
    elif damage == "tag":
        text = text.replace("<bsdf", "<bsdff", 1).replace("</bsdf>", "</bsdff>", 1)
    elif damage == "text":  # a number attribute replaced by hostile text
        i = text.find('value="')
        if i >= 0:
            j = text.index('"', i + 7)
            text = text[:i + 7] + draw(st.sampled_from(_WEIRD_TEXT)) + text[j:]
    elif damage == "doctype":
        text = '<!DOCTYPE scene [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>\n' + text.replace(
            'version="3.0.0">', 'version="3.0.0"><!-- &b; -->', 1)
    elif damage == "nul":
        text = text.replace(">", ">\x00", 1)
    elif damage in ("default", "undefined"):  # a value through a <default> parameter, or an undeclared one
        i = text.find('value="')
        if i >= 0:
            j = text.index('"', i + 7)
            value = text[i + 7:j]
            text = text[:i + 7] + "$p" + text[j:]
            if damage == "default":
                text = text.replace('version="3.0.0">', f'version="3.0.0">\n<default name="p" value="{value}"/>', 1)
    return text


def test_xml_loader_fuzz(files):
    stats = Counter()
    path = files / "fuzz.xml"

    @PROFILE
    @given(text=xml_documents(), untrusted=st.booleans())
    def run(text, untrusted):
        path.write_bytes(text.encode("utf-8"))
        desc = _load(lambda: load_file(path, base_dir_only=untrusted), str(path))
        stats["error" if desc is None else "rendered" if _renders(desc) else "refused"] += 1

    run()
    _check_stats(stats)
