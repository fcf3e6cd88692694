"""Plain-Python description of a scene, the loader's output.

`load_dict` / `load_file` resolve everything Mitsuba leaves implicit (defaults,
named IORs, `ref`s, transforms, fov_axis) into these dataclasses; `_build.py`
turns them into the C++ scene. Every field mirrors `renderer/scene/desc.h`.
All geometry is in world space; matrices are row-major 4x4 numpy float64.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np


def _rgb(v=0.5):
    return (float(v), float(v), float(v))


def _eye():
    return np.eye(4, dtype=np.float64)


class SceneError(ValueError):
    """A scene (file or dict) uses something outside the supported subset, or a
    bad value. The message names the element and its place (file:line or key
    path)."""


@dataclass
class TextureDesc:
    """A texture (renderer/scene/texture.h): `checkerboard` (color0, color1),
    `bitmap` (data: (rows, columns, 1 or 3) float32, linear, row 0 at
    v = 0), `rawconstant` (value: 1 or 3 floats) or `mesh_attribute` (name
    of a mesh's attribute, scale); to_uv maps uv (3x3, affine)."""
    type: str = "checkerboard"
    id: str = ""  # the place it came from, for error messages
    color0: tuple = field(default_factory=lambda: _rgb(0.4))
    color1: tuple = field(default_factory=lambda: _rgb(0.2))
    to_uv: np.ndarray = field(default_factory=lambda: np.eye(3, dtype=np.float64))
    data: Optional[np.ndarray] = None
    filter_type: str = "bilinear"
    wrap_mode: str = "repeat"
    value: tuple = ()  # rawconstant
    name: str = ""  # mesh_attribute
    scale: float = 1.0  # mesh_attribute

    def mean_rgb(self):
        """The channel-wise mean colour (what a plain value in its place would
        be; a mesh attribute's, which depends on the mesh, is taken as grey 0.5)."""
        if self.type == "rawconstant":
            return tuple(float(x) for x in (self.value if len(self.value) == 3 else self.value * 3))
        if self.type == "mesh_attribute":
            return (0.5 * self.scale,) * 3
        if self.type == "bitmap":
            m = np.asarray(self.data, np.float64).reshape(-1, self.data.shape[-1]).mean(axis=0)
            return tuple(float(x) for x in (m if m.size == 3 else np.repeat(m, 3)))
        return tuple(0.5 * (a + b) for a, b in zip(self.color0, self.color1))


@dataclass
class BsdfDesc:
    type: str = "diffuse"  # diffuse conductor roughconductor dielectric roughdielectric
    #                        thindielectric plastic twosided null principled principledthin blendbsdf
    id: str = ""  # the place it came from, for error messages
    reflectance: tuple = field(default_factory=lambda: _rgb(0.5))
    diffuse_reflectance: tuple = field(default_factory=lambda: _rgb(0.5))
    specular_reflectance: tuple = field(default_factory=lambda: _rgb(1.0))
    specular_transmittance: tuple = field(default_factory=lambda: _rgb(1.0))
    eta: tuple = field(default_factory=lambda: _rgb(0.0))  # conductor, relative to ext_ior
    k: tuple = field(default_factory=lambda: _rgb(1.0))
    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    alpha_u: float = 0.1
    alpha_v: float = 0.1
    distribution: str = "beckmann"
    sample_visible: bool = True
    nonlinear: bool = False
    nested: list = field(default_factory=list)  # twosided: [bsdf] or [front, back]; blendbsdf: 2; mask etc.: 1
    # principled, principledthin: base_color; their scalar parameters and
    # blendbsdf's weight by Mitsuba's names, defaults filled in (a textured
    # one holds its texture's mean and has its texture in `textures`).
    base_color: tuple = field(default_factory=lambda: _rgb(0.5))
    floats: dict = field(default_factory=dict)
    opacity: float = 0.5  # mask, when not textured
    scale: float = 1.0  # bumpmap
    flip_invalid_normals: bool = True  # normalmap, bumpmap
    use_shadowing_function: bool = True  # normalmap, bumpmap
    # Textured colour parameters: name -> TextureDesc, replacing the plain
    # value of that name (reflectance, diffuse_reflectance,
    # specular_reflectance), which then holds the texture's mean colour.
    textures: dict = field(default_factory=dict)


@dataclass
class EmitterDesc:
    type: str = "area"  # area point spot projector directional constant envmap
    id: str = ""
    radiance: tuple = field(default_factory=lambda: _rgb(1.0))  # area, constant (scale applied)
    intensity: tuple = field(default_factory=lambda: _rgb(1.0))  # point, spot (scale applied)
    irradiance: tuple = field(default_factory=lambda: _rgb(1.0))  # directional (scale applied), projector
    to_world: np.ndarray = field(default_factory=_eye)  # point/spot position+frame; directional: +z is the direction
    cutoff_angle: float = 20.0
    beam_width: float = -1.0
    # envmap: (rows, columns, 3) float32 linear RGB radiance, scale applied;
    # to_world above maps its local frame (Mitsuba's latitude-longitude
    # convention, +y up) to the world.
    env: Optional[np.ndarray] = None
    # projector: horizontal field of view in degrees, the image's width /
    # height, the factor on its irradiance.
    fov_x: float = 90.0
    aspect: float = 1.0
    scale: float = 1.0
    # spot: {"texture": TextureDesc}, projected along the beam; projector:
    # {"irradiance": ...}; area: {"radiance": ...} (each replacing the plain value).
    textures: dict = field(default_factory=dict)


@dataclass
class GridDesc:
    """A gridvolume: (nz, ny, nx, channels) float32 values over the unit cube
    of its local space, mapped to the world by to_world."""
    data: np.ndarray = field(default_factory=lambda: np.zeros((1, 1, 1, 1), np.float32))
    to_world: np.ndarray = field(default_factory=_eye)
    accel: bool = True  # a majorant grid for tracking (False: one global majorant)


@dataclass
class MediumDesc:
    type: str = "homogeneous"  # homogeneous heterogeneous
    id: str = ""  # its id, or the place it came from, for error messages
    sigma_t: tuple = field(default_factory=lambda: _rgb(1.0))  # per unit length, scale applied
    albedo: tuple = field(default_factory=lambda: _rgb(0.75))
    sigma_t_grid: Optional[GridDesc] = None  # heterogeneous: replaces sigma_t (scale applied by the renderer)
    albedo_grid: Optional[GridDesc] = None  # heterogeneous: replaces albedo
    scale: float = 1.0
    phase: str = "isotropic"  # isotropic | hg
    g: float = 0.0  # hg


@dataclass
class DipoleDesc:
    """A dipole BSSRDF (Jensen et al. 2001) on a shape: Mitsuba 0.6's
    `dipole` subsurface plugin, resolved (renderer/scene/dipole.h)."""
    id: str = ""  # the place it came from, for error messages
    sigma_a: tuple = field(default_factory=lambda: _rgb(0.0))  # per unit length, scale applied
    sigma_s: tuple = field(default_factory=lambda: _rgb(1.0))  # NOT reduced; scale applied
    g: float = 0.0  # sigma_s' = sigma_s (1 - g)
    int_ior: float = 1.5046
    ext_ior: float = 1.000277


@dataclass
class ShapeDesc:
    type: str = "mesh"  # mesh sphere disk cylinder shapegroup instance (rectangle, cube, obj, ply,
    #                     serialized become meshes)
    id: str = ""
    positions: Optional[np.ndarray] = None  # (N, 3) float32, world space
    indices: Optional[np.ndarray] = None  # (M, 3) uint32
    normals: Optional[np.ndarray] = None  # (N, 3) float32 world space, or None (face normals)
    uvs: Optional[np.ndarray] = None  # (N, 2) float32 or None
    to_world: np.ndarray = field(default_factory=_eye)  # sphere, disk
    # sphere: Mitsuba's own object-to-world map of the unit sphere (a mirror
    # kept, unlike to_world), which fixes its texture coordinates.
    object_to_world: Optional[np.ndarray] = None
    center: tuple = (0.0, 0.0, 0.0)  # sphere, world space
    radius: float = 1.0  # sphere, world space; cylinder
    length: float = 1.0  # cylinder (to_world then holds its rigid placement)
    members: list = field(default_factory=list)  # shapegroup: [ShapeDesc] in the group's space
    group: Optional["ShapeDesc"] = None  # instance: its shapegroup (to_world places it)
    flip_normals: bool = False
    bsdf: Optional[BsdfDesc] = None  # None: diffuse 0.5 (Mitsuba's default)
    emitter: Optional[EmitterDesc] = None  # an area emitter attached to this shape
    sensor: Optional["SensorDesc"] = None  # an irradiancemeter attached to this shape
    interior: Optional[MediumDesc] = None  # medium inside (against the normal)
    exterior: Optional[MediumDesc] = None  # medium outside (the normal's side)
    subsurface: Optional[DipoleDesc] = None  # a dipole BSSRDF; bsdf is then its dielectric boundary
    # PLY attributes (Mitsuba's vertex_* / face_*): name -> (vertices or
    # faces, 1 or 3) float32 array, read by mesh_attribute textures.
    attributes: dict = field(default_factory=dict)


@dataclass
class SensorDesc:
    type: str = "perspective"  # perspective orthographic radiancemeter irradiancemeter
    to_world: np.ndarray = field(default_factory=_eye)
    fov_x: float = 39.3077  # degrees, horizontal (fov_axis already resolved)
    near_clip: float = 1e-2
    far_clip: float = 1e4
    width: int = 256
    height: int = 256
    rfilter: str = "gaussian"  # box tent gaussian
    filter_radius: float = 2.0
    filter_stddev: float = 0.5
    spp: int = 4  # from the sampler's sample_count
    sampler: str = "independent"  # the sampler's type (radiometer.samplers)
    jitter: bool = True  # stratified, multijitter: jitter within strata
    # The film's crop window (Mitsuba's crop_offset_x/y, crop_width/height):
    # the pixels rendered and returned; width/height keep the full film's
    # geometry. crop_width/height 0: the full film.
    crop_x: int = 0
    crop_y: int = 0
    crop_width: int = 0
    crop_height: int = 0
    medium: Optional[MediumDesc] = None  # the medium the sensor sits in


@dataclass
class IntegratorDesc:
    type: str = "path"
    params: dict = field(default_factory=dict)  # validated by the renderer facade


@dataclass
class SceneDesc:
    shapes: list = field(default_factory=list)  # [ShapeDesc]
    emitters: list = field(default_factory=list)  # [EmitterDesc], non-area
    sensor: SensorDesc = field(default_factory=SensorDesc)
    integrator: IntegratorDesc = field(default_factory=IntegratorDesc)
    source: str = "<dict>"  # file path or "<dict>", for messages
    warnings: list = field(default_factory=list)  # [str], also raised as SceneWarning at load
