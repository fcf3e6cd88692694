"""The reference image of a canonical scene (reference_scenes/registry.py):
the analytic solution with its exact split into effect classes, or the
committed Mitsuba 3 reference (mean and variance of the mean) with, where
one was made and accepted, a per-effect reference of ours
(benchmarks/effect_refs.py)."""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .registry import SceneSpec, get


@dataclass
class Reference:
    image: np.ndarray  # (H, W, 3) float64
    variance: Optional[np.ndarray]  # None for exact
    effects: Optional[dict]  # effect class -> image, or None when no per-effect reference is available
    effects_variance: Optional[dict]  # per-effect variance (none recorded yet: renders keep only the total's)
    kind: str  # "analytic", "mitsuba", "ours"
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

    res = p.get("res")
    path = spec.reference_file(res)  # ValueError naming the resolutions with a reference
    if not path.exists():
        opt = f" --res {res}" if path != spec.reference_exr else ""
        how = (f"python -m radiometer.reference_scenes.{spec.folder}.make_reference{opt}" if spec.kind == "ours"
               else f"radiometer refs {name}{opt}")
        raise FileNotFoundError(f"{path}: {spec.kind} reference missing ({how})")
    ref = read_exr(path)
    effects = None
    why = "no per-effect reference"
    if effect_ref:
        e = read_exr(effect_ref)
        effects = {k: np.asarray(v, np.float64) for k, v in (e.effects or {}).items()}
        why = e.metadata.get("effects_kind", "ours")
    return Reference(np.asarray(ref.image, np.float64), np.asarray(ref.variance, np.float64), effects, None, spec.kind,
                     why, int(ref.metadata.get("total_spp", 0)))


def reference(name: str, params: dict, effect_ref: Optional[str] = None) -> Reference:
    """The reference of scene `name` rendered with XML `params`; for
    Mitsuba-referenced scenes `effect_ref` is the per-effect reference EXR
    (benchmarks/effect_refs.py), if one was made and accepted."""
    return _cached(name, tuple(sorted(params.items())), effect_ref)
