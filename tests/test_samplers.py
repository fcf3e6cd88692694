"""Samplers (renderer/core/sampler.h, radiometer.samplers): independent,
stratified, multijitter, sobol, zsobol.

What is checked:
- the Sobol points against Joe and Kuo's table as scipy.stats.qmc holds it,
  and the Owen scramble's nesting (exact);
- stratification of every pixel's samples in every 1D draw and 2D draw
  (exact: one sample per stratum), which the independent sampler fails, and
  its size against independent (chi-square of the 8 x 8 cell counts, lower
  tail at ALPHA; discrepancy);
- uniformity and independence of every 1D and 2D projection, pairs of
  dimensions from different draws included, pooled over pixels (chi-square,
  upper tail, Sidak over the projections at ALPHA), with a power check: a
  small injected warp of one dimension is rejected;
- unbiasedness of `path` with each sampler on the analytic scenes (furnace
  with Russian roulette, the disk and rectangle lights) at ALPHA with the
  1 % power check of tests/test_canonical_analytic.py. The render's
  variance is the independent-sample formula, which overstates a
  stratified estimate's variance, so these tests are conservative and their
  power is that of the independent sampler;
- determinism whatever the thread count (camera and light drivers), the
  pattern past N samples, the scene file's and render()'s choice, the
  warnings where an estimator does not use the sampler, and SceneErrors
  naming bad sampler names and parameters.
ALPHA = 1e-3 per statistical test (stated at each).
"""
from __future__ import annotations

import numpy as np
import pytest
from conftest import furnace_dict, reroll
from scipy import stats

import radiometer as rm
from radiometer import _core
from radiometer.analysis.blocks import blocked_z_test

ALPHA = 1e-3
STRUCTURED = ("stratified", "multijitter", "sobol", "zsobol")
SAMPLERS = ("independent",) + STRUCTURED
# A camera sample and a bounce of path, as 1D (1) and 2D (2) draws.
DRAWS = [2, 1, 2, 2, 1, 2, 1, 1, 2, 1]
N = 64  # samples per pixel: square and a power of two, so every sampler's pattern is exactly N
W = H = 16


def draws(sampler, pixel, *, n=N, spp=N, samples=None, seed=7, jitter=True, pattern=DRAWS):
    return _core.sampler_draws(sampler, n, jitter, reroll(seed), W, H, spp, pixel, samples or spp, pattern)


def draw_columns(pattern=DRAWS):
    """(1D columns, 2D column pairs) of a draw pattern."""
    one, two, c = [], [], 0
    for k in pattern:
        (one.append(c) if k == 1 else two.append((c, c + 1)))
        c += k
    return one, two


def strata_counts(x, bins):
    return np.bincount(np.minimum((x * bins).astype(int), bins - 1), minlength=bins)


def cell_counts(x, y, bins):
    ix = np.minimum((x * bins).astype(int), bins - 1)
    iy = np.minimum((y * bins).astype(int), bins - 1)
    return np.bincount(iy * bins + ix, minlength=bins * bins)


# ---------------------------------------------------------------------------
# Building blocks


def test_sobol_points_match_joe_kuo_via_scipy():
    """Our unscrambled Sobol dimensions 1 and 2 are scipy's (Joe and Kuo's
    new-joe-kuo-6.21201, scipy in Gray-code order): the first 2^k points as
    sets, k = 1..12."""
    from scipy.stats import qmc

    ref = qmc.Sobol(d=2, scramble=False).random_base2(12)
    ours = np.array([[_core.sobol_u32(i, 0), _core.sobol_u32(i, 1)] for i in range(1 << 12)], dtype=np.float64)
    ours /= 2.0 ** 32
    for k in range(1, 13):
        a = sorted(map(tuple, ref[: 1 << k]))
        b = sorted(map(tuple, ours[: 1 << k]))
        assert np.array_equal(np.array(a), np.array(b)), f"first 2^{k} Sobol points differ from scipy's"


def test_owen_scramble_is_nested_and_bijective():
    """Two values that share their top k bits keep sharing exactly their top
    k bits after the scramble (a nested scramble of the digits), and the
    scramble of the 2^16 values v << 16 is a permutation of them."""
    rng = np.random.default_rng(3)
    for seed in rng.integers(0, 1 << 32, size=8, dtype=np.uint64):
        seed = int(seed)
        for _ in range(200):
            v = int(rng.integers(0, 1 << 32))
            k = int(rng.integers(0, 31))
            w = v ^ (1 << (31 - k))  # differs first at bit k from the top
            a, b = _core.owen_scramble(v, seed), _core.owen_scramble(w, seed)
            assert (a ^ b) >> (31 - k) == 1, f"seed {seed}: bit {k} from the top is not nested"
        top = {_core.owen_scramble(i << 16, seed) >> 16 for i in range(1 << 16)}
        assert len(top) == 1 << 16, f"seed {seed}: not a bijection of the top 16 bits"


