"""caustic_in_mirror's reference (reference_scenes/caustic_in_mirror): ours,
bdpt on the unfolded twin (method of images, card.md), checked against an
independent estimate: our `path` on the folded scene itself (the mirror,
the caustic seen only in it), a different scene file and an estimator
whose caustic paths (camera, mirror, floor, then through the sphere onto
the light) share no strategy with the light-tracing ones (t = 1) that
carry the caustic in the reference.

The test is over seeds: 16 independent path renders of 256 spp; each
statistic (a region's mean over its pixels and channels) gets its
standard error from the spread of the 16 values (Student t, 15 degrees
of freedom; single renders' own variance estimates miss the rare caustic
paths, as on glass_sphere_caustic, card.md there) combined with the
reference's variance of the mean. Two-sided, alpha 0.01 over the whole
image, and alpha 0.01 / 4 (Bonferroni) for each of four regions. Power:
the reference scaled by 1.03 must be rejected by the whole-image
statistic (measured 2026-12-03: its relative standard error is ~0.3 %, so
3 % is ~10 sigma; the regions' are 0.3 % to 1.2 %, the caustic's the
largest, and their power is not claimed).
"""
import numpy as np
import pytest
from scipy import stats

import radiometer as rm
from radiometer.reference_scenes import references, registry

SPEC = registry.get("caustic_in_mirror")
PARAMS = dict(SPEC.fixed_params)
SEEDS = range(100, 116)
SPP = 256
ALPHA = 0.01
# card.md's regions (y0, y1, x0, x1) at 64 x 64.
REGIONS = {"caustic": (30, 45, 25, 50), "near floor": (45, 64, 0, 64), "sphere and far floor": (0, 30, 0, 64),
           "left of the sphere": (16, 32, 0, 16)}


@pytest.fixture(scope="module")
def renders():
    scene = rm.load_file(SPEC.xml, **PARAMS)
    out = []
    for s in SEEDS:
        r = rm.render(scene, integrator={"type": "path", "max_depth": PARAMS["max_depth"]}, spp=SPP, seed=s,
                      threads=2)
        assert r.stats["nan_samples"] == 0 and r.stats["inf_samples"] == 0
        out.append(np.asarray(r.image, np.float64))
    return np.stack(out)


def _z(renders, ref_img, ref_var, box=None):
    y0, y1, x0, x1 = box or (0, ref_img.shape[0], 0, ref_img.shape[1])
    vals = renders[:, y0:y1, x0:x1].mean(axis=(1, 2, 3))
    r = ref_img[y0:y1, x0:x1]
    n = r.size
    ref_mean = r.mean()
    # the reference's pixels are independent (box filter, independent runs)
    ref_se2 = ref_var[y0:y1, x0:x1].sum() / n ** 2
    se = np.sqrt(vals.var(ddof=1) / len(vals) + ref_se2)
    return (vals.mean() - ref_mean) / se, vals.mean() / ref_mean


def _p(z):
    return 2 * stats.t.sf(abs(z), df=len(SEEDS) - 1)


def test_reference_is_well_formed():
    ref = rm.read_exr(SPEC.reference_exr)
    img, var = np.asarray(ref.image), np.asarray(ref.variance)
    assert img.shape == (64, 64, 3) and var.shape == img.shape
    assert np.all(np.isfinite(img)) and np.all(img >= 0) and np.all(var >= 0)
    assert int(ref.metadata["runs"]) == SPEC.runs and int(ref.metadata["spp_per_run"]) == SPEC.spp
    assert ref.metadata["estimator"] == SPEC.ours_estimator and ref.metadata["scene"] == SPEC.ours_scene
    assert SPEC.reference_exr.stat().st_size < 1 << 20


def test_reference_agrees_with_path_in_the_mirror(renders):
    ref = references.reference(SPEC.name, PARAMS)
    z, ratio = _z(renders, ref.image, ref.variance)
    assert _p(z) > ALPHA, f"whole image: path / reference = {ratio:.4f}, z {z:.2f}"
    for name, box in REGIONS.items():
        z, ratio = _z(renders, ref.image, ref.variance, box)
        assert _p(z) > ALPHA / len(REGIONS), f"{name}: path / reference = {ratio:.4f}, z {z:.2f}"
    # power: a 3 % error in the reference is seen
    z, ratio = _z(renders, ref.image * 1.03, ref.variance * 1.03 ** 2)
    assert _p(z) < ALPHA, f"the reference x 1.03 passed: path / it = {ratio:.4f}, z {z:.2f}"


def test_unfolded_paths_past_depth_12_carry_nothing():
    """The unfolded scene's paths are shorter than the folded ones by their
    mirror bounces, so the two agree only if what max_depth 16 cuts off is
    nothing: with one seed (the same random stream up to the cut) the
    unfolded scene at max_depth 12 and 32 renders the same image."""
    scene = rm.load_file(SPEC.xml.parent / SPEC.ours_scene, **PARAMS)
    a, b = (np.asarray(rm.render(scene, integrator={"type": "path", "max_depth": d}, spp=32, seed=7, threads=2).image,
                       np.float64) for d in (12, 32))
    assert abs(a.sum() / b.sum() - 1) < 1e-5
