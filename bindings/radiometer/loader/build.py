"""From _Nodes to the scene description: each plugin built into its
dataclass of scene_desc.py (refs share one object), then the scene
assembled and checked."""
from __future__ import annotations

import math
import os
import re
import warnings

import numpy as np

from ..scene_desc import (
    BsdfDesc,
    DipoleDesc,
    EmitterDesc,
    GridDesc,
    IntegratorDesc,
    MediumDesc,
    SceneDesc,
    SceneError,
    SensorDesc,
    ShapeDesc,
    TextureDesc,
)
from ..samplers import ALIASES as SAMPLER_ALIASES
from ..samplers import SAMPLER_PARAMS
from .images import read_rgb, read_texture
from .meshes import _cube_mesh, _mesh_shape, _read_obj, _read_ply, _read_serialized, _rectangle_mesh
from .nodes import _Node, _Prop, _Ref
from .parameters import INT32_RANGE, _Params, _parse_float
from .spectra import conductor_ior, conductor_materials
from .transforms import FLOAT32_MAX, _frame_along, _onb_first, _translate, _unit
from .volumes import _read_vol

_MAX_RESOLUTION = 16384
# BSDFs that transmit light (a null boundary included).
_TRANSMITTING = ("dielectric", "roughdielectric", "thindielectric", "null", "principledthin", "mask")
# principled and principledthin: their scalar parameters (float or texture,
# read with eval_1) and plain sampling rates, with Mitsuba 3's defaults
# (src/bsdfs/principled.cpp, principledthin.cpp).
_PRINCIPLED_FLOATS = {
    "principled": {"roughness": 0.5, "anisotropic": 0.0, "metallic": 0.0, "spec_trans": 0.0, "spec_tint": 0.0,
                   "sheen": 0.0, "sheen_tint": 0.0, "flatness": 0.0, "clearcoat": 0.0, "clearcoat_gloss": 0.0},
    "principledthin": {"roughness": 0.5, "anisotropic": 0.0, "spec_trans": 0.0, "spec_tint": 0.0, "sheen": 0.0,
                       "sheen_tint": 0.0, "flatness": 0.0, "eta": 1.5, "diff_trans": 0.0},
}
_PRINCIPLED_RATES = {
    "principled": ("main_specular_sampling_rate", "clearcoat_sampling_rate", "diffuse_reflectance_sampling_rate"),
    "principledthin": ("specular_reflectance_sampling_rate", "specular_transmittance_sampling_rate",
                       "diffuse_reflectance_sampling_rate", "diffuse_transmittance_sampling_rate"),
}
_MAX_SPP = 1 << 24  # render()'s limit on spp, which the sampler's sample_count sets


