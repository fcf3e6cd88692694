"""A corpus of bad scene inputs: each case must give a SceneError (or, for a
valid but suspicious scene, a SceneWarning) whose message names the element
and its place: `scene.xml:LINE:` for XML, the key path `scene['a']['b']` for
dicts, plus the words that say what is wrong. Nothing else may escape (no
OverflowError, RecursionError, LookupError, pybind11 TypeError).

Categories: malformed XML, bad values, meshes (OBJ, PLY), dicts, media,
sensors and films, integrators. XML cases mark the offending line with a
trailing '«' (removed before writing), so that the expected line number
follows the text. Pure Python apart from the few cases that build the C++
scene (marked `core`)."""
import struct
import warnings

import numpy as np
import pytest

import radiometer as rm
from radiometer.loader import SceneWarning, load_dict, load_file
from radiometer.scene_desc import SceneError

MARK = "«"


def _lines(body):
    """(text, line of the marked line) of a scene whose body is `body`."""
    text = f'<scene version="3.0.0">\n{body}\n</scene>\n' if not body.startswith(("<?", "<!", "#raw")) else body
    text = text.removeprefix("#raw")
    for i, line in enumerate(text.split("\n"), 1):
        if line.endswith(MARK):
            return text.replace(MARK, ""), i
    raise AssertionError(f"no line marked with {MARK} in {body!r}")


# -- files referenced by the cases ---------------------------------------------


def _ply(vertices, faces, extra_props="", binary=False, header_extra=""):
    n_props = ["x", "y", "z"] + extra_props.split()
    head = ["ply", "format binary_little_endian 1.0" if binary else "format ascii 1.0",
            f"element vertex {len(vertices)}"] + [f"property float {p}" for p in n_props]
    head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    if header_extra:
        head.append(header_extra)
    head.append("end_header")
    if binary:
        body = b"".join(struct.pack(f"<{len(v)}f", *v) for v in vertices)
        body += b"".join(struct.pack(f"<B{len(f)}i", len(f), *f) for f in faces)
        return ("\n".join(head) + "\n").encode() + body
    rows = [" ".join(map(str, v)) for v in vertices] + [" ".join(map(str, [len(f), *f])) for f in faces]
    return ("\n".join(head + rows) + "\n").encode()


TRI = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]


def _vol(data, version=3, encoding=1, res=None, channels=None, bbox=(0, 0, 0, 1, 1, 1), trunc=0):
    a = np.asarray(data, np.float32)
    nz, ny, nx = a.shape[:3]
    nx, ny, nz = res or (nx, ny, nz)
    ch = channels or (a.shape[3] if a.ndim == 4 else 1)
    raw = b"VOL" + bytes([version]) + struct.pack("<5i", encoding, nx, ny, nz, ch)
    raw += struct.pack("<6f", *bbox) + a.astype("<f4").tobytes()
    return raw[:len(raw) - trunc] if trunc else raw


FILES = {
    "tri.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "nofaces.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\n",
    "short_v.obj": b"v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n",
    "word_v.obj": b"v 0 0 0\nv 1 0 zero\nv 0 1 0\nf 1 2 3\n",
    "nan_v.obj": b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n",
    "inf_v.obj": b"v 0 0 0\nv 1e400 0 0\nv 0 1 0\nf 1 2 3\n",
    "nan_vn.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 nan\nf 1//1 2//1 3//1\n",
    "inf_vt.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt inf 0\nf 1/1 2/1 3/1\n",
    "underscore_v.obj": b"v 0 0 0\nv 1_0 0 0\nv 0 1 0\nf 1 2 3\n",
    "truncated.obj": b"v 0 0 0\nv 1 0 0\nf 1 2 3\n",
    "neg_index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n",
    "zero_index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
    "big_index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n",
    "bad_vt.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n",
    "no_vt.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/1 3/1\n",
    "bad_vn.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//2 3//1\n",
    "no_vn.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\n",
    "mixed_vn.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2 3//1\n",
    "two_verts.obj": b"v 0 0 0\nv 1 0 0\nf 1 2\n",
    "four_slash.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n",
    "word_f.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 three\n",
    "tri.ply": _ply(TRI, [(0, 1, 2)]),
    "quad.ply": _ply(TRI + [(1, 1, 0)], [(0, 1, 2, 3)]),
    "oob.ply": _ply(TRI, [(0, 1, 3)]),
    "neg.ply": _ply(TRI, [(0, 1, -1)]),
    "nan.ply": _ply([(0, 0, 0), (float("nan"), 0, 0), (0, 1, 0)], [(0, 1, 2)]),
    "nan_n.ply": _ply([(0, 0, 0, 0, 0, 1), (1, 0, 0, 0, 0, float("nan")), (0, 1, 0, 0, 0, 1)], [(0, 1, 2)],
                      "nx ny nz"),
    "nan_uv.ply": _ply([(0, 0, 0, 0, 0), (1, 0, 0, float("inf"), 0), (0, 1, 0, 0, 1)], [(0, 1, 2)], "u v"),
    "nofaces.ply": _ply(TRI, []),
    "truncated.ply": _ply(TRI, [(0, 1, 2)], binary=True)[:-7],
    "garbage.ply": b"ply\nformat ascii 1.0\nelement vertex three\nend_header\n",
    "notply.ply": b"solid cube\nfacet normal 0 0 1\n",
    "empty.ply": b"",
    "noxyz.ply": b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nelement face 0\n"
                 b"property list uchar int vertex_indices\nend_header\n0\n",
    "noface_elem.ply": b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                       b"property float z\nend_header\n0 0 0\n",
    "ok.vol": _vol(np.ones((2, 2, 2))),
    "v2.vol": _vol(np.ones((2, 2, 2)), version=2),
    "f16.vol": _vol(np.ones((2, 2, 2)), encoding=2),
    "truncated.vol": _vol(np.ones((2, 2, 2)), trunc=4),
    "nan.vol": _vol(np.full((2, 2, 2), np.nan)),
    "zero_res.vol": _vol(np.ones((2, 2, 2)), res=(0, 2, 2)),
    "two_ch.vol": _vol(np.ones((2, 2, 2, 2))),
    "notvol.vol": b"VOX" + bytes(60),
    "tiny.vol": b"VOL\x03",
    "empty_bbox.vol": _vol(np.ones((2, 2, 2)), bbox=(0, 0, 0, 0, 1, 1)),
}


def _mesh(kind, name, line_mark=True):
    mark = MARK if line_mark else ""
    return f'<shape type="{kind}"><string name="filename" value="{name}"/></shape>{mark}'


def _medium(inner, mark_inner=False):
    return ('<shape type="cube"><bsdf type="null"/>\n'
            f'<medium type="homogeneous" name="interior">{inner}</medium>{MARK if not mark_inner else ""}\n'
            '</shape>')


def _grid(vol, extra=""):
    return ('<shape type="cube"><bsdf type="null"/>\n'
            '<medium type="heterogeneous" name="interior">\n'
            f'<volume type="gridvolume" name="sigma_t"><string name="filename" value="{vol}"/>{extra}</volume>'
            f'{MARK}\n</medium>\n</shape>')


def _sensor(inner, kind="perspective"):
    return f'<sensor type="{kind}">{inner}</sensor>{MARK}'


def _film(inner):
    return f'<sensor type="perspective"><film type="hdrfilm">{inner}</film>{MARK}\n</sensor>'


def _integrator(kind, inner=""):
    return f'<integrator type="{kind}">{inner}</integrator>{MARK}'


