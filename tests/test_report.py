"""The report people look at: the winner matrix, verdicts against the
target relMSE, convergence bands and the slope rule, the history view, the
terminal table's width, and the image viewer driven in headless Chromium
(keys, wheel, drag, exposure) with checks that fail on a broken page.
Tiny scenes and budgets; no timing is asserted."""
import html
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from radiometer.analysis import metrics as M
from radiometer.analysis import tables as T
from radiometer.analysis import verdict as V
from radiometer.benchmarks import matrix as MX
from radiometer.benchmarks import runner
from radiometer.benchmarks.store import Store

HERE = Path(__file__).resolve().parent

TINY = """
name = "tinyreport"
seeds = [0, 1]
budgets = [{ spp = 16 }]
target_relmse = 0.05
[scenes.furnace]
params = { res = 8 }
[scenes.area_lights_disk]
params = { res = 16 }
[estimators.path]
[estimators.ptracer]
"""


@pytest.fixture(scope="module")
def report_run(tmp_path_factory):
    """Two runs of one tiny matrix in one store (the history view needs
    two) and the report of the second."""
    from radiometer.benchmarks import report

    root = tmp_path_factory.mktemp("report")
    mat = root / "tiny.toml"
    mat.write_text(TINY)
    run_id = runner.run(str(mat), root=root, workers=2, progress=False, log=lambda *a: None)
    with Store(root / runner.STORE_NAME) as st:
        recs = st.jobs(run_id)
        # An earlier run of the same matrix at another commit, for the history
        # view: the same records, each error doubled (rendering it twice would
        # only cost time).
        run = st.run(run_id)
        st.add_run("0-earlier", run["matrix"], run["matrix_path"], run["matrix_text"], "earliercommit", {},
                   "2000-01-01T00:00:00+00:00")
        for r in recs:
            m = dict(r["metrics"], relmse=2 * r["metrics"]["relmse"])
            st.add_job("0-earlier", dict(r, uid=None, metrics=m))
    index = report.write(root / runner.STORE_NAME, run_id, log=lambda *a: None)
    return root, run_id, recs, index


# -- the slope rule ---------------------------------------------------------------


def test_slope_needs_four_checkpoints_over_a_factor_four_in_time():
    t = np.array([0.1, 0.2, 0.4, 0.8, 1.6])
    assert M.loglog_slope(t, 3.0 / t) == pytest.approx(-1.0)
    # A photon-map render at a seconds budget: two checkpoints a few per cent
    # apart in time, which a plain fit turns into a slope of about -160.
    two = [(1, 2.90, 0.52), (2, 2.95, 0.03)]
    assert np.polyfit(np.log([2.90, 2.95]), np.log([0.52, 0.03]), 1)[0] < -100
    assert M.loglog_slope([p[1] for p in two], [p[2] for p in two]) is None
    assert M.curves_slope([two, two, two]) is None  # three seeds do not make it four checkpoints
    # Four checkpoints, but within a factor 2 in time: still too few.
    short = [(s, 1.0 + 0.3 * i, 1.0 / (1 + i)) for i, s in enumerate((1, 2, 4, 8))]
    assert M.loglog_slope([p[1] for p in short], [p[2] for p in short]) is None
    # The seeds of a configuration: one fit over the curves that qualify.
    good = [[(s, 0.1 * s * (1 + 0.01 * k), 2.0 / s) for s in (1, 2, 4, 8, 16)] for k in range(3)]
    assert M.curves_slope(good + [two]) == pytest.approx(-1.0, abs=0.02)


# -- verdicts and winners -------------------------------------------------------------


def _rec(scene, est, relmse, seconds, seed=0, noise=None, floor=None, effects=None, budget=None):
    m = {"relmse": relmse}
    if noise is not None:
        m["relmse_noise"] = noise
    if floor is not None:
        m["relmse_floor"] = floor
    return {"scene": scene, "estimator": est, "status": "ok", "seed": seed, "seconds": seconds, "spp": 64,
            "budget": budget or {"seconds": 3.0}, "metrics": m, "curve": [], "target_relmse": 0.05,
            "effect_metrics": {e: {"relmse": v} for e, v in (effects or {}).items()}}


