"""Benchmark matrices: TOML files of scenes x estimators x budgets x seeds.

    name = "default"              # names the run in the store and its files: letters, digits, . _ + -
                                  # (required)
    seeds = [0, 1, 2]             # one job per seed (required)
    threads = 1                   # render threads per job (0..1024, 0 = all cores); the local pool runs
                                  # cores // threads jobs at once
    budgets = [{ seconds = 4.0 }] # each { spp = N } (1..2^24) or { seconds = S } (finite, at most a week)
                                  # (required)
    target_relmse = 0.05          # the error a render must reach to be "usable" (its verdict), and
                                  # time-to-error's target (optional; default 0.05, DEFAULT_TARGET_RELMSE)

    [scenes.cornell_box]          # a scene of reference_scenes/registry.py
    [scenes.furnace]
    params = { res = 8 }          # XML parameters (analytic scenes only)
    estimators = ["path"]         # optional: only these estimators of the matrix

    [estimators.path]             # label; type defaults to the label
    [estimators.bdpt_balance]
    type = "bdpt"
    mis = "balance"               # every other key is an estimator parameter

    [effect_refs]                 # per-effect references of Mitsuba-referenced scenes (optional)
    spp = 8192                    # overrides the scene's budget (smoke matrices use a few spp; >= 2)

An estimator that takes max_depth gets the scene's unless the matrix sets
one. Everything is checked when the file is read; an error names the file
and the key (`MatrixError`). An estimator that exists but refuses a scene
is not a matrix error: the job is recorded as "unsupported" with the
renderer's message.
"""
from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional

from radiometer.reference_scenes import registry as _scenes

HERE = Path(__file__).resolve().parent
TOP_KEYS = {"name", "description", "seeds", "threads", "budgets", "target_relmse", "scenes", "estimators",
            "effect_refs", "checkpoints"}


class MatrixError(ValueError):
    """A matrix file that cannot run; the message names the file and key."""


# The matrix name goes into run ids, and run ids and estimator labels into
# paths under the results folder (runs/RUN/SCENE/LABEL-...exr, reports/RUN):
# each must be one plain file-name component, never a path.
PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]*\Z")
# What render() accepts: at most 2^24 samples per pixel and 1024 threads
# (0 = all cores). A seconds budget longer than a week is a typo.
MAX_SPP = 1 << 24
MAX_THREADS = 1024
MAX_SECONDS = 7 * 24 * 3600
# relMSE 0.05: an RMS relative error of about 22 % per pixel (eps 1e-2 in
# the denominator), the default main job's target.
DEFAULT_TARGET_RELMSE = 0.05
MAX_TARGET_RELMSE = 1e3


def plain_name(s) -> bool:
    """True when `s` can name a file or folder of the results tree by itself."""
    return isinstance(s, str) and len(s) <= 128 and PLAIN_NAME.match(s) is not None


