"""Shared scene builders for the tests (scenes as dicts, the way Mitsuba 3's
own render tests write them)."""
import pytest

import radiometer as rm


def furnace_dict(le=0.5, rho=0.5, res=16, max_depth=2, integrator="path"):
    """A closed analytic sphere of radius 1, emitting `le` and reflecting
    diffusely with albedo `rho` on its inside, seen from its centre.
    Radiance everywhere: L = le * sum_{k < max_depth} rho^k (le / (1 - rho) unbounded)."""
    return {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": max_depth},
        "sphere": {
            "type": "sphere",
            "flip_normals": True,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [rho] * 3}},
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [le] * 3}},
        },
        "sensor": {"type": "perspective", "fov": 70,
                   "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
    }


def furnace_exact(le, rho, max_depth):
    if max_depth < 0:
        return le / (1.0 - rho)
    return le * sum(rho ** k for k in range(max_depth))


@pytest.fixture(scope="session")
def cornell_path():
    from radiometer.reference_scenes import registry

    return registry.get("cornell_box").xml


@pytest.fixture(scope="session")
def small_cornell(cornell_path):
    return rm.load_file(cornell_path, res=24, spp=8)