def test_verdict_names_the_dominant_term_and_says_cannot_tell():
    v = V.verdict(_rec("s", "a", 0.04, 1, noise=0.03, floor=0.001), 0.05)
    assert v["usable"] is True and v["dominant"] == "noise"
    assert v["terms"]["bias"] == pytest.approx(0.009) and v["own_error"] == pytest.approx(0.039)
    v = V.verdict(_rec("s", "a", 0.2, 1, noise=0.01, floor=0.001), 0.05)
    assert v["usable"] is False and v["dominant"] == "bias"
    # The reference's own noise above the target: the measurement cannot judge it.
    v = V.verdict(_rec("s", "a", 0.08, 1, noise=0.01, floor=0.06), 0.05)
    assert v["usable"] is None and v["dominant"] == "reference"
    # A configuration is usable only when every seed is.
    cv = V.config_verdict([_rec("s", "a", 0.04, 1, noise=0.04), _rec("s", "a", 0.06, 1, 1, noise=0.06)], 0.05)
    assert cv["usable"] is False and cv["dominant"] == "noise" and cv["n"] == 2


def test_target_relmse_is_validated_with_a_stated_default(tmp_path):
    base = 'name = "t"\nseeds = [0]\nbudgets = [{ spp = 2 }]\n[scenes.furnace]\nparams = { res = 4 }\n' \
           '[estimators.path]\n'
    p = tmp_path / "m.toml"
    p.write_text(base)
    assert {j.target_relmse for j in MX.load(str(p)).jobs} == {MX.DEFAULT_TARGET_RELMSE}
    for bad in ("-1", "0", '"small"', "1e9"):
        p.write_text("target_relmse = " + bad + "\n" + base)
        with pytest.raises(MX.MatrixError, match=r"target_relmse"):
            MX.load(str(p))


def test_winner_is_the_most_efficient_and_a_tie_within_noise_is_not_resolved():
    recs = []
    b_direct, c_direct = (0.09, 0.11, 0.10, 0.10), (0.12, 0.08, 0.10, 0.095)
    for s in range(4):
        # a: 4x lower total error at equal time; b and c: the same direct error within the seeds' spread.
        recs.append(_rec("x", "a", 0.01 * (1 + 0.02 * (s - 1.5)), 3.0, s, effects={"direct": 0.2}))
        recs.append(_rec("x", "b", 0.04 * (1 + 0.02 * (1.5 - s)), 3.0, s, effects={"direct": b_direct[s]}))
        recs.append(_rec("x", "c", 0.04 * (1 + 0.03 * (s - 1.5)), 3.0, s, effects={"direct": c_direct[s]}))
    w = {x["effect"]: x for x in V.winners(recs)}
    assert w["total"]["winner"] == "a" and w["total"]["ratio"] == pytest.approx(4.0, rel=0.15)
    assert w["total"]["resolved"] == "yes" and w["total"]["equal_time"]
    assert w["direct"]["winner"] in ("b", "c") and w["direct"]["resolved"] == "no"
    # Efficiency, not error alone: the same error in half the time wins.
    recs2 = [_rec("y", "slow", 0.01, 4.0, s) for s in range(3)] + [_rec("y", "fast", 0.01, 2.0, s) for s in range(3)]
    w2 = V.winners(recs2)[0]
    assert w2["winner"] == "fast" and w2["ratio"] == pytest.approx(2.0)


# -- the terminal table -----------------------------------------------------------------


def test_text_table_is_one_screen_wide_with_winners_and_verdicts(report_run):
    root, run_id, recs, _ = report_run
    text = T.effect_table_text(T.aggregate(recs), winners=V.winners(recs))
    assert max(len(ln) for ln in text.splitlines()) <= T.TEXT_WIDTH, text
    assert re.search(r"^  path\s+16\s+\S+\*", text, re.M), text  # path wins the furnace's total: starred
    assert "winners (equal samples, 16 spp" in text and "dominant" in text
    # The worst case: every effect, long labels, a long error message.
    effs = {e: 0.0123 for e in T.EFFECT_ORDER}
    many = []
    for est in ("photonmapper_long_label", "bdpt_balance", "sppm"):
        for s in range(2):
            many.append(_rec("vandehulst_slab_reflectance", est, 1.234e-5, 3.0, s, noise=1e-5, effects=effs))
    many.append(dict(_rec("vandehulst_slab_reflectance", "whitted", 1, 1), status="unsupported",
                     error="ValueError: " + "a very long reason " * 20))
    text = T.effect_table_text(T.aggregate(many), winners=V.winners(many))
    assert max(len(ln) for ln in text.splitlines()) <= T.TEXT_WIDTH, text
    for e in ("emission", "caustic", "volume", "subsurf"):
        assert e in text, text
    # What the check measures: the same table at 200 columns is wider.
    assert max(len(ln) for ln in T.effect_table_text(T.aggregate(many), width=200).splitlines()) > T.TEXT_WIDTH


