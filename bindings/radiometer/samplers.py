"""The samplers (renderer/core/sampler.h), with Mitsuba 3's names and
parameters: one table read by the loader (the sensor's nested sampler) and
by render(sampler=...).

independent  sample_count [4], seed: the PCG stream of (seed, pixel, sample).
stratified   sample_count, seed, jitter [true]: jittered strata per dimension
             (1D: N strata; 2D: a sqrt N x sqrt N grid; N rounded up to a
             square, as Mitsuba 3 does), shuffled per dimension.
multijitter  sample_count, seed, jitter [true]: correlated multi-jittered
             2D points (Kensler 2013), stratified in 2D and in each axis.
sobol        sample_count, seed: Owen-scrambled (by hashing, Burley 2020),
             shuffled Sobol points per pixel, padded in 2D pairs.
zsobol       sample_count, seed: one Owen-scrambled Sobol sequence over the
             film, pixels in hierarchically shuffled Z order (Ahmed and
             Wonka 2020), which spreads the error as blue noise; N rounded
             up to a power of two.
ldsampler    Mitsuba 3's name for a scrambled, shuffled (0, 2)-sequence per
             pixel, padded (Kollig and Keller 2002): rendered by `sobol`, the
             same construction (Sobol's first two dimensions are a (0, 2)-
             sequence) with Owen scrambling.

sample_count sets the scene's default spp, and N, the number of samples a
pixel's pattern is built for, is the render's spp (sample_count under a time
budget); past N samples a fresh pattern begins, so every estimate stays
unbiased. `seed` is accepted for Mitsuba's sake; render()'s seed decides.

The camera driver (path, volpath, direct, whitted, photonmapper's camera
passes) and the light driver (ptracer, bdpt) draw on the sampler; photon
passes, sppm and the vcm family (vcm, bpm, ppm) draw on the independent
stream whatever it is, and render() warns when asked otherwise.
"""
from __future__ import annotations

from numbers import Integral

from .scene_desc import SceneError

# type -> the parameters it takes (besides `type`), in one place.
SAMPLER_PARAMS = {
    "independent": ("sample_count", "seed"),
    "stratified": ("sample_count", "seed", "jitter"),
    "multijitter": ("sample_count", "seed", "jitter"),
    "sobol": ("sample_count", "seed"),
    "zsobol": ("sample_count", "seed"),
    "ldsampler": ("sample_count", "seed"),
}
# Names rendered by another sampler of the table.
ALIASES = {"ldsampler": "sobol"}
SAMPLER_NAMES = tuple(SAMPLER_PARAMS)
# Mitsuba 3 samplers not implemented here, named in the error.
MITSUBA_ONLY = ("orthogonal",)
MAX_SAMPLE_COUNT = 1 << 24


def unknown_sampler(name, where="sampler") -> SceneError:
    extra = f" (Mitsuba's '{name}' is not implemented here)" if name in MITSUBA_ONLY else ""
    return SceneError(f"{where}: unknown sampler type '{name}'{extra}; known: {', '.join(SAMPLER_NAMES)}")


def resolve_sampler(spec, scene_sampler: dict) -> dict:
    """render(sampler=...): None (the scene's), a name, or a dict like the
    scene's ({"type": ..., "sample_count": ..., "jitter": ..., "seed": ...})
    -> {"type", "sample_count", "jitter"}. A name or dict without a
    sample_count keeps the scene's."""
    if spec is None:
        return dict(scene_sampler)
    if isinstance(spec, str):
        spec = {"type": spec}
    if not isinstance(spec, dict):
        raise SceneError(f"sampler: expected None, a name or a dict, got {type(spec).__name__}")
    params = dict(spec)
    t = params.pop("type", None)
    if not isinstance(t, str):
        raise SceneError(f"sampler: a dict needs a 'type' string, got {t!r}")
    if t not in SAMPLER_PARAMS:
        raise unknown_sampler(t)
    out = {"type": ALIASES.get(t, t), "sample_count": scene_sampler.get("sample_count", 4), "jitter": True}
    for k, v in params.items():
        if k not in SAMPLER_PARAMS[t]:
            raise SceneError(f"sampler '{t}': unknown parameter '{k}' (takes: {', '.join(SAMPLER_PARAMS[t])})")
        if k in ("sample_count", "seed"):
            if isinstance(v, bool) or not isinstance(v, Integral):
                raise SceneError(f"sampler '{t}': parameter '{k}' must be an integer, got {v!r}")
            if k == "sample_count" and not 1 <= v <= MAX_SAMPLE_COUNT:
                raise SceneError(f"sampler '{t}': sample_count = {v} is outside [1, {MAX_SAMPLE_COUNT}]")
            if k == "sample_count":
                out[k] = int(v)
        elif k == "jitter":
            if not isinstance(v, bool):
                raise SceneError(f"sampler '{t}': parameter 'jitter' must be a boolean, got {v!r}")
            out[k] = v
    return out