# (id, xml body, words the message must contain). The place is checked
# separately: `<scene file>:<marked line>:`.
XML = [
    # -- malformed XML ----------------------------------------------------------
    ("unclosed", '<shape type="sphere">\n<bsdf type="diffuse">\n</shape>' + MARK, ["malformed XML"]),
    ("mismatched", '<shape type="sphere"></bsdf>' + MARK, ["malformed XML", "mismatched tag"]),
    ("empty_file", "#raw" + MARK, ["malformed XML", "no element found"]),
    ("garbage", "#raw\x00\x01\x02 not xml" + MARK, ["malformed XML"]),
    ("bad_attr_syntax", '<shape type=sphere/>' + MARK, ["malformed XML"]),
    ("duplicate_attr", '<shape type="sphere" type="cube"/>' + MARK, ["malformed XML", "duplicate attribute"]),
    ("undefined_entity", '<shape type="&nope;"/>' + MARK, ["malformed XML", "undefined entity"]),
    ("two_roots", "#raw" + '<scene version="3.0.0"/>\n<scene version="3.0.0"/>' + MARK, ["malformed XML"]),
    ("unknown_encoding", '#raw<?xml version="1.0" encoding="klingon"?>' + MARK + '\n<scene version="3.0.0"/>',
     ["unsupported XML encoding", "klingon"]),
    ("wrong_encoding", '#raw<?xml version="1.0" encoding="utf-16"?>' + MARK + '\n<scene version="3.0.0"/>',
     ["XML"]),
    ("root_not_scene", '#raw<shape type="sphere"/>' + MARK, ["root element must be <scene>"]),
    ("no_version", "#raw<scene>" + MARK + "\n</scene>", ["missing attribute 'version'"]),
    ("version_two_parts", '#raw<scene version="2.1">' + MARK + "\n</scene>", ["cannot parse version '2.1'"]),
    ("version_text", '#raw<scene version="3.x.0">' + MARK + "\n</scene>", ["cannot parse version '3.x.0'"]),
    ("scene_attr", '#raw<scene version="3.0.0" units="mm">' + MARK + "\n</scene>", ["unknown attribute 'units'"]),
    ("unknown_element", "<teapot/>" + MARK, ["unknown element <teapot>"]),
    ("unknown_plugin_attr", '<shape type="sphere" colour="red"/>' + MARK, ["unknown attribute 'colour'"]),
    ("missing_type", "<shape/>" + MARK, ["missing attribute 'type'"]),
    ("unknown_shape", '<shape type="teapot"/>' + MARK, ["shape type 'teapot' is not supported"]),
    ("unknown_bsdf", '<shape type="sphere"><bsdf type="hair"/></shape>' + MARK,
     ["bsdf type 'hair' is not supported"]),
    ("unknown_emitter", '<emitter type="sunsky"/>' + MARK, ["emitter type 'sunsky' is not supported"]),
    ("unknown_sensor", '<sensor type="thinlens"/>' + MARK, ["sensor type 'thinlens' is not supported"]),
    ("unknown_film", '<sensor type="perspective"><film type="specfilm"/></sensor>' + MARK,
     ["film type 'specfilm'"]),
    ("unknown_sampler", '<sensor type="perspective"><sampler type="orthogonal"/></sensor>' + MARK,
     ["sampler type 'orthogonal'"]),
    ("unknown_rfilter", _film('<rfilter type="lanczos"/>'), ["rfilter type 'lanczos'"]),
    ("texture", '<texture type="wood"/>' + MARK, ["texture type 'wood' is not supported"]),
    ("texture_no_file", '<texture type="bitmap"/>' + MARK, ["texture 'bitmap'", "missing parameter 'filename'"]),
    ("texture_param", '<shape type="sphere"><bsdf type="dielectric">\n<texture name="specular_transmittance" '
     'type="checkerboard"/>' + MARK + "\n</bsdf></shape>",
     ["bsdf 'dielectric'", "parameter 'specular_transmittance' cannot take a texture", "texture 'checkerboard'"]),
    ("include_missing", '<include filename="other.xml"/>' + MARK, ["<include>", "file 'other.xml' not found"]),
    ("include_nested_path", '<shape type="sphere">\n<path value="."/>' + MARK + "\n</shape>",
     ["<path> is allowed only at the top level"]),
    ("path_missing", '<path value="no_such_folder"/>' + MARK, ["<path>", "folder 'no_such_folder' not found"]),
    ("alias", '<alias id="a" as="b"/>' + MARK, ["<alias> is not supported"]),
    ("nested_default", '<shape type="sphere"><default name="r" value="1"/></shape>' + MARK,
     ["<default> is not supported (only at the top level)"]),
    ("top_level_property", '<float name="radius" value="1"/>' + MARK, ["not allowed at the top level"]),
    ("property_with_child", '<shape type="sphere"><float name="radius" value="1">\n<float name="x" value="1"/>'
                            + MARK + "\n</float></shape>", ["takes no nested elements"]),
    ("ref_wrong_category", '<medium type="homogeneous" id="fog"/>\n<shape type="sphere">\n<ref id="fog"/>'
     + MARK + "\n</shape>", ["unexpected nested medium 'homogeneous'", "ref_wrong_category.xml:2"]),
    ("ref_with_child", '<bsdf type="diffuse" id="b"/>\n<shape type="sphere"><ref id="b">\n<float name="x" value="1"/>'
                       + MARK + "\n</ref></shape>", ["takes no nested elements"]),
    ("undefined_param", '<shape type="sphere"><float name="radius" value="$r"/></shape>' + MARK,
     ["undefined parameter $r"]),
    ("duplicate_id", '<bsdf type="diffuse" id="b"/>\n<bsdf type="diffuse" id="b"/>' + MARK, ["duplicate id 'b'"]),
    ("unknown_ref", '<shape type="sphere"><ref id="nothing"/></shape>' + MARK, ["unknown id 'nothing'"]),
    ("param_twice", '<shape type="sphere"><float name="radius" value="1"/>\n<float name="radius" value="2"/>'
                    + MARK + "\n</shape>", ["parameter 'radius' given twice"]),
    ("deep_nesting", '<shape type="sphere">\n' + '<bsdf type="twosided">' * 50000 + MARK + "\n"
     + "</bsdf>" * 50000 + "</shape>", ["nested deeper than 64"]),
    ("deep_nesting_lines", '<shape type="sphere">\n' + '<bsdf type="twosided">\n' * 62 + '<bsdf type="twosided">'
     + MARK + '\n' + "</bsdf>\n" * 63 + "</shape>", ["nested deeper than 64"]),
    ("unknown_transform_op", '<shape type="cube"><transform name="to_world">\n<skew value="1"/>' + MARK
     + "\n</transform></shape>", ["unknown transform operation <skew>"]),
    ("transform_op_child", '<shape type="cube"><transform name="to_world">\n<scale value="2"><x/></scale>' + MARK
     + "\n</transform></shape>", ["takes no nested elements"]),
    ("area_top_level", '<emitter type="area"/>' + MARK, ["must be nested in a shape"]),
    ("film_top_level", '<film type="hdrfilm"/>' + MARK, ["must be nested in a sensor"]),
    ("point_in_shape", '<shape type="sphere">\n<emitter type="point"/>' + MARK + "\n</shape>",
     ["only an area emitter can be nested in a shape"]),
    ("perspective_in_shape", '<shape type="sphere">\n<sensor type="perspective"/>' + MARK + "\n</shape>",
     ["only an irradiancemeter"]),
    ("two_bsdfs", '<shape type="sphere"><bsdf type="diffuse"/>\n<bsdf type="diffuse"/>' + MARK + "\n</shape>",
     ["more than one nested bsdf"]),
    ("bsdf_in_bsdf", '<shape type="sphere"><bsdf type="diffuse">\n<bsdf type="diffuse"/>' + MARK
     + "\n</bsdf></shape>", ["unexpected nested bsdf"]),
    # -- bad values --------------------------------------------------------------
    ("float_word", '<shape type="sphere"><float name="radius" value="one"/></shape>' + MARK,
     ["cannot parse numbers from 'one'"]),
    ("float_underscore", '<shape type="sphere"><float name="radius" value="1_6"/></shape>' + MARK,
     ["cannot parse numbers from '1_6'"]),
    ("float_unicode_digits", '<shape type="sphere"><float name="radius" value="\u0661"/></shape>' + MARK,
     ["cannot parse numbers"]),
    ("float_hex", '<shape type="sphere"><float name="radius" value="0x10"/></shape>' + MARK, ["cannot parse"]),
    ("float_nan", '<shape type="sphere"><float name="radius" value="nan"/></shape>' + MARK, ["non-finite"]),
    ("float_inf", '<shape type="sphere"><float name="radius" value="-inf"/></shape>' + MARK, ["non-finite"]),
    ("float_overflow", '<shape type="sphere"><float name="radius" value="1e400"/></shape>' + MARK,
     ["non-finite"]),
    ("float_two_numbers", '<shape type="sphere"><float name="radius" value="1 2"/></shape>' + MARK,
     ["expected 1 numbers, got 2"]),
    ("float_empty", '<shape type="sphere"><float name="radius" value=""/></shape>' + MARK,
     ["expected 1 numbers, got 0"]),
    ("float_no_value", '<shape type="sphere"><float name="radius"/></shape>' + MARK, ["missing attribute 'value'"]),
    ("float_no_name", '<shape type="sphere"><float value="1"/></shape>' + MARK, ["missing attribute 'name'"]),
    ("int_fraction", _integrator("path", '<integer name="max_depth" value="3.5"/>'), ["cannot parse '3.5'"]),
    ("int_underscore", _integrator("path", '<integer name="max_depth" value="1_6"/>'), ["cannot parse '1_6'"]),
    ("int_hex", _integrator("path", '<integer name="max_depth" value="0x10"/>'), ["cannot parse '0x10'"]),
    ("int_5000_digits", _integrator("path", f'<integer name="max_depth" value="{"9" * 5000}"/>'),
     ["too many digits"]),
    ("int_as_float_param_huge", f'<shape type="sphere"><integer name="radius" value="{"9" * 400}"/></shape>'
     + MARK, ["parameter 'radius'", "too large"]),
    ("bool_number", '<shape type="sphere"><boolean name="flip_normals" value="1"/></shape>' + MARK,
     ["must be 'true' or 'false'"]),
    ("bool_yes", '<shape type="sphere"><boolean name="flip_normals" value="yes"/></shape>' + MARK,
     ["must be 'true' or 'false'"]),
    ("bool_for_float", '<shape type="sphere"><boolean name="radius" value="true"/></shape>' + MARK,
     ["parameter 'radius' must be a float, got a boolean"]),
    ("string_for_float", '<shape type="sphere"><string name="radius" value="1"/></shape>' + MARK,
     ["parameter 'radius' must be a float, got a string"]),
    ("float_for_bool", '<shape type="sphere"><float name="flip_normals" value="1"/></shape>' + MARK,
     ["parameter 'flip_normals' must be a boolean"]),
    ("rgb_two", '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.1 0.2"/></bsdf>'
                '</shape>' + MARK, ["expected 1 or 3 numbers, got 2"]),
    ("rgb_four", '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="1,2,3,4"/></bsdf>'
                 '</shape>' + MARK, ["expected 1 or 3 numbers, got 4"]),
    ("rgb_negative", '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.5 -0.1 0.5"/>'
                     '</bsdf></shape>' + MARK, ["parameter 'reflectance': negative value -0.1"]),
    ("rgb_nan", '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.5 nan 0.5"/>'
                '</bsdf></shape>' + MARK, ["non-finite"]),
    ("spectrum_pairs_unsorted", '<shape type="sphere"><bsdf type="diffuse"><spectrum name="reflectance" '
                                'value="700:0.1, 400:0.5"/></bsdf></shape>' + MARK,
     ["parameter 'reflectance'", "wavelengths must increase strictly"]),
    ("point_missing_z", '<shape type="sphere"><point name="center" x="1" y="2"/></shape>' + MARK,
     ["missing attribute 'z'"]),
    ("point_value_and_x", '<shape type="sphere"><point name="center" value="1 2 3" x="1"/></shape>' + MARK,
     ["give either value or x, y, z"]),
    ("point_two_numbers", '<shape type="sphere"><point name="center" value="1 2"/></shape>' + MARK,
     ["expected 3 numbers, got 2"]),
    ("point_for_float", '<shape type="sphere"><point name="radius" value="1 2 3"/></shape>' + MARK,
     ["parameter 'radius' must be a float, got a point"]),
    ("rotate_nonunit", '<shape type="cube"><transform name="to_world">\n<rotate x="1" y="1" angle="45"/>' + MARK
     + "\n</transform></shape>", ["<rotate>", "unit length"]),
    ("rotate_no_angle", '<shape type="cube"><transform name="to_world">\n<rotate x="1"/>' + MARK
     + "\n</transform></shape>", ["missing attribute 'angle'"]),
    ("matrix_12", '<shape type="cube"><transform name="to_world">\n<matrix value="1 0 0 0 0 1 0 0 0 0 1 0"/>'
     + MARK + "\n</transform></shape>", ["expected 9 or 16 numbers, got 12"]),
    ("matrix_singular", '<shape type="cube"><transform name="to_world">' + MARK + '\n<matrix value="1 0 0 0 '
                        '0 0 0 0 0 0 1 0 0 0 0 1"/>\n</transform></shape>', ["degenerate (singular) transform"]),
    ("matrix_projective", '<shape type="cube"><transform name="to_world">' + MARK + '\n<matrix value="1 0 0 0 '
                          '0 1 0 0 0 0 1 0 0 0 1 1"/>\n</transform></shape>', ["projective transforms"]),
    ("scale_zero", '<shape type="cube"><transform name="to_world">' + MARK + '\n<scale value="0"/>\n'
                   '</transform></shape>', ["degenerate"]),
    ("scale_word", '<shape type="cube"><transform name="to_world">\n<scale value="big"/>' + MARK
     + "\n</transform></shape>", ["cannot parse numbers from 'big'"]),
    ("translate_attr", '<shape type="cube"><transform name="to_world">\n<translate w="1"/>' + MARK
     + "\n</transform></shape>", ["unknown attribute 'w'"]),
    ("lookat_same", '<sensor type="perspective"><transform name="to_world">\n<lookat origin="1 1 1" '
                    'target="1 1 1"/>' + MARK + "\n</transform></sensor>", ["origin and target coincide"]),
    ("lookat_up_parallel", '<sensor type="perspective"><transform name="to_world">\n<lookat origin="0 0 0" '
                           'target="0 1 0" up="0 1 0"/>' + MARK + "\n</transform></sensor>",
     ["parallel to the viewing direction"]),
    ("radius_beyond_float32", '<shape type="sphere"><float name="radius" value="1e39"/></shape>' + MARK,
     ["parameter 'radius': 1e+39 is beyond the float32 range"]),
    ("vertices_beyond_float32", '<shape type="rectangle"><transform name="to_world"><scale value="1e39"/>'
                                '</transform></shape>' + MARK, ["vertices beyond the float32 range"]),
    ("sphere_beyond_float32", '<shape type="sphere"><float name="radius" value="1e20"/><transform name="to_world">'
                              '<scale value="1e20"/></transform></shape>' + MARK,
     ["place the sphere beyond the float32 range"]),
    ("lookat_far_apart", '<sensor type="perspective"><transform name="to_world">\n<lookat origin="1e308 0 0" '
                         'target="-1e308 0 0"/>' + MARK + "\n</transform></sensor>", ["too far apart"]),
    ("transform_overflow", '<shape type="cube"><transform name="to_world">' + MARK + '\n<scale value="1e200"/>'
                           '<scale value="1e200"/>\n</transform></shape>', ["non-finite matrix entries"]),
    ("transform_for_float", '<shape type="sphere"><transform name="radius"><scale value="2"/></transform>'
                            '</shape>' + MARK, ["parameter 'radius' must be a float, got a transform"]),
    ("unknown_param", '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectanse" value="0.5"/></bsdf>'
                      '</shape>' + MARK, ["bsdf 'diffuse': unknown parameter 'reflectanse'"]),
    ("radius_zero", '<shape type="sphere"><float name="radius" value="0"/></shape>' + MARK, ["must be > 0"]),
    ("radius_negative", '<shape type="sphere"><float name="radius" value="-1"/></shape>' + MARK, ["must be > 0"]),
    ("sphere_shear", '<shape type="sphere"><transform name="to_world"><scale x="1" y="2" z="1"/></transform>'
                     '</shape>' + MARK, ["non-uniformly"]),
    ("ior_name", '<shape type="sphere"><bsdf type="dielectric"><string name="int_ior" value="unobtainium"/>'
                 '</bsdf></shape>' + MARK, ["unknown IOR name 'unobtainium'"]),
    ("ior_negative", '<shape type="sphere"><bsdf type="dielectric"><float name="int_ior" value="-1.5"/></bsdf>'
                     '</shape>' + MARK, ["parameter 'int_ior' must be > 0"]),
    ("alpha_zero", '<shape type="sphere"><bsdf type="roughconductor"><float name="alpha" value="0"/></bsdf>'
                   '</shape>' + MARK, ["parameter 'alpha' must be > 0"]),
    ("distribution", '<shape type="sphere"><bsdf type="roughconductor"><string name="distribution" '
                     'value="phong"/></bsdf></shape>' + MARK, ["'phong' is not one of"]),
    ("alpha_and_alpha_u", '<shape type="sphere"><bsdf type="roughconductor">' + MARK
     + '\n<float name="alpha" value="0.1"/><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.1"/>'
       "\n</bsdf></shape>", ["either alpha or alpha_u/alpha_v"]),
    ("alpha_u_only", '<shape type="sphere"><bsdf type="roughconductor">' + MARK
     + '\n<float name="alpha_u" value="0.1"/>\n</bsdf></shape>', ["give both alpha_u and alpha_v"]),
    ("conductor_material", '<shape type="sphere"><bsdf type="conductor">\n<string name="material" value="au"/>'
     + MARK + '\n</bsdf></shape>', ["parameter 'material'", "unknown conductor material 'au'", "Au, Be"]),
    ("twosided_three", '<shape type="sphere"><bsdf type="twosided">' + MARK
     + '\n<bsdf type="diffuse"/><bsdf type="diffuse"/><bsdf type="diffuse"/>\n</bsdf></shape>',
     ["one or two nested bsdfs, got 3"]),
    ("twosided_twosided", '<shape type="sphere"><bsdf type="twosided">\n<bsdf type="twosided"><bsdf '
                          'type="diffuse"/></bsdf>' + MARK + "\n</bsdf></shape>",
     ["cannot nest another twosided"]),
    ("twosided_dielectric", '<shape type="sphere"><bsdf type="twosided">\n<bsdf type="dielectric"/>' + MARK
     + "\n</bsdf></shape>", ["nests only reflective bsdfs, got 'dielectric'"]),
    ("twosided_null", '<shape type="sphere"><bsdf type="twosided">\n<bsdf type="diffuse"/>\n<bsdf type="null"/>'
     + MARK + "\n</bsdf></shape>", ["nests only reflective bsdfs, got 'null'"]),
    ("spot_cutoff", '<emitter type="spot"><float name="cutoff_angle" value="200"/></emitter>' + MARK,
     ["exceeds 180 degrees"]),
    ("directional_zero", '<emitter type="directional"><vector name="direction" value="0 0 0"/></emitter>'
     + MARK, ["zero length"]),
    ("emitter_scale", '<emitter type="point"><float name="scale" value="2"/></emitter>' + MARK,
     ["take no 'scale' parameter"]),
    ("point_both", '<emitter type="point">' + MARK + '\n<point name="position" value="0 0 0"/>'
     '<transform name="to_world"><translate x="1"/></transform>\n</emitter>', ["either position or to_world"]),
    ("radiance_negative", '<shape type="sphere"><emitter type="area"><rgb name="radiance" value="-1"/>'
                          '</emitter></shape>' + MARK, ["negative value -1"]),
    # -- meshes ------------------------------------------------------------------
    ("obj_missing", _mesh("obj", "absent.obj"), ["mesh file not found: 'absent.obj'"]),
    ("ply_missing", _mesh("ply", "absent.ply"), ["mesh file not found: 'absent.ply'"]),
    ("obj_directory", _mesh("obj", "."), ["mesh file not found"]),
    ("obj_no_filename", '<shape type="obj"/>' + MARK, ["missing parameter 'filename'"]),
    ("obj_no_faces", _mesh("obj", "nofaces.obj"), ["nofaces.obj", "no faces"]),
    ("obj_short_v", _mesh("obj", "short_v.obj"), ["short_v.obj:2", "cannot parse OBJ line"]),
    ("obj_word_v", _mesh("obj", "word_v.obj"), ["word_v.obj:2", "cannot parse OBJ line"]),
    ("obj_nan_v", _mesh("obj", "nan_v.obj"), ["nan_v.obj:2", "non-finite value in a 'v' statement"]),
    ("obj_inf_v", _mesh("obj", "inf_v.obj"), ["inf_v.obj:2", "non-finite"]),
    ("obj_nan_vn", _mesh("obj", "nan_vn.obj"), ["nan_vn.obj:4", "non-finite value in a 'vn' statement"]),
    ("obj_inf_vt", _mesh("obj", "inf_vt.obj"), ["inf_vt.obj:4", "non-finite value in a 'vt' statement"]),
    ("obj_underscore", _mesh("obj", "underscore_v.obj"), ["underscore_v.obj:2", "cannot parse"]),
    ("obj_truncated", _mesh("obj", "truncated.obj"), ["truncated.obj:3", "face index '3' is out of range"]),
    ("obj_negative_index", _mesh("obj", "neg_index.obj"), ["neg_index.obj:4", "out of range"]),
    ("obj_zero_index", _mesh("obj", "zero_index.obj"), ["zero_index.obj:4", "out of range"]),
    ("obj_huge_index", _mesh("obj", "big_index.obj"), ["big_index.obj:4", "out of range"]),
    ("obj_bad_vt", _mesh("obj", "bad_vt.obj"), ["bad_vt.obj", "invalid texture coordinate"]),
    ("obj_no_vt", _mesh("obj", "no_vt.obj"), ["no_vt.obj", "invalid texture coordinate"]),
    ("obj_bad_vn", _mesh("obj", "bad_vn.obj"), ["bad_vn.obj", "invalid vertex normal"]),
    ("obj_no_vn", _mesh("obj", "no_vn.obj"), ["no_vn.obj", "invalid vertex normal"]),
    ("obj_mixed_vn", _mesh("obj", "mixed_vn.obj"), ["mixed_vn.obj", "some face vertices have normals"]),
    ("obj_two_vertices", _mesh("obj", "two_verts.obj"), ["two_verts.obj:3", "fewer than 3 vertices"]),
    ("obj_four_slashes", _mesh("obj", "four_slash.obj"), ["four_slash.obj:4", "cannot parse OBJ line"]),
    ("obj_word_f", _mesh("obj", "word_f.obj"), ["word_f.obj:4", "cannot parse OBJ line"]),
    ("obj_unknown_param", '<shape type="obj"><string name="filename" value="tri.obj"/>\n'
                          '<boolean name="smooth" value="true"/>' + MARK + "\n</shape>",
     ["unknown parameter 'smooth'"]),
    ("ply_quads", _mesh("ply", "quad.ply"), ["quad.ply", "must be triangles"]),
    ("ply_out_of_range", _mesh("ply", "oob.ply"), ["oob.ply", "face index out of range"]),
    ("ply_negative", _mesh("ply", "neg.ply"), ["neg.ply", "face index out of range"]),
    ("ply_nan", _mesh("ply", "nan.ply"), ["nan.ply", "non-finite vertex data"]),
    ("ply_nan_normal", _mesh("ply", "nan_n.ply"), ["nan_n.ply", "non-finite vertex data"]),
    ("ply_inf_uv", _mesh("ply", "nan_uv.ply"), ["nan_uv.ply", "non-finite vertex data"]),
    ("ply_no_faces", _mesh("ply", "nofaces.ply"), ["nofaces.ply", "no faces"]),
    ("ply_truncated", _mesh("ply", "truncated.ply"), ["truncated.ply", "cannot read PLY file"]),
    ("ply_garbage_header", _mesh("ply", "garbage.ply"), ["garbage.ply", "cannot read PLY file"]),
    ("ply_not_ply", _mesh("ply", "notply.ply"), ["notply.ply", "cannot read PLY file"]),
    ("ply_empty", _mesh("ply", "empty.ply"), ["empty.ply", "cannot read PLY file"]),
    ("ply_no_xyz", _mesh("ply", "noxyz.ply"), ["noxyz.ply", "need x, y, z"]),
    ("ply_no_face_element", _mesh("ply", "noface_elem.ply"), ["noface_elem.ply", "'vertex' and 'face'"]),
    ("ply_flip_tex", '<shape type="ply"><string name="filename" value="tri.ply"/>\n'
                     '<boolean name="flip_tex_coords" value="true"/>' + MARK + "\n</shape>",
     ["unknown parameter 'flip_tex_coords'"]),
    # -- media -----------------------------------------------------------------
    ("albedo_negative", _medium('<rgb name="albedo" value="-0.5"/>'), ["parameter 'albedo': negative value"]),
    ("albedo_above_one", _medium('<rgb name="albedo" value="0.5 1.5 0.5"/>'), ["albedo must lie in [0, 1]"]),
    ("sigma_t_negative", _medium('<rgb name="sigma_t" value="-1"/>'), ["parameter 'sigma_t': negative value"]),
    ("sigma_t_nan", _medium('<rgb name="sigma_t" value="nan"/>'), ["non-finite"]),
    ("sigma_s_negative", _medium('<rgb name="sigma_a" value="1"/><rgb name="sigma_s" value="-1"/>'),
     ["parameter 'sigma_s': negative value"]),
    ("both_forms", '<shape type="cube"><bsdf type="null"/>\n<medium type="homogeneous" name="interior">'
                   + MARK + '\n<rgb name="sigma_t" value="1"/><rgb name="sigma_a" value="1"/>\n</medium></shape>',
     ["either sigma_t + albedo or sigma_a + sigma_s"]),
    ("scale_negative", _medium('<float name="scale" value="-2"/>'), ["parameter 'scale': negative value"]),
    ("sigma_overflow", '<shape type="cube"><bsdf type="null"/>\n<medium type="homogeneous" name="interior">'
                       + MARK + '\n<rgb name="sigma_t" value="1e30"/><float name="scale" value="1e30"/>\n'
                                '</medium></shape>', ["sigma_t * scale", "beyond the float32 range"]),
    ("sigma_beyond_float32", _medium('<rgb name="sigma_t" value="1e39"/>'), ["parameter 'sigma_t': 1e+39 is beyond "
                                                                             "the float32 range"]),
    ("sample_emitters_false", _medium('<boolean name="sample_emitters" value="false"/>'),
     ["sample_emitters = false is not supported"]),
    ("hg_g_one", '<shape type="cube"><bsdf type="null"/>\n<medium type="homogeneous" name="interior">\n'
                 '<phase type="hg"><float name="g" value="1"/></phase>' + MARK + "\n</medium></shape>",
     ["parameter 'g' must lie in (-1, 1)"]),
    ("hg_g_nan", '<shape type="cube"><bsdf type="null"/>\n<medium type="homogeneous" name="interior">\n'
                 '<phase type="hg"><float name="g" value="nan"/></phase>' + MARK + "\n</medium></shape>",
     ["non-finite"]),
    ("unknown_phase", '<shape type="cube"><bsdf type="null"/>\n<medium type="homogeneous" name="interior">\n'
                      '<phase type="rayleigh"/>' + MARK + "\n</medium></shape>", ["phase type 'rayleigh'"]),
    ("two_phases", '<shape type="cube"><bsdf type="null"/>\n<medium type="homogeneous" name="interior">\n'
                   '<phase type="isotropic"/>\n<phase type="isotropic"/>' + MARK + "\n</medium></shape>",
     ["more than one nested phase"]),
    ("unknown_medium", '<medium type="spectral"/>' + MARK, ["medium type 'spectral'"]),
    ("medium_unknown_param", _medium('<float name="density" value="1"/>'), ["unknown parameter 'density'"]),
    ("medium_wrong_name", '<shape type="cube"><bsdf type="null"/>\n<medium type="homogeneous" name="inside"/>'
     + MARK + "\n</shape>", ["unexpected nested medium"]),
    ("grid_missing", _grid("absent.vol"), ["volume file not found: 'absent.vol'"]),
    ("grid_version", _grid("v2.vol"), ["v2.vol", "only version 3 float32"]),
    ("grid_encoding", _grid("f16.vol"), ["f16.vol", "only version 3 float32"]),
    ("grid_truncated", _grid("truncated.vol"), ["truncated.vol", "file size does not match"]),
    ("grid_nan", _grid("nan.vol"), ["nan.vol", "non-finite values"]),
    ("grid_zero_res", _grid("zero_res.vol"), ["zero_res.vol", "bad resolution"]),
    ("grid_two_channels", _grid("two_ch.vol"), ["two_ch.vol", "channel count"]),
    ("grid_not_vol", _grid("notvol.vol"), ["notvol.vol", "no 'VOL' header"]),
    ("grid_tiny", _grid("tiny.vol"), ["tiny.vol", "no 'VOL' header"]),
    ("grid_filter", _grid("ok.vol", '<string name="filter_type" value="nearest"/>'), ["'nearest' is not one of"]),
    ("grid_wrap", _grid("ok.vol", '<string name="wrap_mode" value="repeat"/>'), ["'repeat' is not one of"]),
    ("grid_empty_bbox", _grid("empty_bbox.vol", '<boolean name="use_grid_bbox" value="true"/>'),
     ["bounding box", "is empty"]),
    ("grid_and_value", '<shape type="cube"><bsdf type="null"/>\n<medium type="heterogeneous" name="interior">\n'
                       '<rgb name="sigma_t" value="1"/>\n<volume type="constvolume" name="sigma_t"/>' + MARK
     + "\n</medium></shape>", ["given both as a value and as a nested volume"]),
    ("constvolume_negative", '<shape type="cube"><bsdf type="null"/>\n<medium type="heterogeneous" '
                             'name="interior">\n<volume type="constvolume" name="albedo"><rgb name="value" '
                             'value="-1"/></volume>' + MARK + "\n</medium></shape>", ["negative value"]),
    ("dipole_zero", '<shape type="sphere"><subsurface type="dipole">' + MARK + '\n<rgb name="sigma_a" value="0"/>'
                    '<rgb name="sigma_s" value="0"/>\n</subsurface></shape>', ["nothing to scatter"]),
    ("dipole_g", '<shape type="sphere"><subsurface type="dipole"><rgb name="sigma_a" value="1"/>'
                 '<rgb name="sigma_s" value="1"/>\n<float name="g" value="1"/>' + MARK
     + "\n</subsurface></shape>", ["parameter 'g' must lie in (-1, 1)"]),
    ("dipole_irrsamples", '<shape type="sphere"><subsurface type="dipole"><rgb name="sigma_a" value="1"/>'
                          '<rgb name="sigma_s" value="1"/>\n<integer name="irrSamples" value="64"/>' + MARK
     + "\n</subsurface></shape>", ["irrSamples"]),
    ("dipole_no_coefficients", '<shape type="sphere"><subsurface type="dipole"/>' + MARK + "\n</shape>",
     ["needs sigma_a + sigma_s"]),
    ("dipole_top_level", '<subsurface type="dipole"/>' + MARK, ["must be nested in a shape"]),
    # -- sensors and films ------------------------------------------------------
    ("width_zero", _film('<integer name="width" value="0"/>'), ["parameter 'width' = 0 is outside [1, 16384]"]),
    ("width_negative", _film('<integer name="width" value="-64"/>'), ["outside [1, 16384]"]),
    ("width_absurd", _film('<integer name="width" value="1000000"/>'), ["outside [1, 16384]"]),
    ("height_2_31", _film('<integer name="height" value="2147483648"/>'), ["outside [1, 16384]"]),
    ("width_float", _film('<float name="width" value="64"/>'), ["parameter 'width' must be an integer"]),
    ("pixel_format", _film('<string name="pixel_format" value="xyz"/>'), ["'xyz' is not one of"]),
    ("component_format", _film('<string name="component_format" value="uint8"/>'), ["'uint8' is not one of"]),
    ("crop_width", _film('<integer name="crop_width" value="8"/><integer name="crop_offset_x" value="764"/>'),
     ["crop_offset_x + crop_width = 764 + 8 exceeds the film's width 768"]),
    ("sample_border_tent", _film('<boolean name="sample_border" value="true"/><rfilter type="tent"/>'),
     ["hdrfilm", "sample_border = true with the 'tent' filter is not supported"]),
    ("tent_radius_zero", _film('<rfilter type="tent"><float name="radius" value="0"/></rfilter>'),
     ["parameter 'radius' must be > 0"]),
    ("gaussian_negative", _film('<rfilter type="gaussian"><float name="stddev" value="-1"/></rfilter>'),
     ["parameter 'stddev' must be > 0"]),
    ("box_radius", _film('<rfilter type="box"><float name="radius" value="2"/></rfilter>'),
     ["unknown parameter 'radius'"]),
    ("two_films", '<sensor type="perspective"><film type="hdrfilm"/>\n<film type="hdrfilm"/>' + MARK
     + "\n</sensor>", ["more than one nested film"]),
    ("fov_zero", _sensor('<float name="fov" value="0"/>'), ["fov 0.0 must lie in (0, 180)"]),
    ("fov_180", _sensor('<float name="fov" value="180"/>'), ["must lie in (0, 180)"]),
    ("fov_negative", _sensor('<float name="fov" value="-30"/>'), ["must lie in (0, 180)"]),
    ("fov_string", _sensor('<string name="fov" value="wide"/>'), ["parameter 'fov' must be a float"]),
    ("fov_axis", '<sensor type="perspective"><float name="fov" value="40"/>\n<string name="fov_axis" value="z"/>'
     + MARK + "\n</sensor>", ["fov_axis 'z'"]),
    ("fov_and_focal", '<sensor type="perspective">' + MARK + '\n<float name="fov" value="40"/>'
     '<string name="focal_length" value="50mm"/>\n</sensor>', ["either fov or focal_length"]),
    ("focal_word", _sensor('<string name="focal_length" value="longmm"/>'),
     ["cannot parse focal_length 'longmm'"]),
    ("focal_zero", _sensor('<string name="focal_length" value="0mm"/>'), ["focal_length must be > 0"]),
    ("focal_underscore", _sensor('<string name="focal_length" value="5_0mm"/>'), ["cannot parse focal_length"]),
    ("near_clip_zero", _sensor('<float name="near_clip" value="0"/>'), ["parameter 'near_clip' must be > 0"]),
    ("far_below_near", '<sensor type="perspective">' + MARK + '\n<float name="near_clip" value="10"/>'
     '<float name="far_clip" value="1"/>\n</sensor>', ["far_clip 1.0 must exceed near_clip 10.0"]),
    ("camera_scale", _sensor('<transform name="to_world"><scale value="2"/></transform>'), ["scale factors"]),
    ("principal_point", _sensor('<float name="principal_point_offset_x" value="0.1"/>'),
     ["principal_point_offset_x"]),
    ("radiancemeter_film", '<sensor type="radiancemeter">' + MARK + '\n<film type="hdrfilm">'
     '<integer name="width" value="2"/></film></sensor>', ["1x1 film, got 2x576"]),
    ("radiancemeter_origin_only", '<sensor type="radiancemeter">' + MARK + '\n<point name="origin" value="0 0 0"/>'
     '<film type="hdrfilm"><integer name="width" value="1"/><integer name="height" value="1"/></film></sensor>',
     ["give both origin and direction"]),
    ("radiancemeter_zero_dir", '<sensor type="radiancemeter">' + MARK + '\n<point name="origin" value="0 0 0"/>'
     '<vector name="direction" value="0 0 0"/><film type="hdrfilm"><integer name="width" value="1"/>'
     '<integer name="height" value="1"/></film></sensor>', ["zero length"]),
    ("two_sensors", '<sensor type="perspective"/>\n<sensor type="orthographic"/>' + MARK, ["more than one sensor"]),
    ("irradiancemeter_top", '<sensor type="irradiancemeter"/>' + MARK, ["must be nested in a shape"]),
    ("sample_count_zero", '<sensor type="perspective"><sampler type="independent">'
     '<integer name="sample_count" value="0"/></sampler>' + MARK + "\n</sensor>", ["outside [1, 16777216]"]),
    ("sample_count_2_31", '<sensor type="perspective"><sampler type="independent">'
     '<integer name="sample_count" value="2147483648"/></sampler>' + MARK + "\n</sensor>",
     ["parameter 'sample_count'", "outside [1, 16777216]"]),
    ("sample_count_float", '<sensor type="perspective"><sampler type="independent">'
     '<float name="sample_count" value="4"/></sampler>' + MARK + "\n</sensor>", ["must be an integer"]),
    ("sensor_unknown_param", _sensor('<float name="aperture_radius" value="0.1"/>'),
     ["unknown parameter 'aperture_radius'"]),
    ("ortho_fov", _sensor('<float name="fov" value="40"/>', kind="orthographic"), ["unknown parameter 'fov'"]),
    # -- integrators -----------------------------------------------------------
    ("integrator_unknown", _integrator("aov"), ["integrator type 'aov' is not supported"]),
    ("integrator_mitsuba_unsupported", _integrator("prbvolpath"), ["integrator type 'prbvolpath' is not supported"]),
    ("max_depth_zero", _integrator("path", '<integer name="max_depth" value="0"/>'),
     ["parameter 'max_depth'", "must be -1 (unbounded) or >= 1"]),
    ("max_depth_minus_two", _integrator("bdpt", '<integer name="max_depth" value="-2"/>'), ["parameter 'max_depth'"]),
    ("max_depth_2_31", _integrator("path", '<integer name="max_depth" value="2147483648"/>'),
     ["parameter 'max_depth' = 2147483648", "32-bit integer [-2147483648, 2147483647]"]),
    ("max_depth_minus_2_31", _integrator("path", '<integer name="max_depth" value="-2147483649"/>'),
     ["32-bit integer"]),
    ("max_depth_float", _integrator("path", '<float name="max_depth" value="3"/>'),
     ["parameter 'max_depth'", "expects an integer"]),
    ("max_depth_at_its_line", '<integrator type="path">\n<integer name="rr_depth" value="2"/>\n'
                              '<integer name="max_depth" value="0"/>' + MARK + "\n</integrator>",
     ["parameter 'max_depth' must be -1 (unbounded) or >= 1"]),
    ("rr_depth_zero", _integrator("path", '<integer name="rr_depth" value="0"/>'), ["parameter 'rr_depth'", ">= 1"]),
    ("integrator_unknown_param", _integrator("path", '<integer name="maxdepth" value="3"/>'),
     ["unknown parameter 'maxdepth' for 'path'"]),
    ("hide_emitters_string", _integrator("path", '<string name="hide_emitters" value="true"/>'),
     ["parameter 'hide_emitters'", "expects a boolean"]),
    ("mis_unknown", _integrator("bdpt", '<string name="mis" value="maximum"/>'), ["parameter 'mis'"]),
    ("beta_zero", _integrator("bdpt", '<float name="beta" value="0"/>'), ["parameter 'beta'", "must be > 0"]),
    ("beta_nan", _integrator("bdpt", '<float name="beta" value="nan"/>'), ["non-finite"]),
    ("strategy_images", _integrator("bdpt", '<integer name="strategy_images" value="17"/>'),
     ["parameter 'strategy_images'", "0..16"]),
    ("lookup_size_zero", _integrator("photonmapper", '<integer name="lookup_size" value="0"/>'),
     ["parameter 'lookup_size'", ">= 1"]),
    ("photons_negative", _integrator("photonmapper", '<integer name="global_photons" value="-1"/>'),
     ["parameter 'global_photons'", ">= 0"]),
    ("radius_zero_pm", _integrator("photonmapper", '<float name="global_lookup_radius" value="0"/>'),
     ["parameter 'global_lookup_radius'", "must be > 0"]),
    ("alias_twice", _integrator("sppm", '<integer name="photonCount" value="10"/><integer name="photon_count" '
                                        'value="10"/>'), ["parameter 'photonCount'", "alias"]),
    ("sppm_alpha", _integrator("sppm", '<float name="alpha" value="1.5"/>'), ["parameter 'alpha'", "(0, 1)"]),
    ("sppm_photons_zero", _integrator("sppm", '<integer name="photon_count" value="0"/>'),
     ["parameter 'photon_count'", ">= 1"]),
    ("direct_no_samples", _integrator("direct", '<integer name="emitter_samples" value="0"/>'
                                                '<integer name="bsdf_samples" value="0"/>'), ["not both 0"]),
    ("integrator_rgb", _integrator("path", '<rgb name="max_depth" value="1"/>'),
     ["parameter 'max_depth' must be an integer, float, boolean or string"]),
    ("integrator_nested", '<integrator type="path">\n<sampler type="independent"/>' + MARK + "\n</integrator>",
     ["unexpected nested sampler"]),
    ("two_integrators", '<integrator type="path"/>\n<integrator type="bdpt"/>' + MARK,
     ["more than one integrator"]),
]