@dataclass
class Job:
    scene: str
    estimator: str  # the matrix's label
    integrator: dict  # resolved spec: {"type": ..., every parameter}
    scene_params: dict
    budget: dict  # {"spp": N} or {"seconds": S}
    seed: int
    threads: int
    checkpoints: bool = True
    target_relmse: Optional[float] = None
    effect_ref: Optional[str] = None  # set by the runner for Mitsuba-referenced scenes
    effect_note: Optional[str] = None  # why there is none (set by the runner)

    @property
    def key(self) -> str:
        """Identifies the job within a run (what --resume matches on)."""
        d = {"scene": self.scene, "estimator": self.estimator, "integrator": self.integrator,
             "scene_params": self.scene_params, "budget": self.budget, "seed": self.seed, "threads": self.threads}
        return hashlib.sha1(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    @property
    def config_key(self) -> str:
        """Identifies the configuration across seeds (what compare groups on)."""
        d = {"scene": self.scene, "estimator": self.estimator, "integrator": self.integrator,
             "scene_params": self.scene_params, "budget": self.budget, "threads": self.threads}
        return hashlib.sha1(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["key"] = self.key
        d["config_key"] = self.config_key
        return d


@dataclass
class Matrix:
    name: str
    path: str
    text: str
    jobs: list = field(default_factory=list)
    threads: int = 1
    effect_ref_spp: Optional[int] = None
    description: str = ""


def resolve_path(arg: Optional[str]) -> Path:
    """A matrix argument: a file, or the name of one in benchmarks/ ("smoke")."""
    if arg is None:
        arg = "default"
    p = Path(arg)
    if p.is_dir():
        raise MatrixError(f"{arg}: a folder, not a matrix file (give a .toml file, or a matrix name in benchmarks/)")
    if p.exists():
        return p
    cand = HERE / (arg if arg.endswith(".toml") else arg + ".toml")
    if cand.exists():
        return cand
    known = sorted(f.stem for f in HERE.glob("*.toml"))
    raise MatrixError(f"{arg}: no such matrix file, and not a matrix in benchmarks/ (known: {', '.join(known)})")


def _check_int(v, where, lo=None, hi=None):
    if isinstance(v, bool) or not isinstance(v, int) or (lo is not None and v < lo) or (hi is not None and v > hi):
        want = "" if lo is None else f" >= {lo}" if hi is None else f" in {lo}..{hi}"
        raise MatrixError(f"{where}: expected an integer{want}, got {v!r}")
    return v


def _check_positive(v, where, hi=None):
    """A positive finite number (at most `hi`)."""
    if (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not v > 0
            or (hi is not None and v > hi)):
        want = "a positive finite number" if hi is None else f"a finite number in (0, {hi}]"
        raise MatrixError(f"{where}: expected {want}, got {v!r}")
    return v


def load(arg: Optional[str]) -> Matrix:
    path = resolve_path(arg)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise MatrixError(f"{path}: not UTF-8 text, so not a TOML matrix ({e.reason} at byte {e.start})") from None
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise MatrixError(f"{path}: not valid TOML ({e})") from None
    return parse(d, path=str(path), text=text)


def parse(d: dict, path: str = "<dict>", text: str = "") -> Matrix:
    from radiometer.render import INTEGRATOR_PARAMS, PLANNED_INTEGRATORS, _integrator_desc

    def err(key, msg):
        return MatrixError(f"{path}: {key}: {msg}")

    for k in d:
        if k not in TOP_KEYS:
            raise err(k, f"unknown key (known: {', '.join(sorted(TOP_KEYS))})")
    for k in ("name", "seeds", "budgets", "scenes", "estimators"):
        if k not in d:
            raise err(k, "missing")
    name = d["name"]
    if not plain_name(name):
        raise err("name", f"expected one plain word of letters, digits and . _ + - (it names files of the "
                          f"run), starting with a letter or digit, got {name!r}")
    if isinstance(d["estimators"], dict):
        for label in d["estimators"]:
            if not plain_name(label):
                raise err(f"estimators.{label}", "an estimator label names the files of its jobs: expected one "
                                                 "plain word of letters, digits and . _ + -")
    seeds = d["seeds"]
    if not isinstance(seeds, list) or not seeds:
        raise err("seeds", f"expected a non-empty list of integers, got {seeds!r}")
    for i, s in enumerate(seeds):
        _check_int(s, f"{path}: seeds[{i}]", 0)
    threads = _check_int(d.get("threads", 1), f"{path}: threads", 0, MAX_THREADS)
    checkpoints = d.get("checkpoints", True)
    if not isinstance(checkpoints, bool):
        raise err("checkpoints", f"expected true or false, got {checkpoints!r}")
    target = _check_positive(d.get("target_relmse", DEFAULT_TARGET_RELMSE), f"{path}: target_relmse",
                             MAX_TARGET_RELMSE)
    budgets = d["budgets"]
    if not isinstance(budgets, list) or not budgets:
        raise err("budgets", "expected a non-empty list of tables like { spp = 64 } or { seconds = 2.0 }")
    for i, b in enumerate(budgets):
        where = f"budgets[{i}]"
        if not isinstance(b, dict) or len(b) != 1 or next(iter(b)) not in ("spp", "seconds"):
            raise err(where, f"expected {{ spp = N }} or {{ seconds = S }}, got {b!r}")
        (k, v), = b.items()
        if k == "spp":
            _check_int(v, f"{path}: {where}.spp", 1, MAX_SPP)
        else:
            _check_positive(v, f"{path}: {where}.seconds", MAX_SECONDS)
    effect_ref_spp = None
    if "effect_refs" in d:
        er = d["effect_refs"]
        if not isinstance(er, dict):
            raise err("effect_refs", "expected a table")
        for k in er:
            if k != "spp":
                raise err(f"effect_refs.{k}", "unknown key (known: spp)")
        if "spp" in er:
            # Two samples at least: the reference's z-test needs its per-pixel variance.
            effect_ref_spp = _check_int(er["spp"], f"{path}: effect_refs.spp", 2, MAX_SPP)

    # Estimators: label -> (type, params), checked by the renderer's own validation.
    ests = d["estimators"]
    if not isinstance(ests, dict) or not ests:
        raise err("estimators", "expected a non-empty table of [estimators.NAME] tables")
    est_specs = {}
    for label, e in ests.items():
        where = f"estimators.{label}"
        if not isinstance(e, dict):
            raise err(where, "expected a table")
        e = dict(e)
        itype = e.pop("type", label)
        if itype not in INTEGRATOR_PARAMS:
            why = "not implemented yet" if itype in PLANNED_INTEGRATORS else "unknown estimator"
            raise err(f"{where}.type" if label != itype else where,
                      f"{why} '{itype}' (known: {', '.join(sorted(INTEGRATOR_PARAMS))})")
        for k in e:
            if k not in INTEGRATOR_PARAMS[itype]:
                raise err(f"{where}.{k}", f"unknown parameter for '{itype}' "
                                          f"(known: {', '.join(sorted(INTEGRATOR_PARAMS[itype]))})")
        try:
            _integrator_desc({"type": itype, **e}, None)
        except ValueError as ex:
            raise err(where, str(ex)) from None
        est_specs[label] = (itype, e)

    sc = d["scenes"]
    if not isinstance(sc, dict) or not sc:
        raise err("scenes", "expected a non-empty table of [scenes.NAME] tables")
    jobs = []
    for sname, s in sc.items():
        where = f"scenes.{sname}"
        if sname not in _scenes.ALL_SCENES:
            raise err(where, f"unknown scene (known: {', '.join(sorted(_scenes.ALL_SCENES))})")
        if not isinstance(s, dict):
            raise err(where, "expected a table")
        for k in s:
            if k not in ("params", "estimators"):
                raise err(f"{where}.{k}", "unknown key (known: params, estimators)")
        spec = _scenes.ALL_SCENES[sname]
        try:
            params = _scenes.scene_params(spec, s.get("params") or {})
        except ValueError as ex:
            raise err(f"{where}.params", str(ex)) from None
        labels = s.get("estimators", list(est_specs))
        if not isinstance(labels, list):
            raise err(f"{where}.estimators", f"expected a list of estimator labels, got {labels!r}")
        for lab in labels:
            if lab not in est_specs:
                raise err(f"{where}.estimators", f"'{lab}' is not in [estimators] (known: {', '.join(est_specs)})")
        md = _scenes.max_depth(spec, params)
        for lab in labels:
            itype, eparams = est_specs[lab]
            p = dict(eparams)
            if "max_depth" in INTEGRATOR_PARAMS[itype] and "max_depth" not in p and md is not None:
                p["max_depth"] = md
            integ = _integrator_desc({"type": itype, **p}, None)
            for b in budgets:
                for seed in seeds:
                    jobs.append(Job(sname, lab, integ, params, dict(b), int(seed), threads, checkpoints,
                                    float(target)))
    keys = [j.key for j in jobs]
    if len(set(keys)) != len(keys):
        raise MatrixError(f"{path}: the matrix names the same job twice (duplicate seeds or budgets)")
    return Matrix(name, path, text, jobs, threads, effect_ref_spp, d.get("description", ""))
