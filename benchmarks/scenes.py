"""The canonical scenes the benchmark knows, and their references.

Each entry names the scene's XML, the XML parameters its reference was made
with, and where the reference comes from:

- "analytic": the scene's analytic.py (reference_scenes/<folder>), exact,
  with an exact split into effect classes where the physics gives one
  (furnace: emission / direct / indirect by bounce count; area lights: all
  direct; mirror caustic: direct + caustic). Any XML parameter may be
  overridden (the solution takes them), so a smoke matrix can run them at
  8 x 8 pixels.
- "mitsuba": reference_scenes/<folder>/reference.exr, the mean of 32
  Mitsuba 3 runs with the variance of that mean, made with the parameters
  in reference_scenes/make_reference.py's SCENES, which the benchmark must
  use unchanged (a matrix that overrides them is refused). Their per-effect
  references are long runs of our own unbiased `path`, accepted only when
  their total passes the blocked z-test against Mitsuba's
  (benchmarks/effect_refs.py).

Scenes with media or subsurface scattering are listed too: while our loader
refuses <medium>, their jobs are recorded as "unsupported" with the loader's
error, and they start to count on the day it accepts them.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

ROOT = Path(__file__).resolve().parents[1] / "reference_scenes"
if not ROOT.exists():  # installed (non-editable): the package copy
    from importlib import resources

    ROOT = Path(str(resources.files("radiometer.reference_scenes")))


@dataclass(frozen=True)
class SceneSpec:
    name: str
    xml: Path
    kind: str  # "analytic" or "mitsuba"
    folder: str
    fixed_params: dict = field(default_factory=dict)  # mitsuba: the reference's XML parameters
    # Budget and estimator of the per-effect reference (ours, unbiased, all
    # cores), mitsuba scenes.
    effect_ref_spp: int = 0
    effect_ref_estimator: str = "path"


def _mitsuba(name, effect_ref_spp, estimator="path"):
    from radiometer.reference_scenes.make_reference import SCENES

    return SceneSpec(name, ROOT / name / "scene.xml", "mitsuba", name, dict(SCENES[name]["params"]), effect_ref_spp,
                     estimator)


def _registry():
    reg = {
        "furnace": SceneSpec("furnace", ROOT / "furnace" / "scene.xml", "analytic", "furnace"),
        "area_lights_disk": SceneSpec("area_lights_disk", ROOT / "area_lights" / "disk_light.xml", "analytic",
                                      "area_lights"),
        "area_lights_rect": SceneSpec("area_lights_rect", ROOT / "area_lights" / "rect_light.xml", "analytic",
                                      "area_lights"),
        "mirror_caustic": SceneSpec("mirror_caustic", ROOT / "mirror_caustic" / "scene.xml", "analytic",
                                    "mirror_caustic"),
    }
    # Per-effect reference budgets: about 15-60 s each with `path` on 2 cores
    # (measured 2026-11: cornell ~250 spp/s, glass ~650, veach ~550 at
    # 64 x 64), 10-30 x what a 4 s benchmark job reaches.
    for name, spp in (("cornell_box", 8192), ("glass_sphere_caustic", 16384), ("veach_mis", 16384)):
        reg[name] = _mitsuba(name, spp)
    # ajar_door's near room is lit by a strip `path` finds less than 1 time
    # in 100 per bounce; `bdpt` (unbiased, every strategy filed under its
    # effect class) reaches there in 1024 spp what path would in ~20 000
    # (21 x less error per sample, card.md), in about 20 s on 2 cores.
    reg["ajar_door"] = _mitsuba("ajar_door", 1024, "bdpt")
    for name in ("homogeneous_slab", "fog_room", "vandehulst_slab", "vandehulst_slab_reflectance",
                 "translucent_slab", "translucent_object", "volumetric_caustic"):
        # media: `path` (volpath) passes its z-tests against these references
        # at 512-1024 spp (tests/test_canonical_mitsuba.py); 1024 keeps the
        # main job's first run near 10 minutes (translucent_slab ~36 s).
        reg[name] = _mitsuba(name, 1024)
    return reg


SCENES = _registry()


def get(name: str) -> SceneSpec:
    try:
        return SCENES[name]
    except KeyError:
        raise KeyError(f"unknown scene '{name}' (known: {', '.join(sorted(SCENES))})") from None


def xml_defaults(spec: SceneSpec) -> dict:
    from radiometer.reference_scenes.area_lights.analytic import xml_defaults as _d

    return _d(spec.xml)


def scene_params(spec: SceneSpec, overrides: Optional[dict] = None) -> dict:
    """The XML parameters a job renders with: the reference's, then the
    matrix's overrides (refused for Mitsuba-referenced scenes when they
    differ from the reference's)."""
    overrides = dict(overrides or {})
    if spec.kind == "mitsuba":
        for k, v in overrides.items():
            if k not in spec.fixed_params or spec.fixed_params[k] != v:
                raise ValueError(f"parameter '{k}' = {v!r}: {spec.name}'s Mitsuba reference was made with "
                                 f"{spec.fixed_params}; these cannot change without a new reference")
        return dict(spec.fixed_params)
    defaults = xml_defaults(spec)
    for k in overrides:
        if k not in defaults:
            raise ValueError(f"parameter '{k}': not a <default> of {spec.xml.name} (known: {', '.join(sorted(defaults))})")
    return overrides


