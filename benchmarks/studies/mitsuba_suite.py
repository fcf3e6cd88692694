"""Measurement (not a test): how much of Mitsuba 3's own render test suite
(../shared/peers/mitsuba-data, its README) the loader reads.

For every scene `tests/scenes/*/*.xml` it calls `radiometer.load_file` as
Mitsuba's test_renders.py loads it (the integrator is the last `_` part of
the file name, passed as $integrator where the file uses it) and records
whether it loads or the first line of the SceneError: the first feature that
blocks it. A static scan of each scene (its <include>s followed) lists every
plugin type the loader's plugin table lacks, and non-uniform spectra, so the
table also counts what blocks beyond the first error.

    python -m radiometer.benchmarks.studies.mitsuba_suite [PATH] [--json [OUT]]

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
    """Every plugin type outside `plugins` and every non-uniform spectrum in
    the scene, <include>s followed (folders from <path>, then the scene's)."""
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
            elif c.tag == "spectrum" and (":" in c.get("value", "") or "filename" in c.attrib):
                found.append("spectrum (non-uniform)")
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


def survey(root: Path) -> list:
    import warnings

    from radiometer.loader import PLUGINS, SceneError, load_file

    rows = []
    for path in scenes(root):
        integrator = path.stem.rsplit("_", 1)[-1]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                try:
                    load_file(path, integrator=integrator)
                except SceneError as e:
                    if "never used" not in str(e):
                        raise
                    load_file(path)  # the file does not take $integrator
                status = "loads"
            except SceneError as e:
                status = _first_line(str(e), path)
        blockers = _blockers(path, PLUGINS)
        if integrator not in PLUGINS["integrator"]:  # the one the test passes as $integrator
            blockers.append(f"integrator {integrator}")
        rows.append({"scene": str(path.relative_to(root / "tests" / "scenes")), "status": status,
                     "blockers": blockers})
    return rows


def _print(rows: list) -> None:
    w = max(len(r["scene"]) for r in rows)
    for r in rows:
        print(f"{r['scene']:<{w}}  {r['status'][:110]}")
    n_ok = sum(r["status"] == "loads" for r in rows)
    print(f"\n{n_ok} of {len(rows)} scenes load")
    first = collections.Counter(r["status"] for r in rows if r["status"] != "loads")
    print("\nfirst error (scenes):")
    for msg, n in first.most_common():
        print(f"  {n:3d}  {msg[:110]}")
    every = collections.Counter(b for r in rows for b in r["blockers"])
    print("\nunsupported plugin types and spectra, static scan (scenes needing each):")
    for feat, n in every.most_common():
        print(f"  {n:3d}  {feat}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("path", nargs="?", type=Path, help="the mitsuba-data folder (default: "
                    "../shared/peers/mitsuba-data beside the repository)")
    ap.add_argument("--json", nargs="?", const="default", help="write the rows to benchmarks/results/"
                    "mitsuba_suite.json (or the path given), the studies' layout")
    a = ap.parse_args(argv)
    a.path = a.path or default_path()
    if not (a.path / "tests" / "scenes").is_dir():
        print(f"mitsuba_suite: {a.path} holds no tests/scenes folder", file=sys.stderr)
        return 2
    rows = survey(a.path)
    _print(rows)
    if a.json:
        from radiometer.benchmarks.studies import record

        out = None if a.json == "default" else Path(a.json)
        print("wrote", record.write("mitsuba_suite", {"path": str(a.path)}, {"rows": rows}, out=out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
