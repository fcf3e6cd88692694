"""Where light paths start in media, for the estimators that trace them
(`bdpt`, `ptracer`, `photonmapper`), against `volpath`'s camera paths
(found in review, 2026-11-23):

- Light from an emitter at infinity (directional, constant) through an
  unbounded homogeneous medium never arrives (volpath's shadow rays see
  exp(-sigma_t inf) = 0), while light subpaths and photons used to start
  on the disk outside the scene at full power, lighting the fog from a
  disk-radius away. The same fog inside a null box (bounded) must still
  let the light in: the check can fail both ways.
- A light inside a medium behind a dielectric (a lamp in a glass ball of
  fog) starts in a subsurface medium: its medium vertices are B
  (subsurface), as volpath files them when its camera paths enter through
  the glass, never V (volume).
"""
import numpy as np
import pytest

import radiometer as rm

from test_bdpt import small_room
from test_bdpt_media import FOG, fog_room

SUN = {"type": "directional", "direction": [0.3, 0.4, -1.0], "irradiance": {"type": "rgb", "value": [2.0] * 3}}
SKY = {"type": "constant", "radiance": {"type": "rgb", "value": [0.5] * 3}}
LIGHT_PATHS = [("bdpt", 64, {}), ("ptracer", 64, {}), ("photonmapper", 4, {"volume_photons": 20000,
                                                                           "global_photons": 20000})]


def _fog_scene(light, bounded):
    if bounded:  # the same fog in a null box around the room
        d = fog_room(res=8, fog=None)
        d["fogbox"] = {"type": "cube", "to_world": np.diag([2.0, 2.0, 2.0, 1.0]) @ np.array(
            [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.5], [0, 0, 0, 1.0]]), "bsdf": {"type": "null"}, "interior": FOG}
    else:
        d = fog_room(res=8)
    d["light"] = light
    return rm.load_dict(d)


@pytest.mark.parametrize("light", [SUN, SKY], ids=["directional", "constant"])
@pytest.mark.parametrize("estimator,spp,extra", LIGHT_PATHS, ids=[e[0] for e in LIGHT_PATHS])
def test_light_from_infinity_through_unbounded_fog_is_zero(estimator, spp, extra, light):
    integ = {"type": estimator, "max_depth": 4, **extra}
    if estimator == "ptracer" and light is SKY:
        integ["hide_emitters"] = True  # the camera in fog sees the sky through infinite fog anyway: 0
    unbounded = rm.render(_fog_scene(light, False), integrator=integ, spp=spp, seed=2)
    assert float(np.abs(unbounded.image).max()) == 0.0, f"{estimator}: light from infinity came through unbounded fog"
    bounded = rm.render(_fog_scene(light, True), integrator=integ, spp=spp, seed=2)
    assert float(bounded.image.mean()) > 1e-3, f"{estimator}: no light into a bounded fog box"


def test_light_from_infinity_through_unbounded_fog_is_zero_in_volpath_too():
    """The reference behaviour the light-path estimators are held to."""
    for bounded in (False, True):
        r = rm.render(_fog_scene(SUN, bounded), integrator={"type": "volpath", "max_depth": 4}, spp=64, seed=2)
        assert (float(r.image.mean()) > 1e-3) == bounded


def _lamp_in_glass_fog():
    d = small_room({"type": "sphere", "center": [0.0, 0.0, 0.6], "radius": 0.1,
                    "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [5.0] * 3}}}, res=8)
    d["ball"] = {"type": "sphere", "center": [0.0, 0.0, 0.6], "radius": 0.35,
                 "bsdf": {"type": "dielectric", "int_ior": 1.3},
                 "interior": {"type": "homogeneous", "sigma_t": 3.0, "albedo": 0.9}}
    return rm.load_dict(d)


@pytest.mark.parametrize("estimator,extra", [("volpath", {}), ("bdpt", {}), ("ptracer", {}),
                                             ("photonmapper", {"final_gather": False})])
def test_light_inside_glass_medium_is_subsurface_not_volume(estimator, extra):
    r = rm.render(_lamp_in_glass_fog(), integrator={"type": estimator, "max_depth": 8, **extra}, spp=32, seed=3)
    assert float(r.effects["volume"].max()) == 0.0, f"{estimator}: scattering inside the glass ball filed as volume"
    assert float(r.effects["subsurface"].mean()) > 1e-4, f"{estimator}: no subsurface light"
