"""The intermediate form shared by both front ends: one _Node per plugin
instance, its parameters as _Props, references to ids as _Refs."""
from __future__ import annotations

from ..scene_desc import SceneError

# Deepest nesting of plugins (and of property elements in XML) accepted. Real
# scenes nest a handful of levels (shape > twosided > bsdf; medium > volume);
# the bound turns a runaway or cyclic input into a SceneError long before
# Python's recursion limit.
_MAX_DEPTH = 64


def _fmt_path(keys):
    if len(keys) > 8:  # a path at the depth limit: its ends say where
        return _fmt_path(keys[:3]) + f"...({len(keys) - 5} more)..." + "".join(f"[{k!r}]" for k in keys[-2:])
    return "scene" + "".join(f"[{k!r}]" for k in keys)


def _quote(text, limit=40):
    """`text` for a message, cut to `limit` characters: a value is quoted to
    say which one is wrong, not to echo a long input back."""
    text = str(text)
    return repr(text if len(text) <= limit else text[:limit] + "...")


class _Prop:
    """One parameter: kind is the XML tag ('float', 'rgb', ...) or, for dict
    values whose meaning depends on the parameter, 'vec3'."""

    __slots__ = ("kind", "value", "place")

    def __init__(self, kind, value, place):
        self.kind, self.value, self.place = kind, value, place


class _Ref:
    __slots__ = ("id", "place")

    def __init__(self, id_, place):
        self.id, self.place = id_, place


class _Node:
    def __init__(self, category, type_, place, id_=None):
        self.category = category
        self.type = type_
        self.place = place
        self.id = id_
        self.props = {}  # name -> _Prop
        self.children = []  # [(name, _Node | _Ref)], refs resolved before building
        self.ref_places = {}  # index in children -> place of the ref that put the node there
        self.referenced = False

    def label(self):
        return f"{self.category} '{self.type}'"


def _register(ids, id_, node):
    if id_ in ids:
        raise SceneError(f"{node.place}: duplicate id '{id_}' (first at {ids[id_].place})")
    ids[id_] = node
    node.id = id_