@pytest.mark.parametrize("n", [1, 2, 3, 7, 64, 100, 1000])
def test_permute_index_is_a_permutation(n):
    for key in (0, 1, 0x9E3779B97F4A7C15, 12345):
        img = sorted(_core.permute_index(i, n, key) for i in range(n))
        assert img == list(range(n)), f"n {n}, key {key}: not a permutation"


# ---------------------------------------------------------------------------
# What the plan works out once keeps every value (docs/samplers.md, "Cost per
# sample"): exact comparisons, so one wrong bit of a drawn value fails them.


# (film, spp): zsobol's table of top digits with 3 (16 x 16 at 64 spp, 64 x 64 at
# 4: its size is bounded by the render's samples), 5 (64 x 64 at 64: one pixel
# digit hashed) and 6 digits (64 x 64 at 256: none), 7 spp (an odd count of
# sample bits, the coin), a 1 x 1 film (no pixel digit), an index of 36 bits
# (8192^2 at 1024: digits above bit 31 skipped) and of 44 (131072^2 at 1024:
# the tabled digits all above bit 31, so none are tabled).
@pytest.mark.parametrize("film, spp", [((16, 16), 64), ((64, 64), 4), ((64, 64), 64), ((64, 64), 256),
                                       ((33, 17), 7), ((1, 1), 8), ((8192, 8192), 1024), ((1 << 17, 1 << 17), 1024)])
def test_zsobol_tables_keep_the_values(film, spp):
    """zsobol's values with the plan's tables (the film-wide keys of the
    dimensions and the scrambled top digits of the index) are, to the bit,
    those of the index hashed digit by digit: over about 300 dimensions
    (the tables stop at 264), in the first pattern (tabled) and past it
    (hashed)."""
    w, h = film
    rng = np.random.default_rng(17)
    pattern = [int(k) for k in rng.choice([1, 2], size=200)]
    for seed in (3, 2 ** 40 + 1):
        for pixel in rng.integers(0, w * h, size=3):
            args = ("zsobol", spp, True, seed, w, h, spp, int(pixel), min(spp + 3, 2 * spp), pattern)
            a = _core.sampler_draws(*args)
            b = _core.sampler_draws(*args, tables=False)
            assert a.tobytes() == b.tobytes(), f"{w} x {h} at {spp} spp, seed {seed}, pixel {pixel}: tables differ"


@pytest.mark.parametrize("n", [1, 3, 6, 7, 12, 36, 64, 100, 1000, 12345, (1 << 24) - 3])
def test_stratum_value_is_the_double_quotient(n):
    """stratum_value's (stratum + offset) / n by a multiply by 1 / n is the
    float of the double quotient (its definition), offsets on every 2^-24:
    random ones, the ends, and the quotients that fall on a float rounding
    midpoint (n with a factor 4 or more: the rounding must go to even as the
    division's does)."""
    rng = np.random.default_rng(n)
    strata = rng.integers(0, n, size=200000, dtype=np.uint32)
    k = rng.integers(0, 1 << 24, size=strata.size, dtype=np.uint32)
    k[:1000] = 0
    k[1000:2000] = (1 << 24) - 1
    k[2000:3000] = 1 << 23
    offsets = (k.astype(np.float64) * 2.0 ** -24).astype(np.float32)
    ours = _core.stratum_values(strata, offsets, n)
    ref = np.minimum(((strata.astype(np.float64) + offsets.astype(np.float64)) / n).astype(np.float32),
                     np.float32(np.nextafter(np.float32(1), np.float32(0))))
    assert ours.tobytes() == ref.tobytes(), f"n {n}: {np.count_nonzero(ours != ref)} values differ"
    if n % 4 == 0:
        # the midpoint cases are among those checked: quotients with more
        # than 24 significant bits ending in a lone 1 after the float's
        num = (strata.astype(np.float64) + offsets.astype(np.float64)) / n
        m, e = np.frexp(num[num > 0])
        frac = np.ldexp(m, 25) % 2  # the bit below the float's 24, and anything after it
        assert np.count_nonzero(frac == 1.0) > 100, f"n {n}: no quotient on a rounding midpoint was drawn"


