"""Typed, checked access to a plugin's parameters (floats, integers,
booleans, strings, rgb colours, points and vectors, transforms, IORs),
and the tables they use."""
from __future__ import annotations

import math
import re

import numpy as np

from ..scene_desc import SceneError
from .spectra import XYZ_TO_SRGB, Sampled
from .transforms import FLOAT32_MAX

# Refractive indices at ~589 nm (sodium D line) of the materials Mitsuba names;
# physical constants (e.g. Hecht, "Optics"; refractiveindex.info).
NAMED_IOR = {
    "vacuum": 1.0,
    "helium": 1.000036,
    "hydrogen": 1.000132,
    "air": 1.000277,
    "carbon dioxide": 1.00045,
    "water": 1.3330,
    "acetone": 1.36,
    "ethanol": 1.361,
    "carbon tetrachloride": 1.461,
    "glycerol": 1.4729,
    "benzene": 1.501,
    "silicone oil": 1.52045,
    "bromine": 1.661,
    "water ice": 1.31,
    "fused quartz": 1.458,
    "pyrex": 1.470,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "amber": 1.55,
    "pet": 1.5750,
    "diamond": 2.419,
}

# Perspective-camera parameters that have no effect on a pinhole camera without
# motion: accepted (type-checked) and ignored.
PERSPECTIVE_IGNORED = ("focus_distance", "shutter_open", "shutter_close")


# Number syntax in scene text: decimal, ASCII only. Python's float() and int()
# also take "1_6" (as 16), Unicode digits and surrounding whitespace; Mitsuba's
# parser (strtof) takes none of them. "inf" and "nan" parse, so that their
# message says non-finite rather than unparsable.
_FLOAT_RE = re.compile(r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)",
                       re.IGNORECASE)
_INT_RE = re.compile(r"[+-]?[0-9]+")
# Integers the renderer stores in 32 bits (C++ int).
INT32_RANGE = (-2**31, 2**31 - 1)


def _parse_float(text):
    """A float from scene text; ValueError if it is not a decimal number."""
    if not _FLOAT_RE.fullmatch(text):
        raise ValueError(text)
    return float(text)


def _parse_int(text):
    """An integer from scene text; ValueError if it is not a decimal integer."""
    if len(text) > 4000 or not _INT_RE.fullmatch(text):  # 4000: below int()'s own digit limit
        raise ValueError(text)
    return int(text)


# The parameters that take a texture, by plugin type (the rest refuse one by name).
TEXTURED = {
    "diffuse": ("reflectance",),
    "plastic": ("diffuse_reflectance",),
    "roughplastic": ("diffuse_reflectance",),
    "conductor": ("specular_reflectance",),
    "roughconductor": ("specular_reflectance", "alpha", "alpha_u", "alpha_v"),
    "spot": ("texture",),
    "principled": ("base_color", "roughness", "anisotropic", "metallic", "spec_trans", "spec_tint", "sheen",
                   "sheen_tint", "flatness", "clearcoat", "clearcoat_gloss"),
    "principledthin": ("base_color", "roughness", "anisotropic", "spec_trans", "spec_tint", "sheen", "sheen_tint",
                       "flatness", "eta", "diff_trans"),
    "blendbsdf": ("weight",),
    "projector": ("irradiance",),
    "area": ("radiance",),
    "mask": ("opacity",),
    "normalmap": ("normalmap",),
    "bumpmap": ("(any name: the height field)",),
}
_TEXTURED_TEXT = "; ".join(f"{t}.{', '.join(n)}" for t, n in TEXTURED.items())

_KIND_WORDS = {
    "float": "a float", "integer": "an integer", "boolean": "a boolean",
    "string": "a string", "rgb": "an rgb colour", "spectrum": "a spectrum",
    "point": "a point", "vector": "a vector", "transform": "a transform",
    "vec3": "a 3-vector",
}