class _Builder:
    def __init__(self, base_dir, confine=False, resolve=None):
        self.base_dir = base_dir
        # Relative file names: through the XML's search list (<path>), else base_dir.
        self.resolve = resolve or (lambda name: os.path.join(base_dir, name))
        # Untrusted scenes (load_file's base_dir_only): referenced files stay
        # inside base_dir, and errors quote nothing read from them.
        self.confine = confine
        self.warnings = []  # SceneWarning messages, given once the scene is assembled
        self.built = {}  # id(node) -> description, so refs share one object
        self.attribute_places = {}  # id(a mesh_attribute TextureDesc) -> the place of its name parameter
        self.in_progress = set()

    def cached(self, node, make):
        key = id(node)
        if key in self.built:
            return self.built[key]
        if key in self.in_progress:
            raise SceneError(f"{node.place}: {node.label()}: reference cycle")
        self.in_progress.add(key)
        desc = make(node)
        self.in_progress.discard(key)
        self.built[key] = desc
        return desc

    def file(self, p, what):
        """The path of the file named by parameter 'filename' of p's node,
        relative to base_dir unless absolute; checked to exist and, for an
        untrusted scene, to lie inside base_dir once '..' and symbolic links
        are resolved (checked before existence, so that the error says nothing
        about files outside). An untrusted scene reads the resolved path, so a
        link changed after the check is not followed."""
        filename = p.string("filename")
        place = p.node.props["filename"].place
        if "\0" in filename:
            raise p.error("parameter 'filename' contains a NUL character", place)
        path = self.resolve(filename)  # an absolute filename stays as it is
        if self.confine:
            root = os.path.realpath(self.base_dir)
            path = os.path.realpath(path)
            if os.path.commonpath([root, path]) != root:
                raise p.error(f"{what} file '{filename}' lies outside the scene's folder {root} (an untrusted "
                              f"scene may only name files inside it)", place)
        if not os.path.isfile(path):
            raise p.error(f"{what} file not found: '{filename}' (looked for {path})", place)
        return path

    # -- textures ------------------------------------------------------------

    def texture(self, node):
        return self.cached(node, self._texture)

    def _texture(self, node):
        """checkerboard, bitmap, rawconstant and mesh_attribute, with Mitsuba
        3's parameters and defaults (src/textures/checkerboard.cpp,
        bitmap.cpp, rawconstant.cpp, mesh_attribute.cpp)."""
        p, t = _Params(node), node.type
        tex = TextureDesc(type=t, id=node.id or node.place)
        if t == "rawconstant":
            # Mitsuba: a float or a 3D vector, taken as it is (no colour conversion).
            prop = node.props.get("value")
            if prop is None:
                raise p.error("missing parameter 'value'")
            if prop.kind in ("float", "integer"):
                tex.value = (p.float("value", check="nonneg"),)
            else:
                v = p.vec3("value", what="a float or a 3D vector")
                tex.value = tuple(float(x) for x in v)
                if min(tex.value) < 0:  # as the bitmaps' values: colours and emission are never negative
                    raise p.error(f"parameter 'value': negative value {min(tex.value)}", prop.place)
            p.done()
            return tex
        if t == "mesh_attribute":
            tex.name = p.string("name")
            if not tex.name.startswith(("vertex_", "face_")):
                raise p.error(f"parameter 'name' must start with \"vertex_\" or \"face_\" (as in Mitsuba), got "
                              f"'{tex.name}'", node.props["name"].place)
            tex.scale = p.float("scale", 1.0)
            self.attribute_places[id(tex)] = node.props["name"].place
            p.done()
            return tex
        m = p.transform("to_uv")
        if m is not None:
            # Mitsuba 3.9.1 takes the 3x3 uv map from a 4x4 transform as its
            # rows and columns 0, 1 and 3 (x, y and the translation; z terms
            # dropped), so that <translate>, <scale> and <rotate> about z act
            # on uv (checked against mitsuba.load_dict in tests/test_textures.py).
            tex.to_uv = m[np.ix_([0, 1, 3], [0, 1, 3])]
        if t == "checkerboard":
            for name, default in (("color0", 0.4), ("color1", 0.2)):
                if p.named_child("texture", name) is not None:
                    raise p.error(f"parameter '{name}': a nested texture is not supported here (give a colour)",
                                  node.place)
                setattr(tex, name, p.rgb(name, default))
        elif t == "bitmap":
            path = self.file(p, "texture image")
            raw = p.bool("raw", False)
            tex.data = read_texture(path, f"{node.place}: {node.label()}: '{p.string('filename')}'", raw,
                                    quote=not self.confine)
            tex.filter_type = p.string("filter_type", "bilinear", ("bilinear", "nearest"))
            tex.wrap_mode = p.string("wrap_mode", "repeat", ("repeat", "mirror", "clamp"))
            p.string("format", "auto", ("auto", "variant", "fp16"))  # storage precision; see read_texture
            p.bool("accel", True)  # CUDA hardware interpolation in Mitsuba; no effect on the CPU
        p.done()
        return tex

    def colour(self, p, b, name, default):
        """A colour parameter that takes a texture (parameters.TEXTURED): a
        nested or referenced texture of that name goes into b.textures and
        the plain field gets the texture's mean colour; otherwise p.rgb."""
        node = p.named_child("texture", name)
        if node is None:
            return p.rgb(name, default)
        if p.has(name):
            raise p.error(f"parameter '{name}' given both as a value and as a texture", node.place)
        tex = self.texture(node)
        b.textures[name] = tex
        return tex.mean_rgb()

    def scalar(self, p, b, name, default, lo=None, hi=None):
        """A scalar parameter that takes a texture (read with eval_1): a
        nested or referenced texture of that name goes into b.textures and
        the value is the texture's mean; otherwise p.float, within [lo, hi]
        when given (a texture's range is the renderer's to check)."""
        node = p.named_child("texture", name)
        prop = p.node.props.get(name)
        if node is None and prop is not None and prop.kind in ("rgb", "spectrum"):
            # Mitsuba 3 reads such a parameter with eval_1, which of a colour
            # in its RGB variants is the mean of the channels (measured with
            # blendbsdf in scalar_rgb: weight rgb (0.2, 0.5, 0.9) blends as
            # 0.5333); the colour must be a reflectance, as Mitsuba's srgb
            # texture requires.
            c = p.rgb(name, default)
            if not all(0.0 <= v <= 1.0 for v in c):
                raise p.error(f"parameter '{name}': a colour here is a reflectance, its values must lie in "
                              f"[0, 1], got {c}", prop.place)
            x = float(np.mean(c))
            if (lo is not None and not x >= lo) or (hi is not None and not x <= hi):
                raise p.error(f"parameter '{name}' must lie in [{lo}, {hi}], got {x} (the colour's mean)",
                              prop.place)
            return x
        if node is None:
            x = p.float(name, default)
            if p.has(name) and ((lo is not None and not x >= lo) or (hi is not None and not x <= hi)):
                raise p.error(f"parameter '{name}' must lie in [{lo}, {hi}], got {x}", p.node.props[name].place)
            return x
        if p.has(name):
            raise p.error(f"parameter '{name}' given both as a value and as a texture", node.place)
        tex = self.texture(node)
        b.textures[name] = tex
        return float(np.mean(tex.mean_rgb()))

    def _principled(self, p, b, t):
        """principled and principledthin (Mitsuba 3's names and defaults; the
        model and its value ranges: renderer/scene/bsdf_principled.cpp)."""
        b.base_color = self.colour(p, b, "base_color", 0.5)
        for name, default in _PRINCIPLED_FLOATS[t].items():
            # Mitsuba's documented ranges: [0, 1]; diff_trans [0, 2]; eta > 0.
            hi = {"diff_trans": 2.0, "eta": FLOAT32_MAX}.get(name, 1.0)
            b.floats[name] = self.scalar(p, b, name, default, 0.0, hi)
        if t == "principledthin" and not b.floats["eta"] > 0:
            raise p.error("parameter 'eta' must be > 0", p.node.props["eta"].place)
        for name in _PRINCIPLED_RATES[t]:
            b.floats[name] = p.float(name, 1.0, check="nonneg")
        if t == "principledthin":
            return
        # Mitsuba's get_flag: a lobe exists when its parameter is a texture or non-zero.
        transmits = "spec_trans" in b.textures or b.floats["spec_trans"] != 0.0
        f32 = np.float32
        if p.has("eta") and p.has("specular"):
            raise p.error("give either 'eta' or 'specular', not both (as Mitsuba)", p.node.props["specular"].place)
        if p.has("eta"):
            eta = f32(p.float("eta", check="positive"))
            if transmits and eta == 1:  # as Mitsuba: eta 1 would make the transmission a delta
                eta = f32(1.001)
        else:
            specular = p.float("specular", 0.5)
            if not 0.0 <= specular <= 1.0:
                raise p.error(f"parameter 'specular' must lie in [0, 1], got {specular}",
                              p.node.props["specular"].place)
            specular = f32(specular)
            if transmits and specular == 0:  # as Mitsuba, for the same reason
                specular = f32(1e-3)
            # Burley 2015, sec. 5.1 (F0 = 0.08 specular), inverted for eta,
            # in float32 as Mitsuba computes it.
            eta = f32(2) / (f32(1) - np.sqrt(f32(0.08) * specular)) - f32(1)
        b.floats["eta"] = float(eta)

    # -- BSDFs ---------------------------------------------------------------

    def bsdf(self, node):
        return self.cached(node, self._bsdf)

    def _bsdf(self, node):
        p, t = _Params(node), node.type
        b = BsdfDesc(type=t, id=node.place)
        if t == "diffuse":
            b.reflectance = self.colour(p, b, "reflectance", 0.5)
        elif t in ("conductor", "roughconductor"):
            material = p.string("material", "none") if p.has("material") else None
            if material is not None and (p.has("eta") or p.has("k")):
                raise p.error("give either (eta, k) or material, not both")
            if material is not None and material != "none":
                try:
                    b.eta, b.k = conductor_ior(material)
                except KeyError:
                    raise p.error(f"parameter 'material': unknown conductor material '{material}' (known, as "
                                  f"in Mitsuba's data/ior: none, {', '.join(conductor_materials())})",
                                  node.props["material"].place) from None
            else:  # Mitsuba's material 'none': eta 0, k 1, a perfect mirror
                b.eta = p.rgb("eta", 0.0, spectrum="unbounded")
                b.k = p.rgb("k", 1.0, spectrum="unbounded")
            b.specular_reflectance = self.colour(p, b, "specular_reflectance", 1.0)
        elif t in ("dielectric", "roughdielectric", "thindielectric"):
            b.int_ior = p.ior("int_ior", "bk7")
            b.ext_ior = p.ior("ext_ior", "air")
            b.specular_reflectance = p.rgb("specular_reflectance", 1.0)
            b.specular_transmittance = p.rgb("specular_transmittance", 1.0)
        elif t in ("plastic", "roughplastic"):
            b.diffuse_reflectance = self.colour(p, b, "diffuse_reflectance", 0.5)
            b.specular_reflectance = p.rgb("specular_reflectance", 1.0)
            b.int_ior = p.ior("int_ior", "polypropylene")
            b.ext_ior = p.ior("ext_ior", "air")
            b.nonlinear = p.bool("nonlinear", False)
        elif t == "twosided":
            kids = p.children("bsdf")
            if not 1 <= len(kids) <= 2:
                raise p.error(f"needs one or two nested bsdfs, got {len(kids)}")
            for k in kids:
                if k.type == "twosided":
                    raise p.error("a twosided bsdf cannot nest another twosided", k.place)
                if k.type in ("normalmap", "bumpmap"):  # it would perturb the frame before twosided mirrors wi
                    raise p.error(f"a twosided bsdf cannot nest a '{k.type}' (put the {k.type} around the "
                                  f"twosided instead)", k.place)
                if k.type in _TRANSMITTING:  # as Mitsuba: a two-sided surface has no inside to transmit to
                    raise p.error(f"a twosided bsdf nests only reflective bsdfs, got '{k.type}', which "
                                  f"transmits light", k.place)
            b.nested = [self.bsdf(k) for k in kids]
        elif t in ("principled", "principledthin"):
            self._principled(p, b, t)
        elif t == "blendbsdf":
            # Mitsuba 3.9.1: `weight` has no default; the nested BSDFs count
            # in the order given (measured with mitsuba.load_dict / load_string).
            if not p.has("weight") and p.named_child("texture", "weight") is None:
                raise p.error("missing parameter 'weight' (a float or a texture, as Mitsuba 3 requires)")
            b.floats["weight"] = self.scalar(p, b, "weight", None)
            kids = p.children("bsdf")
            if len(kids) != 2:
                raise p.error(f"needs two nested bsdfs, got {len(kids)}")
            b.nested = [self.bsdf(k) for k in kids]
        elif t in ("mask", "normalmap", "bumpmap"):
            self._bsdf_adapter(p, b, node)
        if t in ("roughconductor", "roughdielectric", "roughplastic"):
            b.distribution = p.string("distribution", "beckmann", ("beckmann", "ggx"))
            # roughconductor's alphas may be textures (read as one number, Texture::eval_1).
            textured = {n: p.named_child("texture", n) if t == "roughconductor" else None
                        for n in ("alpha", "alpha_u", "alpha_v")}

            def given(n):
                return p.has(n) or textured[n] is not None

            def alpha(n, default=None):
                if textured[n] is None:
                    return p.float(n, default, check="positive")
                if p.has(n):
                    raise p.error(f"parameter '{n}' given both as a value and as a texture", textured[n].place)
                tex = self.texture(textured[n])
                for name in (("alpha_u", "alpha_v") if n == "alpha" else (n,)):
                    b.textures[name] = tex
                return float(np.mean(tex.mean_rgb()))

            if given("alpha") and (given("alpha_u") or given("alpha_v")):
                raise p.error("give either alpha or alpha_u/alpha_v")
            if given("alpha_u") != given("alpha_v"):
                raise p.error("give both alpha_u and alpha_v")
            if given("alpha_u"):
                b.alpha_u = alpha("alpha_u")
                b.alpha_v = alpha("alpha_v")
                if t == "roughplastic" and b.alpha_u != b.alpha_v:  # as Mitsuba
                    raise p.error("parameters 'alpha_u' and 'alpha_v' differ: roughplastic supports only "
                                  "isotropic roughness", node.props["alpha_v"].place)
            else:
                b.alpha_u = b.alpha_v = alpha("alpha", 0.1)
            b.sample_visible = p.bool("sample_visible", True)
        if t == "roughplastic" and b.int_ior == b.ext_ior:  # as Mitsuba
            raise p.error("parameters 'int_ior' and 'ext_ior' must differ")
        p.done()
        return b

    def _bsdf_adapter(self, p, b, node):
        """mask, normalmap and bumpmap (Mitsuba 3 src/bsdfs/mask.cpp,
        normalmap.cpp, bumpmap.cpp): one nested bsdf, and the opacity (float
        or texture, default 0.5), the `normalmap` texture, or the height
        texture (any name) and its `scale` (default 1); the maps take
        flip_invalid_normals and use_shadowing_function (default true)."""
        t = node.type
        kids = p.children("bsdf")
        if len(kids) != 1:
            raise p.error(f"needs exactly one nested bsdf, got {len(kids)}")
        if t != "mask" and kids[0].type in ("normalmap", "bumpmap"):
            raise p.error(f"a {t} cannot nest another normalmap or bumpmap (one map per surface)", kids[0].place)
        b.nested = [self.bsdf(kids[0])]
        if t != "mask":  # Mitsuba 3.7.1 on: the fold and the terminator shadowing, both on by default
            b.flip_invalid_normals = p.bool("flip_invalid_normals", True)
            b.use_shadowing_function = p.bool("use_shadowing_function", True)
        if t == "mask":
            tex = p.named_child("texture", "opacity")
            if tex is None:
                b.opacity = p.float("opacity", 0.5)
            elif p.has("opacity"):
                raise p.error("parameter 'opacity' given both as a value and as a texture", tex.place)
            else:
                b.textures["opacity"] = self.texture(tex)
        elif t == "normalmap":
            tex = p.named_child("texture", "normalmap")
            if p.has("normalmap"):
                raise p.error("parameter 'normalmap' must be a texture of tangent-space normals (a bitmap, "
                              "usually with raw = true), not a value", node.props["normalmap"].place)
            if tex is None:
                raise p.error("parameter 'normalmap' is missing: a texture of tangent-space normals")
            b.textures["normalmap"] = self.texture(tex)
        else:
            named = [(n, c) for n, c in node.children if c.category == "texture"]
            p.children("texture")  # any name, as Mitsuba's bumpmap
            if len(named) != 1:
                raise p.error(f"needs exactly one nested texture (the height field), got {len(named)}")
            b.textures[named[0][0] or "bumpmap"] = self.texture(named[0][1])
            b.scale = p.float("scale", 1.0)

    # -- media ---------------------------------------------------------------

    def medium(self, node):
        return self.cached(node, self._medium)

    @np.errstate(over="ignore")  # overflowing coefficients are refused below, by name
    def _medium(self, node):
        p, t = _Params(node), node.type
        m = MediumDesc(type=t, id=node.id or node.place)
        box = np.eye(4)  # where a constant sigma_t of a heterogeneous medium is (below)
        if t == "heterogeneous":
            # sigma_t and albedo: a nested volume (gridvolume, constvolume)
            # named so, or a plain value as for `homogeneous`.
            for name in ("sigma_t", "albedo"):
                vol = p.named_child("volume", name)
                if vol is None:
                    continue
                if p.has(name):
                    raise p.error(f"'{name}' given both as a value and as a nested volume", vol.place)
                value = self.volume(vol)
                if isinstance(value, GridDesc):
                    setattr(m, name + "_grid", value)
                else:  # constvolume: its value stands in for the parameter
                    const, to_world = value
                    node.props[name] = _Prop("rgb", np.array(const), vol.place)
                    if name == "sigma_t":
                        box = to_world
        given_3 = p.has("sigma_t") or p.has("albedo")
        given_06 = p.has("sigma_a") or p.has("sigma_s")
        if given_3 and given_06:
            raise p.error("give either sigma_t + albedo or sigma_a + sigma_s, not both")
        scale = p.float("scale", 1.0, check="nonneg")
        if given_06:
            # not Mitsuba 3 parameters (its homogeneous takes sigma_t + albedo): spectra unclamped
            sa = np.array(p.rgb("sigma_a", 0.0, spectrum="unbounded"))
            ss = np.array(p.rgb("sigma_s", 0.0, spectrum="unbounded"))
            st = sa + ss
            albedo = np.divide(ss, st, out=np.zeros(3), where=st > 0)
        else:
            # As Mitsuba 3.9.1: a sampled spectrum given here as sigma_t is clamped to [0, 1] (as
            # a reflectance), unlike one given as a nested constvolume's value.
            st = np.array(p.rgb("sigma_t", 1.0))
            albedo = np.array(p.rgb("albedo", 0.75))
            if np.any(albedo > 1.0):
                raise p.error(f"albedo must lie in [0, 1], got {tuple(albedo.tolist())}",
                              node.props["albedo"].place)
        m.sigma_t = tuple(float(x) for x in st * scale)
        m.albedo = tuple(float(x) for x in albedo)
        m.scale = scale
        if t == "heterogeneous" and m.sigma_t_grid is None:
            # Mitsuba 3's heterogeneous medium exists only inside its sigma_t
            # volume's box (Medium::intersect_aabb, vacuum elsewhere); a
            # constant sigma_t is a constvolume (a plain value becomes one),
            # whose box is its to_world's unit cube (Volume::update_bbox):
            # a one-voxel grid over that cube has that extent and value.
            m.sigma_t_grid = GridDesc(data=np.array(st, np.float32).reshape(1, 1, 1, 3), to_world=box, accel=False)
        if t == "heterogeneous":
            p.bool("has_spectral_extinction", True)  # an optimisation hint in Mitsuba; no effect here
        if not all(abs(x) <= FLOAT32_MAX for x in m.sigma_t):
            raise p.error(f"sigma_t * scale {m.sigma_t} is beyond the float32 range")
        if not p.bool("sample_emitters", True):
            raise p.error("sample_emitters = false is not supported (next event estimation is always on)",
                          node.props["sample_emitters"].place)
        ph = p.child("phase")
        if ph is not None:
            pp = _Params(ph)
            m.phase = ph.type
            if ph.type == "hg":
                m.g = pp.float("g", 0.8)
                if not -1.0 < m.g < 1.0:
                    raise pp.error(f"parameter 'g' must lie in (-1, 1), got {m.g}", ph.props["g"].place)
            pp.done()
        p.done()
        return m

    def volume(self, node):
        return self.cached(node, self._volume)

    def _volume(self, node):
        """gridvolume -> GridDesc; constvolume -> (its value (3 floats), its to_world)."""
        p, t = _Params(node), node.type
        if t == "constvolume":
            v = p.rgb("value", 1.0, spectrum="unbounded")
            # The value is the same everywhere; to_world places the volume's
            # box (the unit cube), which bounds a heterogeneous medium (_medium).
            m = p.transform("to_world")
            p.done()
            return v, np.eye(4) if m is None else m
        path = self.file(p, "volume")
        data, bbox = _read_vol(path, f"{node.place}: {node.label()}", quote=not self.confine)
        m = p.transform("to_world")
        m = np.eye(4) if m is None else m
        if p.bool("use_grid_bbox", False):
            lo, hi = bbox
            if not np.all(hi > lo):
                raise p.error(f"use_grid_bbox: the file's bounding box {lo.tolist()} .. {hi.tolist()} is empty")
            with np.errstate(over="ignore", invalid="ignore"):
                m = m @ _translate(lo) @ np.diag([*(hi - lo), 1.0])
            if not np.all(np.isfinite(m)):
                raise p.error("use_grid_bbox: the file's bounding box times to_world overflows")
        p.string("filter_type", "trilinear", ("trilinear",))
        p.string("wrap_mode", "clamp", ("clamp",))
        p.bool("raw", False)  # linear RGB values either way (no spectral upsampling here)
        # Mitsuba's majorant grid: true, a coarse grid of local majorants
        # for delta / ratio tracking through a sigma_t grid (Medium in
        # renderer/scene/medium.h); false, one global majorant per channel.
        accel = p.bool("accel", True)
        p.done()
        return GridDesc(data=data, to_world=m, accel=bool(accel))

    def _media_of(self, p):
        """(interior, exterior) MediumDescs nested in or referenced by a shape."""
        out = []
        for name in ("interior", "exterior"):
            node = p.named_child("medium", name)
            out.append(None if node is None else self.medium(node))
        return tuple(out)

    # -- emitters ------------------------------------------------------------

    def emitter(self, node):
        return self.cached(node, self._emitter)

    def _emitter(self, node):
        p, t = _Params(node), node.type
        if p.has("scale") and t not in ("envmap", "projector"):
            raise p.error("Mitsuba 3 emitters take no 'scale' parameter; multiply the "
                          "radiance/intensity/irradiance instead",
                          node.props["scale"].place)
        e = EmitterDesc(type=t, id=node.place)
        if t == "area" and p.named_child("texture", "radiance") is not None:
            # A textured radiance (Mitsuba 3's area emitter), read at the uv of the point.
            node_tex = p.named_child("texture", "radiance")
            if p.has("radiance"):
                raise p.error("parameter 'radiance' given both as a value and as a texture", node_tex.place)
            e.textures["radiance"] = self.texture(node_tex)
        elif t in ("area", "constant"):
            e.radiance = p.rgb("radiance", 1.0, spectrum="emission")
        elif t == "point":
            pos = p.vec3("position")
            m = p.transform("to_world")
            if pos is not None and m is not None:
                raise p.error("give either position or to_world, not both")
            e.intensity = p.rgb("intensity", 1.0, spectrum="emission")
            e.to_world = _translate(pos) if pos is not None else (np.eye(4) if m is None else m)
        elif t == "spot":
            e.intensity = p.rgb("intensity", 1.0, spectrum="emission")
            e.cutoff_angle = p.float("cutoff_angle", 20.0, check="positive")
            if e.cutoff_angle > 180.0:
                raise p.error(f"cutoff_angle {e.cutoff_angle} exceeds 180 degrees")
            # Mitsuba keeps a beam_width beyond the cutoff: the falloff is then a hard edge.
            e.beam_width = p.float("beam_width", 0.75 * e.cutoff_angle, check="positive")
            # Mitsuba 3's spot: an optional texture projected along the beam.
            tex = p.named_child("texture", "texture")
            if tex is not None:
                e.textures["texture"] = self.texture(tex)
            m = p.transform("to_world")
            e.to_world = np.eye(4) if m is None else m
        elif t == "projector":
            # Mitsuba 3's projector (src/emitters/projector.cpp): the image's
            # aspect ratio is the texture's resolution (1 x 1 for a colour).
            node_tex = p.named_child("texture", "irradiance")
            if node_tex is not None:
                if p.has("irradiance"):
                    raise p.error("parameter 'irradiance' given both as a value and as a texture", node_tex.place)
                tex = self.texture(node_tex)
                e.textures["irradiance"] = tex
                if tex.type == "mesh_attribute":
                    raise p.error("parameter 'irradiance': a mesh_attribute texture has no value on a projector's "
                                  "image (it reads a mesh's vertices or faces)", node_tex.place)
                if tex.data is not None:
                    e.aspect = tex.data.shape[1] / tex.data.shape[0]
            else:
                # props.texture, not texture_d65: a uniform spectrum stays grey.
                e.irradiance = p.rgb("irradiance", 1.0, spectrum="unbounded")
            e.scale = p.float("scale", 1.0, check="nonneg")
            e.fov_x = self._fov_x(p, e.aspect)
            m = p.transform("to_world")
            _check_rigid(p, m, "the projector's")
            e.to_world = np.eye(4) if m is None else m
        elif t == "directional":
            d = p.vec3("direction", what="a vector")
            m = p.transform("to_world")
            if d is not None and m is not None:
                raise p.error("give either direction or to_world, not both")
            e.irradiance = p.rgb("irradiance", 1.0, spectrum="emission")
            if d is None:
                d = np.array([0.0, 0.0, 1.0]) if m is None else m[:3, 2]
            d = _unit(d)
            if d is None:
                raise p.error("the direction has zero length")
            e.to_world = _frame_along(d)
        elif t == "envmap":
            path = self.file(p, "environment map")
            img = read_rgb(path, f"{node.place}: {node.label()}: '{p.string('filename')}'", quote=not self.confine)
            if img.shape[0] < 3 or img.shape[1] < 2:
                raise p.error(f"the environment map must be at least 2x3 pixels (Mitsuba's minimum), got "
                              f"{img.shape[1]}x{img.shape[0]}")
            scale = p.float("scale", 1.0, check="nonneg")
            with np.errstate(over="ignore"):
                e.env = np.ascontiguousarray(img * np.float32(scale), dtype=np.float32)
            if not np.all(np.isfinite(e.env)):
                raise p.error(f"the image times scale {scale} overflows float32", node.props["scale"].place)
            m = p.transform("to_world")
            e.to_world = np.eye(4) if m is None else m
            if p.bool("mis_compensation", False):
                raise p.error("mis_compensation = true is not supported", node.props["mis_compensation"].place)
        p.done()
        return e

    # -- shapes --------------------------------------------------------------

    def shape(self, node):
        return self.cached(node, self._shape)

    def _shape(self, node):
        p, t = _Params(node), node.type
        if t == "shapegroup":
            return self._shapegroup(p)
        if t == "instance":
            return self._instance(p)
        m = p.transform("to_world")
        m = np.eye(4) if m is None else m
        s = ShapeDesc(id=node.place, flip_normals=p.bool("flip_normals", False))
        where = f"{node.place}: {node.label()}"
        if t in ("obj", "ply"):
            path = self.file(p, "mesh")
            face_normals = p.bool("face_normals", False)
            flip_tex = p.bool("flip_tex_coords", True) if t == "obj" else False
            quote = not self.confine
            if t == "obj":
                pos, f, n, uv = _read_obj(path, flip_tex, where, quote)
            else:
                pos, f, n, uv, s.attributes = _read_ply(path, where, quote)
            _mesh_shape(s, m, pos, f, n, uv, face_normals, where)
        elif t == "serialized":
            path = self.file(p, "mesh")
            index = p.int("shape_index", 0, lo=0)
            face_normals = p.bool("face_normals", False)
            pos, f, n, uv = _read_serialized(path, index, where, not self.confine)
            _mesh_shape(s, m, pos, f, n, uv, face_normals, where)
        elif t == "cylinder":
            self._cylinder(p, s, m)
        elif t == "rectangle":
            p.bool("face_normals", False)  # Mitsuba accepts it; a plane has no other normal
            pos, f, uv = _rectangle_mesh()
            _mesh_shape(s, m, pos, f, None, uv, True, where)
        elif t == "cube":
            face_normals = p.bool("face_normals", False)
            pos, f, n, uv = _cube_mesh()
            _mesh_shape(s, m, pos, f, n, uv, face_normals, where)
        elif t == "disk":
            s.type, s.to_world = "disk", m
        elif t == "sphere":
            self._sphere(p, s, m)
        bsdf = p.child("bsdf")
        s.bsdf = None if bsdf is None else self.bsdf(bsdf)
        em = p.child("emitter")
        if em is not None:
            if em.type != "area":
                raise p.error(f"only an area emitter can be nested in a shape, got "
                              f"'{em.type}'", em.place)
            s.emitter = self.emitter(em)
        sensor = p.child("sensor")
        if sensor is not None:
            if sensor.type != "irradiancemeter":
                raise p.error(f"only an irradiancemeter can be nested in a shape, got "
                              f"'{sensor.type}'", sensor.place)
            s.sensor = self.sensor(sensor, on_shape=True)
        s.interior, s.exterior = self._media_of(p)
        sub = p.child("subsurface")
        if sub is not None:
            s.subsurface = self.subsurface(sub)
            d = s.subsurface
            if s.interior is not None:
                raise p.error("a shape with a dipole subsurface cannot also have an interior medium "
                              "(the dipole models the inside; use a dielectric + interior medium for "
                              "random-walk subsurface instead)", sub.place)
            if s.bsdf is None:
                s.bsdf = BsdfDesc(type="dielectric", id=f"{sub.place}: dipole boundary",
                                  int_ior=d.int_ior, ext_ior=d.ext_ior)
            elif s.bsdf.type not in ("dielectric", "plastic") or (
                    s.bsdf.type == "plastic" and any(x != 0 for x in s.bsdf.diffuse_reflectance)):
                raise p.error(f"a shape with a dipole subsurface takes no bsdf, a smooth 'dielectric' or a "
                              f"'plastic' with diffuse_reflectance 0 (its boundary), got '{s.bsdf.type}'"
                              + (" with a diffuse part" if s.bsdf.type == "plastic" else ""), bsdf.place)
            elif (abs(s.bsdf.int_ior - d.int_ior) > 1e-6 * d.int_ior
                  or abs(s.bsdf.ext_ior - d.ext_ior) > 1e-6 * d.ext_ior):
                raise p.error(f"the {s.bsdf.type}'s IORs ({s.bsdf.int_ior}, {s.bsdf.ext_ior}) differ from "
                              f"the dipole's ({d.int_ior}, {d.ext_ior})", bsdf.place)
            if s.bsdf.type == "plastic":  # the same boundary, as the renderer's dielectric
                s.bsdf = BsdfDesc(type="dielectric", id=s.bsdf.id, int_ior=d.int_ior, ext_ior=d.ext_ior)
        self._check_attributes(s, node)
        p.done()
        return s

    def _check_attributes(self, s, node):
        """Every mesh_attribute texture on the shape's BSDF or emitter names
        an attribute the shape has (Mitsuba fails at render time; here the
        load fails, at the texture's 'name')."""
        def textures(b):
            yield from b.textures.values()
            for n in b.nested:
                yield from textures(n)

        used = list(textures(s.bsdf)) if s.bsdf is not None else []
        used += list(s.emitter.textures.values()) if s.emitter is not None else []
        for tex in used:
            if tex.type == "mesh_attribute" and tex.name not in s.attributes:
                have = ", ".join(sorted(s.attributes)) or "none"
                raise SceneError(f"{self.attribute_places[id(tex)]}: texture 'mesh_attribute': parameter 'name': "
                                 f"the {node.label()} at {node.place} has no attribute '{tex.name}' (its "
                                 f"attributes: {have}; only PLY meshes carry them)")

    # -- subsurface ----------------------------------------------------------

    def subsurface(self, node):
        return self.cached(node, self._subsurface)

    @np.errstate(over="ignore")  # overflowing coefficients are refused below, by name
    def _subsurface(self, node):
        p = _Params(node)
        if p.has("material"):
            raise p.error("material presets are not supported: give sigma_a + sigma_s (or sigma_t + albedo)",
                          node.props["material"].place)
        # Mitsuba 0.6's irradiance-cache density: it sets nothing here, and
        # an unused parameter is an error (DESIGN sec. 3), so it says why.
        for irr in ("irrSamples", "irr_samples"):  # the latter: a version 0.x file after Mitsuba's upgrade
            if p.has(irr):
                raise p.error(f"{irr} (Mitsuba 0.6's irradiance-cache density) does not apply: exit points "
                              f"are sampled per path here; remove it", node.props[irr].place)

        def name_of(name, alias):
            """The parameter given under its name or Mitsuba 0.6's alias."""
            if p.has(name) and p.has(alias):
                raise p.error(f"'{name}' given twice (also as '{alias}')", node.props[alias].place)
            return alias if p.has(alias) else name

        a_, s_, t_ = name_of("sigma_a", "sigmaA"), name_of("sigma_s", "sigmaS"), name_of("sigma_t", "sigmaT")
        i_, e_ = name_of("int_ior", "intIOR"), name_of("ext_ior", "extIOR")
        given_ts = p.has(t_) or p.has("albedo")
        given_as = p.has(a_) or p.has(s_)
        if given_ts and given_as:
            raise p.error("give either sigma_a + sigma_s or sigma_t + albedo, not both")
        if not given_ts and not given_as:
            raise p.error("needs sigma_a + sigma_s (or sigma_t + albedo)")
        scale = p.float("scale", 1.0, check="positive")
        if given_as:
            sa = np.array(p.rgb(a_, 0.0, spectrum="unbounded"))
            ss = np.array(p.rgb(s_, 0.0, spectrum="unbounded"))
        else:
            st = np.array(p.rgb(t_, 1.0, spectrum="unbounded"))
            albedo = np.array(p.rgb("albedo", 0.75))
            if np.any(albedo > 1.0):
                raise p.error(f"albedo must lie in [0, 1], got {tuple(albedo.tolist())}",
                              node.props["albedo"].place)
            ss = st * albedo
            sa = st - ss
        g = p.float("g", 0.0)
        if not -1.0 < g < 1.0:
            raise p.error(f"parameter 'g' must lie in (-1, 1), got {g}", node.props["g"].place)
        d = DipoleDesc(id=node.id or node.place, g=g,
                       sigma_a=tuple(float(x) for x in sa * scale),
                       sigma_s=tuple(float(x) for x in ss * scale),
                       int_ior=p.ior(i_, "bk7"), ext_ior=p.ior(e_, "air"))
        if not all(abs(x) <= FLOAT32_MAX for x in d.sigma_a + d.sigma_s):
            raise p.error(f"the coefficients times scale, {d.sigma_a} and {d.sigma_s}, are beyond the float32 range")
        if not any(a + b > 0 for a, b in zip(d.sigma_a, d.sigma_s)):
            raise p.error("sigma_a + sigma_s is 0 in every channel: nothing to scatter")
        p.done()
        return d

    def _shapegroup(self, p):
        """Mitsuba 3's shapegroup (src/shapes/shapegroup.cpp): its shapes, in
        the group's own space, drawn only through instances. Like Mitsuba,
        no emitter, sensor or nested instancing inside."""
        node = p.node
        members = []
        for c in p.children("shape"):
            if c.type in ("shapegroup", "instance"):
                raise p.error(f"a shapegroup cannot hold a {c.type} (nested instancing is not supported, "
                              f"as in Mitsuba 3)", c.place)
            for _, k in c.children:
                if k.category in ("emitter", "sensor", "subsurface"):
                    raise SceneError(f"{k.place}: {k.label()} on shape '{c.type}' inside shapegroup "
                                     f"'{node.id or node.place}': a shape in a shapegroup cannot carry an "
                                     f"{k.category} (Mitsuba 3 refuses emitters and sensors in shapegroups "
                                     f"too); place the shape outside the group")
            members.append(self.shape(c))
        p.done()
        return ShapeDesc(type="shapegroup", id=node.id or node.place, members=members)

    def _instance(self, p):
        """Mitsuba 3's instance (src/shapes/instance.cpp): one shapegroup
        placed by to_world (normals by its inverse transpose)."""
        m = p.transform("to_world")
        groups = p.children("shape")
        if len(groups) != 1 or groups[0].type != "shapegroup":
            raise p.error("needs exactly one nested or referenced shapegroup, got "
                          + (", ".join(f"shape '{g.type}'" for g in groups) or "none"))
        g = self.shape(groups[0])
        p.done()
        return ShapeDesc(type="instance", id=p.node.place, group=g, to_world=np.eye(4) if m is None else m)

    def _cylinder(self, p, s, m):
        """Mitsuba 3's cylinder (src/shapes/cylinder.cpp): to_world *
        translate(p0) * to_frame(Frame(d / |d|)) * scale(radius, radius, |d|)
        with d = p1 - p0, split by polar decomposition into a rigid map and a
        stretch whose diagonal gives the radius (x, y) and the length (z).
        Mitsuba warns on shear or unequal x and y scales and renders
        something else; refused here."""
        radius = p.float("radius", 1.0, check="positive")
        p0 = np.asarray(p.vec3("p0", (0.0, 0.0, 0.0)), np.float64)
        p1 = np.asarray(p.vec3("p1", (0.0, 0.0, 1.0)), np.float64)
        d = _unit(p1 - p0)
        if d is None:
            raise p.error("p0 and p1 coincide: the cylinder has no length")
        frame = np.eye(4)
        # Mitsuba's Frame3f(n): s, t from coordinate_system (Duff et al. 2017), t = n x s.
        frame[:3, 0] = _onb_first(d)
        frame[:3, 1] = np.cross(d, frame[:3, 0])
        frame[:3, 2] = d
        length = float(np.linalg.norm(p1 - p0))
        with np.errstate(over="ignore", invalid="ignore"):
            full = m @ _translate(p0) @ frame @ np.diag([radius, radius, length, 1.0])
        if not np.all(np.abs(full) <= FLOAT32_MAX):
            raise p.error("radius, p0, p1 and to_world place the cylinder beyond the float32 range")
        u, sig, vt = np.linalg.svd(full[:3, :3])
        q = u @ vt
        stretch = vt.T @ np.diag(sig) @ vt
        scale = float(sig.max())
        where = p.node.props["to_world"].place if p.has("to_world") else None
        if np.abs(stretch - np.diag(np.diag(stretch))).max() > 1e-5 * scale:
            raise p.error("cylinder to_world must not shear the cylinder (Mitsuba 3 warns and renders "
                          "something else)", where)
        if abs(stretch[0, 0] - stretch[1, 1]) > 1e-5 * scale:
            raise p.error(f"cylinder to_world must scale its x and y axes alike (got {stretch[0, 0]:.6g} "
                          f"and {stretch[1, 1]:.6g}; Mitsuba 3 warns and renders something else)", where)
        s.type = "cylinder"
        s.radius = float(0.5 * (stretch[0, 0] + stretch[1, 1]))
        s.length = float(stretch[2, 2])
        s.to_world = np.eye(4)
        s.to_world[:3, :3] = q
        s.to_world[:3, 3] = full[:3, 3]

    def _sphere(self, p, s, m):
        """Mitsuba: to_world * translate(center) * scale(radius), split by polar
        decomposition into rotation Q and a stretch that must be uniform."""
        center = p.vec3("center", (0.0, 0.0, 0.0))
        radius = p.float("radius", 1.0, check="positive")
        with np.errstate(over="ignore", invalid="ignore"):
            full = m @ _translate(center) @ np.diag([radius, radius, radius, 1.0])
        if not np.all(np.abs(full) <= FLOAT32_MAX):
            raise p.error("center, radius and to_world place the sphere beyond the float32 range")
        u, sig, vt = np.linalg.svd(full[:3, :3])
        if sig.max() - sig.min() > 1e-4 * sig.max():
            raise p.error(f"sphere to_world must not shear or scale non-uniformly "
                          f"(scales {sig.tolist()})", p.node.props["to_world"].place)
        q = u @ vt
        flip = s.flip_normals
        if np.linalg.det(q) < 0:  # a mirror: Mitsuba's radius turns negative, normals flip
            q, flip = -q, not flip
        r = float(sig.mean())
        s.type, s.flip_normals = "sphere", flip
        s.object_to_world = full
        s.center = tuple(float(c) for c in full[:3, 3])
        s.radius = r
        s.to_world = np.eye(4)
        s.to_world[:3, :3] = r * q
        s.to_world[:3, 3] = full[:3, 3]

    # -- sensors, film, sampler ------------------------------------------------

    def sensor(self, node, on_shape=False):
        if node.type == "irradiancemeter" and not on_shape:
            raise SceneError(f"{node.place}: {node.label()}: must be nested in a shape")
        return self.cached(node, self._sensor)

    def _sensor(self, node):
        p, t = _Params(node), node.type
        s = SensorDesc(type=t)
        self._film(p.child("film"), s)
        med = p.named_child("medium", "medium")
        s.medium = None if med is None else self.medium(med)
        sampler = p.child("sampler")
        s.spp = 4
        if sampler is not None:
            sp = _Params(sampler)
            s.sampler = SAMPLER_ALIASES.get(sampler.type, sampler.type)
            s.spp = sp.int("sample_count", 4, lo=1, hi=_MAX_SPP)
            sp.int("seed", 0)  # accepted; the render call's seed decides
            if "jitter" in SAMPLER_PARAMS[sampler.type]:
                s.jitter = sp.bool("jitter", True)
            sp.done()
        m = p.transform("to_world") if t != "irradiancemeter" else None
        if t in ("perspective", "orthographic"):
            s.near_clip = p.float("near_clip", 1e-2, check="positive")
            s.far_clip = p.float("far_clip", 1e4, check="positive")
            if not s.far_clip > s.near_clip:
                raise p.error(f"far_clip {s.far_clip} must exceed near_clip {s.near_clip}")
            for name in ("shutter_open", "shutter_close"):
                p.float(name)
        if t == "perspective":
            _check_rigid(p, m, "the camera's")
            s.fov_x = self._fov_x(p, s.width / s.height)
            p.float("focus_distance")
            for name in ("principal_point_offset_x", "principal_point_offset_y"):
                if p.float(name, 0.0) != 0.0:
                    raise p.error(f"a non-zero '{name}' is not supported",
                                  node.props[name].place)
        elif t == "radiancemeter":
            o = p.vec3("origin")
            d = p.vec3("direction", what="a vector")
            if (o is not None or d is not None) and m is not None:
                raise p.error("give either origin/direction or to_world, not both")
            if (o is None) != (d is None):
                raise p.error("give both origin and direction")
            if d is not None:
                d = _unit(d)
                if d is None:
                    raise p.error("the direction has zero length")
                m = _translate(o) @ _frame_along(d)
            if (s.width, s.height) != (1, 1):
                raise p.error(f"a radiancemeter needs a 1x1 film, got {s.width}x{s.height}")
        elif t == "irradiancemeter" and (s.width, s.height) != (1, 1):
            # Mitsuba 3.9.1 accepts it and fills each pixel with an independent
            # estimate of the same irradiance; the renderer measures one.
            self.warnings.append(f"{node.place}: {node.label()}: a {s.width}x{s.height} film; the irradiance is "
                                 f"measured as one value, rendered as a 1x1 image")
        s.to_world = np.eye(4) if m is None else m
        p.done()
        return s

    @staticmethod
    def _fov_x(p, aspect):
        """Horizontal fov in degrees from fov + fov_axis or a 35 mm-equivalent
        focal length (pinhole geometry: tan(fov/2) = half extent / distance)."""
        if p.has("fov") and p.has("focal_length"):
            raise p.error("give either fov or focal_length, not both")
        if p.has("fov"):
            fov = p.float("fov")
            if not 0.0 < fov < 180.0:
                raise p.error(f"fov {fov} must lie in (0, 180) degrees",
                              p.node.props["fov"].place)
            axis = p.string("fov_axis", "x").lower()
        else:
            text = p.string("focal_length", "50mm")
            num = text[:-2] if text.endswith("mm") else text
            try:
                f = _parse_float(num)
            except ValueError:
                raise p.error(f"cannot parse focal_length '{text}'",
                              p.node.props["focal_length"].place) from None
            if not (math.isfinite(f) and f > 0):
                raise p.error(f"focal_length must be > 0, got '{text}'",
                              p.node.props["focal_length"].place)
            # 35 mm film: 36 x 24 mm, the focal length fixes the diagonal fov.
            fov = math.degrees(2.0 * math.atan(math.hypot(36.0, 24.0) / (2.0 * f)))
            axis = "diagonal"
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "y" if aspect < 1 else "x"
        half = math.tan(math.radians(fov) / 2.0)
        if axis == "x":
            return fov
        if axis == "y":
            return math.degrees(2.0 * math.atan(half * aspect))
        if axis == "diagonal":
            return math.degrees(2.0 * math.atan(half / math.sqrt(1.0 + 1.0 / aspect**2)))
        raise p.error(f"fov_axis '{axis}' is not one of x, y, diagonal, smaller, larger",
                      p.node.props["fov_axis"].place)

    @staticmethod
    def _film(node, s):
        s.width, s.height = 768, 576
        s.rfilter, s.filter_radius, s.filter_stddev = "gaussian", 2.0, 0.5
        if node is None:
            return
        p = _Params(node)
        s.width = p.int("width", 768, lo=1, hi=_MAX_RESOLUTION)
        s.height = p.int("height", 576, lo=1, hi=_MAX_RESOLUTION)
        p.string("pixel_format", "rgb", ("rgb", "rgba"))
        p.string("component_format", "float16", ("float16", "float32"))
        # The crop window (Mitsuba 3's Film): only its pixels are rendered and
        # returned; the sensor keeps the geometry of the full film.
        s.crop_x = p.int("crop_offset_x", 0, lo=0, hi=s.width - 1)
        s.crop_y = p.int("crop_offset_y", 0, lo=0, hi=s.height - 1)
        s.crop_width = p.int("crop_width", s.width, lo=1, hi=s.width)  # Mitsuba's defaults: the full film
        s.crop_height = p.int("crop_height", s.height, lo=1, hi=s.height)
        for axis, off, size, full in (("x", s.crop_x, s.crop_width, s.width),
                                      ("y", s.crop_y, s.crop_height, s.height)):
            if off + size > full:
                name = "crop_width" if axis == "x" else "crop_height"
                raise p.error(f"the crop window crop_offset_{axis} + {name} = {off} + {size} exceeds the film's "
                              f"{'width' if axis == 'x' else 'height'} {full}",
                              (node.props.get(name) or node.props[f"crop_offset_{axis}"]).place)
        if (s.crop_x, s.crop_y, s.crop_width, s.crop_height) == (0, 0, s.width, s.height):
            s.crop_width = s.crop_height = 0  # the full film, whatever width and height become
        sample_border = p.bool("sample_border", False)
        rf = p.child("rfilter")
        if rf is not None:
            fp = _Params(rf)
            s.rfilter = rf.type
            if rf.type == "box":
                s.filter_radius = 0.5
            elif rf.type == "tent":
                s.filter_radius = fp.float("radius", 1.0, check="positive")
            else:
                s.filter_stddev = fp.float("stddev", 0.5, check="positive")
                s.filter_radius = 4.0 * s.filter_stddev
            fp.done()
        # sample_border: Mitsuba 3 then also draws samples in a border of
        # ceil(radius - 0.5) pixels around the crop window, which is none for
        # the box filter; the other filters' border is not supported (light
        # tracing cannot splat from beyond the film).
        if sample_border and s.rfilter != "box":
            raise p.error(f"sample_border = true with the '{s.rfilter}' filter is not supported (samples beyond "
                          f"the crop window); only with the box filter, where Mitsuba's border is empty",
                          node.props["sample_border"].place)
        p.done()

    # -- integrator ------------------------------------------------------------

    @classmethod
    def integrator(cls, node):
        p = _Params(node)
        if node.type == "moment":
            # Mitsuba's `moment` renders its nested integrator(s) and adds
            # per-pixel moments as extra channels; a render here always
            # returns the variance of its estimate (RenderResult.variance),
            # so `moment` is its one nested integrator.
            if node.props:
                name, prop = next(iter(node.props.items()))
                raise p.error(f"unknown parameter '{name}'", prop.place)
            kids = [c for _, c in node.children]
            if len(kids) != 1 or kids[0].category != "integrator":
                raise p.error(f"needs exactly one nested integrator (more are not supported), got "
                              f"{len(kids)} nested plugin(s)")
            return cls.integrator(kids[0])
        params = {}
        for name, prop in node.props.items():
            if prop.kind not in ("integer", "float", "boolean", "string"):
                raise p.error(f"parameter '{name}' must be an integer, float, boolean or "
                              f"string", prop.place)
            if prop.kind == "float" and not math.isfinite(prop.value):
                raise p.error(f"parameter '{name}': non-finite value {prop.value}", prop.place)
            lo, hi = INT32_RANGE
            if prop.kind == "integer" and not lo <= prop.value <= hi:
                raise p.error(f"parameter '{name}' = {prop.value} is outside the range of a 32-bit integer "
                              f"[{lo}, {hi}]", prop.place)
            params[name] = prop.value
        if node.children:
            raise p.error(f"unexpected nested {node.children[0][1].label()}",
                          node.children[0][1].place)
        desc = IntegratorDesc(type=node.type, params=params)
        # The estimator's own parameter check, at load time so that the
        # message carries the file:line (render() checks again, for its
        # `integrator=` argument).
        from ..render import _integrator_desc

        try:
            _integrator_desc(None, desc)
        except SceneError as e:
            # At the parameter's own place when the message names one.
            named = re.search(r"parameter '([^']*)'", str(e))
            prop = node.props.get(named.group(1)) if named else None
            raise SceneError(f"{(prop or node).place}: {e}") from None
        return desc


