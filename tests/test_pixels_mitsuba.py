"""Every estimator against the Mitsuba-referenced surface scenes, pixel by
pixel, over independent seeds (radiometer.analysis.pixels: a Welch t per
pixel and channel, the variance of our side from the seeds, the reference's
from its 32 runs, Sidak over the pixel-channels). The block tests of
test_canonical_mitsuba.py average 4 x 4 pixels and so dilute a bias
confined to a few pixels by 16; these do not.

Significance: each comparison at ALPHA_EACH = 2.5e-4, and at most
N_COMPARISONS = 19 comparisons in the file that can fail by chance (18
estimator x scene comparisons, and the unfloored test of the bdpt finding
rejecting a pixel away from the light), so the file's false-alarm rate
under fresh noise is at most 19 x 2.5e-4 = 0.48 % (Bonferroni; the power
checks are not counted: they must reject). That is the nominal rate of
t-tests on seed means; where those are far from normal (rare large
samples) the floors below carry it. Measured: with the seeds re-rolled
(RADIOMETER_SEED_OFFSET = 0, 1, 2, 3: conftest.py re-rolls
every render's seed) none of the 4 x 16 comparisons failed. 95 to 135 s
on 2 shared cores (about 105 s of CPU). keyhole's two (bdpt, ptracer;
2026-12-03) passed under offsets 0, 1, 2 and add 19-28 s.

Floors on the seeds' variance (pixels.py explains both): the reference's
per-sample variance scaled to our budget (rare paths), for every estimator,
and for estimators that importance-sample the pixel filter (all but
ptracer) the position-sampling variance of the scene's filter (the Cornell
box's gaussian; 0 for the box filter of the other scenes).

Power: in each comparison the reference scaled by 1.1 (or the larger factor
the case table states, where the budget cannot resolve 10 %) in 4 pixels
must be rejected: the 2 x 2 square at a 4 x 4 block corner (so each block
holds one of them) where the comparison's relative standard error is
smallest (quiet_square, chosen from the variances, not the difference);
test_per_pixel_test_sees_what_blocks_miss shows the block test missing
that bias on the same renders.

Exclusions: ptracer's, the registry's (reference_scenes/registry.py: pixels that light
tracing cannot reach, or reaches only through rare huge samples).
"""
from pathlib import Path

import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.blocks import block_mean, block_var_independent, reference_variance_floor, region_mask
from radiometer.analysis.pixels import position_sampling_floor, seed_t_test, sidak_level, two_sample_t_test
from radiometer.reference_scenes import registry as _registry

ROOT = Path(__file__).resolve().parents[1] / "reference_scenes"
RES = 64
ALPHA_EACH = 2.5e-4
N_COMPARISONS = 19
SEEDS = 32
POWER = 1.1
MAX_DEPTH = {"cornell_box": 8, "glass_sphere_caustic": 12, "veach_mis": 8, "ajar_door": 10, "keyhole": 10}
EXCLUDE = {"ptracer": {n: s.exclusions.get("ptracer", []) for n, s in _registry.mitsuba_scenes().items()}}

# Per (estimator, scene): samples per pixel per seed, and the bias factor
# the power check applies to the 4 pixels (POWER unless the budget cannot
# resolve it: measured t of a 10 % bias there in the comment).
UNBIASED = {
    ("path", "cornell_box"): (32, POWER),
    ("bdpt", "cornell_box"): (16, POWER),
    ("ptracer", "cornell_box"): (16, POWER),
    ("path", "glass_sphere_caustic"): (16, POWER),
    # 16 spp: under seed offset 3 a 10 % bias at (15, 3) gave t -6.5 against
    # a level of about -7.3, missed at both reruns (also at stop 24's run).
    ("bdpt", "glass_sphere_caustic"): (32, POWER),
    # 20 %: t -5.8 to -7.1 (32 spp: -7.2); 30 %: t -7.0 and -7.4 under seed
    # offsets 1 and 5, missed against the level (t about -7.3) in both.
    ("ptracer", "glass_sphere_caustic"): (16, 1.5),
    ("path", "veach_mis"): (16, POWER),
    ("bdpt", "veach_mis"): (8, POWER),
    ("ptracer", "veach_mis"): (16, 1.2),  # 10 %: t > -6.6
    ("bdpt", "ajar_door"): (8, 1.2),  # 10 %: t -6.1
    ("ptracer", "ajar_door"): (16, POWER),
    ("bdpt", "keyhole"): (8, 1.2),  # 10 %: t -5.8
    ("ptracer", "keyhole"): (16, 1.2),  # 10 %: t -6.8
}
# `path` on ajar_door is left out: the near room is lit only through the
# door's gap, which camera paths find less than once in 100 bounces (its
# reference is Mitsuba's light tracer, card.md), and the reference's
# per-sample variance, a light tracer's, is no floor for path's there
# (measured: 32 x 16 spp, 13 pixel-channels rejected, down to 0.11 of the
# reference: the heavy tail, not a bias; bdpt and ptracer cover the scene).

