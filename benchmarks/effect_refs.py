"""Per-effect references for the Mitsuba-referenced scenes.

Mitsuba's references hold the total image only. The per-effect reference of
a scene is a long run of our own unbiased `path` (every effect class in its
own layer; `bdpt` where the scene's SceneSpec says so: ajar_door), accepted
only if its total passes the blocked z-test against Mitsuba's reference
(analysis/blocks.py, alpha 0.01, the same test as
tests/test_canonical_mitsuba.py, with the reference's per-sample variance
as a floor for box-filtered scenes). A reference that fails is kept on disk
for inspection but not used: the scene's per-effect errors are then
reported as unavailable, with the z-test's summary as the reason.

They are cached under <results>/refs/<scene>-<hash>.exr, the hash covering
the scene's parameters, the estimator, its budget and seed, so a cache
survives commits (the z-test re-decides whenever one is made). A cached
file that does not read back whole (a copy cut short, a full disk) is
remade, not trusted and not fatal to every later run. A 64 x 64
reference with its seven effect layers is about 0.3 MB (cornell_box at
128 x 128: 0.7 MB); they are not committed. At a resolution of the
registry's more_refs the budget is that entry's (registry.budget) and the
z-test is against that resolution's Mitsuba reference.
"""
from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path

from radiometer.reference_scenes import registry as _scenes

SEED = 987654321


def ref_path(root, scene: str, params: dict, spp: int) -> Path:
    spec = _scenes.get(scene)
    d = {"scene": scene, "params": params, "estimator": spec.effect_ref_estimator,
         "max_depth": _scenes.max_depth(spec, params), "spp": spp, "seed": SEED}
    if spec.effect_ref_params:  # only where given, so that the other scenes' cached files keep their names
        d["estimator_params"] = spec.effect_ref_params
    key = json.dumps(d, sort_keys=True)
    return Path(root) / "refs" / f"{scene}-{hashlib.sha1(key.encode()).hexdigest()[:12]}.exr"


def cached(out: Path) -> tuple:
    """(metadata, None) of the cached reference `out`; (None, None) when
    there is none; (None, why) when the file does not read back whole
    (truncated or corrupt), which the caller remakes (write_exr replaces it)."""
    import radiometer as rm

    if not out.exists():
        return None, None
    try:
        return rm.read_exr(out).metadata, None
    except ValueError as e:  # read_exr: "... is truncated or corrupt" / "not a readable EXR file"
        return None, f"cached per-effect reference {out} is truncated or corrupt ({e})"


def _splatted(scene) -> bool:
    return scene.desc.sensor.rfilter != "box"


def make(scene: str, params: dict, spp: int, out: Path, threads: int = 0, progress=None) -> dict:
    """Renders the per-effect reference of `scene` with `spp` samples per
    pixel of `path` (or the scene's effect_ref_estimator, with its
    effect_ref_params), z-tests its total against Mitsuba's reference and
    writes it to `out` (EXR, metadata `accepted` and `ztest`). Returns the
    metadata."""
    import radiometer as rm
    from radiometer.analysis.blocks import blocked_z_test, reference_variance_floor

    spec = _scenes.get(scene)
    if spec.kind != "mitsuba":
        raise ValueError(f"{scene}: analytic scenes have exact per-effect references")
    if isinstance(spp, bool) or not isinstance(spp, int) or spp < 2:
        raise ValueError(f"{scene}: per-effect reference spp: expected an integer >= 2 (its z-test needs the "
                         f"per-pixel variance of at least two samples), got {spp!r}")
    s = rm.load_file(spec.xml, **params)
    integ = {"type": spec.effect_ref_estimator, **spec.effect_ref_params,
             "max_depth": _scenes.max_depth(spec, params)}
    t0 = time.monotonic()
    res = rm.render(s, integrator=integ, spp=spp, seed=SEED, threads=threads, progress=progress)
    ref = rm.read_exr(spec.reference_file(params.get("res")))
    splatted = _splatted(s)
    floor = None if splatted else reference_variance_floor(ref.variance, int(ref.metadata["total_spp"]), res.spp)
    passed, msg = blocked_z_test(res.image, res.variance, ref.image, ref.variance, b_splatted=splatted,
                                 var_a_floor=floor)
    meta = {"accepted": int(passed), "ztest": msg, "reference_total_spp": int(ref.metadata["total_spp"]),
            "effects_kind": (f"ours: {spec.effect_ref_estimator}"
                             + "".join(f" {k}={v}" for k, v in sorted(spec.effect_ref_params.items()))
                             + f", {res.spp} spp, z-test against Mitsuba "
                             f"{'passed' if passed else 'FAILED'}"),
            "make_seconds": time.monotonic() - t0}
    out.parent.mkdir(parents=True, exist_ok=True)
    rm.write_exr(out, res, **meta)
    return meta


def ensure(root, jobs, spp_override=None, threads: int = 0, log=print) -> dict:
    """Makes the missing per-effect references the jobs need (Mitsuba-
    referenced scenes that load), sets each job's `effect_ref` to the
    accepted reference's path, and returns {scene: note}."""
    import radiometer as rm

    notes = {}
    needed = {}
    for j in jobs:
        spec = _scenes.SCENES.get(j.scene)  # an unknown scene fails in its job, not here
        if spec is not None and spec.kind == "mitsuba":
            needed.setdefault((j.scene, json.dumps(j.scene_params, sort_keys=True)), []).append(j)
    for (scene, pkey), js in needed.items():
        params = json.loads(pkey)
        spec = _scenes.get(scene)
        spp = spp_override or spec.budget(params.get("res"))[2]
        out = ref_path(root, scene, params, spp)
        m, broken = cached(out)
        if broken:
            log(f"{broken}; remaking it")
        if m is None:
            try:
                rm.load_file(spec.xml, **params)
            except (rm.SceneError, ValueError) as e:
                notes[scene] = f"no per-effect reference: the scene does not load ({e})"
                continue
            log(f"per-effect reference for {scene}: {spec.effect_ref_estimator}, {spp} spp "
                f"(made once, cached in {out.parent})")
            from tqdm import tqdm

            with tqdm(total=spp, desc=f"effect reference {scene}", unit="spp", file=sys.stderr, disable=None,
                      leave=False) as bar:
                def progress(done, total):
                    # (done, total) counts samples over the image; the bar counts spp.
                    bar.n = int(done * spp / total) if total else 0
                    bar.refresh()

                m = make(scene, params, spp, out, threads=threads, progress=progress)
            log(f"  {m['effects_kind']} ({m['make_seconds']:.0f} s)")
        if int(m.get("accepted", 0)):
            for j in js:
                j.effect_ref = str(out)
            notes[scene] = m.get("effects_kind", "ours")
        else:
            notes[scene] = (f"per-effect reference rejected (its total failed the z-test against Mitsuba; "
                            f"{out}): {m.get('ztest', '')}")
            for j in js:
                j.effect_note = (f"none: ours ({m.get('effects_kind', '').split(',')[1].strip()}) failed the "
                                 f"z-test against Mitsuba")
    return notes