def test_bench_records_terms_and_verdicts(report_run):
    root, run_id, recs, _ = report_run
    for r in recs:
        v = r["verdict"]
        assert v["target"] == 0.05 and v["dominant"] in V.TERMS + V.BIAS_PARTS + ("none",)
        assert r["metrics"]["relmse_noise"] >= 0
    fur = [r for r in recs if r["scene"] == "furnace"]
    # Light tracing cannot see the emitter: far off the target, its error is bias (the missing emission).
    pt = next(r for r in fur if r["estimator"] == "ptracer")
    assert pt["verdict"]["usable"] is False
    assert next(r for r in fur if r["estimator"] == "path")["verdict"]["usable"] is True


# -- the page and the viewer in headless Chromium ----------------------------------------------


def linked_files(folder: Path) -> list:
    """Every file the report's pages and the viewer's data name, relative
    to `folder`."""
    names = set()
    for page in ("index.html", "viewer.html"):
        text = (folder / page).read_text()
        for m in re.finditer(r"(?:src|href)=['\"]([^'\"#]+)", text):
            if "://" not in m.group(1):
                names.add(html.unescape(m.group(1)))
    idx = (folder / "data" / "index.js").read_text()
    for sc in json.loads(idx[idx.index("(") + 1:idx.rindex(")")])["scenes"]:
        names.add(f"data/{sc}.js")
        p = folder / "data" / f"{sc}.js"
        if p.exists():
            t = p.read_text()
            d = json.loads(t[t.index("(") + 1:t.rindex(")")])
            names.update(d["relerr"].values())
            names.update(d["flip"].values())
    return sorted(names)


def drive_viewer(folder: Path):
    """Opens viewer.html with tests/report_driver.js in headless Chromium;
    returns (console lines, the driver's log or its error, missing linked
    files)."""
    from test_bench import chromium_check

    page = folder / "viewer-driven.html"
    shutil.copyfile(HERE / "report_driver.js", folder / "report_driver.js")
    page.write_text((folder / "viewer.html").read_text().replace(
        "</body>", "<script src='report_driver.js'></script></body>"))
    console, dom = chromium_check(page)
    m = re.search(r'data-drive="([^"]*)"', dom)
    log = json.loads(html.unescape(m.group(1))) if m else {"error": "the driver did not run"}
    missing = [n for n in linked_files(folder) if not (folder / n).is_file()]
    return console, log, missing


def check_viewer(console, log, missing) -> list:
    """What is wrong with a driven viewer: [] for a good page."""
    bad = [f"console: {ln}" for ln in console] + [f"missing file: {n}" for n in missing]
    if isinstance(log, dict):
        return bad + [log["error"]]
    s = {x["what"]: x for x in log}
    want = [("flip", "start", "sig"), ("flip", "start", "source"), ("layer", "flip", "layer"),
            ("error map", "layer back", "err"), ("zoom", "error map", "zoom"), ("zoom", "error map", "transform"),
            ("wheel", "zoom", "zoom"), ("pan", "wheel", "pan"), ("exposure", "pan", "sig"),
            ("exposure", "pan", "exposure"), ("exposure key", "exposure", "sig"), ("reset", "exposure key", "zoom")]
    for after, before, what in want:
        if s[after][what] == s[before][what]:
            bad.append(f"{after}: {what} did not change ({s[after][what]!r})")
    if s["layer back"]["sig"] != s["flip"]["sig"]:
        bad.append("back to the first layer, the image differs from before")
    if not s["error map"]["err"] or not s["error map"]["err"].endswith("-flip.png"):
        bad.append(f"e did not show the FLIP map: {s['error map']['err']!r}")
    return bad


def test_report_page_and_viewer_in_chromium(report_run):
    root, run_id, recs, index = report_run
    from test_bench import chromium_check

    folder = index.parent
    page = index.read_text()
    # The winner matrix: each cell links to an evidence row that exists.
    cells = re.findall(r"<a href='#(ev-[^']+)'>", page)
    assert cells and all(f"id='{c}'" in page for c in cells), cells
    assert "furnace-history.png" in page and "not usable" in page and "usable" in page
    console, dom = chromium_check(index)
    assert not console, console
    m = re.search(r'data-images-ok="(\d+)" data-images-total="(\d+)"', dom)
    assert m and m.group(1) == m.group(2), dom[:2000]
    console, log, missing = drive_viewer(folder)
    assert check_viewer(console, log, missing) == [], (console, log, missing)


