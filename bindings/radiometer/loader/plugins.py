"""The plugin table: the plugin types the loader accepts in each category
(the XML tag or the dict's `type`), and the category of each type."""
from __future__ import annotations

from ..registry import estimator_names
from ..samplers import SAMPLER_NAMES

PLUGINS = {
    "shape": ("obj", "ply", "serialized", "rectangle", "cube", "disk", "sphere", "cylinder", "shapegroup",
              "instance"),
    "bsdf": ("diffuse", "conductor", "roughconductor", "dielectric", "roughdielectric",
             "thindielectric", "plastic", "roughplastic", "twosided", "null", "principled", "principledthin",
             "blendbsdf", "mask", "normalmap", "bumpmap"),
    "emitter": ("area", "point", "spot", "projector", "directional", "constant", "envmap"),
    "sensor": ("perspective", "orthographic", "radiancemeter", "irradiancemeter"),
    "film": ("hdrfilm",),
    "rfilter": ("box", "tent", "gaussian"),
    "sampler": SAMPLER_NAMES,
    # the core's registry, and Mitsuba's `moment` around one of them
    "integrator": estimator_names() + ("moment",),
    "medium": ("homogeneous", "heterogeneous"),
    "phase": ("isotropic", "hg"),
    "volume": ("gridvolume", "constvolume"),
    "subsurface": ("dipole",),
    "texture": ("checkerboard", "bitmap", "rawconstant", "mesh_attribute"),
}
_CATEGORY_OF = {t: c for c, types in PLUGINS.items() for t in types}
