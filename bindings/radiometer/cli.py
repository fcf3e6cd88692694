"""The `radiometer` command line.

  radiometer render SCENE [-i NAME] [--spp N | --seconds S] [-o out.exr]
  radiometer bench [MATRIX] | compare A B | report RUN | refs

SCENE is a Mitsuba 3 XML file or the name of a canonical scene
(`radiometer render cornell-box`).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import EFFECTS, RenderCancelled, SceneError, load_file, render, write_exr


def _scene_path(name: str) -> Path:
    p = Path(name)
    if p.exists():
        return p
    # A canonical scene by name: reference_scenes/<name with _>/scene.xml
    from importlib import resources

    root = Path(str(resources.files("radiometer.reference_scenes")))
    cand = root / name.replace("-", "_") / "scene.xml"
    if cand.exists():
        return cand
    known = sorted(d.name.replace("_", "-") for d in root.iterdir() if (d / "scene.xml").exists())
    raise SceneError(f"{name}: no such file, and not a canonical scene (known: {', '.join(known)})")


class _Progress:
    """A progress bar on stderr for renders longer than a second (tqdm)."""

    def __init__(self, desc):
        self.desc = desc
        self.bar = None
        self.t0 = time.monotonic()

    def __call__(self, done, total):
        if self.bar is None:
            if time.monotonic() - self.t0 < 1.0:
                return
            from tqdm import tqdm

            # disable=None: no bar when stderr is not a terminal (CI logs).
            self.bar = tqdm(total=total or None, initial=done, desc=self.desc, unit="spl", unit_scale=True,
                            file=sys.stderr, leave=False, disable=None, mininterval=0.25)
        self.bar.n = done
        self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _parse_integrator(arg):
    if arg is None:
        return None
    arg = arg.strip()
    if arg.startswith("{"):
        try:
            return json.loads(arg)
        except json.JSONDecodeError as e:
            raise SceneError(f"-i: not valid JSON ({e})") from None
    return arg


def cmd_render(a) -> int:
    scene = load_file(_scene_path(a.scene))
    integrator = _parse_integrator(a.integrator)
    if a.max_depth is not None:
        from .render import _integrator_desc

        spec = _integrator_desc(integrator, scene.desc.integrator)
        spec["max_depth"] = a.max_depth
        integrator = spec
    effects = a.effects.split(",") if a.effects else None
    out = Path(a.output)
    if not out.parent.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
    bar = _Progress(f"render {Path(a.scene).stem}")
    try:
        res = render(scene, integrator=integrator, spp=a.spp, seconds=a.seconds, seed=a.seed, threads=a.threads,
                     effects=effects, progress=bar)
    except RenderCancelled as e:
        bar.close()
        res = e.result
        if res.spp == 0:
            print("cancelled before any pass finished; nothing written", file=sys.stderr)
            return 130
        part = out.with_name(out.stem + ".partial.exr")
        write_exr(part, res)
        print(f"cancelled: wrote the {res.spp} spp finished so far to {part}", file=sys.stderr)
        return 130
    bar.close()
    write_exr(out, res, scene=str(a.scene))
    st = res.stats
    print(f"{out}: {res.image.shape[1]}x{res.image.shape[0]}, {res.integrator['type']}, {res.spp} spp, "
          f"{res.seconds:.2f} s, {st['rays'] / max(res.seconds, 1e-9) / 1e6:.1f} Mrays/s, "
          f"NaN samples {st['nan_samples']}, Inf samples {st['inf_samples']}")
    if res.strategies:
        from .analysis.strategies import strategy_pyramid

        for weighted in (False, True):
            png = out.with_name(out.stem + ("_strategies_weighted.png" if weighted else "_strategies.png"))
            strategy_pyramid(res, png, weighted=weighted)
            print(f"  per-strategy images ({'MIS-weighted' if weighted else 'unweighted'}): {png}")
    means = ", ".join(f"{k} {float(v.mean()):.4g}" for k, v in res.effects.items() if float(abs(v).max()) > 0)
    print(f"  mean radiance {float(res.image.mean()):.5g} (std. error {float(res.variance.mean()) ** 0.5 / res.image[..., 0].size ** 0.5:.2g}); "
          f"by effect: {means}")
    return 0


def cmd_refs(a) -> int:
    """Regenerates the Mitsuba 3 references of the canonical scenes."""
    from .reference_scenes.make_reference import HERE, SCENES, make_mitsuba_reference

    names = a.scenes or sorted(SCENES)
    unknown = [n for n in names if n not in SCENES]
    if unknown:
        raise SceneError(f"refs: no Mitsuba reference is defined for {', '.join(unknown)} "
                         f"(known: {', '.join(sorted(SCENES))})")
    if a.list:
        for n in names:
            cfg = SCENES[n]
            ref = HERE / n / "reference.exr"
            state = "missing"
            if ref.exists():
                from . import read_exr

                m = read_exr(ref).metadata
                state = (f"{m.get('total_spp', '?')} spp, Mitsuba {m.get('mitsuba_version', '?')} "
                         f"{m.get('variant', '?')}, {m.get('date', '?')}")
            print(f"{n}: {cfg['runs']} runs x {cfg['spp']} spp, params {cfg['params']} -- {state}")
        return 0
    out_dir = Path(a.out_dir) if a.out_dir else None
    for n in names:
        cfg = SCENES[n]
        runs, spp = a.runs or cfg["runs"], a.spp or cfg["spp"]
        out = (out_dir / n / "reference.exr") if out_dir else HERE / n / "reference.exr"
        out.parent.mkdir(parents=True, exist_ok=True)
        print(f"{n}: {runs} runs x {spp} spp with Mitsuba {a.variant} -> {out}", file=sys.stderr)
        _, var, meta = make_mitsuba_reference(HERE / n / "scene.xml", out, runs=runs, spp=spp, variant=a.variant,
                                              **cfg["params"])
        print(f"  wrote {out} in {meta['seconds']:.0f} s ({meta['variant']}); mean variance {var.mean():.3g}")
    return 0


def _not_yet(what, issue):
    def run(a) -> int:
        print(f"radiometer {what}: not implemented yet (tracked in issue {issue})", file=sys.stderr)
        return 2

    return run


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="radiometer", description="Physically based validation and benchmark suite")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render", help="render a scene to EXR (image, variance and effect layers)")
    r.add_argument("scene", help="Mitsuba 3 XML file, or a canonical scene name such as cornell-box")
    r.add_argument("-i", "--integrator", help="estimator name (direct, path, ptracer, bdpt) or a JSON dict like the XML's")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--spp", type=int, help="samples per pixel (default: the scene's sampler)")
    g.add_argument("--seconds", type=float, help="wall-clock budget in seconds")
    r.add_argument("--max-depth", type=int, help="override the estimator's max_depth")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--threads", type=int, default=0, help="0 = all cores")
    r.add_argument("--effects", help=f"comma-separated subset of: {','.join(EFFECTS)}")
    r.add_argument("-o", "--output", default="out.exr")
    r.set_defaults(func=cmd_render)
    f = sub.add_parser("refs", help="regenerate the Mitsuba 3 references of the canonical scenes")
    f.add_argument("scenes", nargs="*", help="scene folders (default: every scene with a Mitsuba reference)")
    f.add_argument("--runs", type=int, help="independent Mitsuba renders (default: the scene's)")
    f.add_argument("--spp", type=int, help="samples per pixel per run (default: the scene's)")
    f.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (falls back to scalar_rgb)")
    f.add_argument("--out-dir", help="write under this folder instead of reference_scenes/")
    f.add_argument("--list", action="store_true", help="list the references and how they were made")
    f.set_defaults(func=cmd_refs)
    for name, issue in (("bench", 7), ("compare", 7), ("report", 7)):
        s = sub.add_parser(name, help=f"(issue {issue}, not yet)")
        s.add_argument("args", nargs="*")
        s.set_defaults(func=_not_yet(name, issue))
    a = p.parse_args(argv)
    try:
        return a.func(a)
    except (SceneError, ValueError, FileNotFoundError) as e:
        print(f"radiometer {a.cmd}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
