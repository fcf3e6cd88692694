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
to commit).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

# Per scene: XML parameters and budget of the committed reference. Committed
# files stay small: at most 256 px a side (64 x 64 keeps the EXR ~100 KB).
SCENES = {
    "cornell_box": {
        "params": {"res": 64, "max_depth": 8},
        # 32 x 2048 = 65536 spp in total: the reference's variance is 1/256 of
        # a 256 spp test render's, so it barely widens the z-test. About
        # 3-4 minutes with llvm_ad_rgb on 2 cores.
        "runs": 32,
        "spp": 2048,
    },
    # The canonical scenes of issue 3 (card.md in each folder says what they
    # isolate). Box-filtered, so a sample lands in one pixel and Mitsuba's
    # pixels are independent (its box filter splats nowhere else). Budgets
    # and times: llvm_ad_rgb on 2 shared cores.
    "glass_sphere_caustic": {
        "params": {"res": 64, "max_depth": 12},
        "runs": 32,
        "spp": 16384,  # 524288 spp in all, ~2.5 min
    },
    "veach_mis": {
        "params": {"res": 64, "max_depth": 8},
        "runs": 32,
        "spp": 8192,  # 262144 spp, ~3 min
    },
    "ajar_door": {
        "params": {"res": 64, "max_depth": 10},
        # Mitsuba's light tracer, not its path tracer: the near room is lit
        # only by a narrow strip the lamp throws through the door's gap, which
        # a camera path finds by BSDF sampling less than 1 time in 100 per
        # bounce, while every light path that leaves the far room lands on
        # it first. All surfaces are diffuse, so light tracing sees
        # every path (card.md: its cross-check against Mitsuba's path).
        "integrator": {"type": "ptracer", "max_depth": 10},
        "runs": 32,
        "spp": 4096,
    },
    # Media and subsurface scenes: Mitsuba's volpath only; our loader rejects
    # <medium> until issue 6, and their tests are skipped until then.
    "homogeneous_slab": {
        "params": {"res": 64, "max_depth": 8},
        "runs": 32,
        "spp": 4096,
    },
    "fog_room": {
        "params": {"res": 64, "max_depth": 16},
        "runs": 32,
        "spp": 1024,
    },
    "vandehulst_slab": {
        "params": {"max_depth": 256},  # a 1 x 1 irradiancemeter film
        "runs": 32,
        "spp": 524288,
    },
    "vandehulst_slab_reflectance": {
        "params": {"max_depth": 256},  # a 1 x 1 irradiancemeter film
        "runs": 32,
        "spp": 524288,
    },
    "translucent_slab": {
        "params": {"res": 64, "max_depth": 1024},
        "runs": 32,
        "spp": 256,
    },
    "translucent_object": {
        "params": {"res": 64, "max_depth": 512},
        "runs": 32,
        "spp": 1024,
    },
    "volumetric_caustic": {
        "params": {"res": 64, "max_depth": 12},
        "runs": 32,
        "spp": 2048,
    },
}


def _set_variant(mi, variant: str):
    """Sets `variant`, or falls back to scalar_rgb; returns (variant used, note)."""
    try:
        mi.set_variant(variant)
        return variant, ""
    except Exception as e:  # an unavailable variant raises ImportError or AttributeError
        if variant == "scalar_rgb":
            raise
        mi.set_variant("scalar_rgb")
        return "scalar_rgb", f"requested variant {variant} unavailable ({type(e).__name__}: {e}); fell back to scalar_rgb"


def make_mitsuba_reference(scene_xml, out_exr, *, runs: int = 16, spp: int = 1024, variant: str = "llvm_ad_rgb",
                           progress: bool = True, integrator: dict | None = None, **scene_params):
    """Renders `scene_xml` with Mitsuba 3 `runs` times (seed = 0 .. runs-1,
    `spp` samples per pixel each) and writes to `out_exr` the mean image and
    the variance of that mean (sample variance across runs / runs).
    `scene_params` override the XML's <default> parameters; `integrator`, a
    Mitsuba plugin dict, replaces the XML's integrator. Returns the
    ExrImage-like tuple (mean, var_mean, metadata)."""
    if runs < 2:
        raise ValueError(f"make_mitsuba_reference: need runs >= 2 to estimate a variance, got {runs}")
    if spp < 1:
        raise ValueError(f"make_mitsuba_reference: spp must be >= 1, got {spp}")
    import mitsuba as mi

    used, note = _set_variant(mi, variant)
    scene_xml = Path(scene_xml)
    scene = mi.load_file(str(scene_xml), **scene_params)
    integ = mi.load_dict(dict(integrator)) if integrator else scene.integrator()

    # Welford's running mean and sum of squared deviations, in double precision.
    mean = m2 = None
    t0 = time.perf_counter()
    for i in range(runs):
        img = np.array(mi.render(scene, integrator=integ, seed=i, spp=spp), dtype=np.float64)
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
        "seeds": f"0..{runs - 1}",
        "scene": scene_xml.name,
        "scene_params": json.dumps(scene_params, sort_keys=True),
        "integrator": json.dumps(integrator, sort_keys=True) if integrator else "the scene's",
        "seconds": float(seconds),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "host": f"{platform.system()} {platform.machine()} {platform.python_version()}",
    }
    from radiometer import write_exr

    write_exr(out_exr, None, image=mean.astype(np.float32), variance=var_mean.astype(np.float32), **meta)
    return mean, var_mean, meta


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m radiometer.reference_scenes.make_reference",
                                 description="Regenerates the committed Mitsuba 3 reference of a canonical scene.")
    ap.add_argument("scene", choices=sorted(SCENES), help="scene folder under reference_scenes/")
    ap.add_argument("--runs", type=int, help="independent Mitsuba renders (default: the scene's)")
    ap.add_argument("--spp", type=int, help="samples per pixel per run (default: the scene's)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("-o", "--out", help="output EXR (default: reference_scenes/SCENE/reference.exr)")
    args = ap.parse_args(argv)
    cfg = SCENES[args.scene]
    runs = args.runs or cfg["runs"]
    spp = args.spp or cfg["spp"]
    out = Path(args.out) if args.out else HERE / args.scene / "reference.exr"
    print(f"{args.scene}: {runs} runs x {spp} spp, params {cfg['params']}, variant {args.variant} -> {out}",
          file=sys.stderr)
    _, var_mean, meta = make_mitsuba_reference(HERE / args.scene / "scene.xml", out, runs=runs, spp=spp,
                                               variant=args.variant, integrator=cfg.get("integrator"),
                                               **cfg["params"])
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KB) in {meta['seconds']:.0f} s with {meta['variant']}; "
          f"mean variance of the mean {var_mean.mean():.3g}", file=sys.stderr)


if __name__ == "__main__":
    main()
