"""Emitter selection (`light_sampler = uniform | power | tree`,
scene/light_sampler.h) on a box lit by six emitters whose powers span four
decades (tests/light_sampler_scenes.py):

- each sampler's selections follow the probabilities it reports (Pearson
  chi-square per query point, Sidak over the family at ALPHA, with a power
  check: a 10 % distortion of the probabilities is rejected), and what
  sample() reports is what pmf() gives;
- `power` selects in proportion to each emitter's flux;
- under `tree`, next event estimation's directions follow the density the
  MIS weights of BSDF-sampled hits assign (a chi-square over directions);
- every estimator's image is unchanged in expectation with `power` and
  `tree` against `uniform` (per-block two-sample t-tests over seeds at
  ALPHA, with a power check: a 4 % brighter image is rejected), and the
  images are clean (no NaN, Inf, negative pixel) and thread-count
  independent.
"""
import numpy as np
import pytest
from scipy import stats as _st

import radiometer as rm
from light_sampler_scenes import many_powers
from radiometer.analysis.chi2 import SphereGrid, chi2_test, pearson_chi2, sidak_level
from radiometer.analysis.pixels import two_sample_t_test

ALPHA = 0.01
KINDS = ("uniform", "power", "tree")
# Query points (and normals; zero: a point in a medium) inside the box.
POINTS = np.array([[0.0, -1.0, 0.0], [0.45, -0.55, 0.2], [-1.0, 0.4, 0.5], [0.3, 0.95, -0.35], [0.0, 0.0, 0.0]],
                  np.float32)
NORMALS = np.array([[0, 1, 0], [0, 1, 0], [1, 0, 0], [0, -1, 0], [0, 0, 0]], np.float32)
N_SELECT = 40_000
# Chi-square family: every (kind, point) plus the two light-start samplers.
SELECT_LEVEL = sidak_level(ALPHA, len(KINDS) * len(POINTS) + 2)


@pytest.fixture(scope="module")
def core():
    return rm.load_dict(many_powers()).core()


def _luminance(c):
    return 0.212671 * c[0] + 0.715160 * c[1] + 0.072169 * c[2]


@pytest.mark.parametrize("kind", KINDS)
def test_selection_follows_its_pmf(core, kind):
    n = len(POINTS)
    u = np.random.default_rng(11).random((n, N_SELECT), dtype=np.float32)
    r = core.light_selection(kind, POINTS, NORMALS, u)
    pmf, idx, pick = r["pmf"], r["index"], r["pick"]
    assert np.all(np.isfinite(pmf)) and np.all(pmf >= 0)
    np.testing.assert_allclose(pmf.sum(axis=1), 1.0, atol=1e-5)
    assert np.all(idx >= 0), "every point is lit by some emitter"
    # sample()'s probability is pmf()'s for the emitter it picked
    np.testing.assert_allclose(pick, np.take_along_axis(pmf, idx, axis=1), rtol=1e-6)
    for i in range(n):
        counts = np.bincount(idx[i], minlength=core.emitter_count)
        res = pearson_chi2(counts, N_SELECT * pmf[i].astype(np.float64))
        assert not res["zero_violations"], (kind, i, res)
        assert res["p_value"] >= SELECT_LEVEL, (kind, i, res)
        # power check: the same counts against probabilities distorted by +-10 %
        bent = pmf[i] * (1.0 + 0.1 * np.where(np.arange(pmf.shape[1]) % 2 == 0, 1.0, -1.0))
        bent = bent / bent.sum()
        assert pearson_chi2(counts, N_SELECT * bent)["p_value"] < SELECT_LEVEL, (kind, i)


