"""The XML front end: a Mitsuba 3 XML file -> _Nodes, every element with
its line number; <default> parameters, property elements and transforms."""
from __future__ import annotations

import math
import os
import re
import xml.parsers.expat

import numpy as np

from ..scene_desc import SceneDesc, SceneError
from .build import _assemble
from .nodes import _MAX_DEPTH, _Node, _Prop, _quote, _Ref, _register
from .parameters import _parse_float, _parse_int
from .plugins import PLUGINS
from .transforms import _look_at, _rotate, _translate

# XML tags of Mitsuba 3 that are outside the subset, for a precise message.
_UNSUPPORTED_TAGS = ("texture", "include", "alias", "path", "spectrum_file")
_PROPERTY_TAGS = ("float", "integer", "boolean", "string", "rgb", "spectrum", "point",
                  "vector", "transform")


class _XmlElem:
    __slots__ = ("tag", "attrib", "line", "children")

    def __init__(self, tag, attrib, line):
        self.tag, self.attrib, self.line, self.children = tag, attrib, line, []


def _parse_xml(path, src, untrusted=False):
    """Parse with expat (stdlib) so that every element keeps its line number.
    Nesting is bounded (_MAX_DEPTH); an untrusted file may not declare a DTD
    (entities are the XML way to blow a small file up or pull in another)."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise SceneError(f"{src}: cannot read scene file ({e.strerror})") from None
    parser = xml.parsers.expat.ParserCreate()
    stack, roots = [], []

    def start(tag, attrib):
        elem = _XmlElem(tag, dict(attrib), parser.CurrentLineNumber)
        if len(stack) >= _MAX_DEPTH:
            raise SceneError(f"{src}:{elem.line}: <{tag}>: elements nested deeper than {_MAX_DEPTH} levels")
        (stack[-1].children if stack else roots).append(elem)
        stack.append(elem)

    def end(tag):
        stack.pop()

    def doctype(name, *_):
        raise SceneError(f"{src}:{parser.CurrentLineNumber}: a DOCTYPE declaration is not allowed in an "
                         f"untrusted scene")

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    if untrusted:
        parser.StartDoctypeDeclHandler = doctype
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as e:
        raise SceneError(f"{src}:{e.lineno}: malformed XML: "
                         f"{xml.parsers.expat.ErrorString(e.code)}") from None
    except LookupError as e:  # an encoding Python does not know
        raise SceneError(f"{src}:{parser.CurrentLineNumber}: unsupported XML encoding ({e})") from None
    except ValueError as e:  # SceneError from the handlers, or text that does not decode
        if isinstance(e, SceneError):
            raise
        raise SceneError(f"{src}:{parser.CurrentLineNumber}: cannot decode the XML ({type(e).__name__})") from None
    return roots[0]


_PARAM_RE = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


def _numbers(text, place, what, counts):
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    try:
        vals = [_parse_float(p) for p in parts]
    except ValueError:
        raise SceneError(f"{place}: {what}: cannot parse numbers from {_quote(text)}") from None
    if len(vals) not in counts:
        raise SceneError(f"{place}: {what}: expected {' or '.join(map(str, counts))} "
                         f"numbers, got {len(vals)} in {_quote(text)}")
    for v in vals:
        if not math.isfinite(v):
            raise SceneError(f"{place}: {what}: non-finite value in {_quote(text)}")
    return vals


class _XmlReader:
    def __init__(self, path, params):
        self.src = str(path)
        self.dir = os.path.dirname(os.path.abspath(path))
        self.params = params
        self.used_params = set()
        self.ids = {}

    def place(self, elem):
        return f"{self.src}:{elem.line}"

    def attrs(self, elem, allowed, required=()):
        for a in elem.attrib:
            if a not in allowed:
                raise SceneError(f"{self.place(elem)}: <{elem.tag}>: unknown attribute '{a}'")
        for a in required:
            if a not in elem.attrib:
                raise SceneError(f"{self.place(elem)}: <{elem.tag}>: missing attribute '{a}'")
        return elem.attrib

    def substitute(self, elem):
        """Replace $name in every attribute value (Mitsuba's <default>/params)."""

        def repl(m):
            name = m.group(1)
            if name not in self.params:
                raise SceneError(f"{self.place(elem)}: <{elem.tag}>: undefined parameter "
                                 f"${name}")
            self.used_params.add(name)
            return self.params[name]

        for k, v in elem.attrib.items():
            if "$" in v:
                elem.attrib[k] = _PARAM_RE.sub(repl, v)
        for c in elem.children:
            self.substitute(c)

    def read(self, root):
        place = self.place(root)
        if root.tag != "scene":
            raise SceneError(f"{place}: root element must be <scene>, got <{root.tag}>")
        attrib = self.attrs(root, ("version",), ("version",))
        if not attrib["version"].split(".")[0] == "3":
            raise SceneError(f"{place}: <scene>: only version 3.x scenes are supported, "
                             f"got version '{attrib['version']}'")
        # <default> declares parameters; values passed to load_file override them.
        declared = set()
        body = []
        for elem in root.children:
            if elem.tag == "default":
                a = self.attrs(elem, ("name", "value"), ("name", "value"))
                declared.add(a["name"])
                self.params.setdefault(a["name"], a["value"])
            else:
                body.append(elem)
        for elem in body:
            self.substitute(elem)
        unused = sorted(set(self.params) - self.used_params - declared)
        if unused:
            raise SceneError(f"{self.src}: parameter(s) given but never used in the file: "
                             f"{', '.join(unused)}")
        nodes = []
        for elem in body:
            node = self.element(elem)
            if not isinstance(node, _Node):
                raise SceneError(f"{self.place(elem)}: <{elem.tag}> is not allowed at the "
                                 f"top level of a scene")
            nodes.append(node)
        return nodes

    def element(self, elem):
        """A plugin element -> _Node; a property element -> (name, _Prop); a
        <ref> -> (name, _Ref)."""
        tag, place = elem.tag, self.place(elem)
        if tag in PLUGINS:
            a = self.attrs(elem, ("type", "id", "name"), ("type",))
            t = a["type"]
            if t not in PLUGINS[tag]:
                raise SceneError(f"{place}: {tag} type '{t}' is not supported (supported: "
                                 f"{', '.join(PLUGINS[tag])})")
            node = _Node(tag, t, place)
            if "id" in a:
                _register(self.ids, a["id"], node)
            for c in elem.children:
                item = self.element(c)
                if isinstance(item, _Node):
                    node.children.append((c.attrib.get("name", c.tag), item))
                elif isinstance(item[1], _Ref):
                    node.children.append(item)
                else:
                    name, prop = item
                    if name in node.props:
                        raise SceneError(f"{prop.place}: {node.label()}: parameter '{name}' "
                                         f"given twice (first at {node.props[name].place})")
                    node.props[name] = prop
            return node
        if tag == "ref":
            a = self.attrs(elem, ("id", "name"), ("id",))
            self.no_children(elem)
            return (a.get("name", "ref"), _Ref(a["id"], place))
        if tag in _PROPERTY_TAGS:
            return self.prop(elem)
        if tag in _UNSUPPORTED_TAGS or tag == "default":
            where = " (only at the top level)" if tag == "default" else ""
            raise SceneError(f"{place}: <{tag}> is not supported{where}")
        raise SceneError(f"{place}: unknown element <{tag}>")

    def no_children(self, elem):
        if elem.children:
            raise SceneError(f"{self.place(elem.children[0])}: <{elem.tag}> takes no nested "
                             f"elements")

    def prop(self, elem):
        tag, place = elem.tag, self.place(elem)
        if tag == "transform":
            a = self.attrs(elem, ("name",), ("name",))
            return a["name"], _Prop("transform", self.transform(elem), place)
        self.no_children(elem)
        if tag in ("point", "vector"):
            a = self.attrs(elem, ("name", "value", "x", "y", "z"), ("name",))
            if "value" in a:
                if any(k in a for k in "xyz"):
                    raise SceneError(f"{place}: <{tag}>: give either value or x, y, z")
                v = _numbers(a["value"], place, f"<{tag}>", (3,))
            else:
                for k in "xyz":
                    if k not in a:
                        raise SceneError(f"{place}: <{tag}>: missing attribute '{k}'")
                v = [_numbers(a[k], place, f"<{tag}> {k}", (1,))[0] for k in "xyz"]
            return a["name"], _Prop(tag, np.array(v, dtype=np.float64), place)
        a = self.attrs(elem, ("name", "value"), ("name", "value"))
        name, text = a["name"], a["value"]
        if tag == "float":
            value = _numbers(text, place, "<float>", (1,))[0]
        elif tag == "integer":
            try:
                value = _parse_int(text.strip())
            except ValueError:
                if text.strip().isdigit():
                    raise SceneError(f"{place}: <integer>: {_quote(text)} has too many digits") from None
                raise SceneError(f"{place}: <integer>: cannot parse {_quote(text)} as an integer") from None
        elif tag == "boolean":
            low = text.strip().lower()
            if low not in ("true", "false"):
                raise SceneError(f"{place}: <boolean>: value must be 'true' or 'false', "
                                 f"got {_quote(text)}")
            value = low == "true"
        elif tag == "string":
            value = text
        elif tag == "rgb":
            vals = _numbers(text, place, "<rgb>", (1, 3))
            value = vals[0] if len(vals) == 1 else np.array(vals, dtype=np.float64)
        else:  # spectrum
            if ":" in text:
                raise SceneError(f"{place}: <spectrum>: only uniform spectra (a single "
                                 f"value) are supported")
            value = _numbers(text, place, "<spectrum>", (1,))[0]
        return name, _Prop(tag, value, place)

    def transform(self, elem):
        """Compose the ops of a <transform>; each op left-multiplies, as in
        Mitsuba, so the first op listed is applied first."""
        m = np.eye(4)
        for op in elem.children:
            place = self.place(op)
            self.no_children(op)
            a = op.attrib
            if op.tag == "translate":
                self.attrs(op, ("x", "y", "z", "value"))
                t = self._xyz(op, 0.0)
                step = _translate(t)
            elif op.tag == "scale":
                self.attrs(op, ("x", "y", "z", "value"))
                if "value" in a and len(_numbers(a["value"], place, "<scale>", (1, 3))) == 1:
                    s = [_numbers(a["value"], place, "<scale>", (1,))[0]] * 3
                else:
                    s = self._xyz(op, 1.0)
                step = np.diag([s[0], s[1], s[2], 1.0])
            elif op.tag == "rotate":
                self.attrs(op, ("x", "y", "z", "value", "angle"), ("angle",))
                axis = np.array(self._xyz(op, 0.0))
                angle = _numbers(a["angle"], place, "<rotate> angle", (1,))[0]
                # Mitsuba 3.9.1 uses the axis as given: a non-unit axis makes
                # a non-rigid matrix whose normals Mitsuba then gets wrong
                # (see _check_inverse_transpose), so insist on a unit axis.
                if abs(np.linalg.norm(axis) - 1.0) > 1e-5:
                    raise SceneError(f"{place}: <rotate>: the axis {axis.tolist()} must have "
                                     f"unit length (Mitsuba does not normalise it)")
                step = _rotate(axis, angle)
            elif op.tag == "matrix":
                self.attrs(op, ("value",), ("value",))
                vals = _numbers(a["value"], place, "<matrix>", (9, 16))
                step = np.eye(4)
                if len(vals) == 16:
                    step = np.array(vals).reshape(4, 4)
                else:
                    step[:3, :3] = np.array(vals).reshape(3, 3)
            elif op.tag == "lookat":
                self.attrs(op, ("origin", "target", "up"), ("origin", "target"))
                o = np.array(_numbers(a["origin"], place, "<lookat> origin", (3,)))
                t = np.array(_numbers(a["target"], place, "<lookat> target", (3,)))
                up = (np.array(_numbers(a["up"], place, "<lookat> up", (3,)))
                      if "up" in a else None)
                step = _look_at(o, t, up, place)
            else:
                raise SceneError(f"{place}: unknown transform operation <{op.tag}>")
            with np.errstate(over="ignore", invalid="ignore"):  # overflow: refused where it is used
                m = step @ m
        return m

    def _xyz(self, op, default):
        a, place = op.attrib, self.place(op)
        if "value" in a:
            if any(k in a for k in "xyz"):
                raise SceneError(f"{place}: <{op.tag}>: give either value or x, y, z")
            return _numbers(a["value"], place, f"<{op.tag}>", (3,))
        return [_numbers(a[k], place, f"<{op.tag}> {k}", (1,))[0] if k in a else default
                for k in "xyz"]


def load_file(path, base_dir_only=False, **params) -> SceneDesc:
    """Load a Mitsuba 3 XML scene. `params` override the file's <default>
    values ($name substitution); a parameter the file neither declares nor
    uses is an error. Mesh and volume files resolve relative to the XML file.

    base_dir_only=True is for scenes from an untrusted source: every file
    the scene names must lie in the scene file's folder (or below it), after
    resolving `..` and symbolic links; errors quote no content of those
    files; the XML may not declare a DTD. Without it (the default, Mitsuba's
    behaviour) a scene may name any file the process can read."""
    src = os.fspath(path)
    if not os.path.isfile(src):
        raise SceneError(f"{src}: scene file not found")
    text_params = {k: ("true" if v else "false") if isinstance(v, bool) else str(v)
                   for k, v in params.items()}
    reader = _XmlReader(src, text_params)
    root = _parse_xml(src, src, untrusted=bool(base_dir_only))
    nodes = reader.read(root)
    return _assemble(nodes, reader.ids, src, reader.dir, confine=bool(base_dir_only))
