"""The benchmark harness end to end on the smoke matrix (benchmarks/smoke.toml):
matrix checking, the local pool and Dask runners, the store (atomic jobs,
SIGKILL, --resume, merge), per-effect metrics and the HTML report in
headless Chromium. Tiny scenes and budgets; no timing is asserted."""
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from radiometer.benchmarks import matrix as MX
from radiometer.benchmarks import runner
from radiometer.benchmarks.store import Store
from radiometer.cli import main

REPO = Path(__file__).resolve().parents[1]
RADIOMETER = str(Path(sys.executable).with_name("radiometer"))


# -- matrices -------------------------------------------------------------------


def _write(tmp_path, text, name="m.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


BASE = """
name = "t"
seeds = [0]
budgets = [{ spp = 2 }]
[scenes.furnace]
params = { res = 4 }
[estimators.path]
"""


def test_shipped_matrices_parse():
    smoke = MX.load("smoke")
    assert smoke.name == "smoke" and smoke.jobs
    default = MX.load("default")
    scenes = {j.scene for j in default.jobs}
    # Every canonical scene of the registry takes part in the main job.
    from radiometer.reference_scenes.registry import MODEL_VARIANTS, SCENES

    # ... and the model variants (the dipole scenes: their records carry the model error).
    assert scenes == set(SCENES) | set(MODEL_VARIANTS)
    assert {j.estimator for j in default.jobs} >= {"path", "direct", "ptracer", "bdpt"}
    # Each estimator that takes max_depth gets the scene's.
    j = next(j for j in default.jobs if j.scene == "ajar_door" and j.estimator == "bdpt")
    assert j.integrator["max_depth"] == 10


@pytest.mark.parametrize("text, key, words", [
    (BASE + "[scenes.nope]\n", "scenes.nope", "unknown scene"),
    (BASE + "[estimators.foo]\n", "estimators.foo", "unknown estimator 'foo'"),
    (BASE + "[estimators.bdpt]\nbogus = 1\n", "estimators.bdpt.bogus", "unknown parameter for 'bdpt'"),
    (BASE + "[estimators.b2]\ntype = \"bdpt\"\nmis = \"best\"\n", "estimators.b2", "mis"),
    (BASE.replace("budgets = [{ spp = 2 }]", "budgets = [{ spp = 2, seconds = 1 }]"), "budgets[0]", "spp"),
    (BASE.replace("seeds = [0]", "seeds = [-1]"), "seeds[0]", "integer >= 0"),
    (BASE + "[scenes.cornell_box]\nparams = { res = 32 }\n", "scenes.cornell_box.params", "Mitsuba reference"),
    (BASE + "[scenes.mirror_caustic]\nparams = { colour = 1 }\n", "scenes.mirror_caustic.params", "colour"),
    (BASE + "[scenes.area_lights_disk]\nestimators = [\"ptracer\"]\n", "scenes.area_lights_disk.estimators", "ptracer"),
    ("speed = 3\n" + BASE, "speed", "unknown key"),
    (BASE + "speed = 3\n", "estimators.path.speed", "unknown parameter for 'path'"),
    (BASE.replace('name = "t"', ""), "name", "missing"),
])
def test_bad_matrix_names_file_and_key(tmp_path, text, key, words):
    path = _write(tmp_path, text)
    with pytest.raises(MX.MatrixError) as e:
        MX.load(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}:"), msg
    assert words in msg, msg


def test_bad_matrix_on_the_command_line(tmp_path, capsys):
    path = _write(tmp_path, BASE + "[scenes.nope]\n")
    assert main(["bench", path, "--results", str(tmp_path / "r")]) == 2
    assert "scenes.nope" in capsys.readouterr().err
    assert main(["bench", "no_such_matrix", "--results", str(tmp_path / "r")]) == 2
    assert "known: " in capsys.readouterr().err


# -- one smoke run shared by the tests below -------------------------------------


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench")
    run_id = runner.run("smoke", root=root, workers=2, progress=False, log=lambda *a: None)
    with Store(root / runner.STORE_NAME) as st:
        recs = st.jobs(run_id)
    return root, run_id, recs


def test_smoke_run_records_every_job(smoke):
    root, run_id, recs = smoke
    mat = MX.load("smoke")
    assert sorted(r["key"] for r in recs) == sorted(j.key for j in mat.jobs)
    by = {(r["scene"], r["estimator"], r["seed"]): r for r in recs}
    # The media scene: `direct` refuses media, recorded with the reason; `path` renders it.
    fog = by[("fog_room", "direct", 0)]
    assert fog["status"] == "unsupported" and "participating media" in fog["error"]
    ok = [r for r in recs if (r["scene"], r["estimator"]) != ("fog_room", "direct")]
    assert all(r["status"] == "ok" for r in ok), [r["error"] for r in ok if r["status"] != "ok"]
    for r in ok:
        assert r["spp"] == 4 and r["seconds"] > 0
        assert r["commit"] and r["machine"]["cores"] >= 1
        assert set(r["metrics"]) >= {"relmse", "mse", "smape", "flip", "ciede2000", "slope", "efficiency"}
        assert (root / r["exr"]).exists()
        assert len(r["curve"]) == 3  # checkpoints at 1, 2, 4 spp
    # Analytic per-effect references: the furnace splits into emission, direct, indirect.
    fur = by[("furnace", "path", 0)]
    assert set(fur["effect_metrics"]) == {"emission", "direct", "indirect"}
    # max_depth 3 path tracing of the furnace has zero variance: exact to rounding.
    assert fur["metrics"]["relmse"] < 1e-10
    assert all(d["relmse"] < 1e-10 for d in fur["effect_metrics"].values())
    # Light tracing cannot see the emitter directly: its error is real and nonzero.
    assert by[("furnace", "ptracer", 0)]["metrics"]["relmse"] > 1e-3
    disk = by[("area_lights_disk", "path", 1)]
    assert set(disk["effect_metrics"]) == {"direct"}
    assert disk["effect_metrics"]["direct"]["relmse"] == pytest.approx(disk["metrics"]["relmse"], rel=1e-6)
    # Mitsuba-referenced scene: the total is measured against Mitsuba, with its noise floor.
    cb = by[("cornell_box", "path", 0)]
    assert cb["reference"]["kind"] == "mitsuba" and cb["metrics"]["relmse_floor"] > 0


def test_same_seed_same_metrics(smoke, seeds_as_written):
    """A job is deterministic: its seed fixes the image bit for bit. (The
    smoke run's jobs render in spawned workers, which see the seeds as
    written under RADIOMETER_SEED_OFFSET too, so this rerun does.)"""
    root, run_id, recs = smoke
    rec = next(r for r in recs if r["scene"] == "area_lights_disk" and r["estimator"] == "path")
    job = {k: rec[k] for k in ("scene", "estimator", "integrator", "scene_params", "budget", "seed", "threads",
                               "checkpoints", "target_relmse", "effect_ref", "key", "config_key")}
    again = runner.run_job(job, str(root / "again"), "again", "c", {})
    assert again["status"] == "ok"
    assert again["metrics"]["relmse"] == rec["metrics"]["relmse"]


def test_failed_job_is_recorded_and_the_rest_go_on(tmp_path):
    mat = MX.load("smoke")
    mat.jobs = [j for j in mat.jobs if j.scene == "furnace"][:3]
    mat.jobs[1].scene = "no_such_scene"  # fails inside the worker (KeyError)
    run_id = runner.run(mat, root=tmp_path, workers=2, progress=False, log=lambda *a: None)
    with Store(tmp_path / runner.STORE_NAME) as st:
        recs = st.jobs(run_id)
    assert sorted(r["status"] for r in recs) == ["failed", "ok", "ok"]
    bad = next(r for r in recs if r["status"] == "failed")
    assert "no_such_scene" in bad["error"] and "KeyError" in bad["error"]


def test_bench_command_prints_table_and_report(tmp_path, capsys):
    mat = _write(tmp_path, BASE + "[estimators.ptracer]\n")
    assert main(["bench", mat, "--results", str(tmp_path / "r"), "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^furnace  \(2 spp\)\n  estimator\s+spp\s+total.*\n  path\s+2\s+\S+\s+", out, re.M), out
    assert "emission" in out and "indirect" in out
    m = re.search(r"^report: (.*index\.html)$", out, re.M)
    assert m and Path(m.group(1)).exists(), out


# -- Dask ---------------------------------------------------------------------------


def test_dask_local_cluster_runs_the_same_jobs(tmp_path):
    from distributed import LocalCluster

    mat = MX.load("smoke")
    mat.jobs = [j for j in mat.jobs if j.scene in ("furnace", "fog_room")]
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp://", host="127.0.0.1",
                      dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        run_id = runner.run(mat, root=tmp_path, scheduler=cluster.scheduler_address, progress=False,
                            log=lambda *a: None)
    with Store(tmp_path / runner.STORE_NAME) as st:
        recs = st.jobs(run_id)
    assert len(recs) == len(mat.jobs)
    assert {r["status"] for r in recs if r["scene"] == "furnace"} == {"ok"}
    fog = {r["estimator"]: r["status"] for r in recs if r["scene"] == "fog_room"}
    assert fog == {"path": "ok", "direct": "unsupported"}, fog


# -- the store: SIGKILL, --resume, merge -----------------------------------------------


KILL_MATRIX = """
name = "kill"
seeds = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9]
budgets = [{ seconds = 0.4 }]
[scenes.furnace]
params = { res = 8 }
[estimators.path]
"""


def _count(db):
    if not db.exists():
        return 0
    try:
        c = sqlite3.connect(str(db), timeout=5)
        try:
            return c.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
        finally:
            c.close()
    except sqlite3.OperationalError:
        return 0


def test_sigkill_loses_no_finished_job_and_resume_skips_them(tmp_path):
    mat = _write(tmp_path, KILL_MATRIX)
    res = tmp_path / "r"
    db = res / runner.STORE_NAME
    p = subprocess.Popen([RADIOMETER, "bench", mat, "--results", str(res), "--workers", "1", "--no-report"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120  # a guard against hanging, not a timing assertion
        while _count(db) < 2 and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        os.killpg(p.pid, signal.SIGKILL)  # the runner and its pool workers
        p.wait(timeout=30)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    with Store(db) as st:
        (run,) = st.runs()
        before = st.jobs(run["run_id"])
    assert run["finished"] is None, "the run was killed, it must not be marked finished"
    assert 2 <= len(before) < 10, f"{len(before)} jobs recorded: kill earlier or make the jobs longer"
    for r in before:
        assert r["status"] == "ok" and (res / r["exr"]).exists()
    assert main(["bench", mat, "--results", str(res), "--resume", "--workers", "1", "--no-report"]) == 0
    with Store(db) as st:
        after = st.jobs(run["run_id"])
        assert len(st.runs()) == 1
        assert st.run(run["run_id"])["finished"] is not None
    assert len(after) == 10
    assert len({r["key"] for r in after}) == 10
    kept = {r["uid"]: r for r in after}
    for r in before:  # the finished jobs were skipped, not rerun
        assert kept[r["uid"]]["finished"] == r["finished"]


def test_stores_from_two_machines_merge(tmp_path, capsys):
    mat = _write(tmp_path, BASE)
    for m in ("a", "b"):
        runner.run(mat, root=tmp_path / m, workers=1, progress=False, log=lambda *a: None)
    # Make "b" look like another machine's store with its own run.
    dest = tmp_path / "merged.sqlite"
    assert main(["merge", str(tmp_path / "a" / runner.STORE_NAME), str(tmp_path / "b" / runner.STORE_NAME),
                 "--into", str(dest)]) == 0
    assert "1 runs and 1 jobs added" in capsys.readouterr().out
    with Store(dest) as st:
        assert len(st.runs()) == 2
        assert sum(len(st.jobs(r["run_id"])) for r in st.runs()) == 2
        # Merging again adds nothing.
        assert st.merge(tmp_path / "a" / runner.STORE_NAME) == (0, 0)
    with pytest.raises(ValueError, match="not a"):
        bogus = tmp_path / "bogus.sqlite"
        bogus.write_text("not a database")
        with Store(dest) as st:
            st.merge(bogus)


# -- the report in headless Chromium ------------------------------------------------


def chromium_check(index: Path):
    """Opens `index` in headless Chromium; returns (console lines, dumped
    DOM). The page's own check writes how many images decoded into
    body[data-images-ok] on load."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    assert exe, "Debian's chromium is missing: bash install.sh installs it"
    p = subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--v=0",
                        "--allow-file-access-from-files", "--virtual-time-budget=5000", "--dump-dom",
                        index.resolve().as_uri()], capture_output=True, text=True, timeout=120)
    console = [ln for ln in p.stderr.splitlines() if "CONSOLE" in ln]
    return console, p.stdout


def test_report_renders_in_chromium_without_errors(smoke):
    root, run_id, recs = smoke
    from radiometer.benchmarks import report

    index = report.write(root / runner.STORE_NAME, run_id, log=lambda *a: None)
    html = index.read_text()
    imgs = re.findall(r"<img src='([^']+)'", html)
    # Per scene with finished jobs: convergence plot, image comparison, 3D view.
    scenes_ok = {r["scene"] for r in recs if r["status"] == "ok"}
    for s in scenes_ok:
        assert f"{s}-convergence.png" in imgs and f"{s}-images.png" in imgs, imgs
        assert f"{s}-view.png" in imgs or "no 3D view" in html
    for src in imgs:
        assert (index.parent / src).stat().st_size > 1000, src
    assert "fog_room" in html and "unsupported" in html
    console, dom = chromium_check(index)
    assert not console, "console messages:\n" + "\n".join(console)
    m = re.search(r'data-images-ok="(\d+)" data-images-total="(\d+)"', dom)
    assert m, "the page's load check did not run:\n" + dom[:2000]
    assert int(m.group(1)) == int(m.group(2)) == len(imgs) > 0


def test_chromium_check_catches_a_broken_page(tmp_path):
    """The check above can fail: a script error is a console line, a missing
    image is counted by the page's own check."""
    from radiometer.analysis.report import SELF_CHECK

    page = tmp_path / "index.html"
    page.write_text("<html><body><p id='selfcheck'></p><img src='missing.png'>"
                    f"<script>{SELF_CHECK}</script><script>undefined_function();</script></body></html>")
    console, dom = chromium_check(page)
    assert any("undefined_function" in ln for ln in console), console
    assert 'data-images-ok="0" data-images-total="1"' in dom, dom


# -- per-effect references ----------------------------------------------------------


# The bias injected into a per-effect reference to test its rejection path.
EFFECT_REF_BIAS = 1.03


def test_effect_reference_is_used_only_when_its_total_passes(tmp_path, smoke, monkeypatch):
    """A per-effect reference of a Mitsuba-referenced scene is our path
    tracer's run; it is used only if its total passes the z-test against
    Mitsuba. 512 spp of the glass sphere passes and is used. The rejection
    path is tested with a known error, not with noise: the same render with
    its total (image, every effect layer) scaled by EFFECT_REF_BIAS (3 %,
    the variance by its square) must fail the z-test, stay on disk with
    accepted = 0, and leave the scene's jobs without a per-effect reference,
    the failed z-test named as the reason. The smoke run's Cornell box jobs
    follow their 16 spp reference's verdict, whichever it is (a chance
    outcome at that budget)."""
    import dataclasses

    import numpy as np

    import radiometer as rm
    from radiometer.benchmarks import effect_refs
    from radiometer.benchmarks.matrix import Job
    from radiometer.reference_scenes import registry as scenes

    scene = "glass_sphere_caustic"
    params = dict(scenes.get(scene).fixed_params)
    renders = []
    render = rm.render

    def kept(*args, **kwargs):
        renders.append(render(*args, **kwargs))
        return renders[-1]

    def biased(*args, **kwargs):  # the render above, its total EFFECT_REF_BIAS too bright
        r, f = renders[0], EFFECT_REF_BIAS
        return dataclasses.replace(r, image=r.image * f, variance=r.variance * f * f,
                                   effects={k: v * f for k, v in r.effects.items()})

    def job():
        return Job(scene, "path", {"type": "path"}, params, {"spp": 4}, 0, 1)

    good, bad = tmp_path / "good", tmp_path / "bad"
    monkeypatch.setattr(rm, "render", kept)
    meta = effect_refs.make(scene, params, 512, effect_refs.ref_path(good, scene, params, 512), threads=1)
    assert meta["accepted"] == 1, meta["ztest"]
    e = rm.read_exr(effect_refs.ref_path(good, scene, params, 512))
    assert e.effects["caustic"].max() > 0
    np.testing.assert_allclose(sum(e.effects.values()), e.image, rtol=1e-4, atol=1e-6)
    monkeypatch.setattr(rm, "render", biased)
    meta = effect_refs.make(scene, params, 512, effect_refs.ref_path(bad, scene, params, 512), threads=1)
    missed = f"a {EFFECT_REF_BIAS - 1:.0%} bias in the reference went undetected:\n"
    assert meta["accepted"] == 0, missed + meta["ztest"]
    assert "FAIL" in meta["ztest"]
    monkeypatch.setattr(rm, "render", render)
    # ensure() takes both from its cache (no render) and uses only the one that passed.
    j_good, j_bad = job(), job()
    notes = effect_refs.ensure(good, [j_good], spp_override=512, log=lambda *a: None)
    assert j_good.effect_ref == str(effect_refs.ref_path(good, scene, params, 512)) and j_good.effect_note is None
    assert "passed" in notes[scene]
    notes = effect_refs.ensure(bad, [j_bad], spp_override=512, log=lambda *a: None)
    assert j_bad.effect_ref is None and "failed the z-test" in j_bad.effect_note
    assert "rejected" in notes[scene] and "FAIL" in notes[scene]
    assert len(renders) == 1
    root, run_id, recs = smoke
    refs = list((root / "refs").glob("cornell_box-*.exr"))
    assert len(refs) == 1
    accepted = int(rm.read_exr(refs[0]).metadata["accepted"])
    cornell = [r for r in recs if r["scene"] == "cornell_box"]
    assert cornell
    for r in cornell:
        if accepted:
            assert r["effect_metrics"] and "passed" in r["reference"]["effects"], r["reference"]
        else:
            assert r["effect_metrics"] == {} and "failed the z-test" in r["reference"]["effects"], r["reference"]