@pytest.mark.parametrize("breakage", ["missing data file", "script error", "missing error map"])
def test_viewer_checks_catch_a_broken_page(report_run, tmp_path, breakage):
    """The same checks fail on a page with a file missing or a JS error."""
    _, _, _, index = report_run
    folder = tmp_path / "rep"
    shutil.copytree(index.parent, folder)
    if breakage == "missing data file":
        (folder / "data" / "area_lights_disk.js").unlink()
    elif breakage == "script error":
        js = folder / "viewer.js"
        js.write_text(js.read_text().replace("function paint(canvas, rgb) {",
                                             "function paint(canvas, rgb) { no_such_function();"))
    else:
        (folder / "maps" / "area_lights_disk" / "ptracer-total-flip.png").unlink()  # the one e shows
    problems = check_viewer(*drive_viewer(folder))
    assert problems, f"{breakage}: the checks passed a broken page"
    if breakage == "script error":
        assert any("no_such_function" in p for p in problems), problems
    else:
        assert any("missing file" in p for p in problems) and any("console" in p for p in problems), problems


def test_rgbe_keeps_a_relative_precision_of_1_in_256():
    from radiometer.analysis.viewer import rgbe_bytes, rgbe_decode

    rng = np.random.default_rng(1)
    img = rng.lognormal(0, 3, (7, 5, 3))
    img[0, 0] = 0.0
    back = rgbe_decode(rgbe_bytes(img), img.shape)
    m = img.max(axis=-1, keepdims=True)
    assert np.all(np.abs(back - img) <= m / 256 + 1e-300)
    assert np.all(back[0, 0] == 0)
    # What the bound measures: a coarser encoding (6 bits) breaks it.
    coarse = np.round(img / np.maximum(m, 1e-300) * 64) / 64 * m
    assert np.any(np.abs(coarse - img) > m / 256)


def test_effect_budget_over_seeds_recovers_known_noise_and_bias():
    """Renders made as reference + bias + Gaussian noise of known size:
    the terms come back within their sampling error (fixed seed; 16 seeds of
    a 32 x 32 image, so each mean is over 3072 pixel-channels)."""
    rng = np.random.default_rng(7)
    ref = rng.uniform(0.5, 1.5, (32, 32, 3))
    d = ref ** 2 + 1e-2
    sigma, k = 0.1, 16
    tol = 0.2 * np.mean(sigma ** 2 / d)
    got = {}
    for b in (0.0, 0.05):
        imgs = [ref + b + sigma * rng.standard_normal(ref.shape) for _ in range(k)]
        got[b] = t = V.effect_budget_over_seeds(imgs, ref)
        assert t["noise"] == pytest.approx(np.mean(sigma ** 2 / d), rel=0.1)
        assert abs(t["bias"] - np.mean(b ** 2 / d)) < tol, (b, t)
    # Power: the injected bias is told apart from none.
    assert got[0.0]["bias"] < tol < got[0.05]["bias"], got


def test_time_to_error_section_from_the_study_results(tmp_path):
    """The report's side-by-side section (issue 13 point 4) shows what
    benchmarks/studies/time_to_error.py wrote, and says so when it has not
    run."""
    from radiometer.analysis.report import time_to_error_html
    from radiometer.benchmarks.studies.time_to_error import time_to

    missing = time_to_error_html(tmp_path / "none.json", tmp_path)
    assert "Not measured yet" in missing and "time_to_error" in missing
    pts = [{"spp": 4, "seconds": 1.0, "relmse": 0.04}, {"spp": 16, "seconds": 4.0, "relmse": 0.01}]
    t, extrapolated = time_to(pts, 0.02)
    assert t == pytest.approx(2.0) and not extrapolated  # 1/relMSE linear in time: halfway in log-log
    t, extrapolated = time_to(pts, 0.005)
    assert t == pytest.approx(8.0) and extrapolated
    scene = {"target_relmse": 0.02, "best_ours": "zsobol", "best_mitsuba": "llvm_ad_rgb multijitter", "ratio": 2.5,
             "thread_scaling": {"1": {"ours_msamples_per_s": 0.5, "mitsuba_llvm_msamples_per_s": 1.6}},
             "contenders": [{"renderer": "radiometer", "time_to_target_s": 5.0},
                            {"renderer": "mitsuba", "time_to_target_s": 2.0}]}
    f = tmp_path / "time_to_error.json"
    f.write_text(json.dumps({"commit": "abc1234", "date": "2026-12-06", "machine": {"cpu": "X", "cores": 2},
                             "scenes": {"cornell_box": scene}}))
    page = time_to_error_html(f, tmp_path)
    assert "cornell_box" in page and ">2.50<" in page and "abc1234" in page
    assert "zsobol: 5 s" in page and "llvm_ad_rgb multijitter: 2 s" in page
