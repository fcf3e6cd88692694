"""`irrcache`: irradiance caching, indirect diffuse light interpolated
between records, every other class path traced.

- Exact classes: emission, direct, caustic and specular are `path`'s own
  (the same random streams): byte for byte equal to `path` rendering those
  classes alone.
- Furnace (constant indirect light, zero-variance path tracing at finite
  depth): the image equals the exact radiance to 1e-4, gradients on and off;
  the power check is the next depth's answer, 0.4 % away.
- Without the cache (overture = false) every sample gathers its own
  irradiance: unbiased, so its indirect image passes the blocked z-test
  against `path`'s at level ALPHA, and a 3 % scaled reference is rejected.
- Interpolation bias on the Cornell box (indirect class, against a long
  `path` render): a 4x coarser cache (kappa / 4) shows a larger bias than
  the default, and the default one larger than a 4x finer one; gradients
  on lower it. The bias is the error of the mean over SEEDS renders, its
  noise (the reference's and the renders' spread) measured and required
  to be small against the differences.
- The same on corner_room (reference_scenes/caching.py, many concave
  corners): kappa / 4 reads more than twice the default's bias, gradients
  off more than 1.4 times; the unbiased `path` reads under half of it.
- Determinism: threads = 1 and 2 give the same bytes, cache included.
- The records in res.stats, and bad parameters as SceneError.
"""
import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.blocks import blocked_z_test
from radiometer.reference_scenes import registry
from radiometer.reference_scenes.caching import corner_room, thin_wall
from radiometer.reference_scenes.furnace.analytic import radiance as furnace_radiance
from test_canonical_analytic import assert_clean

ALPHA = 0.01


def cornell(res=24):
    spec = registry.get("cornell_box")
    return rm.load_file(spec.xml, res=res, rfilter="box", max_depth=8)


def furnace(res=12):
    return rm.load_file(registry.get("furnace").xml, res=res)


EXACT = ("emission", "direct", "caustic", "specular")


def test_exact_classes_are_paths_own():
    scene = cornell(16)
    ic = rm.render(scene, integrator={"type": "irrcache", "max_depth": 8}, spp=4, seed=5, threads=2)
    p = rm.render(scene, integrator={"type": "path", "max_depth": 8}, spp=4, seed=5, threads=2, effects=list(EXACT))
    assert_clean(ic)
    for cls in EXACT:
        np.testing.assert_array_equal(ic.effects[cls], p.effects[cls], err_msg=cls)
    # the cache did contribute (the test can fail: indirect light filed elsewhere would break the equalities)
    assert ic.effects["indirect"].mean() > 0.1 * ic.image.mean()


@pytest.mark.parametrize("gradients", [True, False])
def test_furnace_is_exact(gradients):
    md = 5
    r = rm.render(furnace(), integrator={"type": "irrcache", "max_depth": md, "gradients": gradients}, spp=2,
                  seed=3)
    assert_clean(r)
    exact = furnace_radiance(0.5, 0.5, md)
    assert r.stats["irrcache_computed"] >= 1 and r.stats["irrcache_misses"] == 0
    np.testing.assert_allclose(r.image, np.broadcast_to(exact, r.image.shape), rtol=1e-4)
    # power: the answer of one more bounce (0.4 % higher) is rejected at the same tolerance
    assert not np.allclose(r.image, furnace_radiance(0.5, 0.5, md + 1), rtol=1e-4)


def test_without_cache_is_unbiased():
    scene = cornell(12)
    ic = rm.render(scene, integrator={"type": "irrcache", "max_depth": 8, "overture": False,
                                      "gather_resolution": 3}, spp=16, seed=11, effects=["indirect"])
    p = rm.render(scene, integrator={"type": "path", "max_depth": 8}, spp=1024, seed=12, effects=["indirect"])
    assert_clean(ic)
    assert ic.stats["irrcache_computed"] == 0 and ic.stats["irrcache_misses"] > 0
    ok, msg = blocked_z_test(ic.image, ic.variance, p.image, p.variance, alpha=ALPHA, k=2, label="no cache vs path ")
    assert ok, msg
    bad, msg = blocked_z_test(ic.image, ic.variance, p.image * 1.03, p.variance * 1.03 ** 2, alpha=ALPHA, k=2)
    assert not bad, "power: a 3 % bias was not rejected"