# The biased estimators, at settings CI can afford (per seed: spp, the
# estimator's parameters; power factor as above). Measured at these
# settings (32 seeds each, against the reference): no pixel's difference
# beyond 8 of its standard errors, image means 0.995 (photonmapper) and
# 1.001 (sppm) of the reference on the Cornell box, 1.001 and 0.997 on
# glass_sphere_caustic: their per-pixel bias is below what their per-pixel
# noise (median relative standard error 4-5 %) resolves, so they need no
# bias allowance here, and the test catches only large per-pixel errors
# (the power factor). Left out: veach_mis, whose glossy plates sppm and
# photonmapper gather at like diffuse surfaces (sppm.cpp's limits; measured
# for sppm: image mean 0.888, 405 pixel-channels off by more than 8
# standard errors, the sharpest plate's highlight at 0.01 of the reference),
# and ajar_door (1-2 s per sample per pixel at their defaults, beyond CI's
# budget at 32 seeds).
PM = {"global_photons": 20000, "caustic_photons": 20000, "gather_rays": 4}
BIASED = {
    ("photonmapper", "cornell_box"): (2, PM, 1.5),
    # 16 passes: at 8 the test failed under 4 of 10 fresh seed offsets (1, 6,
    # 7, 9: one pixel each, t -8.0 to -10.7, mostly the blue channel of the
    # dark corner at rows 50-59, columns 45-47, where few photons land and
    # the seeds' mean was 0.32 to 0.40 of the reference); at 16 under 1 of
    # those 4 (offset 9, t -9.9 at (50, 47), ratio 0.40), the 50 % power
    # check rejected in all 4.
    ("sppm", "cornell_box"): (16, {"photon_count": 10000}, 1.5),
    ("photonmapper", "glass_sphere_caustic"): (2, PM, 1.5),
    ("sppm", "glass_sphere_caustic"): (8, {"photon_count": 10000}, 1.5),
}


def _scene(name):
    return rm.load_file(ROOT / name / "scene.xml", res=RES)


def _reference(name):
    ref = rm.read_exr(ROOT / name / "reference.exr")
    return ref.image.astype(np.float64), ref.variance.astype(np.float64), int(ref.metadata["runs"]), \
        int(ref.metadata["total_spp"])


_runs = {}


def _render_runs(name, integrator, spp, seeds=SEEDS, base=0):
    """`seeds` renders with independent seeds, once per session."""
    key = (name, repr(sorted(integrator.items())), spp, seeds, base)
    if key not in _runs:
        scene = _scene(name)
        out = []
        for k in range(seeds):
            r = rm.render(scene, integrator=integrator, spp=spp, seed=1000 * (base + 1) + k)
            assert r.stats["nan_samples"] == 0 and r.stats["inf_samples"] == 0, r.stats
            out.append(r.image)
        _runs[key] = np.stack(out).astype(np.float64)
    return _runs[key]


def quiet_square(rel_se, exclude=()):
    """(y0, x0): the 2 x 2 square of pixels [y0, y0 + 2) x [x0, x0 + 2)
    centred on an interior 4 x 4 block corner (one pixel in each of four
    blocks) whose largest relative standard error `rel_se` (over its pixels
    and channels) is smallest: where the comparison resolves best. Chosen
    from the variances alone, not from the difference tested."""
    rel = np.array(rel_se, np.float64)
    rel[~np.isfinite(rel)] = np.inf
    if exclude:
        rel[region_mask(rel.shape, exclude)] = np.inf
    best, where = np.inf, None
    for y in range(4, rel.shape[0] - 3, 4):
        for x in range(4, rel.shape[1] - 3, 4):
            s = rel[y - 1:y + 1, x - 1:x + 1].max()
            if s < best:
                best, where = s, (y - 1, x - 1)
    return where


