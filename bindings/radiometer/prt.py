"""`radiometer.prt`: relighting a `prt` render (renderer/estimators/prt.cpp)
under new distant lighting, without precomputing its transfer again.

    res = rm.render(scene, integrator={"type": "prt", "bands": 5}, spp=64)
    tr = rm.prt.Transfer(res)       # keeps the per-pixel transfer vectors
    relit = tr.relight({"type": "envmap", "filename": "sky.exr", "scale": 2})
    relit.image, relit.effects      # (H, W, 3): what prt renders under that lighting
    relit.seconds                   # {"load": ..., "project": ..., "dot": ...}

The new lighting is an emitter dict (constant, envmap, directional; Mitsuba
3's, as load_dict takes them), a dict of several (a scene dict without
shapes), a radiometer Scene (its emitters at infinity), or SH coefficients
directly, an (n, 3) array of RGB values (index l (l + 1) + m, core/sh.h).
`relight(env, bands=k)` uses only the first k bands of the transfer and of
the lighting, so one precomputation shows the band-limit error of every
k <= bands. The image is the render's own for the render's lighting: the
same dot product, the same clamping of each effect at 0 (the projected
lighting can ring negative), in float32 here (float64 sums in the render).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

# The effect classes a prt transfer is kept for, in its array's order.
PRT_EFFECTS = ("emission", "direct", "indirect")


@dataclass
class Relit:
    image: np.ndarray  # (H, W, 3) float32
    effects: dict  # effect class -> (H, W, 3); they sum to image
    coefficients: np.ndarray  # (bands^2, 3) the lighting's SH coefficients used
    bands: int
    clamped: int  # values of effect images clamped at 0 (negative band-limited light)
    # "load" (an emitter dict made a scene: the envmap read), "project" (its
    # SH projection), "dot" (the relighting)
    seconds: dict = field(default_factory=dict)


def latlong_envmap(path, fn, width=256, height=129):
    """Writes an EXR for Mitsuba 3's `envmap` whose grid vertex (i, j) holds
    fn(d) at its direction d, in Mitsuba's parametrisation
    (renderer/scene/emitter.cpp EnvMapEmitter): d = (sin phi sin theta,
    cos theta, -cos phi sin theta), phi = 2 pi (i + 1/2) / width, theta =
    pi j / (height - 1); the envmap's bilinear lookup then gives fn to the
    grid's interpolation error. fn maps (N, 3) directions to (N, 3) RGB.
    Returns the path as a string."""
    from .exr import write_exr

    u, v = (np.arange(width) + 0.5) / width, np.arange(height) / (height - 1)
    P, T = np.meshgrid(2 * np.pi * u, np.pi * v)
    d = np.stack([np.sin(P) * np.sin(T), np.cos(T), -np.cos(P) * np.sin(T)], -1)
    write_exr(path, image=np.asarray(fn(d.reshape(-1, 3)), np.float32).reshape(height, width, 3))
    return str(path)


class Transfer:
    """The transfer of one prt render: (H, W, effect, channel, coefficient)
    float32 in `.transfer`, the render's lighting in `.light`."""

    def __init__(self, res):
        arrays = getattr(res, "arrays", None) or {}
        if "prt_transfer" not in arrays:
            raise ValueError("Transfer: not a prt render (res.arrays has no 'prt_transfer'); render with "
                             "integrator='prt'")
        self.transfer = np.asarray(arrays["prt_transfer"])
        self.light = np.asarray(arrays["prt_light"])
        n = self.transfer.shape[-1]
        self.bands = math.isqrt(n)
        self.env_samples = int(res.integrator.get("env_samples", 64))
        self.spp = res.spp
        # Per channel, contiguous (pixels x effects, coefficients): one
        # matrix-vector product each relights it.
        h, w, e, _, n = self.transfer.shape
        self._by_channel = [np.ascontiguousarray(self.transfer[..., c, :]).reshape(h * w * e, n) for c in range(3)]

    @property
    def nbytes(self) -> int:
        return int(self.transfer.nbytes)

    def coefficients(self, env, bands=None) -> np.ndarray:
        """The SH coefficients (bands^2, 3) of `env` (see the module's doc)."""
        return self._project(self._lighting(env), bands)

    def _lighting(self, env):
        """`env` as SH coefficients (an array) or a committed core scene."""
        from .scene import Scene

        if isinstance(env, np.ndarray) or isinstance(env, (list, tuple)):
            a = np.asarray(env, dtype=np.float64)
            if a.ndim != 2 or a.shape[1] != 3 or math.isqrt(a.shape[0]) ** 2 != a.shape[0]:
                raise ValueError(f"relight: SH coefficients must have shape (k^2, 3), got {a.shape}")
            return a
        if isinstance(env, dict):
            from . import load_dict

            env = load_dict(dict(env) if env.get("type") == "scene" else {"type": "scene", "light": env})
        if not isinstance(env, Scene):
            raise TypeError(f"relight: expected an emitter dict, a Scene or an (n, 3) array, got {type(env).__name__}")
        return env.core()

    def _project(self, lighting, bands=None) -> np.ndarray:
        from . import _core

        bands = self.bands if bands is None else int(bands)
        n = bands * bands
        if isinstance(lighting, np.ndarray):
            out = np.zeros((n, 3))
            k = min(n, lighting.shape[0])
            out[:k] = lighting[:k]
            return out
        return np.asarray(_core.sh_project(lighting, bands, max(self.env_samples, bands)), dtype=np.float64)

    def relight(self, env, bands=None, clamp=True) -> Relit:
        """The image under the lighting `env`, from the kept transfer."""
        bands = self.bands if bands is None else int(bands)
        if not 1 <= bands <= self.bands:
            raise ValueError(f"relight: bands must be in 1..{self.bands} (the transfer's), got {bands}")
        t0 = time.perf_counter()
        lighting = self._lighting(env)
        tp = time.perf_counter()
        L = self._project(lighting, bands)
        t1 = time.perf_counter()
        n = bands * bands
        h, w, e = self.transfer.shape[:3]
        out = np.empty((h, w, e, 3), dtype=np.float64)
        for c in range(3):
            out[..., c] = (self._by_channel[c][:, :n] @ L[:, c].astype(np.float32)).reshape(h, w, e)
        clamped = int((out < 0).sum()) if clamp else 0
        if clamp:
            np.maximum(out, 0.0, out=out)
        effects = {e: out[:, :, k, :].astype(np.float32) for k, e in enumerate(PRT_EFFECTS)}
        image = out.sum(axis=2).astype(np.float32)
        t2 = time.perf_counter()
        return Relit(image=image, effects=effects, coefficients=L, bands=bands, clamped=clamped,
                     seconds={"load": tp - t0, "project": t1 - tp, "dot": t2 - t1})