SEEDS = (1, 2, 3)
BLOCK = 4


def _blocks(a, k=BLOCK):
    h, w, c = a.shape
    return a.reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def _rms_bias(imgs, ref):
    """RMS over BLOCK x BLOCK block means of (mean of `imgs` - reference),
    with the noise of both (the seeds' spread, the reference's variance)
    subtracted, relative to the reference's mean: an estimate of the RMS
    bias alone."""
    b = np.array([_blocks(i) for i in imgs])
    m, vm = b.mean(0), b.var(0, ddof=1) / len(b)
    rb, rv = _blocks(ref.image), _blocks(ref.variance) / BLOCK ** 2
    b2 = np.mean((m - rb) ** 2) - np.mean(vm + rv)
    return float(np.sqrt(max(b2, 0.0)) / ref.image.mean())


def _renders(scene, **params):
    imgs, recs = [], []
    for s in SEEDS:
        r = rm.render(scene, integrator={"type": "irrcache", "max_depth": 8, **params}, spp=1, seed=s,
                      effects=["indirect"])
        assert_clean(r)
        imgs.append(r.image)
        recs.append(len(r.arrays["irrcache_records"]))
    return imgs, int(np.mean(recs))


@pytest.fixture(scope="module")
def cornell_ref():
    scene = cornell(24)
    return scene, rm.render(scene, integrator={"type": "path", "max_depth": 8}, spp=2048, seed=99,
                            effects=["indirect"])


# Measured (seed offsets 0..3 of this file's renders): RMS bias of the 4 x 4
# block means 2.8 .. 4.4 % at the defaults, 20.5 .. 23 % at kappa 0.25
# (records 4x farther apart): ratio >= 4.7; at kappa 0.5, 5.8 .. 8.4 % with
# gradients, 11.5 .. 14.1 % without: ratio >= 1.39. The bounds (3 and 1.25)
# sit below those.


def test_bias_grows_with_record_spacing(cornell_ref):
    scene, ref = cornell_ref
    default, n_default = _renders(scene)
    coarse, n_coarse = _renders(scene, kappa=0.25)
    b_default, b_coarse = _rms_bias(default, ref), _rms_bias(coarse, ref)
    print(f"RMS bias: defaults {b_default:.4f} ({n_default} records), kappa 0.25 {b_coarse:.4f} ({n_coarse})")
    assert n_coarse < n_default
    assert b_coarse > 3 * b_default, (b_coarse, b_default)
    # power: the metric sees a 5 % error through the noise
    assert _rms_bias([i * 1.05 for i in default], ref) > 0.04


def test_gradients_lower_the_bias(cornell_ref):
    scene, ref = cornell_ref
    on = _rms_bias(_renders(scene, kappa=0.5)[0], ref)
    off = _rms_bias(_renders(scene, kappa=0.5, gradients=False)[0], ref)
    print(f"RMS bias at kappa 0.5: gradients on {on:.4f}, off {off:.4f}")
    assert off > 1.25 * on, (on, off)


@pytest.fixture(scope="module")
def corner_ref():
    scene = corner_room(24)
    return scene, rm.render(scene, integrator={"type": "path", "max_depth": 8}, spp=2048, seed=98,
                            effects=["indirect"])


# corner_room (many concave corners, docs/irrcache.md). Measured (seed
# offsets 0..3): RMS bias 1.7 .. 2.3 % at the defaults, 6.5 .. 7.0 % at kappa
# 0.25 (ratio >= 3.0), 3.3 .. 4.3 % without gradients (ratio >= 1.68). The
# bounds (2 and 1.4) sit below those. The unbiased `path` (64 spp per seed)
# reads 0 .. 0.43 % on the same statistic (at most 0.19 of the defaults';
# the bound is 0.5), and 5.1 .. 5.4 % when scaled by 1.05 (the bound is 4 %).