def _floor(name, estimator, spp):
    ref, var, _, total = _reference(name)
    floor = reference_variance_floor(var, total, spp)
    if estimator != "ptracer":  # filter importance sampling: the position-sampling variance
        sd = _scene(name).desc.sensor
        floor = np.maximum(floor, position_sampling_floor(ref, sd.rfilter, sd.filter_radius, sd.filter_stddev, spp))
    return floor


def _compare(estimator, name, spp, power=None, params=None):
    """The per-pixel test of `estimator`'s renders against the reference;
    with `power`, against the reference scaled by it in quiet_square's 4
    pixels. Returns (result, square or None, runs, the image tested)."""
    ref, var, runs_ref, _ = _reference(name)
    runs = _render_runs(name, {"type": estimator, "max_depth": MAX_DEPTH[name], **(params or {})}, spp)
    exclude = EXCLUDE.get(estimator, {}).get(name, [])
    mask = ~region_mask(ref.shape, exclude)[..., None] if exclude else None
    floor = _floor(name, estimator, spp)
    image, square = ref, None
    if power is not None:
        var_mean = np.maximum(runs.var(axis=0, ddof=1), floor) / len(runs) + var
        with np.errstate(divide="ignore", invalid="ignore"):
            square = quiet_square(np.sqrt(var_mean) / ref, exclude)
        y, x = square
        image = ref.copy()
        image[y:y + 2, x:x + 2] *= power
    r = seed_t_test(runs, image, var, runs_ref - 1, alpha=ALPHA_EACH, var_floor=floor, mask=mask)
    return r, square, runs, image


def _check(estimator, name, spp, power, params=None):
    r, _, _, _ = _compare(estimator, name, spp, params=params)
    assert r.passed, f"{name}: {estimator} ({SEEDS} seeds x {spp} spp) per pixel:\n{r.summary()}"
    p, (y, x), _, _ = _compare(estimator, name, spp, power=power, params=params)
    assert not p.passed, (f"{name}: {estimator}: a {(power - 1) * 100:.0f} % bias in the 4 pixels at ({y}, {x}) "
                          f"went undetected:\n{p.summary()}")


@pytest.mark.parametrize("estimator,name", sorted(UNBIASED), ids=lambda v: v)
def test_unbiased_estimator_matches_mitsuba_per_pixel(estimator, name):
    spp, power = UNBIASED[(estimator, name)]
    _check(estimator, name, spp, power)


@pytest.mark.parametrize("estimator,name", sorted(BIASED), ids=lambda v: v)
def test_biased_estimator_matches_mitsuba_per_pixel(estimator, name):
    spp, params, power = BIASED[(estimator, name)]
    _check(estimator, name, spp, power, params)