# (n, stratum, k): quotients (stratum + k 2^-24) / n whose product by the
# rounded 1 / n rounds to the other float than the double quotient does
# (found by search, about 1 in 6 10^5 random triples): stratum_value must
# notice them and divide.
NEAR_MIDPOINT = [(44974, 41967, 13963153), (5988, 5124, 4916898), (980, 684, 14277146), (1968, 682, 13623884),
                 (32662, 19851, 12659123), (1730, 1555, 1867925), (6468, 2628, 10125945), (996, 306, 14090283),
                 (6434, 5877, 1258275), (474, 456, 6943611), (308, 153, 16549373), (22812, 21742, 3607166),
                 (1992, 1645, 14375516), (3610, 3582, 7546673), (1878, 1352, 9127735), (28976, 18324, 3641496),
                 (3536, 3199, 16627272), (206, 159, 10523081), (25208, 11771, 7460162), (32730, 18255, 33045)]


def test_stratum_value_where_the_multiply_alone_rounds_wrong():
    """The power check of the test above: on these triples the multiply
    alone gives the other float (checked here, so the list stays a check),
    and stratum_value still gives the double quotient's."""
    for n, s, k in NEAR_MIDPOINT:
        off = np.float32(k * 2.0 ** -24)
        num = np.float64(s) + np.float64(off)
        ref = np.float32(num / n)
        assert np.float32(num * (1.0 / n)) != ref, f"({n}, {s}, {k}): the multiply alone is right here"
        ours = _core.stratum_values([s], [float(off)], n)[0]
        assert ours == ref, f"({n}, {s}, {k}): {ours!r} != {ref!r}"


# ---------------------------------------------------------------------------
# Stratification and uniformity of the samples


PIXELS = [0, 1, 17, 100, 255, 37, 200, 128]


@pytest.mark.parametrize("sampler", STRUCTURED)
def test_every_draw_is_stratified(sampler):
    """Each pixel's N = 64 samples put exactly one value into each of the 64
    strata of every 1D draw and into each of the 8 x 8 cells of every 2D
    draw; multijitter, sobol and zsobol also into each of the 64 strata of
    each axis of a 2D draw (N-rooks). The independent sampler fails the same
    check (its counts are multinomial), so the check can fail."""
    one, two = draw_columns()
    for p in PIXELS:
        u = draws(sampler, p)
        assert u.min() >= 0.0 and u.max() < 1.0
        for c in one:
            assert np.all(strata_counts(u[:, c], N) == 1), f"{sampler}, pixel {p}, 1D dim {c}: not stratified"
        for a, b in two:
            assert np.all(cell_counts(u[:, a], u[:, b], 8) == 1), f"{sampler}, pixel {p}, 2D dims {a, b}"
            if sampler != "stratified":
                for c in (a, b):
                    assert np.all(strata_counts(u[:, c], N) == 1), f"{sampler}, pixel {p}, axis {c} of 2D draw"
    u = draws("independent", PIXELS[0])
    assert not np.all(cell_counts(u[:, 0], u[:, 1], 8) == 1), "the independent sampler looks stratified"


@pytest.mark.parametrize("sampler", STRUCTURED)
def test_stratified_beyond_chance_and_lower_discrepancy(sampler):
    """Chi-square of the 8 x 8 cell counts of every 2D draw, summed over the
    pixels: below the ALPHA quantile of its chi-square distribution (more
    even than independent samples are but with probability ALPHA); the
    independent sampler's sum is not (power). The mean centred L2
    discrepancy of the 2D draws is below half of the independent
    sampler's."""
    _, two = draw_columns()

    def chi2_and_cd(s):
        x2, cd = 0.0, []
        for p in PIXELS:
            u = draws(s, p)
            for a, b in two:
                c = cell_counts(u[:, a], u[:, b], 8)
                x2 += float(((c - 1.0) ** 2).sum())
                cd.append(stats.qmc.discrepancy(u[:, [a, b]].astype(np.float64), method="CD"))
        return x2, float(np.mean(cd))

    df = len(PIXELS) * len(two) * 63
    lo = stats.chi2.ppf(ALPHA, df)
    x2, cd = chi2_and_cd(sampler)
    x2_ind, cd_ind = chi2_and_cd("independent")
    assert x2 < lo, f"{sampler}: cell chi-square {x2:.1f} not below the {ALPHA} quantile {lo:.1f} of chi2({df})"
    assert x2_ind >= lo, f"independent: cell chi-square {x2_ind:.1f} below {lo:.1f}: the check has no power"
    assert cd < 0.5 * cd_ind, f"{sampler}: centred discrepancy {cd:.3g} vs independent {cd_ind:.3g}"