@pytest.mark.parametrize("kind", ["power", "tree"])
def test_light_start_selection_is_by_power(core, kind):
    """Light paths start without a point: `power` and `tree` both select
    by flux there, and the selections follow it."""
    u = np.random.default_rng(12).random((1, N_SELECT), dtype=np.float32)
    r = core.light_selection(kind, POINTS[:1], NORMALS[:1], u, start=True)
    pmf = r["pmf"][0]
    d = many_powers()
    lo, hi = np.array(core.bbox[0]), np.array(core.bbox[1])
    radius = 0.5 * np.linalg.norm(hi - lo)
    disk = max(radius * 1.001 + 1e-6 * min(radius, 1.0), 1e-18)
    # flux luminance: pi L A (one-sided area lights), 4 pi I (points), the
    # spot's 2 pi I ((1 - cos b) + (cos b - cos c) / 2), the sky's L 4 pi pi r^2
    b, c = np.radians(0.75 * 30.0), np.radians(30.0)
    phi = {"lamp": np.pi * _luminance([40, 36, 30]) * 0.4 * 0.4,
           "panel": np.pi * _luminance([0.2, 0.25, 0.3]) * 0.6 * 0.6,
           "dim_point": 4 * np.pi * 0.05, "bright_point": 4 * np.pi * _luminance([3.0, 2.5, 2.0]),
           "spot": 6.0 * 2 * np.pi * ((1 - np.cos(b)) + (np.cos(b) - np.cos(c)) / 2),
           "sky": 0.05 * 4 * np.pi * np.pi * disk * disk}
    order = [k for k in d if k in phi]  # emitters in scene order
    want = np.array([phi[k] for k in order])
    np.testing.assert_allclose(pmf, want / want.sum(), rtol=1e-4)
    counts = np.bincount(r["index"][0], minlength=len(pmf))
    res = pearson_chi2(counts, N_SELECT * pmf.astype(np.float64))
    assert res["p_value"] >= SELECT_LEVEL, res
    if kind == "tree":  # the tree's light-start selection is the power sampler's, exactly
        p = core.light_selection("power", POINTS[:1], NORMALS[:1], u, start=True)
        np.testing.assert_array_equal(p["index"], r["index"])


def test_tree_follows_the_point(core):
    """The tree's probabilities depend on where they are seen from: the dim
    point light gets more near it than from across the box, a one-sided
    light is never picked from behind, an omnidirectional one always can
    be."""
    u = np.zeros((2, 1), np.float32)
    near = np.array([[0.5, -0.6, 0.2], [0.9, -0.9, -0.9]], np.float32)
    r = core.light_selection("tree", near, np.array([[0, 1, 0], [0, 1, 0]], np.float32), u)
    names = [k for k in many_powers() if k in ("lamp", "panel", "dim_point", "bright_point", "spot", "sky")]
    dim, lamp, panel = names.index("dim_point"), names.index("lamp"), names.index("panel")
    assert r["pmf"][0, dim] > 3 * r["pmf"][1, dim]
    # above the ceiling lamp (it faces down) and behind the wall panel (it
    # faces +x), each beyond its bounding sphere (the tree bounds a cluster
    # by its box's sphere, which holds the points just behind it)
    behind = np.array([[0.0, 1.5, 0.0], [-1.6, 0.0, -0.3]], np.float32)
    r = core.light_selection("tree", behind, np.zeros((2, 3), np.float32), u)
    assert r["pmf"][0, lamp] == 0.0 and r["pmf"][1, panel] == 0.0
    pts = np.random.default_rng(3).uniform(-0.95, 0.95, (500, 3)).astype(np.float32)
    r = core.light_selection("tree", pts, np.zeros((500, 3), np.float32), np.zeros((500, 1), np.float32))
    assert np.all(r["pmf"][:, names.index("bright_point")] > 0)


def test_tree_nee_density_matches_its_mis_density():
    """From a floor point, light samples under `tree` (pick and point on the
    emitter) land on directions with the density that mis_emission_hit
    gives the same directions (chi-square over the sphere; the point
    lights' and spot's samples are the off-histogram bin). Without the sky:
    the density of a BSDF-sampled direction is that of the emitter the ray
    hits, and the walls hide most of the sky."""
    core = rm.load_dict(many_powers(env=False)).core()
    ref, nrm = POINTS[0] + np.float32([0, 1e-3, 0]), NORMALS[0]

    def sample(rng, n):
        s = core.sample_emitter_direction(np.broadcast_to(ref, (n, 3)), rng.random((n, 4), dtype=np.float32),
                                          light_sampler="tree", normal=np.broadcast_to(nrm, (n, 3)))
        return s["d"], s["is_delta"] > 0, s["pdf"] > 0

    def pdf(d):
        return core.pdf_emitter_direction(ref[None, :], np.asarray(d, np.float32), light_sampler="tree",
                                          normal=nrm[None, :])

    r = chi2_test(sample, pdf, n_samples=50_000, grid=SphereGrid(n_theta=12, n_phi=24), seed=5, level=ALPHA,
                  label="tree", min_depth=4, max_depth=8, rtol=1e-5, atol=1e-4)
    assert r.passed, r.summary()
    # power check: the pick's probability 8 % off in the density is rejected
    bad = chi2_test(sample, lambda d: 1.08 * pdf(d), n_samples=50_000, grid=SphereGrid(n_theta=12, n_phi=24),
                    seed=5, level=ALPHA, label="tree x1.08", min_depth=4, max_depth=8, rtol=1e-5, atol=1e-4)
    assert not bad.passed, bad.summary()


