"""Turns a SceneDesc (the loader's output) into the C++ scene."""
from __future__ import annotations

import numpy as np

from . import _core
from .scene_desc import BsdfDesc, SceneDesc, SceneError


def _bsdf(d: BsdfDesc) -> "_core.BsdfDesc":
    c = _core.BsdfDesc()
    c.type = d.type
    c.id = d.id
    for name in ("reflectance", "diffuse_reflectance", "specular_reflectance", "specular_transmittance", "eta", "k"):
        setattr(c, name, tuple(float(x) for x in getattr(d, name)))
    c.int_ior = float(d.int_ior)
    c.ext_ior = float(d.ext_ior)
    c.alpha_u = float(d.alpha_u)
    c.alpha_v = float(d.alpha_v)
    c.distribution = d.distribution
    c.sample_visible = bool(d.sample_visible)
    c.nonlinear = bool(d.nonlinear)
    c.opacity = float(d.opacity)
    c.scale = float(d.scale)
    c.flip_invalid_normals = bool(d.flip_invalid_normals)
    c.use_shadowing_function = bool(d.use_shadowing_function)
    c.nested = [_bsdf(n) for n in d.nested]
    c.base_color = tuple(float(x) for x in d.base_color)
    c.floats = {name: float(v) for name, v in d.floats.items()}
    c.textures = {name: _texture(t) for name, t in d.textures.items()}
    return c


def _texture(t) -> "_core.TextureDesc":
    c = _core.TextureDesc()
    c.type = t.type
    c.id = t.id
    c.color0 = tuple(float(x) for x in t.color0)
    c.color1 = tuple(float(x) for x in t.color1)
    c.to_uv = [float(x) for x in np.asarray(t.to_uv, np.float64).reshape(9)]
    c.filter_type = t.filter_type
    c.wrap_mode = t.wrap_mode
    c.value = [float(x) for x in t.value]
    c.name = t.name
    c.scale = float(t.scale)
    if t.data is not None:
        c.height, c.width, c.channels = (int(v) for v in t.data.shape)
        c.data = np.ascontiguousarray(t.data, np.float32).reshape(-1, 1)
    return c


def _emitter(e) -> "_core.EmitterDesc":
    c = _core.EmitterDesc()
    c.type = e.type
    c.id = e.id
    c.radiance = tuple(float(x) for x in e.radiance)
    c.intensity = tuple(float(x) for x in e.intensity)
    c.irradiance = tuple(float(x) for x in e.irradiance)
    c.to_world = np.asarray(e.to_world, dtype=np.float64)
    c.cutoff_angle = float(e.cutoff_angle)
    c.beam_width = float(e.beam_width)
    c.fov_x, c.aspect, c.scale = float(e.fov_x), float(e.aspect), float(e.scale)
    c.textures = {name: _texture(t) for name, t in e.textures.items()}
    if e.env is not None:
        c.env_height, c.env_width = int(e.env.shape[0]), int(e.env.shape[1])
        c.env_data = np.ascontiguousarray(e.env, np.float32).reshape(-1, 1)
    return c


def _medium_index(scene, media, m, source):
    """Index of MediumDesc `m` in the C++ scene (added once per object; refs
    share one), -1 for None."""
    if m is None:
        return -1
    if id(m) not in media:
        c = _core.MediumDesc()
        c.type = m.type
        c.id = m.id
        c.sigma_t = tuple(float(x) for x in m.sigma_t)
        c.albedo = tuple(float(x) for x in m.albedo)
        c.phase = m.phase
        c.g = float(m.g)
        c.scale = float(m.scale)
        for name in ("sigma_t_grid", "albedo_grid"):
            g = getattr(m, name)
            if g is not None:
                cg = _core.GridDesc()
                cg.nz, cg.ny, cg.nx, cg.channels = (int(v) for v in g.data.shape)
                cg.data = np.ascontiguousarray(g.data, np.float32).reshape(-1, 1)
                cg.to_world = np.asarray(g.to_world, np.float64)
                cg.accel = bool(g.accel)
                setattr(c, name, cg)
        try:
            media[id(m)] = scene.add_medium(c)
        except ValueError as e:
            raise SceneError(f"{source}: {e}") from None
    return media[id(m)]


