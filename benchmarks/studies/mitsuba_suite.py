"""Measurement (not a test): how much of Mitsuba 3's own render test suite
(../shared/peers/mitsuba-data, its README) the loader reads.

For every scene `tests/scenes/*/*.xml` it calls `radiometer.load_file` as
Mitsuba's test_renders.py loads it (the integrator is the last `_` part of
the file name, passed as $integrator where the file uses it) and records
whether it loads or the first line of the SceneError: the first feature that
blocks it. A static scan of each scene (its <include>s followed) lists every
plugin type the loader's plugin table lacks, so the table also counts what
blocks beyond the first error.

    python -m radiometer.benchmarks.studies.mitsuba_suite [PATH] [--json [OUT]] [--render]

With --render, every scene that loads is rendered with its own integrator
at spp = 2,000,000 // pixels, seed 0, and judged by Mitsuba's test
(src/render/tests/test_renders.py): image, reference and reference variance
in XYZ (the references were made in XYZ and stored as RGB; the test converts
both back with the linear sRGB-to-XYZ matrix, which makes the variances
those of XYZ again), z = |ours - ref| sqrt(spp / max(ref_var, 1e-4)) per
pixel and channel, two-sided p, Sidak level 1 - 0.99^(1 / pixels); it
passes when the rejected pixel-channels number at most 0.75 % of the pixels.

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


def protocol(path: Path, threads: int = 0, change=None) -> dict:
    """Mitsuba's test on one scene (see the module docstring). `change`
    (a power check): a function that alters the loaded scene description
    in place before it is rendered."""
    import warnings

    import numpy as np
    from scipy import stats

    import radiometer as rm
    from radiometer.exr import read_exr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        desc = _load(path)
        if change is not None:
            change(desc)
        h, w = desc.sensor.height, desc.sensor.width
        spp = 2_000_000 // (h * w)
        res = rm.render(rm.Scene(desc), spp=spp, seed=0, threads=threads)
    name = path.stem.rsplit("_", 1)[0]
    ref = read_exr(path.parent / "refs" / f"{name}_ref_rgb.exr").image
    var = read_exr(path.parent / "refs" / f"{name}_ref_rgb_var.exr").image
    # Linear sRGB (Rec. 709 primaries, D65) to CIE XYZ, as Mitsuba's Bitmap converts.
    m = np.array([[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]])
    ours, ref, var = (a.astype(np.float64) @ m.T for a in (res.image, ref, var))
    z = np.abs(ours - ref) * np.sqrt(spp / np.maximum(var, 1e-4))
    level = 1 - 0.99 ** (1 / (h * w))
    rejected = int((2 * stats.norm.sf(z) < level).sum())
    allowed = 0.0075 * h * w
    return {"spp": spp, "seconds": round(res.seconds, 1), "rejected": rejected, "allowed": allowed,
            "passes": bool(rejected <= allowed), "mean_ratio": float(ours[..., 1].mean() / ref[..., 1].mean()),
            "negative_ref_var": int((var < 0).sum())}


def survey(root: Path, render: bool = False, threads: int = 0) -> list:
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
            rows[-1]["protocol"] = protocol(path, threads)
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
    a = ap.parse_args(argv)
    a.path = a.path or default_path()
    if not (a.path / "tests" / "scenes").is_dir():
        print(f"mitsuba_suite: {a.path} holds no tests/scenes folder", file=sys.stderr)
        return 2
    rows = survey(a.path, render=a.render, threads=a.threads)
    _print(rows)
    if a.json:
        from radiometer.benchmarks.studies import record

        out = None if a.json == "default" else Path(a.json)
        print("wrote", record.write("mitsuba_suite", {"path": str(a.path), "render": a.render}, {"rows": rows},
                                    out=out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
