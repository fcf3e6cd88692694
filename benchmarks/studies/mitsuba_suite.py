"""Measurement (not a test): how much of Mitsuba 3's own render test suite
(../shared/peers/mitsuba-data, its README) the loader reads.

For every scene `tests/scenes/*/*.xml` it calls `radiometer.load_file` as
Mitsuba's test_renders.py loads it (the integrator is the last `_` part of
the file name, passed as $integrator where the file uses it) and records
whether it loads or the first line of the SceneError: the first feature that
blocks it. A static scan of each scene (its <include>s followed) lists every
plugin type the loader's plugin table lacks, so the table also counts what
blocks beyond the first error.

    python -m radiometer.benchmarks.studies.mitsuba_suite [PATH] [--json [OUT]] [--render [--fresh]]

With --render, every scene that loads is rendered with its own integrator
at spp = 2,000,000 // pixels, seed 0, and judged by Mitsuba's test
(src/render/tests/test_renders.py): image, reference and reference variance
in XYZ (the references were made in XYZ and stored as RGB; the test converts
both back with the linear sRGB-to-XYZ matrix, which makes the variances
those of XYZ again), z = |ours - ref| sqrt(spp / max(ref_var, 1e-4)) per
pixel and channel, two-sided p, Sidak level 1 - 0.99^(1 / pixels); it
passes when the rejected pixel-channels number at most 0.75 % of the pixels.
With --fresh, each rendered scene also gets the second test, which counts
both renderers' variances against a fresh Mitsuba render (`radiometer refs
--suite` makes them; see "the second test" below).

PATH defaults to ../shared/peers/mitsuba-data beside the repository. Prints
a table per scene and the feature counts; with --json writes them in the
studies' layout (studies/record.py). Only the loader's public entry points
and its plugin table are used, so the script also measures older builds.
"""
from __future__ import annotations

import argparse
import collections
import os
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

_CATEGORIES = ("shape", "bsdf", "emitter", "sensor", "film", "rfilter", "sampler", "integrator", "medium", "phase",
               "volume", "subsurface", "texture")


def default_path() -> Path:
    return Path(__file__).resolve().parents[2].parent / "shared" / "peers" / "mitsuba-data"


def scenes(root: Path) -> list:
    return sorted((root / "tests" / "scenes").glob("*/*.xml"))


def _blockers(path: Path, plugins: dict) -> list:
    """Every plugin type outside `plugins` in the scene, <include>s followed
    (folders from <path>, then the scene's)."""
    search = [path.parent]
    found = []

    def resolve(name, base):
        for d in [*search, base]:
            if (d / name).exists():
                return d / name
        return None

    def walk(elem, src, depth):
        for c in elem:
            if not isinstance(c.tag, str):
                continue
            if c.tag == "path" and depth == 0:
                p = Path(c.get("value", ""))
                p = p if p.is_absolute() else (src.parent / p)
                search.insert(0, p.resolve())
            elif c.tag == "include":
                inc = resolve(c.get("filename", ""), src.parent)
                if inc is not None:
                    try:
                        walk(ET.parse(inc).getroot(), inc, depth)
                    except (ET.ParseError, RecursionError):
                        found.append("unreadable include")
            elif c.tag in _CATEGORIES and "type" in c.attrib:
                t = c.get("type")
                if not t.startswith("$") and t not in plugins.get(c.tag, ()):
                    found.append(f"{c.tag} {t}")
                walk(c, src, depth + 1)
            else:
                walk(c, src, depth + 1)

    try:
        walk(ET.parse(path).getroot(), path, 0)
    except ET.ParseError:
        found.append("unreadable XML")
    return sorted(set(found))


def _first_line(msg: str, path: Path) -> str:
    """The SceneError's message without its file:line place."""
    line = msg.splitlines()[0] if msg else ""
    return re.sub(r"^\S+?:\d+: ", "", line).replace(str(path.parent) + os.sep, "")


def _load(path: Path):
    """The scene as Mitsuba's test loads it: $integrator from the file name
    when the file takes it."""
    from radiometer.loader import SceneError, load_file

    try:
        return load_file(path, integrator=path.stem.rsplit("_", 1)[-1])
    except SceneError as e:
        if "never used" not in str(e):
            raise
        return load_file(path)  # the file does not take $integrator


def _render(path: Path, threads: int = 0, change=None, spp=None):
    """Our render of a suite scene at Mitsuba's test budget (spp =
    2,000,000 // pixels, seed 0), or at `spp`. `change` (a power check): a
    function that alters the loaded scene description in place first."""
    import warnings

    import radiometer as rm

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        desc = _load(path)
        if change is not None:
            change(desc)
        return rm.render(rm.Scene(desc), spp=spp or _suite_spp(desc), seed=0, threads=threads)


