"""The intermediate form shared by both front ends: one _Node per plugin
instance, its parameters as _Props, references to ids as _Refs."""
from __future__ import annotations

from ..scene_desc import SceneError


def _fmt_path(keys):
    return "scene" + "".join(f"[{k!r}]" for k in keys)


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
        self.referenced = False

    def label(self):
        return f"{self.category} '{self.type}'"


def _register(ids, id_, node):
    if id_ in ids:
        raise SceneError(f"{node.place}: duplicate id '{id_}' (first at {ids[id_].place})")
    ids[id_] = node
    node.id = id_
