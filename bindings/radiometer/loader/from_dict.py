"""The dict front end: the dict that `mitsuba.load_dict` takes -> _Nodes."""
from __future__ import annotations

import os

import numpy as np

from ..scene_desc import SceneDesc, SceneError
from .build import _assemble
from .nodes import _fmt_path, _Node, _Prop, _Ref, _register
from .plugins import _CATEGORY_OF


def _dict_value(v, keys):
    place = _fmt_path(keys)
    if isinstance(v, (bool, np.bool_)):
        return _Prop("boolean", bool(v), place)
    if isinstance(v, (int, np.integer)):
        return _Prop("integer", int(v), place)
    if isinstance(v, (float, np.floating)):
        return _Prop("float", float(v), place)
    if isinstance(v, str):
        return _Prop("string", v, place)
    # A Mitsuba (Scalar)(Affine)Transform4f, duck-typed: a 4x4 `matrix`
    # attribute (Dr.Jit vectors have a `matrix` attribute too, of another shape).
    m = getattr(v, "matrix", None) if not isinstance(v, np.ndarray) else None
    if m is not None:
        try:
            m = np.squeeze(np.array(m, dtype=np.float64))
        except (TypeError, ValueError):
            m = None
        if m is not None and m.shape == (4, 4):
            _check_inverse_transpose(v, m, place)
            return _Prop("transform", m, place)
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{place}: unsupported value of type {type(v).__name__}") from None
    if a.shape == (3,):
        return _Prop("vec3", a, place)
    if a.shape == (4, 4):
        return _Prop("transform", a, place)
    raise SceneError(f"{place}: unsupported value {v!r} (expected a number, string, "
                     f"3-vector, 4x4 matrix, transform or plugin dict)")


def _check_inverse_transpose(t, m, place):
    """Mitsuba keeps a transform's inverse transpose (used for normals) apart
    from its matrix and composes both; its rotate() neither normalises the axis
    nor inverts the rotation part, so a non-unit axis leaves the two
    inconsistent and Mitsuba's normals disagree with its geometry. Refuse such
    a transform rather than reproduce only half of it."""
    it = getattr(t, "inverse_transpose", None)
    if it is None or np.isscalar(it):
        return
    try:
        it = np.squeeze(np.array(it, dtype=np.float64))
        expected = np.linalg.inv(m).T
    except (TypeError, ValueError, np.linalg.LinAlgError):
        return  # a singular matrix is reported where the transform is used
    if it.shape == (4, 4) and not np.allclose(it, expected, rtol=1e-4,
                                              atol=1e-4 * max(1.0, np.abs(expected).max())):
        raise SceneError(f"{place}: the transform's inverse_transpose does not match its "
                         f"matrix (a rotate() about a non-unit axis?); give rotation axes "
                         f"of unit length")


def _dict_colour(v, keys):
    place = _fmt_path(keys)
    extra = set(v) - {"type", "value"}
    if extra:
        raise SceneError(f"{place}: {v['type']} value: unknown key '{sorted(extra)[0]}'")
    if "value" not in v:
        raise SceneError(f"{place}: {v['type']} value: missing 'value'")
    val = v["value"]
    if isinstance(val, (bool, np.bool_)) or isinstance(val, str):
        raise SceneError(f"{place}: {v['type']} value must be numeric, got {val!r}")
    if np.isscalar(val):
        return _Prop(v["type"], float(val), place)
    if v["type"] == "spectrum":
        raise SceneError(f"{place}: only uniform spectra (a single float) are supported")
    try:
        a = np.asarray(val, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{place}: rgb value must be 3 numbers, got {val!r}") from None
    if a.shape != (3,):
        raise SceneError(f"{place}: rgb value must be 3 numbers, got {val!r}")
    return _Prop("rgb", a, place)


def _dict_node(d, keys, ids):
    place = _fmt_path(keys)
    t = d.get("type")
    if not isinstance(t, str):
        raise SceneError(f"{place}: plugin dict needs a string 'type'")
    category = _CATEGORY_OF.get(t)
    if category is None:
        raise SceneError(f"{place}: plugin type '{t}' is not supported")
    node = _Node(category, t, place)
    for k, v in d.items():
        if k == "type":
            continue
        if not isinstance(k, str):
            raise SceneError(f"{place}: keys must be strings, got {k!r}")
        kk = keys + [k]
        if k == "id":
            if not isinstance(v, str):
                raise SceneError(f"{_fmt_path(kk)}: 'id' must be a string")
            _register(ids, v, node)
        elif isinstance(v, dict):
            vt = v.get("type")
            if vt == "ref":
                if set(v) != {"type", "id"} or not isinstance(v["id"], str):
                    raise SceneError(f"{_fmt_path(kk)}: a ref is {{'type': 'ref', 'id': str}}")
                node.children.append((k, _Ref(v["id"], _fmt_path(kk))))
            elif vt in ("rgb", "spectrum"):
                node.props[k] = _dict_colour(v, kk)
            else:
                node.children.append((k, _dict_node(v, kk, ids)))
        else:
            node.props[k] = _dict_value(v, kk)
    return node


def load_dict(d: dict) -> SceneDesc:
    """Load the scene dict that `mitsuba.load_dict` takes (top-level keys are
    ids; `{'type': 'ref', 'id': ...}` refers to them). Relative mesh file
    names resolve against the current directory."""
    if not isinstance(d, dict):
        raise SceneError(f"scene: expected a dict, got {type(d).__name__}")
    if d.get("type") != "scene":
        raise SceneError(f"scene: the top-level dict needs 'type': 'scene', got "
                         f"{d.get('type')!r}")
    ids, nodes = {}, []
    for key, value in d.items():
        if key == "type":
            continue
        if not isinstance(key, str):
            raise SceneError(f"scene: keys must be strings, got {key!r}")
        if not isinstance(value, dict):
            raise SceneError(f"{_fmt_path([key])}: top-level entries must be plugin dicts, "
                             f"got {type(value).__name__}")
        if value.get("type") == "ref":
            raise SceneError(f"{_fmt_path([key])}: a ref cannot stand at the top level")
        node = _dict_node(value, [key], ids)
        if node.id is None:
            _register(ids, key, node)
        nodes.append(node)
    return _assemble(nodes, ids, "<dict>", os.getcwd())
