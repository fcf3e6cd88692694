"""The benchmark harness and the command line against bad input: stores are
opened read-only where nothing is written, nothing escapes the results
folder, a resume or a matrix that cannot mean what it says is refused when it
is read, a broken cache is remade, and every refusal is an `error:` line
naming what is wrong (exit 2), never a traceback or a silent exit 0."""
import sqlite3
from pathlib import Path

import pytest

from radiometer import cli
from radiometer.benchmarks import compare as C
from radiometer.benchmarks import matrix as MX
from radiometer.benchmarks import runner
from radiometer.benchmarks.store import Store
from radiometer.cli import main

TINY = """
name = "{name}"
seeds = [0]
budgets = [{{ spp = 1 }}]
[scenes.furnace]
params = {{ res = 4 }}
[estimators.path]
"""


def _matrix(tmp_path, name="t", text=None, file="m.toml"):
    p = tmp_path / file
    p.write_text(TINY.format(name=name) if text is None else text)
    return str(p)


def _tables(db: Path) -> set:
    c = sqlite3.connect(str(db))
    try:
        return {r[0] for r in c.execute("SELECT name FROM sqlite_master")}
    finally:
        c.close()


def _foreign(path: Path) -> Path:
    """Someone else's SQLite database (not WAL, so a reader leaves no files)."""
    c = sqlite3.connect(str(path))
    c.execute("CREATE TABLE notes (id INTEGER PRIMARY KEY, text TEXT)")
    c.execute("INSERT INTO notes (text) VALUES ('keep me')")
    c.commit()
    c.close()
    return path


@pytest.fixture
def no_bench(monkeypatch):
    """runner.run that fails the test if the command gets as far as running jobs."""
    def boom(*a, **k):
        raise AssertionError("the bench ran although its input is bad")
    monkeypatch.setattr(runner, "run", boom)


# -- read-only stores ----------------------------------------------------------------


def _readers(store: Path, results: Path):
    """The commands that only read a store, each aimed at `store`."""
    return {
        "runs": ["runs", "--results", str(results)],
        "compare": ["compare", str(store), str(store)],
        "report": ["report", str(store), "-o", str(results / "rep")],
    }


@pytest.mark.parametrize("cmd", ["runs", "compare", "report"])
def test_readers_leave_an_empty_file_alone(tmp_path, capsys, cmd):
    results = tmp_path / "r"
    results.mkdir()
    store = results / runner.STORE_NAME
    store.touch()
    assert main(_readers(store, results)[cmd]) == 2
    err = capsys.readouterr().err
    assert f"radiometer {cmd}: error:" in err and str(store) in err and "not a results store" in err, err
    assert "empty" in err, err
    assert store.stat().st_size == 0  # no tables were created in it
    assert sorted(p.name for p in results.iterdir()) == [runner.STORE_NAME]


@pytest.mark.parametrize("cmd", ["runs", "compare", "report"])
def test_readers_leave_a_foreign_database_alone(tmp_path, capsys, cmd):
    results = tmp_path / "r"
    results.mkdir()
    store = _foreign(results / runner.STORE_NAME)
    before = store.read_bytes()
    assert main(_readers(store, results)[cmd]) == 2
    err = capsys.readouterr().err
    assert str(store) in err and "not a results store" in err and "notes" in err, err
    assert store.read_bytes() == before and _tables(store) == {"notes"}


def test_readers_name_a_file_that_is_not_sqlite(tmp_path, capsys):
    store = tmp_path / "junk.sqlite"
    store.write_text("not a database, " * 100)
    assert main(["compare", str(store), str(store)]) == 2
    err = capsys.readouterr().err
    assert str(store) in err and "not an SQLite" in err, err


def test_read_only_store_of_a_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.sqlite"):
        Store(tmp_path / "nowhere.sqlite", readonly=True)
    assert not (tmp_path / "nowhere.sqlite").exists()


def test_read_only_store_cannot_write(tmp_path):
    """The control: a real store opens read-only, reads, and refuses writes."""
    db = tmp_path / "s.sqlite"
    with Store(db) as st:
        st.add_run("r1", "m", "-", "", "c", {}, "2026-01-01T00:00:00+00:00")
    with Store(db, readonly=True) as st:
        assert [r["run_id"] for r in st.runs()] == ["r1"]
        with pytest.raises(sqlite3.OperationalError, match="readonly"):
            st.add_run("r2", "m", "-", "", "c", {}, "2026-01-01T00:00:00+00:00")