def projection_pvalues(u, bins1=32, bins2=8):
    """p-values of the chi-square uniformity test of every 1D column (bins1
    bins) and every pair of columns (bins2 x bins2 cells) of u."""
    n, d = u.shape
    ps = []
    for c in range(d):
        cnt = strata_counts(u[:, c], bins1)
        ps.append(stats.chisquare(cnt).pvalue)
    for a in range(d):
        for b in range(a + 1, d):
            cnt = cell_counts(u[:, a], u[:, b], bins2)
            ps.append(stats.chisquare(cnt).pvalue)
    return np.array(ps)


def pooled(sampler, pixels=range(256), spp=16, seed=11):
    # Fewer samples per pixel than cells, so a pixel's stratification does
    # not make the pooled counts exact: the pixels' independence shows.
    return np.concatenate([draws(sampler, p, n=spp, spp=spp, seed=seed) for p in pixels])


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_pooled_projections_are_uniform_and_independent(sampler):
    """All 1D and 2D projections of the 15 dimensions of DRAWS, pooled over
    256 pixels x 16 samples (4096 points; 32 bins, 8 x 8 cells): no
    chi-square p-value below the Sidak level for ALPHA over the 120
    projections. Power: the same points with one dimension warped u -> u^1.25
    (a 1D bias) and with one pair of draws sharing a pixel's permutation
    (dimension 3 copied into 9 for a quarter of the samples) are rejected."""
    u = pooled(sampler)
    ps = projection_pvalues(u)
    level = 1.0 - (1.0 - ALPHA) ** (1.0 / len(ps))
    assert ps.min() >= level, f"{sampler}: projection p = {ps.min():.2e} < {level:.2e} (index {ps.argmin()})"
    warped = u.copy()
    warped[:, 4] = warped[:, 4] ** 1.25
    assert projection_pvalues(warped).min() < level, f"{sampler}: a warped dimension went undetected"
    copied = u.copy()
    copied[::4, 9] = copied[::4, 3]
    assert projection_pvalues(copied).min() < level, f"{sampler}: correlated dimensions went undetected"


def test_past_the_pattern_a_fresh_pattern():
    """Samples past N (a render longer than its pattern, e.g. under a time
    budget) start a fresh pattern: every block of N samples is stratified on
    its own, and the blocks differ."""
    for s in ("stratified", "multijitter", "zsobol"):
        u = _core.sampler_draws(s, 16, True, reroll(5), W, H, 16, 3, 48, [2, 1])
        for k in range(3):
            blk = u[16 * k: 16 * (k + 1)]
            assert np.all(cell_counts(blk[:, 0], blk[:, 1], 4) == 1), f"{s}: block {k} not stratified"
        assert not np.array_equal(u[:16], u[16:32]), f"{s}: blocks repeat"
    # sobol is one sequence: its first 2^k samples are stratified for every k
    u = _core.sampler_draws("sobol", 16, True, reroll(5), W, H, 16, 3, 64, [2])
    for k in (4, 8, 16, 32, 64):
        side = int(round(np.sqrt(k))) if int(round(np.sqrt(k))) ** 2 == k else None
        if side:
            assert np.all(cell_counts(u[:k, 0], u[:k, 1], side) == 1), f"sobol: first {k} not stratified"


def test_non_square_counts_keep_the_samples_uniform():
    """A sample count that is not the pattern's (stratified 10 -> 16, zsobol 10
    -> 16, multijitter 10 -> 3 x 4): the samples drawn are a random subset of
    the strata, so every 1D draw's values pooled over pixels stay uniform
    (chi-square at ALPHA, 10 bins, Sidak over the draws)."""
    for s in ("stratified", "multijitter", "zsobol"):
        u = np.concatenate([_core.sampler_draws(s, 10, True, reroll(9), W, H, 10, p, 10, [1, 2, 1])
                            for p in range(256)])
        ps = [stats.chisquare(strata_counts(u[:, c], 10)).pvalue for c in range(4)]
        assert min(ps) >= 1 - (1 - ALPHA) ** 0.25, f"{s} at 10 spp: p = {min(ps):.2e}"


