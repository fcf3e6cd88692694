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
from .spectra import Sampled, parse_pairs, read_spd
from .transforms import _look_at, _rotate, _translate

# XML tags of Mitsuba 3 that are outside the subset, for a precise message.
_UNSUPPORTED_TAGS = ("alias", "spectrum_file")
# <include> levels (Mitsuba 3: MI_XML_INCLUDE_MAX_RECURSION) and included
# files in all (a file included twice by a file included twice ... grows
# exponentially without a cycle).
_MAX_INCLUDE_DEPTH = 15
_MAX_INCLUDES = 1000
_PROPERTY_TAGS = ("float", "integer", "boolean", "string", "rgb", "spectrum", "point",
                  "vector", "transform")


class _XmlElem:
    __slots__ = ("tag", "attrib", "line", "children", "src")

    def __init__(self, tag, attrib, line, src):
        self.tag, self.attrib, self.line, self.children, self.src = tag, attrib, line, [], src


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
        elem = _XmlElem(tag, dict(attrib), parser.CurrentLineNumber, src)
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


def _version(elem, place):
    """Mitsuba's version attribute: three period-separated integers."""
    text = elem.attrib["version"]
    parts = text.strip().split(".")
    if len(parts) != 3 or not all(p.isdigit() and p.isascii() and len(p) < 10 for p in parts):
        raise SceneError(f"{place}: <scene>: cannot parse version {_quote(text)} (three period-separated "
                         f"numbers, e.g. '3.0.0')")
    return tuple(int(p) for p in parts)


def _underscore(name):
    """Mitsuba 3's upgrade of a Mitsuba 0.x parameter name (upgrade_tree in
    src/core/xml.cpp): camelCase to underscore_case, an upper-case run after a
    lower-case letter lower-cased ('intIOR' -> 'int_ior', 'sigmaA' ->
    'sigma_a')."""
    out, i = name, 0
    while i < len(out) - 1:
        if out[i].islower() and out[i + 1].isupper():
            j = i + 1
            while j < len(out) and out[j].isupper():
                j += 1
            out = out[:i + 1] + "_" + out[i + 1:j].lower() + out[j:]
            i = j + 1
        else:
            i += 1
    return out


def _upgrade(elem, parent=None):
    """Mitsuba 3 reads a file of version < 2.0.0 after rewriting it in memory
    (upgrade_tree, src/core/xml.cpp): parameter names to underscore_case
    (but not <default> names), <lookAt> to <lookat>, a diffuse bsdf's
    diffuse_reflectance to reflectance. (Its rule for a texture's
    uoffset/vscale, moved into to_uv, is not applied: such a file gets the
    unknown-parameter error naming them.)"""
    if elem.tag == "lookAt":
        elem.tag = "lookat"
    if "name" in elem.attrib and elem.tag != "default":
        elem.attrib["name"] = _underscore(elem.attrib["name"])
        if (elem.attrib["name"] == "diffuse_reflectance" and parent is not None and parent.tag == "bsdf"
                and parent.attrib.get("type") == "diffuse"):
            elem.attrib["name"] = "reflectance"
    for c in elem.children:
        _upgrade(c, elem)