def build_scene(desc: SceneDesc) -> "_core.Scene":
    """Builds and commits the C++ scene. C++ errors about a part are re-raised
    as SceneError naming that part."""
    scene = _core.Scene()
    # A shape without a BSDF gets Mitsuba 3's default (its Shape
    # constructor): a diffuse of reflectance 0.5, or 0 (black) when the
    # shape is an emitter. One of each is shared by every such shape.
    default_bsdfs = {}
    sensor_shape = -1
    media = {}
    groups = {}  # id(shapegroup ShapeDesc) -> its index in the C++ scene

    def bsdf_of(s):
        if s.bsdf is None:
            black = s.emitter is not None
            if black not in default_bsdfs:
                d = BsdfDesc(id="default diffuse of an emitter" if black else "default diffuse")
                if black:
                    d.reflectance = (0.0, 0.0, 0.0)
                default_bsdfs[black] = scene.add_bsdf(_bsdf(d))
            return default_bsdfs[black]
        return scene.add_bsdf(_bsdf(s.bsdf))

    def add_geometry(s, where, group=-1):
        """The shape's geometry (in the scene, or in shapegroup `group`): its index there."""
        b = bsdf_of(s)
        flip = bool(s.flip_normals)
        if s.type == "mesh":
            return scene.add_mesh(where, np.asarray(s.positions, np.float32), np.asarray(s.indices, np.uint32),
                                  None if s.normals is None else np.asarray(s.normals, np.float32),
                                  None if s.uvs is None else np.asarray(s.uvs, np.float32), b, flip, group)
        if s.type == "sphere":
            return scene.add_sphere(where, tuple(float(x) for x in s.center), float(s.radius), b, flip,
                                    None if s.object_to_world is None else np.asarray(s.object_to_world, np.float64),
                                    group)
        if s.type == "disk":
            return scene.add_disk(where, np.asarray(s.to_world, np.float64), b, flip, group)
        if s.type == "cylinder":
            return scene.add_cylinder(where, np.asarray(s.to_world, np.float64), float(s.radius), float(s.length), b,
                                      flip, group)
        raise SceneError(f"{desc.source}: {where}: unknown shape type '{s.type}'")

    def media_of(s, idx):
        if s.interior is not None or s.exterior is not None:
            scene.set_shape_media(idx, _medium_index(scene, media, s.interior, desc.source),
                                  _medium_index(scene, media, s.exterior, desc.source))

    def add_attributes(s, idx, group=-1):
        """The mesh attributes (PLY vertex_* / face_*) of ShapeDesc s, shape
        idx (of shapegroup `group` when >= 0: its instances read them)."""
        for name, a in s.attributes.items():
            scene.add_mesh_attribute(idx, name, name.startswith("face_"), int(a.shape[1]),
                                     np.ascontiguousarray(a, np.float32).reshape(-1, 1), group)

    def group_of(g):
        """The C++ shapegroup of ShapeDesc g, made (with its members) on first use."""
        if id(g) not in groups:
            gi = scene.add_shapegroup(g.id)
            for k, m in enumerate(g.members):
                where = m.id or f"{g.id} member #{k}"
                try:
                    mi = add_geometry(m, where, gi)
                    add_attributes(m, mi, gi)
                except (ValueError, RuntimeError) as e:
                    if isinstance(e, SceneError):
                        raise
                    raise SceneError(f"{desc.source}: {where}: {e}") from None
                if m.interior is not None or m.exterior is not None:
                    # Media of a member: kept on the member, which its instances copy.
                    scene.set_member_media(gi, mi, _medium_index(scene, media, m.interior, desc.source),
                                           _medium_index(scene, media, m.exterior, desc.source))
            groups[id(g)] = gi
        return groups[id(g)]

    for i, s in enumerate(desc.shapes):
        where = s.id or f"shape #{i}"
        if s.type == "shapegroup":
            group_of(s)  # drawn only through its instances
            continue
        try:
            if s.type == "instance":
                scene.add_instance(where, group_of(s.group), np.asarray(s.to_world, np.float64))
                continue
            idx = add_geometry(s, where)
            add_attributes(s, idx)
            if s.emitter is not None:
                scene.add_area_emitter(idx, _emitter(s.emitter))
            if s.sensor is not None:
                sensor_shape = idx
            if s.subsurface is not None:
                c = _core.DipoleDesc()
                d = s.subsurface
                c.id = d.id
                c.sigma_a = tuple(float(x) for x in d.sigma_a)
                c.sigma_s = tuple(float(x) for x in d.sigma_s)
                c.g = float(d.g)
                c.int_ior = float(d.int_ior)
                c.ext_ior = float(d.ext_ior)
                scene.add_dipole(idx, c)
            media_of(s, idx)
        except (ValueError, RuntimeError) as e:
            if isinstance(e, SceneError):
                raise
            raise SceneError(f"{desc.source}: {where}: {e}") from None
    for e in desc.emitters:
        try:
            scene.add_emitter(_emitter(e))
        except ValueError as err:
            raise SceneError(f"{desc.source}: emitter {e.id or e.type}: {err}") from None
    sd = desc.sensor
    c = _core.SensorDesc()
    c.type = sd.type
    c.to_world = np.asarray(sd.to_world, np.float64)
    c.fov_x = float(sd.fov_x)
    c.near_clip = float(sd.near_clip)
    c.far_clip = float(sd.far_clip)
    c.width = int(sd.width)
    c.height = int(sd.height)
    crop = (int(sd.crop_x), int(sd.crop_y), int(sd.crop_width), int(sd.crop_height))
    if crop[2] > 0 and crop != (0, 0, int(sd.width), int(sd.height)):  # else the full film (0: its default)
        c.crop_x, c.crop_y, c.crop_width, c.crop_height = crop
    c.rfilter = sd.rfilter
    c.filter_radius = float(sd.filter_radius)
    c.filter_stddev = float(sd.filter_stddev)
    c.shape = sensor_shape
    c.medium = _medium_index(scene, media, sd.medium, desc.source)
    if sd.type == "irradiancemeter" and sensor_shape < 0:
        raise SceneError(f"{desc.source}: sensor 'irradiancemeter' must be nested in a shape")
    try:
        scene.set_sensor(c)
    except ValueError as e:
        msg = str(e).removeprefix("sensor: ")
        raise SceneError(f"{desc.source}: sensor: {msg}") from None
    try:
        scene.commit()
    except ValueError as e:
        raise SceneError(f"{desc.source}: {e}") from None
    _warn_beyond_far_clip(scene, sd, desc.source)
    return scene


def _warn_beyond_far_clip(scene, sd, source):
    """A camera whose far_clip ends before every shape renders black with the
    camera estimators, while light tracing (which the clip does not bound)
    still finds the camera: a scene scaled up without its clip planes. Valid
    (Mitsuba renders it the same way), so a warning, not an error."""
    if sd.type not in ("perspective", "orthographic") or scene.shape_count == 0:
        return
    lo, hi = (np.asarray(b, np.float64) for b in scene.bbox)
    eye = np.asarray(sd.to_world, np.float64).reshape(4, 4)[:3, 3]
    nearest = float(np.linalg.norm(eye - np.clip(eye, lo, hi)))
    if nearest > sd.far_clip:
        import warnings

        from .loader import SceneWarning

        warnings.warn(f"{source}: sensor: every shape lies beyond its far_clip ({sd.far_clip:g}; the nearest is "
                      f"{nearest:g} away): camera paths reach no geometry, light paths still do; raise far_clip",
                      SceneWarning, stacklevel=3)