# ---------------------------------------------------------------------------
# Unbiasedness on the analytic scenes (path)


def _blocked(img, var, ref, label):
    return blocked_z_test(img, var, ref, None, alpha=ALPHA, label=label)


@pytest.mark.parametrize("sampler", STRUCTURED)
def test_path_unbiased_on_the_furnace(sampler):
    """The furnace (reference_scenes/furnace) with Russian roulette: L = Le /
    (1 - rho), 4 x 4 block means with the variance pooled over the image
    (every pixel has the same distribution), level ALPHA; the exact value *
    1.01 is rejected."""
    from radiometer.reference_scenes.furnace import analytic as furnace

    scene = rm.load_file(furnace.XML)
    r = rm.render(scene, integrator={"type": "path", "max_depth": -1}, spp=256, seed=41, sampler=sampler)
    assert r.stats["sampler"] == sampler
    assert r.stats["nan_samples"] == 0 and r.stats["inf_samples"] == 0 and r.image.min() >= 0
    ref, _ = furnace.reference(max_depth=-1)
    pooled_var = np.broadcast_to(r.variance.mean(axis=(0, 1)), r.variance.shape)
    ok, msg = _blocked(r.image, pooled_var, ref, f"furnace {sampler}: ")
    assert ok, f"{sampler}: mean {r.image.mean():.5f} vs {ref[0, 0, 0]:.5f}\n{msg}"
    ok, msg = _blocked(r.image, pooled_var, ref * 1.01, f"furnace {sampler} x1.01: ")
    assert not ok, f"{sampler}: a 1 % bias went undetected\n{msg}"


# Every estimator that draws on the sampler: the camera driver's (path,
# direct) and the light driver's (ptracer; bdpt draws both subpaths on it).
SAMPLER_ESTIMATORS = ("path", "direct", "ptracer", "bdpt")


@pytest.mark.parametrize("sampler", STRUCTURED)
@pytest.mark.parametrize("est", SAMPLER_ESTIMATORS)
@pytest.mark.parametrize("light", ["disk", "rect"])
def test_unbiased_under_area_lights(light, est, sampler):
    """Each estimator that draws on the sampler (max_depth 2) under the disk
    and rectangle lights (reference_scenes/area_lights) against the exact
    box-filtered image, 4 x 4 blocks, level ALPHA; the exact image * 1.01 is
    rejected (path, direct at 64 spp; ptracer and bdpt, whose light paths
    land anywhere on the film, at 128)."""
    from radiometer.reference_scenes.area_lights import analytic as area

    xml, ref = (area.DISK_XML, area.reference_disk()[0]) if light == "disk" else (area.RECT_XML,
                                                                                    area.reference_rect()[0])
    spp = 64 if est in ("path", "direct") else 128
    integ = {"type": est} if est == "direct" else {"type": est, "max_depth": 2}  # direct: two segments by definition
    r = rm.render(rm.load_file(xml), integrator=integ, spp=spp, seed=43, sampler=sampler)
    assert r.stats["sampler"] == sampler, f"{est} did not draw on {sampler}"
    assert r.stats["nan_samples"] == 0 and r.stats["inf_samples"] == 0 and r.image.min() >= 0
    where = f"{light}, {est}, {sampler}"
    ok, msg = _blocked(r.image, r.variance, ref, f"{where}: ")
    ratio = r.image.sum() / ref.sum()
    assert ok, f"{where}: image sum / exact = {ratio:.5f}\n{msg}"
    ok, msg = _blocked(r.image, r.variance, ref * 1.01, f"{where} x1.01: ")
    assert not ok, f"{where}: a 1 % bias went undetected\n{msg}"


# ---------------------------------------------------------------------------
# Determinism, plumbing, errors


@pytest.mark.parametrize("sampler", STRUCTURED)
def test_threads_do_not_change_the_bytes(sampler, small_cornell):
    """path (camera driver) and bdpt (light driver): threads=1 and threads=2
    give byte-identical images with each sampler; and the sampler is used
    (the image differs from the independent sampler's)."""
    for est in ("path", "bdpt"):
        a = rm.render(small_cornell, integrator=est, spp=4, seed=5, threads=1, sampler=sampler)
        b = rm.render(small_cornell, integrator=est, spp=4, seed=5, threads=2, sampler=sampler)
        assert a.stats["sampler"] == sampler
        assert a.image.tobytes() == b.image.tobytes(), f"{est}, {sampler}: threads change the image"
        c = rm.render(small_cornell, integrator=est, spp=4, seed=5, threads=2)
        assert c.image.tobytes() != a.image.tobytes(), f"{est}, {sampler}: the same image as independent"