_IDS = [c[0] for c in XML]
assert len(set(_IDS)) == len(_IDS), "duplicate case ids"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("bad_inputs")
    for name, data in FILES.items():
        (root / name).write_bytes(data)
    return root


@pytest.mark.parametrize("case", XML, ids=_IDS)
def test_bad_xml(files, case):
    name, body, words = case
    text, line = _lines(body)
    path = files / f"{name}.xml"
    path.write_bytes(text.encode("utf-8"))
    with pytest.raises(SceneError) as info:
        load_file(path)
    message = str(info.value)
    assert f"{path}:{line}:" in message, message
    for w in words:
        assert w in message, message


# -- dicts -----------------------------------------------------------------------


def _s(**entries):
    return {"type": "scene", **entries}


def _deep(levels):
    d = {"type": "diffuse"}
    for _ in range(levels):
        d = {"type": "twosided", "b": d}
    return _s(ball={"type": "sphere", "bsdf": d})


def _cyclic():
    d = {"type": "twosided"}
    d["b"] = d
    return _s(ball={"type": "sphere", "bsdf": d})


def _self_list():
    v = [1.0, 2.0]
    v.append(v)
    return _s(ball={"type": "sphere", "center": v})


class _Opaque:
    pass


BALL, REFL = "scene['ball']", "scene['ball']['bsdf']['reflectance']"
FILM = "scene['cam']['film']"


