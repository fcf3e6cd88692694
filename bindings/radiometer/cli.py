"""The `radiometer` command line.

  radiometer render SCENE [-i NAME] [--spp N | --seconds S] [-o out.exr]
  radiometer render --help-integrator NAME
  radiometer bench [MATRIX] [--scheduler ADDRESS] [--resume [RUN]]
  radiometer compare A B | report [RUN] | merge STORE... | runs | refs [--effects]

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
from .exr import check_output


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


class _HelpIntegrator(argparse.Action):
    """--help-integrator NAME: prints the estimator's parameter table and
    exits, like --help (before the required SCENE is asked for)."""

    def __call__(self, parser, namespace, values, option_string=None):
        from .registry import help_text

        try:
            text = help_text(values)
        except KeyError as e:
            parser.exit(2, f"radiometer render: error: {e.args[0]}\n")
        print(text)
        parser.exit(0)


def _parse_effects(arg):
    """--effects: None (all effect classes) or the named ones. An empty
    string, or an empty name in the list, is a mistake, not "all"."""
    if arg is None:
        return None
    known = f"(known: {', '.join(EFFECTS)})"
    if not arg.strip():
        raise ValueError(f"--effects: empty; name at least one effect class {known}, or leave --effects out for all")
    names = [e.strip() for e in arg.split(",")]
    if "" in names:
        raise ValueError(f"--effects {arg!r}: an empty name in the list {known}")
    for e in names:
        if e not in EFFECTS:
            raise ValueError(f"--effects: unknown effect class {e!r} {known}")
    return names


def cmd_render(a) -> int:
    effects = _parse_effects(a.effects)
    scene = load_file(_scene_path(a.scene), base_dir_only=a.untrusted)
    integrator = _parse_integrator(a.integrator)
    if a.max_depth is not None:
        from .render import _integrator_desc

        spec = _integrator_desc(integrator, scene.desc.integrator)
        spec["max_depth"] = a.max_depth
        integrator = spec
    out = Path(a.output)
    if not out.parent.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
    # Before the render: an output that cannot be written must not cost a render.
    check_output(out, "-o")
    bar = _Progress(f"render {Path(a.scene).stem}")
    try:
        res = render(scene, integrator=integrator, spp=a.spp, seconds=a.seconds, seed=a.seed, threads=a.threads,
                     effects=effects, progress=bar, sampler=a.sampler)
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
    std_error = float(res.variance.mean()) ** 0.5 / res.image[..., 0].size ** 0.5
    print(f"  mean radiance {float(res.image.mean()):.5g} (std. error {std_error:.2g}); by effect: {means}")
    return 0


def cmd_refs(a) -> int:
    """Regenerates the Mitsuba 3 references of the canonical scenes."""
    if a.effects:
        return _effect_refs(a)
    if a.suite:
        return _suite_refs(a)
    from .reference_scenes.make_reference import make_scene_reference
    from .reference_scenes.registry import mitsuba_scenes

    scenes = mitsuba_scenes()
    # With --res and no scene named: those with a reference declared at it.
    names = a.scenes or sorted(n for n, s in scenes.items() if a.res is None or a.res in s.resolutions)
    unknown = [n for n in names if n not in scenes]
    if unknown:
        raise SceneError(f"refs: no Mitsuba reference is defined for {', '.join(unknown)} "
                         f"(known: {', '.join(sorted(scenes))})")
    if a.list:
        for n in names:
            spec = scenes[n]
            for r in spec.resolutions or (None,):
                ref = spec.reference_file(r)
                state = "missing"
                if ref.exists():
                    from . import read_exr

                    m = read_exr(ref).metadata
                    state = (f"{m.get('total_spp', '?')} spp, Mitsuba {m.get('mitsuba_version', '?')} "
                             f"{m.get('variant', '?')}, {m.get('date', '?')}")
                runs, spp, _ = spec.budget(r)
                integ = (spec.mitsuba_integrator or {}).get("type", "the scene's integrator")
                params = {**spec.fixed_params, **({"res": r} if r else {})}
                print(f"{n}: {runs} runs x {spp} spp, Mitsuba {integ}, params {params} -- {state}")
        return 0
    out_dir = Path(a.out_dir) if a.out_dir else None
    for n in names:
        spec = scenes[n]
        res = a.res
        try:
            committed = spec.reference_file(res)
        except ValueError as e:
            raise SceneError(f"refs: {e}") from None
        out = (out_dir / n / committed.name) if out_dir else None
        out, var, meta = make_scene_reference(spec, res, a.runs, a.spp, a.variant, out)
        print(f"  wrote {out} in {meta['seconds']:.0f} s ({meta['variant']}); mean variance {var.mean():.3g}")
    return 0


def _suite_refs(a) -> int:
    """Fresh Mitsuba 3 references of scenes of Mitsuba's own render test
    suite, for the second test (both variances; benchmarks/studies/
    mitsuba_suite.py): kept under RESULTS/refs/mitsuba_suite."""
    from .benchmarks.studies import mitsuba_suite as ms

    root = Path(a.suite_data) if a.suite_data else ms.default_path()
    if not (root / "tests" / "scenes").is_dir():
        raise SceneError(f"refs --suite: {root} holds no tests/scenes folder (Mitsuba's mitsuba-data)")
    every = {str(p.relative_to(root / "tests" / "scenes")): p for p in ms.scenes(root)}
    names = a.scenes or sorted(every)
    unknown = [n for n in names if n not in every]
    if unknown:
        raise SceneError(f"refs --suite: no scene {', '.join(unknown)} in {root / 'tests' / 'scenes'} "
                         f"(e.g. {next(iter(sorted(every)), 'none')})")
    if a.res is not None:
        raise SceneError("refs --suite: --res does not apply (a suite scene renders at its own film size)")
    for n in names:
        path, out = every[n], ms.fresh_path(a.results, every[n])
        if a.list:
            state = "missing"
            if out.exists():
                from . import read_exr

                m = read_exr(out).metadata
                state = (f"{m.get('total_spp', '?')} spp, Mitsuba {m.get('mitsuba_version', '?')} "
                         f"{m.get('variant', '?')}")
            print(f"{n}: {state} ({out})")
            continue
        if out.exists() and not a.force:
            print(f"{n}: kept {out} (--force remakes it)")
            continue
        try:
            runs = a.runs or ms.FRESH_RUNS
            spp = a.spp or ms.FRESH_SPP_FACTOR * ms.suite_spp(path)
        except SceneError as e:
            print(f"{n}: skipped, the scene does not load here ({str(e).splitlines()[0]})")
            continue
        print(f"{n}: {runs} runs x {spp} spp -> {out}", file=sys.stderr)
        meta = ms.make_fresh(path, out, runs=runs, spp=spp, variant=a.variant, progress=True)
        print(f"  wrote {out} in {meta['seconds']:.0f} s ({meta['variant']})")
    return 0


def _effect_refs(a) -> int:
    """Makes (or lists) the per-effect references of the benchmark's
    Mitsuba-referenced scenes: long runs of our path tracer, kept only when
    their total passes the z-test against Mitsuba."""
    from .benchmarks import effect_refs
    from .reference_scenes import registry as scenes

    names = a.scenes or [n for n, s in sorted(scenes.SCENES.items())
                         if s.kind == "mitsuba" and (a.res is None or a.res in s.resolutions)]
    for n in names:
        spec = scenes.get(n)
        if spec.kind != "mitsuba":
            print(f"{n}: analytic; its per-effect reference is exact")
            continue
        params = dict(spec.fixed_params)
        if a.res is not None:
            try:
                spec.reference_file(a.res)
            except ValueError as e:
                raise SceneError(f"refs --effects: {e}") from None
            params["res"] = a.res
        spp = a.spp or spec.budget(a.res)[2]
        out = effect_refs.ref_path(a.results, n, params, spp)
        m, broken = (None, None) if a.force else effect_refs.cached(out)
        if broken:
            print(f"{broken}; {'listed as missing' if a.list else 'remaking it'}", file=sys.stderr)
        if m is None:
            try:
                load_file(spec.xml, **params)
            except SceneError as e:
                print(f"{n}: none, the scene does not load here ({e})")
                continue
            if a.list:
                print(f"{n}: {spp} spp -- missing ({out})")
                continue
            print(f"{n}: {spec.effect_ref_estimator}, {spp} spp -> {out}", file=sys.stderr)
            bar = _Progress(f"effect reference {n}")
            m = effect_refs.make(n, params, spp, out, threads=a.threads, progress=bar)
            bar.close()
        print(f"{n}: {m.get('effects_kind')} ({out})")
    return 0


def _store_path(a) -> Path:
    from .benchmarks.runner import STORE_NAME

    return Path(a.results) / STORE_NAME


def _print_effect_table(store_path: Path, run_id: str):
    from .analysis.tables import aggregate, effect_table_text
    from .analysis.verdict import winners
    from .benchmarks.store import Store

    with Store(store_path, readonly=True) as st:
        recs = st.jobs(run_id)
    print(f"\nper-effect error -- run {run_id}")
    print(effect_table_text(aggregate(recs), winners=winners(recs)))


def cmd_bench(a) -> int:
    """Runs a benchmark matrix, prints the per-effect error table and writes the report.
    Exit status 1 when no job ran or a job failed (the reasons on stderr)."""
    from .benchmarks import runner
    from .benchmarks.store import Store

    try:
        run_id = runner.run(a.matrix, root=a.results, scheduler=a.scheduler, workers=a.workers, resume=a.resume)
    except KeyboardInterrupt:
        print("bench: interrupted; every finished job is in the store: continue with "
              "'radiometer bench [MATRIX] --resume'", file=sys.stderr)
        return 130
    store = _store_path(a)
    with Store(store, readonly=True) as st:
        rc, summary = runner.summary(st.jobs(run_id))
    if summary.startswith("no job"):  # nothing to tabulate or report
        print(f"radiometer bench: error: run {run_id}: {summary}", file=sys.stderr)
        print(f"results store: {store.resolve()} (run {run_id})")
        return rc
    _print_effect_table(store, run_id)
    if not a.no_report:
        from .benchmarks import report

        index = report.write(store, run_id, log=lambda m: print(m, file=sys.stderr))
        print(f"\nreport: {index.resolve()}")
    print(f"results store: {store.resolve()} (run {run_id})")
    if rc:
        print(f"radiometer bench: error: run {run_id}: {summary}", file=sys.stderr)
    return rc


def cmd_compare(a) -> int:
    from .benchmarks import compare

    compare.check_options(a.metric, a.factor)  # before opening anything
    la, ra = compare.open_run(a.a, _store_path(a))
    lb, rb = compare.open_run(a.b, _store_path(a))
    changes = compare.compare_records(ra, rb, metric=a.metric, factor=a.factor)
    print(f"A = {la}\nB = {lb}")
    print(f"changes are flagged when the 95 % intervals over seeds do not overlap and B/A is beyond "
          f"{1 / a.factor:.3g}..{a.factor:.3g}")
    print(compare.table(changes, only_changed=a.only_changed))
    bad = [c for c in changes if c.verdict == "regression"]
    if bad:
        print(f"\n{len(bad)} regression(s)", file=sys.stderr)
        return 1
    return 0


def cmd_report(a) -> int:
    from .benchmarks import report

    store, run = _store_path(a), a.run
    p = Path(a.run) if a.run else None
    if p is not None and p.is_file():
        store, run = p, None
    elif a.run and ":" in a.run and Path(a.run.rsplit(":", 1)[0]).is_file():
        store, run = Path(a.run.rsplit(":", 1)[0]), a.run.rsplit(":", 1)[1]
    if not store.is_file():
        raise FileNotFoundError(f"report: no results store at {store} (run 'radiometer bench' first, or pass a store)")
    index = report.write(store, run, out_dir=a.output, log=lambda m: print(m, file=sys.stderr))
    print(index.resolve())
    return 0


def cmd_merge(a) -> int:
    from .benchmarks.store import Store

    dest = Path(a.into) if a.into else _store_path(a)
    with Store(dest) as st:
        for src in a.stores:
            runs, jobs = st.merge(src)
            print(f"{src}: {runs} runs and {jobs} jobs added to {dest}")
    return 0


def cmd_runs(a) -> int:
    from .benchmarks.store import Store

    store = _store_path(a)
    if not store.is_file():
        raise FileNotFoundError(f"no results store at {store}")
    with Store(store, readonly=True) as st:
        for r in st.runs():
            print(f"{r['run_id']}  {r['matrix']}  {r['n_jobs']} jobs  commit {r['commit_id']}  "
                  f"{r['started']} .. {r['finished'] or '(unfinished)'}")
    return 0


def _add_results_arg(p):
    p.add_argument("--results", default="out/results",
                   help="results folder: the store bench.sqlite, renders, per-effect references, reports "
                        "(default: out/results)")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="radiometer", description="Physically based validation and benchmark suite")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render", help="render a scene to EXR (image, variance and effect layers)")
    r.add_argument("scene", help="Mitsuba 3 XML file, or a canonical scene name such as cornell-box")
    from .registry import estimator_names

    r.add_argument("-i", "--integrator",
                   help=f"estimator name ({', '.join(estimator_names())}) or a JSON dict like the XML's; "
                        "--help-integrator NAME lists its parameters")
    r.add_argument("--help-integrator", metavar="NAME", action=_HelpIntegrator,
                   help="print estimator NAME's parameters (type, default, allowed values) and exit")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--spp", type=int, help="samples per pixel (default: the scene's sampler)")
    g.add_argument("--seconds", type=float, help="wall-clock budget in seconds")
    r.add_argument("--max-depth", type=int, help="override the estimator's max_depth")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--sampler", help="independent, stratified, multijitter, sobol or zsobol (default: the scene's)")
    r.add_argument("--threads", type=int, default=0, help="0 = all cores")
    r.add_argument("--effects", help=f"comma-separated subset of: {','.join(EFFECTS)}")
    r.add_argument("-o", "--output", default="out.exr")
    r.add_argument("--untrusted", action="store_true",
                   help="the scene comes from an untrusted source: it may only name files inside its own folder, "
                        "and errors quote nothing from them")
    r.set_defaults(func=cmd_render)
    f = sub.add_parser("refs", help="regenerate the Mitsuba 3 references of the canonical scenes")
    f.add_argument("scenes", nargs="*", help="scene folders (default: every scene with a Mitsuba reference); with "
                                             "--suite, suite scenes as FOLDER/FILE.xml (default: all)")
    f.add_argument("--res", type=int, help="resolution (default: each scene's own; another only where the "
                                           "registry declares a reference at it, reference_RES.exr)")
    f.add_argument("--runs", type=int, help="independent Mitsuba renders (default: the scene's)")
    f.add_argument("--spp", type=int, help="samples per pixel per run (default: the scene's)")
    f.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (falls back to scalar_rgb)")
    f.add_argument("--out-dir", help="write under this folder instead of reference_scenes/")
    f.add_argument("--list", action="store_true", help="list the references and how they were made")
    f.add_argument("--effects", action="store_true",
                   help="per-effect references for the benchmark instead (long runs of our path tracer, accepted "
                        "when their total passes the z-test against Mitsuba; cached under RESULTS/refs)")
    f.add_argument("--suite", action="store_true",
                   help="fresh Mitsuba references of Mitsuba's own render test suite for the second test (both "
                        "variances), under RESULTS/refs/mitsuba_suite")
    f.add_argument("--suite-data", metavar="PATH", help="with --suite: the mitsuba-data folder (default: "
                                                        "../shared/peers/mitsuba-data beside the repository)")
    f.add_argument("--force", action="store_true", help="with --effects or --suite: remake existing ones")
    f.add_argument("--threads", type=int, default=0, help="with --effects: render threads (0 = all cores)")
    _add_results_arg(f)
    f.set_defaults(func=cmd_refs)
    b = sub.add_parser("bench", help="run a benchmark matrix (default: benchmarks/default.toml)")
    b.add_argument("matrix", nargs="?", help="a TOML file, or a matrix name in benchmarks/ (default, smoke)")
    b.add_argument("--scheduler", help="address of a Dask distributed scheduler (default: a local process pool)")
    b.add_argument("--workers", type=int, help="local pool size (default: cores / the matrix's threads per job)")
    b.add_argument("--resume", nargs="?", const="latest",
                   help="continue a run, skipping its recorded jobs (default: the latest run of this matrix)")
    b.add_argument("--no-report", action="store_true", help="skip the HTML report")
    _add_results_arg(b)
    b.set_defaults(func=cmd_bench)
    c = sub.add_parser("compare", help="compare two runs; exit 1 on a regression beyond run-to-run noise")
    c.add_argument("a", help="baseline: a store file (its latest run), STORE:RUN, or a run id in the results store")
    c.add_argument("b", help="candidate, the same forms")
    c.add_argument("--metric", default="relmse", help="error metric (relmse, mse, smape, flip, ciede2000)")
    c.add_argument("--factor", type=float, default=1.1, help="smallest ratio that counts as a change (default 1.1)")
    c.add_argument("--only-changed", action="store_true", help="list only changed configurations")
    _add_results_arg(c)
    c.set_defaults(func=cmd_compare)
    rp = sub.add_parser("report", help="write the static HTML report of a run")
    rp.add_argument("run", nargs="?", help="a run id (or prefix) in the results store, a store file, or STORE:RUN "
                                           "(default: the latest run)")
    rp.add_argument("-o", "--output", help="folder for index.html (default: RESULTS/reports/RUN)")
    _add_results_arg(rp)
    rp.set_defaults(func=cmd_report)
    mg = sub.add_parser("merge", help="merge results stores (e.g. from several machines) into one")
    mg.add_argument("stores", nargs="+", help="store files to merge in")
    mg.add_argument("--into", help="the store to merge into (default: RESULTS/bench.sqlite)")
    _add_results_arg(mg)
    mg.set_defaults(func=cmd_merge)
    ru = sub.add_parser("runs", help="list the runs in the results store")
    _add_results_arg(ru)
    ru.set_defaults(func=cmd_runs)
    a = p.parse_args(argv)
    try:
        return a.func(a)
    except (SceneError, ValueError, OSError, KeyError) as e:  # OSError: files, folders, an unreachable scheduler
        if isinstance(e, KeyError):
            e = e.args[0] if e.args else e
        print(f"radiometer {a.cmd}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
