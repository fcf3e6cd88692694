"""Mitsuba 3 references for the canonical scenes (DESIGN section 4).

A reference is an EXR holding the mean of `runs` independent Mitsuba renders
(seeds 0 .. runs-1) and the variance of that mean, estimated from the spread
across the runs: var_mean = s^2 / runs with s^2 the unbiased sample variance.
The spread is measured between whole renders, never modelled, so it is valid
whatever Mitsuba does inside one render (its gaussian splatting correlates
neighbouring pixels, and its film divides by the summed filter weights, a
ratio estimator); only the per-pixel variance is used by the z-test.

    python -m radiometer.reference_scenes.make_reference cornell_box

regenerates reference_scenes/cornell_box/reference.exr (64 x 64, small enough
to commit) with the parameters and budget that reference_scenes/registry.py
gives it; `--res 128` makes its reference_128.exr where the registry
declares one (more_refs).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import importlib
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .registry import mitsuba_scenes


def _set_variant(mi, variant: str):
    """Sets `variant`, or falls back to scalar_rgb; returns (variant used, note)."""
    try:
        mi.set_variant(variant)
        return variant, ""
    except Exception as e:  # an unavailable variant raises ImportError or AttributeError
        if variant == "scalar_rgb":
            raise
        mi.set_variant("scalar_rgb")
        return "scalar_rgb", (f"requested variant {variant} unavailable ({type(e).__name__}: {e}); "
                              f"fell back to scalar_rgb")


def make_mitsuba_reference(scene_xml, out_exr, *, runs: int = 16, spp: int = 1024, variant: str = "llvm_ad_rgb",
                           progress: bool = True, integrator: dict | None = None, scene_note: str = "",
                           first_seed: int = 0, xml_params: dict | None = None, **scene_params):
    """Renders `scene_xml` with Mitsuba 3 `runs` times (seed = first_seed ..
    first_seed + runs-1,
    `spp` samples per pixel each) and writes to `out_exr` the mean image and
    the variance of that mean (sample variance across runs / runs).
    `scene_params` (and `xml_params`, for names that clash with this
    function's, such as $integrator) override the XML's <default>
    parameters; `integrator`, a
    Mitsuba plugin dict, replaces the XML's integrator; `scene_note`, when
    given, says in the metadata what Mitsuba rendered. Returns the
    ExrImage-like tuple (mean, var_mean, metadata)."""
    if runs < 2:
        raise ValueError(f"make_mitsuba_reference: need runs >= 2 to estimate a variance, got {runs}")
    if spp < 1:
        raise ValueError(f"make_mitsuba_reference: spp must be >= 1, got {spp}")
    import mitsuba as mi

    previous = mi.variant()
    used, note = _set_variant(mi, variant)
    try:
        return _render_runs(mi, used, note, variant, scene_xml, out_exr, runs, spp, progress, integrator, scene_note,
                            first_seed, {**(xml_params or {}), **scene_params})
    finally:
        # Mitsuba's variant is process-wide: the caller's (a test that set
        # scalar_rgb, say) is restored.
        if previous is not None and previous != mi.variant():
            mi.set_variant(previous)


def _render_runs(mi, used, note, variant, scene_xml, out_exr, runs, spp, progress, integrator, scene_note,
                 first_seed, scene_params):
    scene_xml = Path(scene_xml)
    scene = mi.load_file(str(scene_xml), **scene_params)
    integ = mi.load_dict(dict(integrator)) if integrator else scene.integrator()

    # Welford's running mean and sum of squared deviations, in double precision.
    mean = m2 = None
    t0 = time.perf_counter()
    for i in range(runs):
        img = np.array(mi.render(scene, integrator=integ, seed=first_seed + i, spp=spp), dtype=np.float64)
        if img.ndim != 3 or img.shape[2] < 3:
            raise ValueError(f"make_mitsuba_reference: expected an (H, W, 3) RGB film, got {img.shape}")
        img = img[..., :3]
        if mean is None:
            mean = np.zeros_like(img)
            m2 = np.zeros_like(img)
        delta = img - mean
        mean += delta / (i + 1)
        m2 += delta * (img - mean)
        if progress:
            el = time.perf_counter() - t0
            print(f"  run {i + 1}/{runs}: {spp} spp, {el:.1f} s elapsed, ~{el / (i + 1) * (runs - i - 1):.0f} s left",
                  file=sys.stderr, flush=True)
    seconds = time.perf_counter() - t0
    var_mean = m2 / (runs - 1) / runs

    meta = {
        "kind": "mitsuba reference: mean over runs, variance of that mean",
        "mitsuba_version": mi.__version__,
        "variant": used,
        "variant_requested": variant,
        "variant_note": note or "none",
        "spp_per_run": int(spp),
        "runs": int(runs),
        "total_spp": int(spp) * int(runs),
        "seeds": f"{first_seed}..{first_seed + runs - 1}",
        "scene": scene_xml.name,
        "scene_note": scene_note or "the scene's XML",
        "scene_params": json.dumps(scene_params, sort_keys=True),
        "integrator": json.dumps(integrator, sort_keys=True) if integrator else "the scene's",
        "seconds": float(seconds),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "host": f"{platform.system()} {platform.machine()} {platform.python_version()}",
    }
    from radiometer import write_exr

    write_exr(out_exr, None, image=mean.astype(np.float32), variance=var_mean.astype(np.float32), **meta)
    return mean, var_mean, meta


def mitsuba_xml(spec, tmp: Path):
    """(the XML Mitsuba renders for `spec`, a note on it): the scene's own,
    or what its registry `mitsuba_writer` writes into the folder `tmp`."""
    if not spec.mitsuba_writer:
        return spec.xml, ""
    mod, fn = spec.mitsuba_writer.split(":")
    writer = getattr(importlib.import_module(f"radiometer.reference_scenes.{spec.folder}.{mod}"), fn)
    return Path(writer(tmp / spec.xml.name)), f"{spec.folder}/{mod}.py {fn}: {writer.__doc__.split(chr(10))[0]}"


def make_scene_reference(spec, res=None, runs=None, spp=None, variant: str = "llvm_ad_rgb", out=None,
                         progress: bool = True):
    """Makes the Mitsuba reference of registry scene `spec` at resolution
    `res` (None: the registry's own; otherwise one its more_refs declares)
    with that resolution's budget unless `runs` / `spp` are given, into
    `out` (default: the committed file, spec.reference_file(res)). The one
    path both this module's command and `radiometer refs` take. Returns
    (out, var_mean, metadata)."""
    r_runs, r_spp, _ = spec.budget(res)  # ValueError naming the resolutions with a reference
    first_seed = spec.first_seed(res)
    runs, spp = runs or r_runs, spp or r_spp
    out = Path(out) if out else spec.reference_file(res)
    params = dict(spec.fixed_params)
    if res is not None:
        params["res"] = int(res)
    print(f"{spec.name}: {runs} runs x {spp} spp, params {params}, variant {variant} -> {out}", file=sys.stderr)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        xml, note = mitsuba_xml(spec, Path(tmp))
        _, var_mean, meta = make_mitsuba_reference(xml, out, runs=runs, spp=spp, variant=variant,
                                                   integrator=spec.mitsuba_integrator, scene_note=note,
                                                   progress=progress, first_seed=first_seed, **params)
    return out, var_mean, meta


def main(argv=None):
    scenes = mitsuba_scenes()
    ap = argparse.ArgumentParser(prog="python -m radiometer.reference_scenes.make_reference",
                                 description="Regenerates the committed Mitsuba 3 reference of a canonical scene.")
    ap.add_argument("scene", choices=sorted(scenes), help="scene folder under reference_scenes/")
    ap.add_argument("--res", type=int, help="resolution (default: the scene's own; others as registry more_refs "
                                            "declares, written to reference_RES.exr)")
    ap.add_argument("--runs", type=int, help="independent Mitsuba renders (default: the scene's)")
    ap.add_argument("--spp", type=int, help="samples per pixel per run (default: the scene's)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("-o", "--out", help="output EXR (default: reference_scenes/SCENE/reference.exr)")
    args = ap.parse_args(argv)
    out, var_mean, meta = make_scene_reference(scenes[args.scene], args.res, args.runs, args.spp, args.variant,
                                               args.out)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KB) in {meta['seconds']:.0f} s with {meta['variant']}; "
          f"mean variance of the mean {var_mean.mean():.3g}", file=sys.stderr)


if __name__ == "__main__":
    main()
