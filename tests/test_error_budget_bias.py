"""The error budget's discretisation and model terms: each is
checked where its true value is known.

* discretisation, same render: sppm's and photonmapper's photon-radius bias
  from the density estimate at r and r / sqrt(2) of the same photons
  (Richardson in r^2; photonmapper adds its k-nearest rim photon), against
  the bias measured on exact images: the mirror caustic's caustic layer
  (method of images) and the closed furnace;
* discretisation and model, from the matrix (verdict.matrix_terms): the
  seeds of one configuration against the reference, on the furnace whose
  exact image is known for any albedo;
* the bench end to end: both terms in the record, the store, the EXR's
  metadata and the report; the verdict names them.

Significance: two-sided t-tests over seeds at ALPHA = 0.01 (16 seeds);
each has a power check, an estimate that is off (a wrong exponent in the
Richardson step, a scale, a missing term) rejected at the same level.
"""
import json

import numpy as np
import pytest
from scipy import stats as st

import radiometer as rm
from conftest import furnace_dict, furnace_exact
from radiometer.analysis import verdict as V
from radiometer.reference_scenes.mirror_caustic import analytic as mirror

ALPHA = 0.01
SEEDS = range(16)
# A wrong exponent: a Richardson step that assumed bias ~ r (first order)
# would multiply the difference L_r - L_{r/sqrt 2} by 1 / (1 - 2^-1/2)
# instead of 1 / (1 - 1/2), i.e. the estimate by this factor.
WRONG_EXPONENT = (1.0 / (1.0 - 2.0 ** -0.5)) / 2.0


def _accepts(measured, estimated):
    return st.ttest_1samp(np.asarray(measured) - np.asarray(estimated), 0.0).pvalue > ALPHA


def test_sppm_radius_bias_matches_the_mirror_caustics_exact_bias():
    """sppm on the mirror caustic (32 x 32) with a wide, slowly shrinking
    radius (0.4, alpha 0.99: the disc spans a fifth of the view) so the
    disc's blur of the caustic's curvature is large: per seed, the caustic
    layer's mean bias against the exact layer over the columns at least r
    from the mirror (x < 0.3; the caustic's edge at x = 1 breaks the r^2
    assumption, as the term's label says) against the mean of the render's
    per-pixel estimate (arrays radius_bias) there. Measured (offset 0):
    6.3e-4 +- 0.2e-4 measured, the estimate within 1 se. Power: the
    estimate times WRONG_EXPONENT (1.71), times 1.5 and times 0.6 are
    each rejected. The term's own standard error (over the passes) is
    the spread of its value over seeds within a factor of 2."""
    scene = rm.load_file(mirror.XML, res=32)
    exact = mirror.effects(res=32)["caustic"].astype(np.float64)
    cols = slice(0, 20)  # pixel columns whose x + r < 1
    integ = {"type": "sppm", "photon_count": 20000, "initial_radius": 0.4, "alpha": 0.99}
    measured, estimated, whole, whole_se = [], [], [], []
    for s in SEEDS:
        res = rm.render(scene, integrator=integ, spp=16, seed=s)
        measured.append(float((res.effects["caustic"] - exact)[:, cols].mean()))
        estimated.append(float(np.asarray(res.arrays["radius_bias"])[:, cols].mean()))
        term = res.error_budget["discretisation"]
        assert term["from"] == "same render" and term["batches"] == 16 and "r^2" in term["assumption"]
        whole.append(np.mean(term["bias_mean"]))
        whole_se.append(np.mean(term["bias_se"]))
    measured, estimated = np.array(measured), np.array(estimated)
    assert measured.mean() > 5 * measured.std(ddof=1) / 4  # the bias is resolved at all
    assert _accepts(measured, estimated), (measured.mean(), estimated.mean())
    for wrong in (WRONG_EXPONENT, 1.5, 0.6):
        assert not _accepts(measured, wrong * estimated), wrong
    assert 0.5 < np.median(whole_se) / np.std(whole, ddof=1) < 2.0, (np.median(whole_se), np.std(whole, ddof=1))