def test_corner_room_bias(corner_ref):
    scene, ref = corner_ref
    default, _ = _renders(scene)
    coarse, _ = _renders(scene, kappa=0.25)
    off, _ = _renders(scene, gradients=False)
    b_default, b_coarse, b_off = _rms_bias(default, ref), _rms_bias(coarse, ref), _rms_bias(off, ref)
    print(f"corner_room RMS bias: defaults {b_default:.4f}, kappa 0.25 {b_coarse:.4f}, no gradients {b_off:.4f}")
    assert b_coarse > 2 * b_default, (b_coarse, b_default)
    assert b_off > 1.4 * b_default, (b_off, b_default)
    # the statistic can fail: path (unbiased) reads below the default's bias, so a swapped pair fails
    unbiased = [rm.render(scene, integrator={"type": "path", "max_depth": 8}, spp=64, seed=s,
                          effects=["indirect"]).image for s in SEEDS]
    b_path = _rms_bias(unbiased, ref)
    b_scaled = _rms_bias([i * 1.05 for i in unbiased], ref)
    print(f"corner_room RMS bias of path: {b_path:.4f}, of path scaled by 1.05: {b_scaled:.4f}")
    assert b_path < 0.5 * b_default, (b_path, b_default)
    # power: the figure sees a 5 % error in path's images through their noise
    assert b_scaled > 0.04, b_scaled


def test_threads_do_not_change_the_bytes():
    scene = cornell(16)
    integ = {"type": "irrcache", "max_depth": 8, "gather_resolution": 4}
    a = rm.render(scene, integrator=integ, spp=2, seed=4, threads=1)
    b = rm.render(scene, integrator=integ, spp=2, seed=4, threads=2)
    assert a.image.tobytes() == b.image.tobytes()
    assert a.arrays["irrcache_records"].tobytes() == b.arrays["irrcache_records"].tobytes()
    c = rm.render(scene, integrator=integ, spp=2, seed=5, threads=2)
    assert a.image.tobytes() != c.image.tobytes()  # the seed does change them


def test_records_in_stats():
    r = rm.render(cornell(16), integrator={"type": "irrcache", "max_depth": 8, "min_spacing": 0.01,
                                           "max_spacing": 0.2}, spp=1, seed=2)
    rec = r.arrays["irrcache_records"]
    cols = r.stats["irrcache_records_columns"]
    assert rec.shape == (int(r.stats["irrcache_computed"]), len(cols)) and rec.shape[0] > 10
    radius = rec[:, cols.index("radius")]
    n = rec[:, cols.index("nx"):cols.index("nz") + 1]
    # the box's bounding sphere: radius about sqrt(3) (the box spans about [-1, 1]^3; measured 1.735)
    big = np.sqrt(3) * 1.01
    assert radius.min() >= 0.01 * np.sqrt(3) * 0.99 and radius.max() <= 0.2 * big
    assert np.any(radius < 0.02 * big) and np.any(radius > 0.1 * np.sqrt(3))  # both clamps matter here
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-4)
    assert np.all(np.abs(rec[:, :3]) <= 1.01)  # on the box's walls and blocks
    assert np.all(rec[:, cols.index("E_r"):] >= 0)


def test_bad_parameters_are_scene_errors():
    with pytest.raises(rm.SceneError, match="min_spacing"):
        rm.render(furnace(4), integrator={"type": "irrcache", "min_spacing": 0.5, "max_spacing": 0.1}, spp=1)
    with pytest.raises(rm.SceneError, match="weight"):
        rm.render(furnace(4), integrator={"type": "irrcache", "weight": "gauss"}, spp=1)


def _dark_side(img, res):
    """The dark half's pixels (the image's right half): the columns next
    to the wall (within 3 pixels) and the rest."""
    half = res // 2
    return img[:, half:half + 3], img[:, half + 4:]


def test_thin_wall_leaks_only_by_the_minimum_spacing():
    res = 32
    scene = rm.load_dict(thin_wall(res))
    p = rm.render(scene, integrator={"type": "path"}, spp=16, seed=1)
    near, far = _dark_side(p.image, res)
    assert not near.any() and not far.any()  # the geometry: the dark half is exactly black for path
    lit = float(p.image[:, : res // 2 - 1].mean())
    assert lit > 0.05
    leaks = {}
    for ms in (0.005, 0.1):
        r = rm.render(scene, integrator={"type": "irrcache", "min_spacing": ms}, spp=1, seed=1)
        assert_clean(r)
        near, far = _dark_side(r.image, res)
        leaks[ms] = float(near.mean()) / lit
        assert not far.any(), ms  # far from the wall no record reaches across
    print(f"thin wall: leak next to the wall / lit mean {leaks}")
    assert leaks[0.1] > 0.01  # a radius floor of 0.1 x the scene's size reaches across the 0.01 wall
    assert leaks[0.005] < 0.2 * leaks[0.1]