class _XmlReader:
    def __init__(self, path, params, confine=False):
        self.src = str(path)
        self.dir = os.path.dirname(os.path.abspath(path))
        self.params = params
        self.used_params = set()
        self.ids = {}
        self.confine = confine
        # Mitsuba's file resolver: each <path> is put first; the scene's folder
        # is last. (Mitsuba 3 also looks in the working directory, before the
        # scene's folder; here a scene means the same wherever it is loaded.)
        self.search = [self.dir]
        self.n_includes = 0

    def resolve(self, name):
        """The file a relative name refers to: the first folder of the search
        list holding it, else (for the error message) the scene's folder."""
        if os.path.isabs(name):
            return name
        for base in self.search:
            path = os.path.join(base, name)
            if os.path.exists(path):
                return path
        return os.path.join(self.dir, name)

    def place(self, elem):
        return f"{elem.src}:{elem.line}"

    def attrs(self, elem, allowed, required=()):
        for a in elem.attrib:
            if a not in allowed:
                raise SceneError(f"{self.place(elem)}: <{elem.tag}>: unknown attribute '{a}'")
        for a in required:
            if a not in elem.attrib:
                raise SceneError(f"{self.place(elem)}: <{elem.tag}>: missing attribute '{a}'")
        return elem.attrib

    def sub_value(self, elem, text):
        """$name replaced in one attribute value (Mitsuba's <default>/params)."""

        def repl(m):
            name = m.group(1)
            if name not in self.params:
                raise SceneError(f"{self.place(elem)}: <{elem.tag}>: undefined parameter "
                                 f"${name}")
            self.used_params.add(name)
            return self.params[name]

        return _PARAM_RE.sub(repl, text) if "$" in text else text

    def substitute(self, elem):
        """Replace $name in every attribute value."""
        for k, v in elem.attrib.items():
            elem.attrib[k] = self.sub_value(elem, v)
        for c in elem.children:
            self.substitute(c)

    def check_root(self, root):
        place = self.place(root)
        if root.tag != "scene":
            raise SceneError(f"{place}: root element must be <scene>, got <{root.tag}>")
        self.attrs(root, ("version",), ("version",))
        # Mitsuba 3 reads every version; older than 2.0.0 after its upgrade.
        if _version(root, place) < (2, 0, 0):
            _upgrade(root)

    def confined(self, path, elem, what):
        """An untrusted scene names only files inside its folder."""
        if not self.confine:
            return path
        root = os.path.realpath(self.dir)
        real = os.path.realpath(path)
        if os.path.commonpath([root, real]) != root:
            raise SceneError(f"{self.place(elem)}: <{elem.tag}>: {what} lies outside the scene's folder {root} "
                             f"(an untrusted scene may only name files inside it)")
        return real

    def add_path(self, elem):
        """<path value="..."/>: a folder searched first for relative file
        names (meshes, volumes, includes); a relative one is taken from the
        folder of the file that declares it, else through the search list
        (Mitsuba 3's Tag::Resource)."""
        a = self.attrs(elem, ("value",), ("value",))
        self.no_children(elem)
        value = self.sub_value(elem, a["value"])
        if "\0" in value:
            raise SceneError(f"{self.place(elem)}: <path>: the value contains a NUL character")
        path = value
        if not os.path.isabs(path):
            path = os.path.join(os.path.dirname(os.path.abspath(elem.src)), value)
            if not os.path.isdir(path):
                path = self.resolve(value)
        path = self.confined(path, elem, f"folder '{value}'")
        if not os.path.isdir(path):
            raise SceneError(f"{self.place(elem)}: <path>: folder '{value}' not found (looked for {path})")
        self.search.insert(0, os.path.abspath(path))

    def include(self, elem, chain, top):
        """<include filename="..."/> -> the included file's elements: a
        <scene> root's children, else the root itself (Mitsuba 3's
        Tag::Include). `chain`: the includes that led here, [(real path,
        place of the include)], for cycles."""
        a = self.attrs(elem, ("filename",), ("filename",))
        self.no_children(elem)
        place = self.place(elem)
        name = self.sub_value(elem, a["filename"])
        if "\0" in name:
            raise SceneError(f"{place}: <include>: the filename contains a NUL character")
        path = self.confined(self.resolve(name), elem, f"included file '{name}'")
        if not os.path.isfile(path):
            raise SceneError(f"{place}: <include>: file '{name}' not found (looked for {path})")
        real = os.path.realpath(path)
        if real == os.path.realpath(self.src) or any(real == r for r, _ in chain):
            steps = " -> ".join(f"{p} includes" for _, p in chain + [(real, place)])
            raise SceneError(f"{place}: <include>: include cycle: {steps} {name}, which is already being read")
        if len(chain) >= _MAX_INCLUDE_DEPTH:
            raise SceneError(f"{place}: <include>: includes nested deeper than {_MAX_INCLUDE_DEPTH} levels")
        self.n_includes += 1
        if self.n_includes > _MAX_INCLUDES:
            raise SceneError(f"{place}: <include>: more than {_MAX_INCLUDES} included files in all")
        root = _parse_xml(path, path, untrusted=self.confine)
        chain = chain + [(real, place)]
        if root.tag == "scene":
            self.check_root(root)
            return self.expand(root.children, chain, top=top)
        return self.expand([root], chain, top=False)

    def expand(self, elems, chain, top):
        """Elements with <include>s replaced by what they include and <path>s
        applied, in document order (a <path> applies to what follows it)."""
        out = []
        for elem in elems:
            if elem.tag == "include":
                out.extend(self.include(elem, chain, top))
                continue
            if elem.tag == "path":
                if not top:
                    raise SceneError(f"{self.place(elem)}: <path> is allowed only at the top level of a scene")
                self.add_path(elem)
                continue
            if elem.tag == "default" and top:
                a = self.attrs(elem, ("name", "value"), ("name", "value"))
                self.params.setdefault(a["name"], a["value"])
            elem.children = self.expand(elem.children, chain, top=False)
            out.append(elem)
        return out

    def read(self, root):
        self.check_root(root)
        # <include> and <path> first, in document order; <default> declares
        # parameters (values passed to load_file override them).
        given = set(self.params)
        children = self.expand(root.children, [], top=True)
        declared = set()
        body = []
        for elem in children:
            if elem.tag == "default":
                declared.add(elem.attrib["name"])
            else:
                body.append(elem)
        for elem in body:
            self.substitute(elem)
        unused = sorted(given - self.used_params - declared)
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

    def element(self, elem, owner=None):
        """A plugin element -> _Node; a property element -> (name, _Prop); a
        <ref> -> (name, _Ref). `owner`: the plugin node it is nested in."""
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
                item = self.element(c, node)
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
            return self.prop(elem, owner)
        if tag in _UNSUPPORTED_TAGS or tag == "default":
            where = " (only at the top level)" if tag == "default" else ""
            raise SceneError(f"{place}: <{tag}> is not supported{where}")
        raise SceneError(f"{place}: unknown element <{tag}>")

    def no_children(self, elem):
        if elem.children:
            raise SceneError(f"{self.place(elem.children[0])}: <{elem.tag}> takes no nested "
                             f"elements")

    def prop(self, elem, owner=None):
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
        if tag == "spectrum":
            return self.spectrum(elem, owner)
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
        return name, _Prop(tag, value, place)

    def spectrum(self, elem, owner):
        """<spectrum name=".." value="0.5"/> (uniform), value="400:0.1, 700:0.5"
        (wavelength:value pairs, nm) or filename="x.spd" (a spectrum file,
        found as meshes are)."""
        place = self.place(elem)
        a = self.attrs(elem, ("name", "value", "filename"), ("name",))
        name = a["name"]
        where = f"{place}: {owner.label() + ': ' if owner is not None else ''}parameter '{name}': <spectrum>"
        if ("value" in a) == ("filename" in a):
            raise SceneError(f"{where}: give either value or filename")
        if "filename" in a:
            fname = a["filename"]
            if "\0" in fname:
                raise SceneError(f"{where}: the filename contains a NUL character")
            path = self.confined(self.resolve(fname), elem, f"spectrum file '{fname}'")
            if not os.path.isfile(path):
                raise SceneError(f"{where}: spectrum file '{fname}' not found (looked for {path})")
            try:
                wl, vals = read_spd(path, path, _parse_float, quote=not self.confine)
            except ValueError as e:
                raise SceneError(f"{where}: {e}") from None
            return name, _Prop("spectrum", Sampled(wl, vals, path), place)
        text = a["value"]
        if ":" not in text:
            return name, _Prop("spectrum", _numbers(text, place, "<spectrum>", (1,))[0], place)
        try:
            wl, vals = parse_pairs(text, _parse_float)
        except ValueError as e:
            raise SceneError(f"{where}: {e} in {_quote(text)}") from None
        return name, _Prop("spectrum", Sampled(wl, vals, place), place)

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
    reader = _XmlReader(src, text_params, confine=bool(base_dir_only))
    root = _parse_xml(src, src, untrusted=bool(base_dir_only))
    nodes = reader.read(root)
    return _assemble(nodes, reader.ids, src, reader.dir, confine=bool(base_dir_only), resolve=reader.resolve)