def _sidak(z, pixels: int, df=None) -> dict:
    """Mitsuba's decision on |z| per pixel and channel: two-sided p (normal,
    or Student's t with `df` degrees of freedom per pixel-channel), Sidak
    level 1 - 0.99^(1 / pixels), pass when at most 0.75 % of the pixels'
    worth of pixel-channels are rejected."""
    from scipy import stats

    level = 1 - 0.99 ** (1 / pixels)
    p = 2 * (stats.norm.sf(z) if df is None else stats.t.sf(z, df))
    rejected = int((p < level).sum())
    allowed = 0.0075 * pixels
    return {"rejected": rejected, "allowed": allowed, "passes": bool(rejected <= allowed)}


# Linear sRGB (Rec. 709 primaries, D65) to CIE XYZ, as Mitsuba's Bitmap converts.
_RGB_TO_XYZ = ((0.412453, 0.357580, 0.180423), (0.212671, 0.715160, 0.072169), (0.019334, 0.119193, 0.950227))


_PROTOCOL_CACHE = {}  # (path, threads) -> protocol's row of the scene as it is: renders are deterministic


def protocol(path: Path, threads: int = 0, change=None, res=None) -> dict:
    """Mitsuba's test on one scene (see the module docstring) of our render
    (made here unless `res` is given). `change` (a power check): a function
    that alters the loaded scene description in place before it is
    rendered. The row of an unchanged scene rendered here is kept for the
    process (a seed's render is the same bytes whatever the thread count),
    so the tests that check one scene's feature and the test of the whole
    suite share one render."""
    key = (str(Path(path).resolve()), threads)
    if change is None and res is None and key in _PROTOCOL_CACHE:
        return dict(_PROTOCOL_CACHE[key])
    row = _protocol(path, threads, change, res)
    if change is None and res is None:
        _PROTOCOL_CACHE[key] = dict(row)
    return row


def _protocol(path: Path, threads: int, change, res) -> dict:
    import numpy as np

    from radiometer.exr import read_exr

    res = res if res is not None else _render(path, threads, change)
    h, w = res.image.shape[:2]
    spp = res.spp
    name = path.stem.rsplit("_", 1)[0]
    ref = read_exr(path.parent / "refs" / f"{name}_ref_rgb.exr").image
    var = read_exr(path.parent / "refs" / f"{name}_ref_rgb_var.exr").image
    m = np.array(_RGB_TO_XYZ)
    ours, ref, var = (a.astype(np.float64) @ m.T for a in (res.image, ref, var))
    z = np.abs(ours - ref) * np.sqrt(spp / np.maximum(var, 1e-4))
    return {"spp": spp, "seconds": round(res.seconds, 1), **_sidak(z, h * w),
            "mean_ratio": float(ours[..., 1].mean() / ref[..., 1].mean()),
            "negative_ref_var": int((var < 0).sum())}


# -- the second test: both variances, against a fresh Mitsuba render ------------
#
# Mitsuba's protocol scales each difference by the reference's per-sample
# variance, which presumes that the renderer under test has Mitsuba's
# variance: an estimator that is right but noisier (another sampling
# strategy) fails it, and a reference whose variance file is itself noisy
# (32,000 samples of a heavy-tailed estimator; negative "variances" where
# XYZ was stored as RGB) misjudges either way. The second test counts both
# variances, each measured: ours (res.variance, the variance of our
# pixel mean) and a fresh Mitsuba render's (`radiometer refs --suite`: the
# mean of R independent renders and the variance of that mean from their
# spread, reference_scenes/make_reference.py), per pixel and channel in
# linear RGB, z = (ours - ref) / sqrt(var_ours + var_ref), with Mitsuba's
# Sidak level and 0.75 % rule (_sidak). Both variances are estimates, the
# reference's from only R runs: z then follows Student's t with the
# Welch-Satterthwaite degrees of freedom (var_o + var_r)^2 / (var_o^2 / d_o
# + var_r^2 / d_r), d_r = R - 1 and d_o = spp - 1 for a camera driver, 31
# for the light driver's 32 batch means (renderer/render/light_render.cpp).
# Under the normal quantile instead, a pixel whose variance is mostly the
# reference's 4-run estimate is rejected far too often. And a variance
# estimated from samples misses rare events: on projector_constant_direct a
# pixel next to the projector's frustum edge has 868 samples of which ~1.5
# fall outside (value 0, through the Gaussian filter's tail), so in about a
# fifth of those pixels none does, and the pixel reads 1 with variance 0
# while Mitsuba's (splatted) render reads 0.9983: 48 of 17.3 allowed
# rejected, every one such a pixel. Each variance therefore is its own or
# the mean over its 3 x 3 neighbourhood (per channel), whichever is larger:
# a pixel's unseen rare events are its neighbours' seen ones. (The
# neighbourhood's largest instead cost most of the test's power: the
# envmap 10 % darker on hetero_sigmat_albedo fell from 633 to 48 rejected.)