def test_writer_refuses_a_foreign_database(tmp_path, capsys):
    """bench and merge write, but not into someone else's database."""
    a = tmp_path / "a"
    runner.run(_matrix(tmp_path), root=a, workers=1, progress=False, log=lambda *x: None)
    dest = _foreign(tmp_path / "theirs.sqlite")
    before = dest.read_bytes()
    assert main(["merge", str(a / runner.STORE_NAME), "--into", str(dest)]) == 2
    err = capsys.readouterr().err
    assert str(dest) in err and "not a results store" in err and "notes" in err, err
    assert dest.read_bytes() == before
    results = tmp_path / "r"
    results.mkdir()
    _foreign(results / runner.STORE_NAME)
    assert main(["bench", _matrix(tmp_path), "--results", str(results), "--no-report"]) == 2
    assert "not a results store" in capsys.readouterr().err
    assert _tables(results / runner.STORE_NAME) == {"notes"}


# -- nothing escapes the results folder ------------------------------------------------


@pytest.mark.parametrize("name", ["x/../../escaped", "../escaped", "a:b", ".hidden", "", "a b"])
def test_matrix_name_is_one_plain_word(tmp_path, capsys, name):
    path = _matrix(tmp_path, name=name)
    with pytest.raises(MX.MatrixError) as e:
        MX.load(path)
    assert str(e.value).startswith(f"{path}: name:"), e.value
    assert repr(name) in str(e.value)
    results = tmp_path / "deep" / "r"
    assert main(["bench", path, "--results", str(results)]) == 2
    assert f"{path}: name:" in capsys.readouterr().err
    assert not (tmp_path / "escaped").exists() and not (tmp_path / "deep" / "escaped").exists()


def test_estimator_label_is_one_plain_word(tmp_path):
    """A label names the job's EXR file (runs/RUN/SCENE/LABEL-...exr)."""
    text = TINY.format(name="t").replace("[estimators.path]", '[estimators."../../../up"]\ntype = "path"')
    path = _matrix(tmp_path, text=text)
    with pytest.raises(MX.MatrixError) as e:
        MX.load(path)
    assert str(e.value).startswith(f"{path}: estimators.../../../up:"), e.value


def test_plain_names_still_pass():
    """The control: the shipped matrices' names and labels are accepted."""
    for m in ("smoke", "default"):
        assert MX.load(m).name == m


def test_report_refuses_a_run_id_that_is_a_path(tmp_path):
    """A merged store may hold a run id from anywhere; the report folder is named after it."""
    db = tmp_path / "r" / runner.STORE_NAME
    with Store(db) as st:
        st.add_run("../../evil", "m", "-", "", "c", {}, "2026-01-01T00:00:00+00:00")
    from radiometer.benchmarks import report

    with pytest.raises(ValueError, match=r"'\.\./\.\./evil'"):
        report.write(db, "../../evil", log=lambda *a: None)
    assert not (tmp_path / "evil").exists()


@pytest.mark.parametrize("field, value", [("scene", "../../../evil"), ("exr", "../../secret.exr"),
                                          ("exr", "/etc/secret.exr")])
def test_report_refuses_a_job_that_points_outside(tmp_path, field, value):
    """The page names images after each job's scene and reads its EXR under the store's folder."""
    from test_compare import _record

    from radiometer.benchmarks import report

    db = tmp_path / "r" / runner.STORE_NAME
    rec = dict(_record("cornell_box", "path", 0, 0.01, 1.0), exr="runs/x/cornell_box/path.exr")
    rec[field] = value
    with Store(db) as st:
        st.add_run("r1", "m", "-", "", "c", {}, "2026-01-01T00:00:00+00:00")
        st.add_job("r1", rec)
    with pytest.raises(ValueError, match=repr(value).replace(".", r"\.")):
        report.write(db, "r1", log=lambda *a: None)
    assert not (tmp_path / "r" / "reports").exists()


# -- --resume ---------------------------------------------------------------------------


def test_resume_refuses_a_run_of_another_matrix(tmp_path, capsys):
    res = tmp_path / "r"
    first = runner.run(_matrix(tmp_path, name="first"), root=res, workers=1, progress=False, log=lambda *a: None)
    other = _matrix(tmp_path, name="other", file="other.toml")
    assert main(["bench", other, "--results", str(res), "--resume", first, "--no-report"]) == 2
    err = capsys.readouterr().err
    assert first in err and "'first'" in err and "'other'" in err, err
    with Store(res / runner.STORE_NAME, readonly=True) as st:
        assert [r["run_id"] for r in st.runs()] == [first]
        assert len(st.jobs(first)) == 1
    # The control: resuming it with its own matrix is fine (nothing left to run).
    assert main(["bench", _matrix(tmp_path, name="first"), "--results", str(res), "--resume", first,
                 "--no-report"]) == 0


# -- a truncated cached per-effect reference ----------------------------------------------------


def _truncate(p: Path):
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])