def _cam_film(**film):
    return _s(cam={"type": "perspective", "film": {"type": "hdrfilm", **film}})


def _ball_bsdf(**bsdf):
    return _s(ball={"type": "sphere", "bsdf": bsdf})


def _fog(**medium):
    return _s(box={"type": "cube", "bsdf": {"type": "null"}, "interior": {"type": "homogeneous", **medium}})


# (id, scene (or a function making it), key path the message starts with, words)
DICTS = [
    ("not_a_dict", [1, 2], "scene", ["expected a dict, got list"]),
    ("no_scene_type", {"ball": {"type": "sphere"}}, "scene", ["'type': 'scene'"]),
    ("key_not_string", {"type": "scene", 3: {"type": "sphere"}}, "scene", ["keys must be strings"]),
    ("nested_key_not_string", _s(ball={"type": "sphere", 3: 1.0}), BALL, ["keys must be strings"]),
    ("top_level_value", _s(radius=1.0), "scene['radius']", ["top-level entries must be plugin dicts"]),
    ("top_level_ref", _s(r={"type": "ref", "id": "x"}), "scene['r']", ["cannot stand at the top level"]),
    ("no_type", _s(ball={"radius": 1.0}), BALL, ["needs a string 'type'"]),
    ("type_not_string", _s(ball={"type": 3}), BALL, ["needs a string 'type'"]),
    ("unknown_type", _s(ball={"type": "teapot"}), BALL, ["'teapot' is not supported"]),
    ("id_not_string", _s(ball={"type": "sphere", "id": 3}), "scene['ball']['id']", ["'id' must be a string"]),
    ("duplicate_id", _s(a={"type": "diffuse", "id": "x"}, b={"type": "diffuse", "id": "x"}), "scene['b']",
     ["duplicate id 'x'"]),
    ("ref_extra_key", _s(b={"type": "diffuse"}, ball={"type": "sphere", "bsdf": {"type": "ref", "id": "b", "x": 1}}),
     "scene['ball']['bsdf']", ["a ref is"]),
    ("ref_unknown", _s(ball={"type": "sphere", "bsdf": {"type": "ref", "id": "nope"}}), "scene['ball']['bsdf']",
     ["unknown id 'nope'"]),
    ("ref_wrong_category", _s(fog={"type": "homogeneous"}, ball={"type": "sphere", "bsdf": {"type": "ref",
                                                                                          "id": "fog"}}),
     "scene['ball']['bsdf']", ["unexpected nested medium 'homogeneous' (the reference to scene['fog'])"]),
    ("rgb_unknown_key", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": 0.5, "gamma": 2}), REFL,
     ["unknown key 'gamma'"]),
    ("rgb_no_value", _ball_bsdf(type="diffuse", reflectance={"type": "rgb"}), REFL, ["missing 'value'"]),
    ("rgb_string", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": "0.5"}), REFL,
     ["must be a real number"]),
    ("rgb_bool", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": True}), REFL,
     ["must be a real number"]),
    ("rgb_complex", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": 0.5j}), REFL,
     ["must be a real number"]),
    ("rgb_two_values", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": [0.1, 0.2]}), REFL,
     ["must be 3 numbers"]),
    ("rgb_string_list", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": ["0.1", "0.2", "0.3"]}),
     REFL, ["expected real numbers, got str"]),
    ("rgb_bool_list", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": [True, False, True]}), REFL,
     ["expected real numbers, got bool"]),
    ("rgb_complex_array", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": np.array([1j, 0, 0])}),
     REFL, ["expected real numbers"]),
    ("rgb_huge_int", _ball_bsdf(type="diffuse", reflectance={"type": "rgb", "value": 10**400}), REFL,
     ["too large"]),
    ("spectrum_list", _ball_bsdf(type="diffuse", reflectance={"type": "spectrum", "value": [(400, 0.1)]}), REFL,
     ["at least two wavelength:value pairs"]),
    ("colour_bool_list", _ball_bsdf(type="diffuse", reflectance=[True, False, True]), REFL,
     ["expected real numbers, got bool"]),
    ("colour_string_array", _ball_bsdf(type="diffuse", reflectance=np.array(["1", "2", "3"])), REFL,
     ["expected real numbers"]),
    ("colour_bool_array", _ball_bsdf(type="diffuse", reflectance=np.array([True, False, True])), REFL,
     ["expected real numbers"]),
    ("colour_nan", _ball_bsdf(type="diffuse", reflectance=[0.5, np.nan, 0.5]), REFL, ["non-finite"]),
    ("center_complex_list", _s(ball={"type": "sphere", "center": [1j, 0, 0]}), "scene['ball']['center']",
     ["expected real numbers, got complex"]),
    ("center_strings", _s(ball={"type": "sphere", "center": ["1", "2", "3"]}), "scene['ball']['center']",
     ["expected real numbers, got str"]),
    ("center_none", _s(ball={"type": "sphere", "center": [None, 0, 0]}), "scene['ball']['center']",
     ["expected real numbers, got NoneType"]),
    ("center_huge", _s(ball={"type": "sphere", "center": [10**400, 0, 0]}), "scene['ball']['center']",
     ["out of range"]),
    ("center_self_list", _self_list(), "scene['ball']['center']", ["expected real numbers"]),
    ("center_two", _s(ball={"type": "sphere", "center": [1.0, 2.0]}), "scene['ball']['center']",
     ["unsupported value"]),
    ("radius_huge_int", _s(ball={"type": "sphere", "radius": 10**400}), "scene['ball']['radius']",
     ["parameter 'radius'", "too large"]),
    ("radius_complex", _s(ball={"type": "sphere", "radius": 1j}), "scene['ball']['radius']",
     ["unsupported value of type complex"]),
    ("radius_none", _s(ball={"type": "sphere", "radius": None}), "scene['ball']['radius']",
     ["unsupported value of type NoneType"]),
    ("radius_object", _s(ball={"type": "sphere", "radius": _Opaque()}), "scene['ball']['radius']",
     ["unsupported value of type _Opaque"]),
    ("radius_set", _s(ball={"type": "sphere", "radius": {1.0}}), "scene['ball']['radius']",
     ["unsupported value"]),
    ("radius_string", _s(ball={"type": "sphere", "radius": "1"}), "scene['ball']['radius']",
     ["must be a float, got a string"]),
    ("radius_bool", _s(ball={"type": "sphere", "radius": True}), "scene['ball']['radius']",
     ["must be a float, got a boolean"]),
    ("radius_inf", _s(ball={"type": "sphere", "radius": float("inf")}), "scene['ball']['radius']",
     ["non-finite"]),
    ("matrix_3x3", _s(box={"type": "cube", "to_world": np.eye(3)}), "scene['box']['to_world']",
     ["unsupported value"]),
    ("matrix_bool", _s(box={"type": "cube", "to_world": np.eye(4, dtype=bool)}), "scene['box']['to_world']",
     ["expected real numbers"]),
    ("matrix_nested_too_deep", _s(box={"type": "cube", "to_world": [[[1.0]]]}), "scene['box']['to_world']",
     ["expected real numbers"]),
    ("matrix_nan", _s(box={"type": "cube", "to_world": np.diag([1.0, np.nan, 1.0, 1.0])}),
     "scene['box']['to_world']", ["non-finite"]),
    ("deep_nesting", _deep(50000), "scene['ball']['bsdf']", ["nested deeper than 64"]),
    ("cyclic_dict", _cyclic(), "scene['ball']['bsdf']", ["nested deeper than 64"]),
    ("width_2_63", _cam_film(width=2**63), f"{FILM}['width']", ["outside [1, 16384]"]),
    ("width_float", _cam_film(width=256.0), f"{FILM}['width']", ["must be an integer"]),
    ("width_numpy_bool", _cam_film(width=np.bool_(True)), f"{FILM}['width']", ["must be an integer, got a boolean"]),
    ("height_zero", _cam_film(height=0), f"{FILM}['height']", ["outside [1, 16384]"]),
    ("max_depth_2_31", _s(integrator={"type": "path", "max_depth": 2**31}), "scene['integrator']['max_depth']",
     ["32-bit integer [-2147483648, 2147483647]"]),
    ("max_depth_2_64", _s(integrator={"type": "bdpt", "max_depth": 2**64}), "scene['integrator']['max_depth']",
     ["32-bit integer"]),
    ("photons_2_31", _s(integrator={"type": "sppm", "photon_count": 2**31}),
     "scene['integrator']['photon_count']", ["32-bit integer"]),
    ("max_depth_zero", _s(integrator={"type": "path", "max_depth": 0}), "scene['integrator']",
     ["parameter 'max_depth'", "must be -1"]),
    ("integrator_bad_param", _s(integrator={"type": "bdpt", "weights": "power"}), "scene['integrator']",
     ["unknown parameter 'weights' for 'bdpt'"]),
    ("integrator_list_param", _s(integrator={"type": "path", "max_depth": [1, 2, 3]}),
     "scene['integrator']['max_depth']", ["must be an integer, float, boolean or string"]),
    ("two_integrators", _s(a={"type": "path"}, b={"type": "bdpt"}), "scene['b']", ["more than one integrator"]),
    ("sample_count_2_31", _s(cam={"type": "perspective", "sampler": {"type": "independent",
                                                                     "sample_count": 2**31}}),
     "scene['cam']['sampler']['sample_count']", ["outside [1, 16777216]"]),
    ("fov_zero", _s(cam={"type": "perspective", "fov": 0.0}), "scene['cam']['fov']", ["must lie in (0, 180)"]),
    ("fov_huge_int", _s(cam={"type": "perspective", "fov": 10**400}), "scene['cam']['fov']", ["too large"]),
    ("focal_underscore", _s(cam={"type": "perspective", "focal_length": "3_5mm"}), "scene['cam']['focal_length']",
     ["cannot parse focal_length"]),
    ("albedo_negative", _fog(albedo=-0.1), "scene['box']['interior']['albedo']", ["negative value"]),
    ("albedo_bool_list", _fog(albedo=[True, True, True]), "scene['box']['interior']['albedo']",
     ["expected real numbers"]),
    ("sigma_t_huge", _fog(sigma_t=10**400), "scene['box']['interior']['sigma_t']", ["too large"]),
    ("sigma_a_string", _fog(sigma_a="1", sigma_s=1.0), "scene['box']['interior']['sigma_a']",
     ["must be an rgb colour or a float"]),
    ("medium_unknown_key", _fog(density=1.0), "scene['box']['interior']['density']", ["unknown parameter"]),
    ("grid_missing", _s(box={"type": "cube", "bsdf": {"type": "null"}, "interior": {
        "type": "heterogeneous", "sigma_t": {"type": "gridvolume", "filename": "/nonexistent/x.vol"}}}),
     "scene['box']['interior']['sigma_t']['filename']", ["volume file not found"]),
    ("grid_filename_nul", _s(box={"type": "cube", "bsdf": {"type": "null"}, "interior": {
        "type": "heterogeneous", "sigma_t": {"type": "gridvolume", "filename": "a\0b.vol"}}}),
     "scene['box']['interior']['sigma_t']['filename']", ["NUL"]),
    ("mesh_filename_int", _s(m={"type": "obj", "filename": 3}), "scene['m']['filename']",
     ["must be a string, got an integer"]),
    ("mesh_missing", _s(m={"type": "ply", "filename": "/nonexistent/bunny.ply"}), "scene['m']['filename']",
     ["mesh file not found"]),
    ("emitter_radiance_complex", _s(ball={"type": "sphere", "emitter": {"type": "area", "radiance": 1 + 2j}}),
     "scene['ball']['emitter']['radiance']", ["unsupported value of type complex"]),
    ("spot_bool_intensity", _s(l={"type": "spot", "intensity": [True, 1.0, 1.0]}), "scene['l']['intensity']",
     ["expected real numbers, got bool"]),
    ("direction_strings", _s(sun={"type": "directional", "direction": ["0", "0", "1"]}),
     "scene['sun']['direction']", ["expected real numbers, got str"]),
]