FRESH_RUNS, FRESH_SPP_FACTOR = 4, 2  # default fresh reference: 4 runs, together 8x the test's spp


def fresh_path(results, path: Path) -> Path:
    """Where `radiometer refs --suite` keeps the fresh reference of a suite
    scene: RESULTS/refs/mitsuba_suite/<folder>/<scene>.exr."""
    return Path(results) / "refs" / "mitsuba_suite" / path.parent.name / f"{path.stem}.exr"


def suite_spp(path: Path) -> int:
    """Mitsuba's test budget for the scene: 2,000,000 // pixels."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        desc = _load(path)
    return _suite_spp(desc)


def _suite_spp(desc) -> int:
    return 2_000_000 // (desc.sensor.height * desc.sensor.width)


def make_fresh(path: Path, out: Path, runs: int = FRESH_RUNS, spp: int | None = None,
               variant: str = "llvm_ad_rgb", first_seed: int = 1000, progress: bool = False) -> dict:
    """A fresh Mitsuba 3 reference of one suite scene, rendered as its test
    renders it (its own integrator as $integrator), `runs` renders of
    `spp` (default: FRESH_SPP_FACTOR x the test's spp) from seed
    `first_seed` on; writes `out` and returns its metadata."""
    from radiometer.reference_scenes.make_reference import make_mitsuba_reference

    spp = spp or FRESH_SPP_FACTOR * suite_spp(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    _, _, meta = make_mitsuba_reference(path, out, runs=runs, spp=spp, variant=variant, progress=progress,
                                        scene_note=f"Mitsuba's render test suite scene {path.parent.name}/"
                                                   f"{path.name}", first_seed=first_seed,
                                        xml_params={"integrator": path.stem.rsplit("_", 1)[-1]})
    return meta


def both_variances(path: Path, ref_exr: Path, threads: int = 0, change=None, res=None) -> dict:
    """The second test (above) of our render (made here unless `res` is
    given) against the fresh reference `ref_exr`. Also reports the ratio of
    our per-sample variance to Mitsuba's (median over pixel-channels where
    both are positive): what our estimator costs in samples for the same
    noise on this scene."""
    import numpy as np

    from radiometer.exr import read_exr

    res = res if res is not None else _render(path, threads, change)
    ref = read_exr(ref_exr)
    m = ref.metadata
    ours, vo = res.image.astype(np.float64), np.asarray(res.variance, np.float64)
    if vo.ndim == 2:
        vo = vo[..., None]
    mean, vr = ref.image.astype(np.float64), ref.variance.astype(np.float64)
    if vr.ndim == 2:
        vr = vr[..., None]
    if mean.shape != ours.shape:
        raise ValueError(f"{ref_exr}: reference is {mean.shape[1]} x {mean.shape[0]}, our render "
                         f"{ours.shape[1]} x {ours.shape[0]}")
    from scipy.ndimage import uniform_filter

    ratio_o, ratio_r = vo * res.spp, vr  # before pooling, for the variance ratio below
    vo, vr = (np.maximum(v, uniform_filter(v, size=(3, 3, 1), mode="nearest")) for v in (vo, vr))
    # Mitsuba's floor on the per-sample variance (1e-4), as a variance of our mean.
    floor = 1e-4 / res.spp
    z = np.abs(ours - mean) / np.sqrt(np.maximum(vo + vr, floor))
    ref_spp = int(m.get("total_spp", 0))
    from radiometer.registry import estimator

    d_o = res.spp - 1 if estimator(res.integrator["type"])["capabilities"]["driver"] == "camera" else 31
    d_r = int(m.get("runs", 2)) - 1
    with np.errstate(divide="ignore", invalid="ignore"):
        df = (vo + vr) ** 2 / (vo ** 2 / d_o + vr ** 2 / d_r)
    df = np.where(np.isfinite(df) & (vo + vr > floor), np.clip(df, min(d_o, d_r), d_o + d_r), np.inf)
    both = (ratio_o > 0) & (ratio_r > 0)
    ratio = float(np.median(ratio_o[both] / (ratio_r * ref_spp)[both])) if both.any() and ref_spp else None
    h, w = ours.shape[:2]
    return {"spp": res.spp, "ref_spp": ref_spp, "ref_variant": m.get("variant"), **_sidak(z, h * w, df),
            "mean_ratio": float(ours.mean() / max(mean.mean(), 1e-30)),
            "variance_ratio": None if ratio is None else round(ratio, 3)}


def survey(root: Path, render: bool = False, threads: int = 0, fresh=None, fresh_runs: int = FRESH_RUNS,
           fresh_spp=None, variant: str = "llvm_ad_rgb") -> list:
    """A row per scene: loads or the first error, the static blockers; with
    `render`, Mitsuba's test of our render; with `fresh` (a results folder)
    also the second test against the fresh reference kept there (made
    first when missing: `fresh_runs` Mitsuba renders of `fresh_spp`)."""
    import warnings

    from radiometer.loader import PLUGINS, SceneError

    rows = []
    for path in scenes(root):
        integrator = path.stem.rsplit("_", 1)[-1]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                _load(path)
                status = "loads"
            except SceneError as e:
                status = _first_line(str(e), path)
        blockers = _blockers(path, PLUGINS)
        if integrator not in PLUGINS["integrator"]:  # the one the test passes as $integrator
            blockers.append(f"integrator {integrator}")
        rows.append({"scene": str(path.relative_to(root / "tests" / "scenes")), "status": status,
                     "blockers": blockers})
        if render and status == "loads":
            res = _render(path, threads)
            rows[-1]["protocol"] = protocol(path, res=res)
            if fresh is not None:
                ref = fresh_path(fresh, path)
                if not ref.exists():
                    print(f"{rows[-1]['scene']}: fresh Mitsuba reference -> {ref}", file=sys.stderr, flush=True)
                    make_fresh(path, ref, fresh_runs, fresh_spp, variant)
                rows[-1]["both_variances"] = both_variances(path, ref, res=res)
    return rows


def _print(rows: list) -> None:
    w = max(len(r["scene"]) for r in rows)
    for r in rows:
        print(f"{r['scene']:<{w}}  {r['status'][:110]}")
        if "protocol" in r:
            p = r["protocol"]
            print(f"{'':<{w}}    Mitsuba's test: {'passes' if p['passes'] else 'FAILS'}, rejected {p['rejected']} / "
                  f"allowed {p['allowed']:.2f} pixel-channels, {p['spp']} spp, {p['seconds']} s, mean Y ours / ref "
                  f"{p['mean_ratio']:.4f}")
        if "both_variances" in r:
            b = r["both_variances"]
            print(f"{'':<{w}}    both variances, fresh Mitsuba ({b['ref_spp']} spp, {b['ref_variant']}): "
                  f"{'passes' if b['passes'] else 'FAILS'}, rejected {b['rejected']} / allowed {b['allowed']:.2f}, "
                  f"mean ours / ref {b['mean_ratio']:.4f}, per-sample variance ours / Mitsuba "
                  f"{b['variance_ratio']}")
    n_ok = sum(r["status"] == "loads" for r in rows)
    print(f"\n{n_ok} of {len(rows)} scenes load")
    first = collections.Counter(r["status"] for r in rows if r["status"] != "loads")
    print("\nfirst error (scenes):")
    for msg, n in first.most_common():
        print(f"  {n:3d}  {msg[:110]}")
    every = collections.Counter(b for r in rows for b in r["blockers"])
    print("\nunsupported plugin types, static scan (scenes needing each):")
    for feat, n in every.most_common():
        print(f"  {n:3d}  {feat}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("path", nargs="?", type=Path, help="the mitsuba-data folder (default: "
                    "../shared/peers/mitsuba-data beside the repository)")
    ap.add_argument("--json", nargs="?", const="default", help="write the rows to benchmarks/results/"
                    "mitsuba_suite.json (or the path given), the studies' layout")
    ap.add_argument("--render", action="store_true", help="also render each scene that loads under Mitsuba's "
                    "test protocol")
    ap.add_argument("--threads", type=int, default=0, help="render threads (0: all cores)")
    ap.add_argument("--fresh", nargs="?", const="out/results", help="with --render: also the second test "
                    "(both variances) against fresh Mitsuba references kept under FRESH/refs/mitsuba_suite "
                    "(made where missing, as `radiometer refs --suite` makes them; default out/results)")
    ap.add_argument("--fresh-runs", type=int, default=FRESH_RUNS, help="Mitsuba renders per fresh reference")
    ap.add_argument("--fresh-spp", type=int, help="spp per render (default: "
                    f"{FRESH_SPP_FACTOR} x the test's)")
    a = ap.parse_args(argv)
    a.path = a.path or default_path()
    if not (a.path / "tests" / "scenes").is_dir():
        print(f"mitsuba_suite: {a.path} holds no tests/scenes folder", file=sys.stderr)
        return 2
    if a.fresh and not a.render:
        print("mitsuba_suite: --fresh needs --render", file=sys.stderr)
        return 2
    rows = survey(a.path, render=a.render, threads=a.threads, fresh=a.fresh and Path(a.fresh),
                  fresh_runs=a.fresh_runs, fresh_spp=a.fresh_spp)
    _print(rows)
    if a.json:
        from radiometer.benchmarks.studies import record

        out = None if a.json == "default" else Path(a.json)
        print("wrote", record.write("mitsuba_suite", {"path": str(a.path), "render": a.render}, {"rows": rows},
                                    out=out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