def max_depth(spec: SceneSpec, params: dict) -> Optional[int]:
    """The scene's max_depth (the job's parameter, else the XML default)."""
    if "max_depth" in params:
        return int(params["max_depth"])
    d = xml_defaults(spec).get("max_depth")
    return None if d is None else int(float(d))


@dataclass
class Reference:
    image: np.ndarray  # (H, W, 3) float64
    variance: Optional[np.ndarray]  # None for exact
    effects: Optional[dict]  # effect class -> image, or None when no per-effect reference is available
    effects_variance: Optional[dict]  # per-effect variance (none recorded yet: renders keep only the total's)
    kind: str  # "analytic", "mitsuba"
    effects_kind: str  # "analytic", "ours:<estimator> <spp> spp (z-test vs Mitsuba passed)", or why there is none
    spp: int = 0  # total spp of a Mitsuba reference


def _furnace_effects(p):
    """Emission Le (1 segment), direct Le rho (2), indirect the rest."""
    from radiometer.reference_scenes.area_lights.analytic import _rgb
    from radiometer.reference_scenes.furnace import analytic as fa

    q = fa.scene_params(fa.XML, **p)
    res, md = int(q["res"]), int(q["max_depth"])
    le, rho = _rgb(q["le"]), _rgb(q["rho"])
    total = fa.radiance(le, rho, md)
    em = le * (md == -1 or md >= 1)
    di = le * rho * (md == -1 or md >= 2)
    out = {"emission": em, "direct": di, "indirect": total - em - di}
    return {k: np.broadcast_to(v, (res, res, 3)).astype(np.float64) for k, v in out.items()}


def _analytic(spec: SceneSpec, p: dict):
    if spec.folder == "furnace":
        eff = _furnace_effects(p)
    elif spec.folder == "area_lights":
        from radiometer.reference_scenes.area_lights import analytic as aa

        img, _ = aa.reference("disk" if spec.name.endswith("disk") else "rect", **p)
        eff = {"direct": img}
    elif spec.folder == "mirror_caustic":
        from radiometer.reference_scenes.mirror_caustic import analytic as ma

        eff = ma.effects(**p)
    else:  # pragma: no cover - registry and this function go together
        raise KeyError(spec.name)
    total = sum(eff.values())
    return Reference(np.asarray(total, np.float64), None, eff, None, "analytic", "analytic")


@functools.lru_cache(maxsize=32)
def _cached(name: str, params_key: tuple, effect_ref: Optional[str]):
    spec = get(name)
    p = dict(params_key)
    if spec.kind == "analytic":
        return _analytic(spec, p)
    from radiometer import read_exr

    path = spec.xml.parent / "reference.exr"
    if not path.exists():
        raise FileNotFoundError(f"{path}: Mitsuba reference missing (radiometer refs {name})")
    ref = read_exr(path)
    effects = effects_var = None
    why = "no per-effect reference"
    if effect_ref:
        e = read_exr(effect_ref)
        effects = {k: np.asarray(v, np.float64) for k, v in (e.effects or {}).items()}
        why = e.metadata.get("effects_kind", "ours")
    return Reference(np.asarray(ref.image, np.float64), np.asarray(ref.variance, np.float64), effects, None, "mitsuba", why, int(ref.metadata.get("total_spp", 0)))


def reference(name: str, params: dict, effect_ref: Optional[str] = None) -> Reference:
    """The reference of scene `name` rendered with XML `params`; for
    Mitsuba-referenced scenes `effect_ref` is the per-effect reference EXR
    (benchmarks/effect_refs.py), if one was made and accepted."""
    return _cached(name, tuple(sorted(params.items())), effect_ref)