def _check_rigid(p, m, whose):
    """A perspective camera's or a projector's to_world (None: none) has no
    scale factors (Mitsuba refuses them for the camera; the projector's
    image geometry assumes none either)."""
    if m is not None:
        sv = np.linalg.svd(m[:3, :3], compute_uv=False)
        if np.any(np.abs(sv - 1.0) > 1e-3):
            raise p.error(f"scale factors in {whose} to_world are not allowed (as in Mitsuba)",
                          p.node.props["to_world"].place)


def _resolve_refs(nodes, ids):
    """Replace every _Ref by the node it names (anywhere in the document)."""
    stack = list(nodes)
    seen = set()
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        for i, (name, child) in enumerate(node.children):
            if isinstance(child, _Ref):
                target = ids.get(child.id)
                if target is None:
                    raise SceneError(f"{child.place}: {node.label()}: reference to unknown "
                                     f"id '{child.id}'")
                target.referenced = True
                node.children[i] = (name, target)
                node.ref_places[i] = child.place
            else:
                stack.append(child)


def _assemble(nodes, ids, source, base_dir, confine=False, resolve=None):
    _resolve_refs(nodes, ids)
    b = _Builder(base_dir, confine, resolve)
    scene = SceneDesc(source=source)
    sensors, integrators = [], []
    for node in nodes:
        cat = node.category
        if cat == "shape":
            shape = b.shape(node)
            scene.shapes.append(shape)
            if shape.sensor is not None:
                sensors.append((shape.sensor, node.place))
        elif cat == "emitter":
            if node.type == "area":
                if not node.referenced:
                    raise SceneError(f"{node.place}: {node.label()}: an area emitter must "
                                     f"be nested in a shape")
                b.emitter(node)  # validated here, attached where referenced
            else:
                scene.emitters.append(b.emitter(node))
        elif cat == "sensor":
            sensors.append((b.sensor(node), node.place))
        elif cat == "bsdf":
            b.bsdf(node)  # a declaration for refs; validate it even if unused
        elif cat == "medium":
            b.medium(node)  # a declaration for refs; validate it even if unused
        elif cat == "texture":
            b.texture(node)  # a declaration for refs; validate it even if unused
        elif cat == "integrator":
            integrators.append((b.integrator(node), node.place))
        elif cat == "subsurface":
            if not node.referenced:
                raise SceneError(f"{node.place}: {node.label()}: must be nested in a shape")
            b.subsurface(node)
        else:
            raise SceneError(f"{node.place}: {node.label()}: must be nested in a sensor, "
                             f"not at the top level")
    if len(sensors) > 1:
        raise SceneError(f"{sensors[1][1]}: more than one sensor (first at {sensors[0][1]}); "
                         f"radiometer renders exactly one")
    if sensors:
        scene.sensor = sensors[0][0]
    else:  # Mitsuba's default perspective camera, see the module docstring
        scene.sensor = b.sensor(_Node("sensor", "perspective", f"{source}: default sensor"))
    if len(integrators) > 1:
        raise SceneError(f"{integrators[1][1]}: more than one integrator (first at "
                         f"{integrators[0][1]})")
    if integrators:
        scene.integrator = integrators[0][0]
    for msg in b.warnings + _media_warnings(scene):
        scene.warnings.append(msg)
        warnings.warn(msg, SceneWarning, stacklevel=4)
    return scene