def test_photonmapper_radius_bias_matches_the_furnaces_exact_bias():
    """photonmapper on the closed furnace (le 0.5, rho 0.5, max_depth 3,
    exact 0.875) with 16 photons per estimate: the radiance is uniform, so
    the disc blurs nothing and the bias is the k-nearest estimate's own,
    the n-th photon on the rim (about L_indirect / (n - 1) = 0.125 / 15);
    the term's image mean against the image's measured bias, per seed, with
    final gathering and without. Measured (offset 0, 8 seeds): 8.13e-3 +-
    0.10e-3 against 8.35e-3 (gathered), 9.6e-3 +- 1.1e-3 against 9.2e-3.
    Power: a plain Richardson step that counts the rim photon in the disc
    (twice the rim term: the estimate plus the rim's share, about 2x), no
    rim term (about 0) and 1.5x the estimate are rejected."""
    exact = furnace_exact(0.5, 0.5, 3)
    scene = rm.load_dict(furnace_dict(le=0.5, rho=0.5, res=8, max_depth=3))
    for fg in (True, False):
        integ = {"type": "photonmapper", "direct_samples": 1, "gather_rays": 4, "global_photons": 20000,
                 "lookup_size": 16, "max_depth": 3, "final_gather": fg}
        measured, estimated, own_se = [], [], []
        for s in SEEDS:
            res = rm.render(scene, integrator=integ, spp=16, seed=s)
            term = res.error_budget["discretisation"]
            assert term["from"] == "same render" and term["batches"] == 64 * 16
            measured.append(float(res.image.mean()) - exact)
            estimated.append(float(np.mean(term["bias_mean"])))
            own_se.append(float(np.mean(term["bias_se"])))
        measured, estimated = np.array(measured), np.array(estimated)
        assert _accepts(measured, estimated), (fg, measured.mean(), estimated.mean())
        for wrong in (2.0, 0.0, 1.5):
            assert not _accepts(measured, wrong * estimated), (fg, wrong)
        # Its standard error over camera samples misses the shared photon
        # map's randomness; here it is still within a factor 2 of the
        # spread over seeds (measured 0.78 and 1.1).
        assert 0.5 < np.median(own_se) / estimated.std(ddof=1) < 2.0, (fg, np.median(own_se), estimated.std(ddof=1))


def test_discretisation_term_says_where_it_comes_from():
    """Unbiased estimators: 0, exact. Biased ones without a same-render
    estimate: None, with the reason and "from the matrix". A render whose
    scene needs no photons: 0. The term is in the EXR's metadata."""
    scene = rm.load_dict(furnace_dict(le=0.5, rho=0.5, res=4, max_depth=3))
    d = rm.render(scene, integrator="path", spp=2, seed=0).error_budget["discretisation"]
    assert d["exact"] and d["bias_mean"] == [0.0] * 3
    for est in ("irrcache", "vpl"):
        d = rm.render(scene, integrator=est, spp=2, seed=0).error_budget["discretisation"]
        assert d["bias_mean"] is None and "matrix" in d["reason"] and est in d["reason"]
    flat = rm.load_dict(furnace_dict(le=0.5, rho=0.5, res=4, max_depth=2))  # direct light only: no photon map
    d = rm.render(flat, integrator={"type": "sppm", "photon_count": 1000, "max_depth": 2}, spp=2, seed=0).error_budget[
        "discretisation"]
    assert d["exact"] and d["bias_mean"] == [0.0] * 3
    assert rm.render(scene, integrator="path", spp=2, seed=0).error_budget["model"] is None


def test_discretisation_term_in_exr_metadata(tmp_path):
    scene = rm.load_dict(furnace_dict(le=0.5, rho=0.5, res=4, max_depth=3))
    res = rm.render(scene, integrator={"type": "sppm", "photon_count": 2000}, spp=4, seed=0)
    res.write_exr(tmp_path / "a.exr")
    meta = rm.read_exr(tmp_path / "a.exr").metadata
    b = json.loads(meta["error_budget"])
    assert b["discretisation"]["bias_mean"] == pytest.approx(res.error_budget["discretisation"]["bias_mean"])
    assert "discretisation" in b["how"] and "model" in b["how"]


