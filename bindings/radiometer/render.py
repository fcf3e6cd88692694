"""`radiometer.render`: the Python face of the C++ render driver."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from .samplers import resolve_sampler
from .scene_desc import IntegratorDesc, SceneError

EFFECTS = ("emission", "direct", "indirect", "caustic", "specular", "volume", "subsurface")



def __getattr__(name):
    # Views of the estimators' declarations in the core (radiometer.registry),
    # made on first use: INTEGRATOR_PARAMS maps each estimator name (aliases
    # too) to {parameter: (Python type, default or None)}; PLANNED_INTEGRATORS
    # lists the names the scene format knows that are not implemented yet.
    from . import registry

    if name == "INTEGRATOR_PARAMS":
        return registry.integrator_params()
    if name == "PLANNED_INTEGRATORS":
        return registry.planned_estimators()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
    # effect class -> (H, W, 3) variance of that effect's estimate, when
    # render(effect_variance=True) asked and the estimator's film keeps it
    # (camera estimators); None otherwise.
    effect_variance: Optional[dict] = None
    # What the render knows of its own error (analysis/verdict.py
    # render_error_budget): the standard error of the image mean, and per
    # effect where effect_variance was kept.
    error_budget: dict = field(default_factory=dict)
    # Arrays an estimator keeps beyond the images, by name (numpy, float32;
    # the names of an array's last axis, where it has them, in
    # stats[NAME + "_columns"]): prt's per-pixel transfer "prt_transfer" and
    # the lighting's SH coefficients "prt_light" (radiometer.prt.Transfer
    # relights from them).
    arrays: dict = field(default_factory=dict)

    def write_exr(self, path, **metadata):
        from .exr import write_exr

        write_exr(path, self, **metadata)


def _integrator_desc(spec, scene_integrator: IntegratorDesc):
    """Resolves `integrator=` (None, a name or a dict like the XML's) into
    {"type": ..., every parameter}: the core checks each against the
    estimator's declaration and fills in the defaults (SceneError naming the
    estimator and the parameter otherwise)."""
    if spec is None:
        itype, params = scene_integrator.type, dict(scene_integrator.params)
    elif isinstance(spec, str):
        itype, params = spec, {}
    elif isinstance(spec, dict):
        params = dict(spec)
        if "type" not in params:
            raise SceneError("integrator: dict needs a 'type'")
        itype = params.pop("type")
    else:
        raise SceneError(f"integrator: expected None, a name or a dict, got {type(spec).__name__}")
    if not isinstance(itype, str):
        raise SceneError(f"integrator: 'type' must be a string, got {itype!r}")
    from . import _core

    return {"type": itype, **_core.resolve_integrator(_core.IntegratorDesc(itype, params))}


def _core_integrator(spec: dict):
    from . import _core

    params = dict(spec)
    return _core.IntegratorDesc(params.pop("type"), params)


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
        for m in s.members or (s.group.members if s.group is not None else []):  # shapegroups, instances
            visit(m.bsdf)
    return sorted(set(found))


def _warn(stats, msg):
    import warnings

    stats.setdefault("warnings", []).append(msg)
    warnings.warn(msg, stacklevel=3)


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


def refusal(scene, integrator) -> Optional[str]:
    """None, or why the estimator refuses `scene` by its own check (the
    message render() would raise: prt's local lights or non-diffuse BSDFs),
    without rendering. Media and dipoles are the capabilities'
    (radiometer.estimators()), not checked here."""
    from . import _core
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise TypeError(f"refusal: expected a radiometer Scene, got {type(scene).__name__}")
    spec = _integrator_desc(integrator, scene.desc.integrator)
    return _core.check_scene(scene.core(), _core_integrator(spec))


def render(scene, integrator=None, spp: Optional[int] = None, seconds: Optional[float] = None, seed: int = 0,
           threads: int = 0, checkpoints=None, effects=None,
           progress: Optional[Callable[[int, int], None]] = None, effect_variance: bool = False,
           sampler=None) -> RenderResult:
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
    effect_variance: also keep each effect's per-pixel variance
        (res.effect_variance; camera estimators, whose film sums the
        squares; 21 more doubles a pixel). The image is the same either way.
    sampler: None (the scene sensor's), a name or a dict like the scene's
        ({"type": "sobol", "sample_count": 64}); see radiometer.samplers.
        Camera and light paths draw on it; photon passes, sppm and the vcm
        family on the independent stream (a warning says so).
    Ctrl-C raises RenderCancelled carrying the finished passes.
    """
    from . import _core
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise TypeError(f"render: expected a radiometer Scene (from load_file/load_dict), got {type(scene).__name__}")
    spec = _integrator_desc(integrator, scene.desc.integrator)
    if seconds is not None:
        if (isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds)
                or seconds <= 0):
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
    if not isinstance(effect_variance, (bool, np.bool_)):
        raise ValueError(f"effect_variance: expected True or False, got {effect_variance!r}")
    mask = _effects_mask(effects)
    sens = scene.desc.sensor
    smp = resolve_sampler(sampler, {"type": getattr(sens, "sampler", "independent"), "sample_count": sens.spp,
                                    "jitter": getattr(sens, "jitter", True)})
    core_scene = scene.core()
    r = _core.render(core_scene, _core_integrator(spec), mask, int(spp), float(seconds or 0.0), int(seed),
                     int(threads), checkpoints, progress, bool(effect_variance), smp["type"], smp["sample_count"],
                     smp["jitter"])
    stats = dict(r["stats"])
    stats.update(threads=r["threads"], cancelled=r["cancelled"], features=core_scene.features,
                 effects_simulated=[e for e, m in zip(EFFECTS, mask) if m])
    stats["sampler"] = r["sampler"] or "independent"
    if smp["type"] != "independent" and r["sampler"] != smp["type"]:
        _warn(stats, f"{spec['type']}: sampler '{smp['type']}' is not used: this estimator draws its paths on "
                     f"streams of its own (photon passes, sppm, vcm, bpm, ppm), on the independent sampler")
    elif smp["type"] != "independent" and spec["type"] == "photonmapper":
        _warn(stats, f"photonmapper: sampler '{smp['type']}' draws the camera passes; the photon passes use the "
                     f"independent sampler")
    medium_classes = mask[EFFECTS.index("volume")] or mask[EFFECTS.index("subsurface")]
    if spec.get("equiangular") is True and medium_classes and not stats.get("equiangular_samples") \
            and not r["cancelled"]:
        _warn(stats, f"{spec['type']}: equiangular = true made no equiangular sample: it samples distances in "
                     f"homogeneous media towards point, spot and area lights (renderer/estimators/volpath.cpp), "
                     f"and this scene has none on its camera paths (no media, grid media only, or only emitters "
                     f"at infinity)")
    if stats.get("mlt_chains", 0) > stats.get("mlt_chains_requested", float("inf")):
        _warn(stats, f"mmlt: chains raised from {stats['mlt_chains_requested']:.0f} to {stats['mlt_chains']:.0f}, two "
                     f"for each depth 2 .. max_depth (renderer/estimators/pssmlt.cpp)")
    result = RenderResult(image=r["image"], variance=r["variance"], effects=dict(r["effects"]), spp=r["spp"],
                          seconds=r["seconds"], stats=stats, checkpoints=list(r["checkpoints"]), integrator=spec,
                          seed=int(seed), strategies=dict(r["strategies"]),
                          strategies_unweighted=dict(r["strategies_unweighted"]),
                          effect_variance=None if r["effect_variance"] is None else dict(r["effect_variance"]),
                          arrays=dict(r["arrays"]))
    from .analysis.verdict import render_error_budget

    result.error_budget = render_error_budget(result)
    if spec["type"] in ("sppm", "ppm"):
        mixed = _mixed_bsdfs(scene.desc)
        if mixed:
            # A known limit (renderer/estimators/sppm.cpp, vcm.cpp's ppm): the
            # visible point is the first vertex with a smooth lobe, so a BSDF
            # that also has a delta lobe (plastic's coat) never passes the
            # camera path on: its reflections (the `specular` class there) are
            # missing at any budget.
            est = spec["type"]
            msg = (f"{est}: BSDF(s) {', '.join(mixed)} have a delta and a smooth lobe; {est} stops camera paths at "
                   "them, so what their delta lobe reflects is missing (not consistent there); use photonmapper, "
                   "bdpt, vcm or path for these")
            stats.setdefault("warnings", []).append(msg)
            import warnings

            warnings.warn(msg, stacklevel=2)
    for name, pm in stats.get("photon_maps", {}).items():
        if not pm["target_reached"] and not r["cancelled"]:
            # The give-up bound of photon tracing (renderer/transport/photon_trace.cpp).
            msg = (f"{spec['type']}: the {name} photon map stored {pm['photons']} of the {pm['target']} photons "
                   f"asked for: tracing gave up after {pm['paths']} light paths (at most {pm['max_paths']}), as "
                   f"few of this scene's light paths store one; its estimate is noisier and blurrier than asked")
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