def test_direct_matches_path_per_pixel():
    """`direct` has no Mitsuba reference (every reference is multi-bounce):
    against our `path` at max_depth 2 on the Cornell box, both sides over
    32 seeds (two_sample_t_test), each side's variance floored by the
    position-sampling variance of the gaussian filter (from path's mean);
    power as above on path's side."""
    name, spp = "cornell_box", 16
    a = _render_runs(name, {"type": "direct"}, spp)
    b = _render_runs(name, {"type": "path", "max_depth": 2}, spp, base=1)
    sd = _scene(name).desc.sensor
    floor = position_sampling_floor(b.mean(axis=0), sd.rfilter, sd.filter_radius, sd.filter_stddev, spp)
    r = two_sample_t_test(a, b, alpha=ALPHA_EACH, var_floor=floor, var_floor_b=floor)
    assert r.passed, f"direct against path (max_depth 2) per pixel:\n{r.summary()}"
    var_b = np.maximum(b.var(axis=0, ddof=1), floor) / len(b)
    var_a = np.maximum(a.var(axis=0, ddof=1), floor) / len(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        y, x = quiet_square(np.sqrt(var_a + var_b) / b.mean(axis=0))
    b2 = b.copy()
    b2[:, y:y + 2, x:x + 2] *= POWER
    r = two_sample_t_test(a, b2, alpha=ALPHA_EACH, var_floor=floor, var_floor_b=floor)
    assert not r.passed, f"a 10 % bias in the 4 pixels at ({y}, {x}) went undetected:\n{r.summary()}"


def test_per_pixel_test_sees_what_blocks_miss():
    """The power claim: on the Cornell box, `path` at 32 seeds x 32 spp
    (the renders of the test above), the reference scaled by 1.1 in 4
    pixels, one in each of four 4 x 4 blocks, is rejected by the per-pixel
    test (with certainty: t beyond -10), while the block test
    (test_canonical_mitsuba's: 4 x 4 block means of the same renders, block
    variance from the pixels' and the reference variance floor, each
    channel at 0.01 / 3 with Sidak over the blocks) would see it with
    probability under 25 %: the bias moves those four blocks' z by 1.5 to
    2.8 (measured), against a threshold above 4.3. (The shift is the bias over the
    block's standard error; the detection probability follows from it
    under normal block means, independent of the renders' noise.)"""
    name, spp = "cornell_box", UNBIASED[("path", "cornell_box")][0]
    r, (y, x), runs, biased = _compare("path", name, spp, power=POWER)
    assert not r.passed, f"the per-pixel test missed a 10 % bias at ({y}, {x}):\n{r.summary()}"
    assert r.worst[:2] in [(y + i, x + j) for i in (0, 1) for j in (0, 1)], r.summary()
    ref, var, _, total = _reference(name)
    var_mean = np.maximum(runs.var(axis=0, ddof=1) / len(runs),
                          reference_variance_floor(var, total, spp * len(runs)))
    shift = (block_mean(biased) - block_mean(ref)) / np.sqrt(block_var_independent(var_mean) +
                                                              block_var_independent(var))
    touched = shift[(y // 4):(y // 4) + 2, (x // 4):(x // 4) + 2]
    assert np.count_nonzero(shift) == touched.size, "the 4 pixels must fall in four blocks"
    assert r.worst_t < -10, r.summary()
    from scipy.stats import norm

    z_crit = norm.isf(sidak_level(0.01 / 3, shift[..., 0].size) / 2)
    miss = np.prod(norm.cdf(z_crit - np.abs(touched)) - norm.cdf(-z_crit - np.abs(touched)))
    assert 1 - miss < 0.25, f"the block test would see the bias: z shifts {touched.round(2).tolist()}"


def test_bdpt_dark_light_border_is_filter_position_sampling():
    """The finding behind a reported bdpt bias on the Cornell box: next to
    the light, ceiling pixels seemed 10 to 46 % dark over 8 seeds (t down
    to -38). The gaussian filter (radius 2 pixels) lands about one camera
    sample in 1000 of those pixels on the light itself (each such sample
    worth L_e); few seeds see one, and bdpt's ceiling is otherwise smooth
    (light tracing), so seeds that saw none agree closely and t is large
    with no bias (pixels.py). On the renders of the test above: without
    the floors the test fails, every rejected pixel within the filter's
    radius of the light; with the position-sampling floor it passes (the
    test above), and so did 8 x 512 spp without any floor (measured)."""
    from scipy import ndimage

    name, spp = "cornell_box", UNBIASED[("bdpt", "cornell_box")][0]
    ref, var, runs_ref, _ = _reference(name)
    runs = _render_runs(name, {"type": "bdpt", "max_depth": MAX_DEPTH[name]}, spp)
    plain = seed_t_test(runs, ref, var, runs_ref - 1, alpha=ALPHA_EACH)
    assert not plain.passed, plain.summary()
    near_light = ndimage.binary_dilation(ref[..., 1] > 1.0, iterations=2)
    rejected = np.argwhere(plain.p < plain.level)
    assert all(near_light[y, x] for y, x, _ in rejected), rejected.tolist()
    assert plain.worst_ratio < 0.9, plain.summary()


def test_false_alarm_budget_counts_every_comparison():
    """The module docstring's bound: every comparison that can fail by
    chance is counted (the tables, direct, the bdpt finding)."""
    assert len(UNBIASED) + len(BIASED) + 2 == N_COMPARISONS
    assert N_COMPARISONS * ALPHA_EACH < 0.005