def _records(scene_rho, ref_rho, est, label, seeds, model_of=None):
    """Job records as the bench makes them, of furnace renders with albedo
    scene_rho against the exact furnace of albedo ref_rho (its reference)."""
    le, depth = 0.5, -1
    scene = rm.load_dict(furnace_dict(le=le, rho=scene_rho, res=8, max_depth=depth))
    ref = float(furnace_exact(le, ref_rho, depth))
    out = []
    for s in seeds:
        res = rm.render(scene, integrator=est, spp=4, seed=s)
        m = {"relmse": 0.0, "image_mean": [float(x) for x in res.image.reshape(-1, 3).mean(axis=0)],
             "reference_mean": [ref] * 3, "reference_mean_se": None}
        out.append({"key": f"{label}-{s}", "config_key": label, "status": "ok", "scene": label, "estimator": est,
                    "seed": s, "metrics": m, "error_budget": json.loads(json.dumps(res.error_budget)),
                    **({"model_of": model_of} if model_of else {})})
    return out, ref


def test_model_term_from_the_matrix_is_the_known_model_error():
    """A stand-in for the dipole against the random walk whose model error
    is exact: the furnace with albedo 0.5 (the 'model') against the exact
    furnace of albedo 0.55 (the 'alternative': its reference), path at
    unbounded depth (Russian roulette makes it noisy: 4 spp, 16 seeds).
    matrix_terms' model error must be 0.5 / 0.5 - 0.5 / 0.45 = -0.111
    within its standard error (z test at ALPHA), and 15 % of it more is
    rejected (15 %: the standard error is about 2.3 % of it). A
    vpl render (no same-render estimate) gets its discretisation term from
    its seeds the same way; path's stays 0 (unbiased)."""
    recs, ref = _records(0.5, 0.55, {"type": "path", "max_depth": -1}, "furnace_model", SEEDS,
                         model_of="furnace_055")
    vrecs, _ = _records(0.5, 0.5, "vpl", "furnace_vpl", range(4))
    changed = V.matrix_terms(recs + vrecs)
    assert len(changed) == len(recs) + len(vrecs)
    true = float(furnace_exact(0.5, 0.5, -1)) - ref
    mdl = recs[0]["error_budget"]["model"]
    assert mdl["seeds"] == 16 and "furnace_055" in mdl["from"] and mdl["alternative_scene"] == "furnace_055"
    z = (np.array(mdl["error_mean"]) - true) / np.array(mdl["error_se"])
    assert np.all(np.abs(z) < st.norm.ppf(1 - ALPHA / 2)), z
    zw = (np.array(mdl["error_mean"]) - 1.15 * true) / np.array(mdl["error_se"])
    assert np.all(np.abs(zw) > st.norm.ppf(1 - ALPHA / 2)), zw
    assert recs[0]["error_budget"]["discretisation"]["bias_mean"] == [0.0] * 3  # path: unbiased, untouched
    d = vrecs[0]["error_budget"]["discretisation"]
    assert d["from"].startswith("the matrix") and d["seeds"] == 4
    want = np.mean([r["metrics"]["image_mean"] for r in vrecs], axis=0) - furnace_exact(0.5, 0.5, -1)
    assert d["bias_mean"] == pytest.approx(list(want))