def test_scene_file_and_dict_choose_the_sampler(tmp_path):
    """The sensor's nested sampler decides (XML and dict), with its
    sample_count as the default spp; render(sampler=...) overrides it; the
    default is independent and explicit 'independent' gives its bytes."""
    d = furnace_dict(res=8, max_depth=3)
    d["sensor"]["sampler"] = {"type": "multijitter", "sample_count": 9, "jitter": False}
    s = rm.load_dict(d)
    r = rm.render(s, seed=1)
    assert r.stats["sampler"] == "multijitter" and r.spp == 9
    assert rm.render(s, seed=1, sampler="sobol").stats["sampler"] == "sobol"
    assert rm.render(s, seed=1, sampler={"type": "ldsampler"}).stats["sampler"] == "sobol"  # Mitsuba's name
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><integrator type="path"/><shape type="sphere"><bsdf type="diffuse"/>'
                   '<emitter type="area"/></shape><sensor type="perspective"><film type="hdrfilm">'
                   '<integer name="width" value="8"/><integer name="height" value="8"/></film>'
                   '<sampler type="zsobol"><integer name="sample_count" value="8"/>'
                   '<integer name="seed" value="3"/></sampler></sensor></scene>')
    r = rm.render(rm.load_file(str(xml)), seed=2)
    assert r.stats["sampler"] == "zsobol" and r.spp == 8
    plain = rm.load_dict(furnace_dict(res=8, max_depth=3))
    a = rm.render(plain, spp=4, seed=2)
    b = rm.render(plain, spp=4, seed=2, sampler={"type": "independent"})
    assert a.stats["sampler"] == "independent" and a.image.tobytes() == b.image.tobytes()


def test_estimators_with_their_own_streams_warn():
    """sppm draws on its own streams: asking for sobol warns and says so;
    photonmapper's warning says its photon passes stay independent."""
    s = rm.load_dict(furnace_dict(res=8, max_depth=3))
    with pytest.warns(UserWarning, match="sampler 'sobol' is not used"):
        r = rm.render(s, integrator={"type": "sppm", "photon_count": 2000}, spp=2, seed=1, sampler="sobol")
    assert r.stats["sampler"] == "independent"
    with pytest.warns(UserWarning, match="photon passes use the independent"):
        rm.render(s, integrator={"type": "photonmapper", "global_photons": 2000, "caustic_photons": 2000},
                  spp=2, seed=1, sampler="sobol")


@pytest.mark.parametrize("spec, names", [
    ("orthogonal", ["orthogonal", "not implemented"]),
    ("halton", ["halton", "zsobol"]),
    ({"type": "sobol", "jitter": True}, ["'jitter'", "sobol"]),
    ({"type": "stratified", "sample_count": 0}, ["sample_count", "stratified"]),
    ({"type": "stratified", "sample_count": 2.5}, ["sample_count"]),
    ({"type": "multijitter", "jiter": False}, ["'jiter'"]),
    ({"type": "multijitter", "jitter": 1}, ["'jitter'"]),
    ({"sample_count": 4}, ["'type'"]),
    (3, ["sampler"]),
])
def test_bad_sampler_in_render_names_it(spec, names):
    s = rm.load_dict(furnace_dict(res=4, max_depth=2))
    with pytest.raises(rm.SceneError) as e:
        rm.render(s, spp=1, sampler=spec)
    for n in names:
        assert n in str(e.value), f"{spec!r}: '{n}' not in {e.value}"


@pytest.mark.parametrize("sampler, names", [
    ({"type": "orthogonal"}, ["orthogonal"]),
    ({"type": "sobol", "jitter": False}, ["jitter"]),
    ({"type": "stratified", "sample_count": 0}, ["sample_count"]),
    ({"type": "stratified", "jitter": 3}, ["jitter"]),
])
def test_bad_sampler_in_a_scene_names_it(sampler, names):
    d = furnace_dict(res=4, max_depth=2)
    d["sensor"]["sampler"] = sampler
    with pytest.raises(rm.SceneError) as e:
        rm.load_dict(d)
    for n in names:
        assert n in str(e.value), f"{sampler!r}: '{n}' not in {e.value}"