# Every estimator, each sampler against uniform: (integrator, spp).
ESTIMATORS = {
    "path": ({"type": "path", "max_depth": 4}, 512),
    "direct": ({"type": "direct"}, 256),
    "whitted": ({"type": "whitted"}, 256),
    "ptracer": ({"type": "ptracer", "max_depth": 4}, 256),
    "bdpt": ({"type": "bdpt", "max_depth": 4}, 128),
    "vcm": ({"type": "vcm", "max_depth": 4}, 64),
    "bpm": ({"type": "bpm", "max_depth": 4}, 256),
    "ppm": ({"type": "ppm", "max_depth": 4}, 256),  # 64 spp missed the 50 % power check under offset 1
    "photonmapper": ({"type": "photonmapper", "global_photons": 4000, "caustic_photons": 1000,
                      "gather_rays": 2}, 4),
    "sppm": ({"type": "sppm", "photon_count": 4000, "max_depth": 4}, 16),
}
SEEDS = 8
# The bias each power check injects, the smallest that these budgets reject
# under RADIOMETER_SEED_OFFSET 0..3: 4 % for path, bdpt, ptracer; 10 % for
# direct, whitted, vcm; 50 % for the photon-map estimators, whose noise here
# (a map rebuilt per render, merging near the point lights) is large: their
# test only shows that no sampler moves them by more than that.
POWER = {"direct": 1.10, "whitted": 1.10, "vcm": 1.10, **{e: 1.5 for e in ("photonmapper", "bpm", "ppm", "sppm")}}
RES = 12
BLOCK = 6
N_ZTESTS = len(ESTIMATORS) * 2  # the per-estimator tests share ALPHA (Sidak)


def _blocks(img):
    h, w, c = img.shape
    return img.reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean(axis=(1, 3))


def _runs(scene, integ, spp, kind, seed0):
    out = []
    for s in range(SEEDS):
        res = rm.render(scene, integrator=dict(integ, light_sampler=kind), spp=spp, seed=seed0 + s, threads=2)
        img = np.asarray(res.image, np.float64)
        assert np.all(np.isfinite(img)) and img.min() >= 0.0, (integ["type"], kind)
        out.append(_blocks(img))
    return np.array(out)


@pytest.fixture(scope="module")
def scene():
    return rm.load_dict(many_powers(res=RES))


def _agree(runs, base, level):
    """Two parts at level / 2 each: per-block Welch t-tests over the seeds
    (Sidak over the blocks, analysis/pixels.py) and a Welch t-test of the
    whole image's mean (the most power for a bias spread over the image).
    Returns (passed, message)."""
    r = two_sample_t_test(runs, base, alpha=level / 2)
    p_mean = float(_st.ttest_ind(runs.mean(axis=(1, 2, 3)), base.mean(axis=(1, 2, 3)), equal_var=False).pvalue)
    return r.passed and p_mean >= level / 2, f"{r.summary()}; image mean p {p_mean:.3g}"


@pytest.mark.parametrize("est", sorted(ESTIMATORS))
def test_estimator_unchanged_in_expectation(scene, est):
    integ, spp = ESTIMATORS[est]
    base = _runs(scene, integ, spp, "uniform", 100)
    level = 1.0 - (1.0 - ALPHA) ** (1.0 / N_ZTESTS)
    for k, kind in enumerate(("power", "tree")):
        runs = _runs(scene, integ, spp, kind, 200 + 100 * k)
        ok, msg = _agree(runs, base, level)
        assert ok, f"{est} {kind}: {msg}"
        # power check: the same renders a few % brighter are rejected
        ok, msg = _agree(runs * POWER.get(est, 1.04), base, level)
        assert not ok, f"{est} {kind}: no power ({msg})"


