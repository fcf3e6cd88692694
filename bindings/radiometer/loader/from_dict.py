"""The dict front end: the dict that `mitsuba.load_dict` takes -> _Nodes."""
from __future__ import annotations

import os

import numpy as np

from ..scene_desc import SceneDesc, SceneError
from .build import _assemble
from .nodes import _MAX_DEPTH, _fmt_path, _Node, _Prop, _quote, _Ref, _register
from .parameters import _parse_float
from .plugins import _CATEGORY_OF
from .spectra import Sampled, check_samples, read_spd


def _real(x):
    """A real number, as Python or numpy has them (not a bool, complex or string)."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _real_array(v, place):
    """`v` (a list, tuple, numpy array or Mitsuba vector/matrix) as a float64
    array, refusing what numpy would otherwise convert: booleans (to 0/1),
    strings of digits, complex numbers (dropping the imaginary part)."""
    if isinstance(v, (list, tuple)):
        todo = [(v, 0)]
        while todo:  # iterative, and shallow: a 4x4 matrix is two levels
            x, depth = todo.pop()
            if isinstance(x, (list, tuple)) and depth < 2:
                todo.extend((y, depth + 1) for y in x)
            elif not _real(x):
                raise SceneError(f"{place}: expected real numbers, got {type(x).__name__} "
                                 f"{_quote(x)} in {_quote(v)}")
    try:
        a = np.asarray(v)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(f"{place}: unsupported value of type {type(v).__name__}") from None
    if a.ndim == 0 and not _real(v):  # None, a complex number, any other object
        raise SceneError(f"{place}: unsupported value of type {type(v).__name__}")
    if a.dtype.kind == "O":  # Python integers too large for int64: convert one by one
        try:
            a = a.astype(np.float64)
        except (TypeError, ValueError, OverflowError):
            raise SceneError(f"{place}: numbers out of range or not real in {_quote(v)}") from None
    if a.dtype.kind not in "iuf":
        raise SceneError(f"{place}: expected real numbers, got an array of {a.dtype} ({_quote(v)})")
    return a.astype(np.float64)


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
        except (TypeError, ValueError, OverflowError):
            m = None
        if m is not None and m.shape == (4, 4):
            _check_inverse_transpose(v, m, place)
            return _Prop("transform", m, place)
    a = _real_array(v, place)
    if a.shape == (3,):
        return _Prop("vec3", a, place)
    if a.shape == (4, 4):
        return _Prop("transform", a, place)
    raise SceneError(f"{place}: unsupported value {_quote(v)} (expected a number, string, "
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


def _dict_spectrum(v, place):
    """{'type': 'spectrum', 'value': [(wavelength, value), ...]} or
    {'type': 'spectrum', 'filename': 'x.spd'} (relative to the current
    directory), as mitsuba.load_dict takes them."""
    if set(v) != {"type", "filename"} or not isinstance(v["filename"], (str, os.PathLike)):
        raise SceneError(f"{place}: a spectrum dict is {{'type': 'spectrum', 'value': ...}} or "
                         f"{{'type': 'spectrum', 'filename': str}}")
    fname = os.fspath(v["filename"])
    if "\0" in fname:
        raise SceneError(f"{place}: spectrum: the filename contains a NUL character")
    path = os.path.abspath(fname)
    if not os.path.isfile(path):
        raise SceneError(f"{place}: spectrum file '{fname}' not found (looked for {path})")
    try:
        wl, vals = read_spd(path, path, _parse_float)
    except ValueError as e:
        raise SceneError(f"{place}: spectrum: {e}") from None
    return _Prop("spectrum", Sampled(wl, vals, path), place)


def _dict_pairs(val, place):
    a = _real_array(val, place) if isinstance(val, (list, tuple, np.ndarray)) else None
    if a is None or a.ndim != 2 or a.shape[1] != 2:
        raise SceneError(f"{place}: spectrum value: expected a number or a list of (wavelength, value) pairs, "
                         f"got {_quote(val)}")
    why = check_samples(list(a[:, 0]), list(a[:, 1]))
    if why:
        raise SceneError(f"{place}: spectrum value: {why}")
    return _Prop("spectrum", Sampled(a[:, 0], a[:, 1], place), place)


def _dict_colour(v, keys):
    place = _fmt_path(keys)
    if v["type"] == "spectrum" and "filename" in v:
        return _dict_spectrum(v, place)
    extra = set(v) - {"type", "value"}
    if extra:
        raise SceneError(f"{place}: {v['type']} value: unknown key {_quote(sorted(map(str, extra))[0])}")
    if "value" not in v:
        raise SceneError(f"{place}: {v['type']} value: missing 'value'")
    val = v["value"]
    if not isinstance(val, (list, tuple, np.ndarray)) and np.ndim(val) == 0:
        if not _real(val):
            raise SceneError(f"{place}: {v['type']} value must be a real number, got {_quote(val)}")
        return _Prop(v["type"], val, place)
    if v["type"] == "spectrum":
        return _dict_pairs(val, place)
    a = _real_array(val, place)
    if a.shape != (3,):
        raise SceneError(f"{place}: rgb value must be 3 numbers, got {_quote(val)}")
    return _Prop("rgb", a, place)


def _dict_node(d, keys, ids):
    place = _fmt_path(keys)
    if len(keys) > _MAX_DEPTH:
        raise SceneError(f"{place}: plugin dicts nested deeper than {_MAX_DEPTH} levels")
    t = d.get("type")
    if not isinstance(t, str):
        raise SceneError(f"{place}: plugin dict needs a string 'type'")
    category = _CATEGORY_OF.get(t)
    if category is None:
        raise SceneError(f"{place}: plugin type {_quote(t)} is not supported")
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
