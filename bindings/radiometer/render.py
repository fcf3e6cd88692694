"""`radiometer.render`: the Python face of the C++ render driver."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from .scene_desc import IntegratorDesc, SceneError

EFFECTS = ("emission", "direct", "indirect", "caustic", "specular", "volume", "subsurface")

# Parameters each implemented estimator takes, with Mitsuba 3's defaults.
_COMMON = {"max_depth": (int, -1), "rr_depth": (int, 5), "hide_emitters": (bool, False)}
INTEGRATOR_PARAMS = {
    "path": dict(_COMMON),
    "volpath": dict(_COMMON),
    # Light tracing; Mitsuba's samples_per_pass (wavefront sizing) is accepted and ignored.
    # strategy_images D (bdpt and ptracer): keep one image per strategy (s, t)
    # of path depth s + t - 1 <= D in RenderResult.strategies (0: none).
    "ptracer": dict(_COMMON, samples_per_pass=(int, None), strategy_images=(int, 0)),
    # Bidirectional path tracing; mis in {"power", "balance", "uniform"}, beta the power heuristic's exponent.
    "bdpt": dict(_COMMON, mis=(str, "power"), beta=(float, 2.0), strategy_images=(int, 0)),
    "direct": {"emitter_samples": (int, 1), "bsdf_samples": (int, 1), "hide_emitters": (bool, False),
               "shading_samples": (int, None)},
    # Photon mapping (Jensen), Mitsuba 0.6's parameters in snake_case (directSamples -> direct_samples,
    # globalPhotons, causticPhotons, globalLookupRadius, causticLookupRadius, lookupSize, maxDepth,
    # rrDepth, hideEmitters; the camelCase names are aliases, MITSUBA06_ALIASES; granularity accepted
    # and ignored); gather_rays and final_gather are ours. In scenes with media (issue 6): volume_photons
    # (volumePhotons) in the volume photon map, volume_lookup_radius (volumeLookupRadius), and ours:
    # volume_lookup_size (photons per volume estimate) and step_size (ray marching, world units;
    # 0 = the densest channel's mean free path, at most 1/16 of the scene's radius);
    # volume_boundary_rays K > 0 (ours) corrects the estimate's sphere volume for the part of it
    # behind the medium's boundary, measured with K rays (0: the seed's 4/3 pi r^3).
    # Radii are relative to the scene's bounding-sphere radius. See renderer/estimators/photonmapper.cpp.
    "photonmapper": dict(_COMMON, direct_samples=(int, 16), global_photons=(int, 250000),
                         caustic_photons=(int, 250000), global_lookup_radius=(float, 0.05),
                         caustic_lookup_radius=(float, 0.0125), lookup_size=(int, 120), gather_rays=(int, 32),
                         final_gather=(bool, True), volume_photons=(int, 250000),
                         volume_lookup_radius=(float, 0.05), volume_lookup_size=(int, 64),
                         step_size=(float, 0.0), volume_boundary_rays=(int, 0), granularity=(int, None)),
    # Stochastic progressive photon mapping (Hachisuka & Jensen 2009): Mitsuba 0.6's photonCount,
    # initialRadius (0 = automatic), alpha, maxDepth, rrDepth; granularity accepted and ignored.
    # One pass per spp. See renderer/estimators/sppm.cpp.
    "sppm": dict(_COMMON, photon_count=(int, 250000), initial_radius=(float, 0.0), alpha=(float, 0.7),
                 granularity=(int, None)),
}
# Mitsuba 0.6's camelCase names of the photon estimators' parameters (its XML
# files use them), accepted as aliases of ours.
MITSUBA06_ALIASES = {
    "photonmapper": {"directSamples": "direct_samples", "globalPhotons": "global_photons",
                     "causticPhotons": "caustic_photons", "globalLookupRadius": "global_lookup_radius",
                     "causticLookupRadius": "caustic_lookup_radius", "lookupSize": "lookup_size",
                     "volumePhotons": "volume_photons", "volumeLookupRadius": "volume_lookup_radius",
                     "maxDepth": "max_depth", "rrDepth": "rr_depth", "hideEmitters": "hide_emitters"},
    "sppm": {"photonCount": "photon_count", "initialRadius": "initial_radius", "maxDepth": "max_depth",
             "rrDepth": "rr_depth", "hideEmitters": "hide_emitters"},
}
# Known to the scene format, arriving in later issues.
PLANNED_INTEGRATORS = ("vcm", "pssmlt", "vpl", "irrcache", "radiosity")


class RenderCancelled(KeyboardInterrupt):
    """Ctrl-C stopped a render. `.result` holds the finished passes (its `spp`
    says how many samples per pixel they are), so nothing finished is lost."""

    def __init__(self, result: "RenderResult"):
        super().__init__(f"render cancelled after {result.spp} spp")
        self.result = result


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) float32, linear RGB
    variance: np.ndarray  # (H, W, 3) float32, variance of the per-pixel estimate
    effects: dict  # effect class -> (H, W, 3) float32; they sum to image
    spp: int
    seconds: float
    stats: dict
    checkpoints: list = field(default_factory=list)  # [(spp, seconds, image, variance)]
    integrator: dict = field(default_factory=dict)
    seed: int = 0
    # (s, t) -> (H, W, 3), when the integrator's strategy_images asked for
    # them: MIS-weighted contributions (summing to the image when every
    # depth is kept) and unweighted ones (each an estimate on its own).
    strategies: dict = field(default_factory=dict)
    strategies_unweighted: dict = field(default_factory=dict)

    def write_exr(self, path, **metadata):
        from .exr import write_exr

        write_exr(path, self, **metadata)


def _integrator_desc(spec, scene_integrator: IntegratorDesc):
    """Resolves `integrator=` (None, a name or a dict like the XML's) into
    (type, params), checking every parameter."""
    if spec is None:
        itype, params, where = scene_integrator.type, dict(scene_integrator.params), "scene integrator"
    elif isinstance(spec, str):
        itype, params, where = spec, {}, f"integrator '{spec}'"
    elif isinstance(spec, dict):
        params = dict(spec)
        if "type" not in params:
            raise SceneError("integrator: dict needs a 'type'")
        itype = params.pop("type")
        where = "integrator"
    else:
        raise SceneError(f"integrator: expected None, a name or a dict, got {type(spec).__name__}")
    if itype not in INTEGRATOR_PARAMS:
        if itype in PLANNED_INTEGRATORS:
            raise SceneError(f"{where}: estimator '{itype}' is not implemented yet")
        raise SceneError(f"{where}: unknown estimator '{itype}' (known: {', '.join(sorted(INTEGRATOR_PARAMS))})")
    schema = INTEGRATOR_PARAMS[itype]
    aliases = MITSUBA06_ALIASES.get(itype, {})
    for old, new in aliases.items():
        if old in params:
            if new in params:
                raise SceneError(f"{where}['{old}']: given together with its alias '{new}'; give one")
            params[new] = params.pop(old)
    resolved = {}
    for k, v in params.items():
        if k not in schema:
            raise SceneError(f"{where}['{k}']: unknown parameter for '{itype}' (known: {', '.join(sorted(schema))})")
        typ = schema[k][0]
        if typ is bool:
            if not isinstance(v, (bool, np.bool_)):
                raise SceneError(f"{where}['{k}']: expected a boolean, got {v!r}")
            v = bool(v)
        elif typ is str:
            if not isinstance(v, str):
                raise SceneError(f"{where}['{k}']: expected a string, got {v!r}")
        elif typ is float:
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise SceneError(f"{where}['{k}']: expected a finite number, got {v!r}")
            v = float(v)
        else:
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise SceneError(f"{where}['{k}']: expected an integer, got {v!r}")
            v = int(v)
        resolved[k] = v
    out = {"type": itype}
    for k, (typ, default) in schema.items():
        val = resolved.get(k, default)
        if val is not None:
            out[k] = val
    out.pop("samples_per_pass", None)
    out.pop("granularity", None)
    if itype in ("path", "volpath", "ptracer", "bdpt", "photonmapper", "sppm"):
        if out["max_depth"] == 0 or out["max_depth"] < -1:
            raise SceneError(f"{where}['max_depth']: must be -1 (unbounded) or >= 1, got {out['max_depth']}")
        if out["rr_depth"] < 1:
            raise SceneError(f"{where}['rr_depth']: must be >= 1, got {out['rr_depth']}")
    if itype == "bdpt":
        if out["mis"] not in ("power", "balance", "uniform"):
            raise SceneError(f"{where}['mis']: must be 'power', 'balance' or 'uniform', got {out['mis']!r}")
        if not out["beta"] > 0:
            raise SceneError(f"{where}['beta']: must be > 0, got {out['beta']}")
    if itype in ("bdpt", "ptracer") and not 0 <= out["strategy_images"] <= 16:
        raise SceneError(f"{where}['strategy_images']: must be a path depth in 0..16 (0: none), "
                         f"got {out['strategy_images']}")
    if itype == "photonmapper":
        for k in ("direct_samples", "global_photons", "caustic_photons", "volume_photons", "volume_boundary_rays"):
            if out[k] < 0:
                raise SceneError(f"{where}['{k}']: must be >= 0, got {out[k]}")
        for k in ("lookup_size", "gather_rays", "volume_lookup_size"):
            if out[k] < 1:
                raise SceneError(f"{where}['{k}']: must be >= 1, got {out[k]}")
        if not out["step_size"] >= 0:
            raise SceneError(f"{where}['step_size']: must be >= 0 (world units; 0 = automatic), "
                             f"got {out['step_size']}")
        for k in ("global_lookup_radius", "caustic_lookup_radius", "volume_lookup_radius"):
            if not out[k] > 0:
                raise SceneError(f"{where}['{k}']: must be > 0 (relative to the scene's radius), got {out[k]}")
    if itype == "sppm":
        if out["photon_count"] < 1:
            raise SceneError(f"{where}['photon_count']: must be >= 1, got {out['photon_count']}")
        if not out["initial_radius"] >= 0:
            raise SceneError(f"{where}['initial_radius']: must be >= 0 (0 = automatic), got {out['initial_radius']}")
        if not 0 < out["alpha"] < 1:
            raise SceneError(f"{where}['alpha']: must lie in (0, 1), got {out['alpha']}")
    if itype == "direct":
        if "shading_samples" in out:  # Mitsuba: sets both counts
            out["emitter_samples"] = out["bsdf_samples"] = out.pop("shading_samples")
        if out["emitter_samples"] < 0 or out["bsdf_samples"] < 0 or out["emitter_samples"] + out["bsdf_samples"] == 0:
            raise SceneError(f"{where}: emitter_samples and bsdf_samples must be >= 0 and not both 0")
    return out


def _core_integrator(spec: dict):
    from . import _core

    c = _core.IntegratorDesc()
    c.type = spec["type"]
    for k in ("max_depth", "rr_depth", "hide_emitters", "emitter_samples", "bsdf_samples", "mis", "beta",
              "strategy_images", "direct_samples", "global_photons", "caustic_photons", "global_lookup_radius",
              "caustic_lookup_radius", "lookup_size", "gather_rays", "final_gather", "volume_photons",
              "volume_lookup_radius", "volume_lookup_size", "step_size", "volume_boundary_rays", "photon_count",
              "initial_radius", "alpha"):
        if k in spec:
            setattr(c, k, spec[k])
    return c


def _mixed_bsdfs(desc) -> list:
    """Names of the scene's BSDFs that have both a delta and a smooth lobe."""
    found = []

    def visit(b):
        if b is None:
            return
        if b.type == "plastic":
            found.append(b.id or "plastic")
        for n in getattr(b, "nested", []) or []:
            visit(n)

    for s in desc.shapes:
        visit(s.bsdf)
    return sorted(set(found))


def _effects_mask(effects):
    if effects is None:
        return [True] * len(EFFECTS)
    if isinstance(effects, str):
        effects = [effects]
    mask = [False] * len(EFFECTS)
    for e in effects:
        if e not in EFFECTS:
            raise ValueError(f"effects: unknown effect class '{e}' (known: {', '.join(EFFECTS)})")
        mask[EFFECTS.index(e)] = True
    if not any(mask):
        raise ValueError("effects: empty list; name at least one effect class")
    return mask


def render(scene, integrator=None, spp: Optional[int] = None, seconds: Optional[float] = None, seed: int = 0,
           threads: int = 0, checkpoints=None, effects=None,
           progress: Optional[Callable[[int, int], None]] = None) -> RenderResult:
    """Renders `scene` (from load_file/load_dict) and returns a RenderResult.

    integrator: None (the scene's), a name, or a dict like the XML's.
    spp: samples per pixel (default: the scene sampler's sample_count); with
        `seconds` it caps the render.
    seconds: wall-clock budget (steady clock).
    seed: fixes the result bit for bit, whatever `threads` is.
    checkpoints: spp counts at which to keep (spp, seconds, image, variance);
        True for every power of two.
    effects: simulate only these effect classes (see EFFECTS).
    progress: called with (done, total) samples; total is 0 under a time budget.
    Ctrl-C raises RenderCancelled carrying the finished passes.
    """
    from . import _core
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise TypeError(f"render: expected a radiometer Scene (from load_file/load_dict), got {type(scene).__name__}")
    spec = _integrator_desc(integrator, scene.desc.integrator)
    if seconds is not None:
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds) or seconds <= 0:
            raise ValueError(f"seconds: expected a positive finite number, got {seconds!r}")
    if spp is None:
        spp = 0 if seconds is not None else scene.desc.sensor.spp
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 0 or spp > 1 << 24:
        raise ValueError(f"spp: expected an integer in 1..{1 << 24}, got {spp!r}")
    if spp == 0 and seconds is None:
        raise ValueError("spp: must be >= 1 when no seconds budget is given")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 1 << 64:
        raise ValueError(f"seed: expected an integer in [0, 2^64), got {seed!r}")
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or not 0 <= threads <= 1024:
        raise ValueError(f"threads: expected an integer in 0..1024 (0 = all cores), got {threads!r}")
    if checkpoints is True:
        top = spp if spp > 0 else 1 << 20
        checkpoints = [1 << k for k in range(0, 31) if (1 << k) <= top]
    elif checkpoints is None or checkpoints is False:
        checkpoints = []
    else:
        checkpoints = [int(c) for c in checkpoints]
        if any(c < 1 for c in checkpoints):
            raise ValueError("checkpoints: spp counts must be >= 1")
    mask = _effects_mask(effects)
    core_scene = scene.core()
    r = _core.render(core_scene, _core_integrator(spec), mask, int(spp), float(seconds or 0.0), int(seed),
                     int(threads), checkpoints, progress)
    stats = dict(r["stats"])
    stats.update(threads=r["threads"], cancelled=r["cancelled"], features=core_scene.features,
                 effects_simulated=[e for e, m in zip(EFFECTS, mask) if m])
    result = RenderResult(image=r["image"], variance=r["variance"], effects=dict(r["effects"]), spp=r["spp"],
                          seconds=r["seconds"], stats=stats, checkpoints=list(r["checkpoints"]), integrator=spec,
                          seed=int(seed), strategies=dict(r["strategies"]),
                          strategies_unweighted=dict(r["strategies_unweighted"]))
    if spec["type"] == "sppm":
        mixed = _mixed_bsdfs(scene.desc)
        if mixed:
            # A known limit (renderer/estimators/sppm.cpp): the visible point is
            # the first vertex with a smooth lobe, so a BSDF that also has a
            # delta lobe (plastic's coat) never passes the camera path on: its
            # reflections (the `specular` class there) are missing at any budget.
            msg = (f"sppm: BSDF(s) {', '.join(mixed)} have a delta and a smooth lobe; sppm stops camera paths at "
                   "them, so what their delta lobe reflects is missing (not consistent there); use photonmapper, "
                   "bdpt or path for these")
            stats.setdefault("warnings", []).append(msg)
            import warnings

            warnings.warn(msg, stacklevel=2)
    if spec["type"] == "ptracer":  # light tracing makes only the t = 1 strategies
        for d in (result.strategies, result.strategies_unweighted):
            for k in [k for k in d if k[1] != 1]:
                del d[k]
    if r["interrupted"]:
        raise RenderCancelled(result)
    return result