class SceneWarning(UserWarning):
    """A scene that loads and renders as written, but probably not as meant."""


def _bbox(shape):
    if shape.type == "sphere":
        c, r = np.asarray(shape.center, np.float64), float(shape.radius)
        return c - r, c + r
    if shape.positions is not None and len(shape.positions):
        p = np.asarray(shape.positions, np.float64)
        return p.min(axis=0), p.max(axis=0)
    return None  # disks: flat, they enclose nothing


def _media_warnings(scene):
    """Warnings about a shape that declares an interior medium but no exterior
    while it sits in another medium (inside the bounding box of a shape
    whose interior is a medium, or in a camera medium that no shape bounds).
    Such a scene is valid, and rendered as Mitsuba 3 renders it: the medium
    changes only at shapes that declare one, so a path leaving the shape is
    in vacuum, not in the medium around it, while light arriving from that
    medium was attenuated by it. Estimators then disagree only through
    which of the two they trace (measured: bdpt 0.955 of volpath for a
    medium-filled glass ball in fog without an exterior). Usually the
    exterior was forgotten."""
    out = []
    bounded = {id(m) for s in scene.shapes for m in (s.interior, s.exterior) if m is not None}
    cam = scene.sensor.medium
    for s in scene.shapes:
        if s.interior is None or s.exterior is not None:
            continue
        around = None
        if cam is not None and id(cam) not in bounded:
            around = f"the sensor's medium ({cam.id or 'unnamed'}), which no shape bounds"
        else:
            box = _bbox(s)
            for c in scene.shapes:
                cb = None if c is s or c.interior is None or box is None else _bbox(c)
                if cb is not None and np.all(cb[0] <= box[0]) and np.all(box[1] <= cb[1]):
                    around = f"shape {c.id or 'unnamed'}'s interior medium ({c.interior.id or 'unnamed'})"
                    break
        if around is not None:
            msg = (f"{scene.source}: shape {s.id or 'unnamed'} declares an interior medium but no exterior, "
                   f"and it lies in {around}: paths leaving it continue in vacuum (Mitsuba 3's rule: the "
                   f"medium changes only at shapes that declare one); declare <ref name=\"exterior\" "
                   f"id=\"...\"/> on it if it sits in that medium")
            out.append(msg)
    return out