@pytest.mark.parametrize("kind", ["power", "tree"])
def test_thread_count_does_not_change_the_image(scene, kind):
    for est in ("path", "bdpt", "vcm"):
        integ, _ = ESTIMATORS[est]
        a = rm.render(scene, integrator=dict(integ, light_sampler=kind), spp=2, seed=9, threads=1)
        b = rm.render(scene, integrator=dict(integ, light_sampler=kind), spp=2, seed=9, threads=2)
        assert np.array_equal(a.image, b.image), (est, kind)


def test_bad_light_sampler_is_a_clear_error(scene):
    with pytest.raises(rm.SceneError, match="light_sampler"):
        rm.render(scene, integrator={"type": "path", "light_sampler": "bvh"}, spp=1)


# Stress: 10^4 dim point lights and one 10^9 times brighter; 64 coincident
# point lights. Every estimator (cheap budgets), every sampler: no NaN, Inf
# or negative pixel, the same bytes with 1 and 2 threads.
STRESS_BUDGET = {"path": 2, "direct": 2, "whitted": 2, "ptracer": 2, "bdpt": 1, "vcm": 1, "bpm": 1, "ppm": 1,
                 "photonmapper": 1, "sppm": 1}


@pytest.fixture(scope="module")
def stress_scenes():
    from light_sampler_scenes import grid_of_points
    return {"bright_among_10k": rm.load_dict(grid_of_points(100, 1e-6, bright=1e3, res=6)),
            "coincident": rm.load_dict(grid_of_points(8, 0.05, coincident=True, res=6))}


@pytest.mark.parametrize("name", ["bright_among_10k", "coincident"])
@pytest.mark.parametrize("kind", KINDS)
def test_stress_scenes_clean_and_deterministic(stress_scenes, name, kind):
    scene = stress_scenes[name]
    for est, spp in STRESS_BUDGET.items():
        integ = dict(ESTIMATORS[est][0], light_sampler=kind)
        if est == "photonmapper":
            integ.update(global_photons=500, caustic_photons=100)
        if est == "sppm":
            integ.update(photon_count=500)
        a = rm.render(scene, integrator=integ, spp=spp, seed=4, threads=1)
        b = rm.render(scene, integrator=integ, spp=spp, seed=4, threads=2)
        img = np.asarray(a.image)
        assert np.all(np.isfinite(img)) and img.min() >= 0.0, (name, est, kind)
        if est not in ("bpm", "ppm"):  # merging alone may find nothing in 36 light paths
            assert img.max() > 0.0, (name, est, kind)  # the lights reach the camera
        assert np.array_equal(a.image, b.image), (name, est, kind)
    if name == "bright_among_10k" and kind != "uniform":
        # the bright light takes almost every selection from the floor
        core = scene.core()
        r = core.light_selection(kind, np.float32([[0, -1, 0]]), np.float32([[0, 1, 0]]),
                                 np.zeros((1, 1), np.float32))
        assert r["pmf"][0, -1] > 0.99


@pytest.mark.parametrize("kind", ["power", "tree"])
@pytest.mark.parametrize("est", ["bdpt", "vcm"])
def test_bidirectional_mis_weights_with_each_sampler(kind, est):
    """bdpt's and vcm's linear-time MIS weights equal the brute-force ones
    (every strategy's full-path density from scratch) and sum to 1 over a
    path's strategies when p_NEE (the tree's selection from the vertex next
    to the emitter) and p_LE (light-start selection by power) differ, point
    lights and the sky included."""
    from radiometer import _core
    from radiometer.render import _core_integrator, _integrator_desc
    scene = rm.load_dict(many_powers(res=6))
    spec = _integrator_desc({"type": est, "max_depth": 4, "light_sampler": kind}, scene.desc.integrator)
    if est == "bdpt":
        fast, brute, sums, _ = _core.bdpt_mis_check(scene.core(), _core_integrator(spec), 7, 1500)
    else:
        fast, brute, _, sums, own_fast, own_brute = _core.vcm_mis_check(scene.core(), _core_integrator(spec), 7,
                                                                        1500, 0, 0)
        np.testing.assert_allclose(own_fast, own_brute, rtol=2e-4, atol=1e-6)
    assert len(fast) > 500
    np.testing.assert_allclose(sums, 1.0, rtol=0, atol=1e-4)  # a partition of unity: unbiased
    np.testing.assert_allclose(fast, brute, rtol=2e-4, atol=1e-6)