_DICT_IDS = [c[0] for c in DICTS]
assert len(set(_DICT_IDS)) == len(_DICT_IDS), "duplicate case ids"


@pytest.mark.parametrize("case", DICTS, ids=_DICT_IDS)
def test_bad_dict(case):
    _, scene, where, words = case
    with pytest.raises(SceneError) as info:
        load_dict(scene)
    message = str(info.value)
    assert message.startswith(where), message
    for w in words:
        assert w in message, message


# -- valid but suspicious: a SceneWarning naming the shape ---------------------------


def _medium_ball_in_fog(camera_fog):
    fog = {"type": "homogeneous", "sigma_t": 0.1, "albedo": 0.5}
    d = _s(ball={"type": "sphere", "bsdf": {"type": "dielectric"},
                 "interior": {"type": "homogeneous", "sigma_t": 2.0}},
           cam={"type": "perspective", "to_world": np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5.0],
                                                             [0, 0, 0, 1]])})
    if camera_fog:
        d["cam"]["medium"] = fog
    else:
        d["fog"] = {"type": "cube", "to_world": np.diag([3.0, 3.0, 3.0, 1.0]), "bsdf": {"type": "null"},
                    "interior": fog}
    return d


WARNINGS = [
    ("ball_in_camera_fog", lambda: load_dict(_medium_ball_in_fog(True)),
     ["shape scene['ball'] declares an interior medium but no exterior", "sensor's medium"]),
    ("ball_in_fog_cube", lambda: load_dict(_medium_ball_in_fog(False)),
     ["shape scene['ball'] declares an interior medium but no exterior", "shape scene['fog']"]),
    ("irradiancemeter_film", lambda: load_dict(_s(meter={"type": "rectangle", "sensor": {
        "type": "irradiancemeter", "film": {"type": "hdrfilm", "width": 4, "height": 3}}})),
     ["scene['meter']['sensor']: sensor 'irradiancemeter': a 4x3 film", "1x1 image"]),
    # core: a camera whose far_clip misses every shape (a scene scaled up past it renders black).
    ("far_clip_misses", lambda: rm.load_dict(_s(ball={"type": "sphere", "center": [0, 0, 50.0]},
                                                cam={"type": "perspective", "far_clip": 10.0})).core(),
     ["<dict>: sensor", "far_clip"]),
]


@pytest.mark.parametrize("case", WARNINGS, ids=[c[0] for c in WARNINGS])
def test_suspicious_scenes_warn(case):
    _, load, words = case
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load()
    found = [str(w.message) for w in caught if issubclass(w.category, SceneWarning)]
    assert len(found) == 1, [str(w.message) for w in caught]
    for w in words:
        assert w in found[0], found[0]


def test_extreme_but_valid_inputs_load():
    """Values near the ends of float64 load without numpy's overflow: a
    direction of length 1e-200 (normalised), a cube scaled by 1e-300 (its
    normals still unit vectors)."""
    sun = load_dict(_s(sun={"type": "directional", "direction": [1e-200, 1e-200, 0.0]})).emitters[0]
    np.testing.assert_allclose(sun.to_world[:3, 2], [2**-0.5, 2**-0.5, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        box = load_dict(_s(box={"type": "cube", "to_world": np.diag([1e-300, 1e-300, 1e-300, 1.0])})).shapes[0]
    np.testing.assert_allclose(np.linalg.norm(box.normals, axis=1), 1.0, rtol=1e-6)


def test_corpus_size():
    """At least 150 bad inputs, over every category."""
    assert len(XML) + len(DICTS) + len(WARNINGS) >= 150