def test_truncated_effect_reference_is_remade(tmp_path):
    import radiometer as rm
    from radiometer.benchmarks import effect_refs

    text = TINY.format(name="cb").replace("[scenes.furnace]\nparams = { res = 4 }", "[scenes.cornell_box]")
    mat = MX.parse(__import__("tomllib").loads(text + "[effect_refs]\nspp = 2\n"))
    logs = []
    effect_refs.ensure(tmp_path, mat.jobs, 2, threads=1, log=logs.append)
    (ref,) = (tmp_path / "refs").glob("cornell_box-*.exr")
    good = rm.read_exr(ref).metadata
    _truncate(ref)
    with pytest.raises(ValueError, match="truncated or corrupt"):
        rm.read_exr(ref)
    logs.clear()
    notes = effect_refs.ensure(tmp_path, mat.jobs, 2, threads=1, log=logs.append)
    assert "cornell_box" in notes
    assert any(str(ref) in m and "truncated or corrupt" in m and "remaking" in m for m in logs), logs
    again = rm.read_exr(ref).metadata  # whole again, and the same seeded reference
    assert again["ztest"] == good["ztest"]


def test_refs_command_remakes_a_truncated_effect_reference(tmp_path, capsys):
    import radiometer as rm

    args = ["refs", "--effects", "cornell_box", "--spp", "2", "--threads", "1", "--results", str(tmp_path)]
    assert main(args) == 0
    (ref,) = (tmp_path / "refs").glob("cornell_box-*.exr")
    _truncate(ref)
    capsys.readouterr()
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "truncated or corrupt" in captured.err and "remaking" in captured.err, captured
    assert rm.read_exr(ref).image.shape == (64, 64, 3)


# -- resource limits of a matrix --------------------------------------------------------


@pytest.mark.parametrize("old, new, key, words", [
    ("seeds = [0]", "seeds = [0]\nthreads = 100000", "threads", "0..1024"),
    ("seeds = [0]", "seeds = [0]\nthreads = -1", "threads", "0..1024"),
    ("{ spp = 1 }", "{ seconds = inf }", "budgets[0].seconds", "finite"),
    ("{ spp = 1 }", "{ seconds = nan }", "budgets[0].seconds", "finite"),
    ("{ spp = 1 }", "{ seconds = 1e300 }", "budgets[0].seconds", "604800"),
    ("{ spp = 1 }", "{ spp = 1099511627776 }", "budgets[0].spp", "1..16777216"),
    ("{ spp = 1 }", "{ spp = 0 }", "budgets[0].spp", "1..16777216"),
    ("seeds = [0]", "seeds = [0]\ntarget_relmse = inf", "target_relmse", "finite"),
    ("[estimators.path]", "[estimators.path]\n[effect_refs]\nspp = 1099511627776", "effect_refs.spp",
     "2..16777216"),
    ("[estimators.path]", "[estimators.path]\n[effect_refs]\nspp = 1", "effect_refs.spp", "2..16777216"),
])
def test_matrix_budgets_are_bounded(tmp_path, old, new, key, words):
    path = _matrix(tmp_path, text=TINY.format(name="t").replace(old, new))
    with pytest.raises(MX.MatrixError) as e:
        MX.load(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}:") and words in msg, msg


def test_matrix_at_the_limits_is_accepted(tmp_path):
    """The control: the largest values render() allows pass."""
    text = TINY.format(name="t").replace("seeds = [0]", "seeds = [0]\nthreads = 1024").replace(
        "{ spp = 1 }", "{ spp = 16777216 }, { seconds = 604800 }")
    m = MX.load(_matrix(tmp_path, text=text))
    assert {j.threads for j in m.jobs} == {1024} and len(m.jobs) == 2


def test_bench_with_every_job_unsupported_is_an_error(tmp_path, capsys):
    text = ('name = "u"\nseeds = [0]\nbudgets = [{ spp = 1 }]\n[scenes.fog_room]\n[estimators.direct]\n'
            "[effect_refs]\nspp = 2\n")
    path = _matrix(tmp_path, text=text)
    rc = main(["bench", path, "--results", str(tmp_path / "r"), "--workers", "1", "--no-report"])
    err = capsys.readouterr().err
    assert rc == 1, err
    assert "error:" in err and "no job ran" in err and "1 unsupported" in err, err
    assert "participating media" in err, err  # the reason, once


def test_bench_summary_counts_failed_jobs():
    ok = {"status": "ok", "error": None}
    unsup = {"status": "unsupported", "error": "ValueError: direct: no media"}
    failed = {"status": "failed", "error": "Traceback ...\nKeyError: 'x'"}
    assert runner.summary([ok, unsup])[0] == 0
    rc, msg = runner.summary([ok, failed, failed])
    assert rc == 1 and "2 failed" in msg and "KeyError: 'x'" in msg, msg
    rc, msg = runner.summary([unsup, unsup])
    assert rc == 1 and "no job ran" in msg and msg.count("no media") == 1, msg
    rc, msg = runner.summary([])
    assert rc == 1 and "no job" in msg