class _Params:
    """Typed access to one node's parameters; records what was used so that
    `done()` can reject the rest (Mitsuba's 'unreferenced property')."""

    def __init__(self, node):
        self.node = node
        self.used = set()
        self.used_children = set()

    def error(self, msg, place=None):
        return SceneError(f"{place or self.node.place}: {self.node.label()}: {msg}")

    def has(self, name):
        return name in self.node.props

    def _take(self, name, kinds, what):
        prop = self.node.props.get(name)
        if prop is None:
            return None
        self.used.add(name)
        if prop.kind not in kinds:
            raise self.error(f"parameter '{name}' must be {what}, got "
                             f"{_KIND_WORDS.get(prop.kind, prop.kind)}", prop.place)
        return prop

    def _finite(self, name, x, place):
        """x as a finite float (an integer too large for a float, 10**400,
        included in the refusal)."""
        try:
            x = float(x)
        except OverflowError:
            raise self.error(f"parameter '{name}': value {str(x)[:20]}... is too large", place) from None
        if not math.isfinite(x):
            raise self.error(f"parameter '{name}': non-finite value {x}", place)
        if abs(x) > FLOAT32_MAX:
            raise self.error(f"parameter '{name}': {x:g} is beyond the float32 range (|x| <= {FLOAT32_MAX:.3g}) "
                             f"the renderer computes in", place)
        return x

    def float(self, name, default=None, check=None):
        """check: None, 'positive' (> 0) or 'nonneg' (>= 0)."""
        prop = self._take(name, ("float", "integer"), "a float")
        if prop is None:
            return default
        x = self._finite(name, prop.value, prop.place)
        if check == "positive" and not x > 0:
            raise self.error(f"parameter '{name}' must be > 0, got {x}", prop.place)
        if check == "nonneg" and x < 0:
            raise self.error(f"parameter '{name}': negative value {x}", prop.place)
        return x

    def int(self, name, default=None, lo=None, hi=None):
        prop = self._take(name, ("integer",), "an integer")
        if prop is None:
            return default
        x = int(prop.value)
        if (lo is not None and x < lo) or (hi is not None and x > hi):
            raise self.error(f"parameter '{name}' = {x} is outside [{lo}, {hi}]", prop.place)
        return x

    def bool(self, name, default=None):
        prop = self._take(name, ("boolean",), "a boolean")
        return default if prop is None else bool(prop.value)

    def string(self, name, default=None, choices=None):
        prop = self._take(name, ("string",), "a string")
        if prop is None:
            if default is None:
                raise self.error(f"missing parameter '{name}'")
            return default
        s = str(prop.value)
        if choices is not None and s not in choices:
            raise self.error(f"parameter '{name}' = '{s}' is not one of {list(choices)}",
                             prop.place)
        return s

    def rgb(self, name, default, nonneg=True, spectrum="bounded"):
        """A colour: rgb, a spectrum, a float or (dicts) a 3-list. A sampled
        spectrum becomes RGB as Mitsuba's RGB variants convert it (spectra.py);
        `spectrum` says how: 'bounded' (clamped to [0, 1]: reflectances),
        'unbounded' (e.g. eta, k) or 'emission' (no D65 weight, unbounded:
        an emitter's radiance, intensity or irradiance)."""
        prop = self._take(name, ("rgb", "spectrum", "float", "integer", "vec3"),
                          "an rgb colour or a float")
        if prop is None:
            return (float(default),) * 3 if np.isscalar(default) else tuple(default)
        v = prop.value
        if isinstance(v, Sampled):
            v = v.rgb(spectrum)
        elif prop.kind == "spectrum" and spectrum == "emission":
            # A uniform spectrum on an emitter: Mitsuba 3's RGB variants
            # (xml.cpp, create_texture_from_spectrum) take it as XYZ =
            # (value, value, value) and convert that to sRGB, a slightly
            # purple colour, value x (1.2048, 0.9483, 0.9088), so that RGB and
            # spectral renders agree; as a float or rgb it stays grey.
            c = self._finite(name, v, prop.place)
            v = tuple(c * x for x in XYZ_TO_SRGB.sum(axis=1))
        vals = [self._finite(name, c, prop.place) for c in ([v] * 3 if np.isscalar(v) else v)]
        for c in vals:
            if nonneg and c < 0:
                raise self.error(f"parameter '{name}': negative value {c}", prop.place)
        return tuple(vals)

    def vec3(self, name, default=None, what="a point"):
        prop = self._take(name, ("point", "vector", "vec3"), what)
        if prop is None:
            return None if default is None else np.asarray(default, dtype=np.float64)
        v = np.asarray(prop.value, dtype=np.float64)
        for c in v:
            self._finite(name, float(c), prop.place)
        return v

    def transform(self, name="to_world"):
        prop = self._take(name, ("transform",), "a transform")
        if prop is None:
            return None
        m = np.asarray(prop.value, dtype=np.float64)
        if not np.all(np.isfinite(m)):
            raise self.error(f"parameter '{name}': non-finite matrix entries", prop.place)
        if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
            raise self.error(f"parameter '{name}': projective transforms are not supported "
                             f"(last row {m[3].tolist()})", prop.place)
        # Singular relative to its own scale (a scene scaled by 1e-4 has a
        # determinant of ~1e-15 and is fine): the smallest singular value
        # against the largest.
        sv = np.linalg.svd(m[:3, :3], compute_uv=False)
        if not (sv[0] > 0 and sv[-1] > 1e-9 * sv[0]):
            raise self.error(f"parameter '{name}': degenerate (singular) transform", prop.place)
        return m

    def ior(self, name, default_name):
        prop = self._take(name, ("float", "integer", "string"), "a float or an IOR name")
        if prop is None:
            return NAMED_IOR[default_name]
        if prop.kind == "string":
            key = str(prop.value).lower()
            if key not in NAMED_IOR:
                raise self.error(f"parameter '{name}': unknown IOR name '{prop.value}' "
                                 f"(known: {', '.join(NAMED_IOR)})", prop.place)
            return NAMED_IOR[key]
        x = self._finite(name, prop.value, prop.place)
        if not x > 0:
            raise self.error(f"parameter '{name}' must be > 0, got {x}", prop.place)
        return x

    def children(self, category):
        out = []
        for i, (_, child) in enumerate(self.node.children):
            if child.category == category:
                self.used_children.add(i)
                out.append(child)
        return out

    def named_child(self, category, name):
        """The nested plugin of `category` given under `name` (XML: its name
        attribute or the <ref>'s name; dicts: the key), or None."""
        found = None
        for i, (n, child) in enumerate(self.node.children):
            if child.category == category and n == name:
                if found is not None:
                    raise self.error(f"more than one nested {category} named '{name}'", child.place)
                self.used_children.add(i)
                found = child
        return found

    def child(self, category):
        kids = self.children(category)
        if len(kids) > 1:
            raise self.error(f"more than one nested {category}", kids[1].place)
        return kids[0] if kids else None

    def done(self):
        for name, prop in self.node.props.items():
            if name not in self.used:
                raise self.error(f"unknown parameter '{name}'", prop.place)
        for i, (_, child) in enumerate(self.node.children):
            if i not in self.used_children:
                if child.category == "texture":
                    name = self.node.children[i][0]
                    via = f" (the reference to {child.place})" if i in self.node.ref_places else ""
                    raise self.error(f"parameter '{name}' cannot take a texture (got texture '{child.type}'{via}); "
                                     f"textured here: {_TEXTURED_TEXT}",
                                     self.node.ref_places.get(i, child.place))
                if i in self.node.ref_places:  # a ref: name where it stands and what it refers to
                    raise self.error(f"unexpected nested {child.label()} (the reference to {child.place})",
                                     self.node.ref_places[i])
                raise self.error(f"unexpected nested {child.label()}", child.place)
