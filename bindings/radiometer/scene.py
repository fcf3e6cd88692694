"""The Scene handle returned by load_file / load_dict."""
from __future__ import annotations

from .scene_desc import SceneDesc


class Scene:
    """A loaded scene: its description (`desc`) and, built on first use, the
    C++ scene with its Embree BVH."""

    def __init__(self, desc: SceneDesc):
        self.desc = desc
        self._core = None

    def core(self):
        if self._core is None:
            from ._build import build_scene

            self._core = build_scene(self.desc)
        return self._core

    @property
    def width(self) -> int:
        return self.desc.sensor.width

    @property
    def height(self) -> int:
        return self.desc.sensor.height

    @property
    def spp(self) -> int:
        return self.desc.sensor.spp

    @property
    def features(self) -> dict:
        return self.core().features

    def __repr__(self):
        d = self.desc
        return (f"<radiometer.Scene {d.source}: {len(d.shapes)} shapes, {len(d.emitters)} other emitters, "
                f"{d.sensor.type} {d.sensor.width}x{d.sensor.height}, integrator {d.integrator.type}>")