@pytest.mark.parametrize("workers", ["0", "-3"])
def test_bench_workers_must_be_positive(tmp_path, capsys, workers):
    assert main(["bench", _matrix(tmp_path), "--results", str(tmp_path / "r"), "--workers", workers]) == 2
    assert "--workers" in capsys.readouterr().err


# -- compare's options ---------------------------------------------------------------------


def _two_runs(tmp_path):
    from test_compare import _rows, _store

    a = _store(tmp_path / "a.sqlite", _rows("cornell_box", "path", [0.01, 0.011, 0.0105], [1, 1, 1]))
    b = _store(tmp_path / "b.sqlite", _rows("cornell_box", "path", [0.05, 0.051, 0.0505], [1, 1, 1]))
    return str(a), str(b)


def test_compare_refuses_an_unknown_metric(tmp_path, capsys):
    a, b = _two_runs(tmp_path)
    assert main(["compare", a, b, "--metric", "relmsee"]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and "'relmsee'" in err and "relmse" in err.split("'relmsee'")[1], err
    with pytest.raises(ValueError, match="unknown metric 'rmse'"):
        C.compare_records([], [], metric="rmse")
    # The control: the real metric sees the regression.
    assert main(["compare", a, b, "--metric", "relmse"]) == 1


@pytest.mark.parametrize("factor", ["0", "-2", "0.5", "nan", "inf"])
def test_compare_refuses_a_factor_that_turns_the_gate_off(tmp_path, capsys, factor):
    a, b = _two_runs(tmp_path)
    assert main(["compare", a, b, "--factor", factor]) == 2
    err = capsys.readouterr().err
    assert "radiometer compare: error: --factor" in err and "Traceback" not in err, err
    with pytest.raises(ValueError, match="factor"):
        C.compare_records([], [], factor=float(factor))


def test_compare_factor_one_is_allowed(tmp_path):
    a, b = _two_runs(tmp_path)
    assert main(["compare", a, b, "--factor", "1"]) == 1


# -- bench's input errors ------------------------------------------------------------------


def test_directory_as_matrix_is_an_error_line(tmp_path, capsys):
    d = tmp_path / "folder.toml"
    d.mkdir()
    assert main(["bench", str(d), "--results", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert f"radiometer bench: error: {d}: a folder" in err, err
    assert not (tmp_path / "r").exists()


def test_matrix_that_is_not_text_is_an_error_line(tmp_path, capsys):
    p = tmp_path / "bin.toml"
    p.write_bytes(b"\xff\xfe\x00name = 1")
    assert main(["bench", str(p), "--results", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert f"{p}: not UTF-8" in err, err


@pytest.mark.parametrize("address, words", [
    ("tcp://127.0.0.1:1", "cannot reach"),
    ("nonsense::", "invalid address"),
    ("no-port-here", "missing port"),
])
def test_unreachable_scheduler_is_an_error_line(tmp_path, capsys, address, words):
    import dask
    import distributed  # noqa: F401  (its config defaults, before dask.config.set below)

    res = tmp_path / "r"
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
        rc = main(["bench", _matrix(tmp_path), "--results", str(res), "--scheduler", address])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert f"radiometer bench: error: --scheduler {address}:" in err and words in err, err
    assert "Traceback" not in err, err
    # Nothing was started: no run in the store.
    if (res / runner.STORE_NAME).exists():
        with Store(res / runner.STORE_NAME, readonly=True) as st:
            assert st.runs() == []


# -- render --effects --------------------------------------------------------------------


@pytest.fixture
def seen_effects(monkeypatch):
    """cli.render replaced by one that records its `effects` and stops."""
    seen = []

    def fake(*a, effects=None, **k):
        seen.append(effects)
        raise SystemExit(0)
    monkeypatch.setattr(cli, "render", fake)
    return seen


@pytest.mark.parametrize("arg, words", [
    ("", "empty"),
    (" ", "empty"),
    ("direct,", "empty name"),
    (",,", "empty name"),
    ("direct,causticz", "'causticz'"),
])
def test_render_effects_must_name_effects(tmp_path, capsys, seen_effects, arg, words):
    rc = main(["render", "cornell-box", "--spp", "1", "--effects", arg, "-o", str(tmp_path / "o.exr")])
    err = capsys.readouterr().err
    assert rc == 2 and "radiometer render: error: --effects" in err and words in err, err
    assert "known: emission" in err, err
    assert seen_effects == []


def test_render_effects_control(tmp_path, seen_effects):
    for arg, want in (("direct", ["direct"]), (" direct , caustic", ["direct", "caustic"]), (None, None)):
        argv = ["render", "cornell-box", "--spp", "1", "-o", str(tmp_path / "o.exr")]
        with pytest.raises(SystemExit):
            main(argv + (["--effects", arg] if arg is not None else []))
        assert seen_effects[-1] == want