def test_verdict_names_the_bias_part_that_explains_it():
    """The dominant term: the bias part (truncation, discretisation,
    model, in relMSE units as the squared relative bias of the image mean)
    when the remainder dominates and the part explains at least what the
    parts leave unexplained; otherwise plain "bias"."""
    def rec(total, noise, disc=None, model=None, trunc=None):
        b = {"discretisation": {"bias_mean": disc}, "model": {"error_mean": model},
             "truncation": {"missing_mean": trunc}}
        return {"status": "ok", "metrics": {"relmse": total, "relmse_noise": noise, "reference_mean": [1.0] * 3},
                "error_budget": b}

    # bias remainder 0.09; discretisation (0.3)^2 = 0.09 explains it
    v = V.verdict(rec(0.1, 0.01, disc=[0.3] * 3), 0.05)
    assert v["dominant"] == "discretisation" and v["terms"]["discretisation"] == pytest.approx(0.09)
    v = V.verdict(rec(0.1, 0.01, model=[-0.25] * 3, trunc=[0.05] * 3), 0.05)
    assert v["dominant"] == "model"
    assert V.verdict(rec(0.1, 0.01, disc=[0.1] * 3), 0.05)["dominant"] == "bias"  # 0.01 of 0.09 explained
    assert V.verdict(rec(0.1, 0.09, disc=[0.1] * 3), 0.05)["dominant"] == "noise"
    cv = V.config_verdict([rec(0.1, 0.01, disc=[0.3] * 3), rec(0.12, 0.01, disc=[0.32] * 3)], 0.05)
    assert cv["dominant"] == "discretisation" and cv["terms"]["discretisation"] > 0.09


MATRIX = """
name = "budgetterms"
seeds = [0, 1]
budgets = [{ spp = 64 }]
target_relmse = 0.05
[scenes.furnace]
params = { res = 8 }
estimators = ["sppm", "vpl"]
[scenes.translucent_slab_dipole]
estimators = ["path"]
[estimators.sppm]
photon_count = 2000
[estimators.vpl]
[estimators.path]
"""


def test_bench_records_the_new_terms_in_store_exr_and_report(tmp_path):
    """A tiny matrix: sppm (same-render term), vpl (from the matrix) on
    the furnace, and the dipole slab against the random walk's reference
    (its model term): the terms in the store's records, the EXR metadata
    and the report's verdict table."""
    from radiometer.benchmarks import report, runner
    from radiometer.benchmarks.store import Store

    mat = tmp_path / "m.toml"
    mat.write_text(MATRIX)
    run_id = runner.run(str(mat), root=tmp_path, workers=1, progress=False, log=lambda *a: None)
    with Store(tmp_path / runner.STORE_NAME) as stt:
        recs = stt.jobs(run_id)
    by = {(r["scene"], r["estimator"], r["seed"]): r for r in recs}
    assert all(r["status"] == "ok" for r in recs), [r.get("error") for r in recs]
    sp = by[("furnace", "sppm", 0)]["error_budget"]["discretisation"]
    assert sp["from"] == "same render"
    vp = by[("furnace", "vpl", 1)]["error_budget"]["discretisation"]
    assert vp["from"] == "the matrix: 2 seed(s) against the reference" and vp["bias_mean"] is not None
    dp = by[("translucent_slab_dipole", "path", 0)]
    mdl = dp["error_budget"]["model"]
    assert dp["model_of"] == "translucent_slab" and mdl["error_mean"] is not None and mdl["seeds"] == 2
    # The dipole misses most of the slab's transmitted light (card.md: lit half at 0.48 / 0.25 / 0.09 of
    # the reference): its model error is negative, many standard errors from 0, and names the verdict.
    assert all(m < -5 * s for m, s in zip(mdl["error_mean"], mdl["error_se"])), mdl
    assert dp["verdict"]["dominant"] == "model" and dp["verdict"]["terms"]["model"] > 0
    meta = rm.read_exr(tmp_path / dp["exr"]).metadata
    assert json.loads(meta["error_budget"])["model"]["error_mean"] == pytest.approx(mdl["error_mean"])
    sexr = rm.read_exr(tmp_path / by[("furnace", "sppm", 0)]["exr"])
    assert "radius_bias" in sexr.layers
    index = report.write(tmp_path / runner.STORE_NAME, run_id, log=lambda *a: None)
    html = index.read_text()
    assert "discretisation" in html and "model" in html and "translucent_slab_dipole" in html
