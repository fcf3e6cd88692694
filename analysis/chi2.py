"""Pearson chi-square test of a direction sampler against its pdf (DESIGN sec. 4).

The test follows the one Mitsuba 3 (`src/python/python/chi2.py`,
`ChiSquareTest`) and pbrt-v4 (`src/pbrt/bsdfs_test.cpp`, `Chi2Test`) run on
their BSDFs, with three differences that make it a proper multinomial
goodness-of-fit test:

* Samples go into a histogram over the whole sphere, parameterised by
  (theta, phi) as pbrt does or (cos theta, phi) as Mitsuba's SphericalDomain
  does (equal-solid-angle rows). Samples of a delta lobe, and failed samples
  (pdf 0), cannot be histogrammed; they go into one extra "off" cell whose
  expected probability is 1 - (integral of the pdf over the sphere). A pdf that
  forgets a lobe-selection probability (a global scale) is then rejected too,
  which a histogram-only test cannot see. The off count also gets its own
  two-sided binomial test; each of the two tests runs at half the level.
* The expected count of a cell is N times the pdf integrated over it with
  adaptive Gauss-Legendre cubature (pbrt uses nested adaptive Simpson, Mitsuba
  a fixed trapezoid grid): a rectangle is split in four while its estimate and
  its children's disagree by more than the tolerance, so jumps (the horizon,
  the half-vector horizon of rough transmission) get refined where they lie;
  rectangles that hold samples but integrate to ~0 are refined until the
  nodes find the sliver the samples came from; jumps still unresolved at the
  depth limit are integrated by jittered stratified sampling, whose errors
  cancel instead of adding up (see integrate_pdf). The expected counts are
  therefore accurate to a few samples in total, well under the counting
  noise. An even n_theta puts the horizon on a cell edge.
* Cells are pooled as pbrt and Mitsuba do: sorted by expected count, the
  cells below `min_expected` (5) are merged, and further cells are added
  until the pool reaches it; dof = bins - 1 (no fitted parameters). Samples in
  a cell of expected count 0 reject at once, beyond pbrt's allowance of
  1e-5 N for rounding at boundaries.

Significance: `sidak_level(alpha, n_tests)` = 1 - (1 - alpha)^(1/n) is the
per-test level at which n independent tests reject with overall probability
alpha when every null hypothesis holds (Sidak 1967; the correction both
Mitsuba's `run(significance_level, test_count)` and pbrt's `Chi2Test` apply).

Usage:
    sample, pdf = bsdf_adapter(bsdf, wi)
    r = chi2_test(sample, pdf, n_samples=200_000, seed=1, level=sidak_level(0.01, 40))
    assert r.passed, r.summary()
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats as _st

__all__ = [
    "sidak_level", "pearson_chi2", "chi2_p_value", "binomial_p_value", "SphereGrid", "integrate_pdf",
    "histogram_directions", "Chi2Result", "chi2_test", "bsdf_adapter",
]


# ---------------------------------------------------------------------------
# Significance


def sidak_level(alpha: float, n_tests: int) -> float:
    """Per-test level so that n_tests independent tests, all under H0, reject
    at least once with probability alpha: 1 - (1 - alpha)^(1 / n)."""
    if not (0.0 < alpha < 1.0):
        raise ValueError(f"sidak_level: alpha must be in (0, 1), got {alpha}")
    if n_tests < 1:
        raise ValueError(f"sidak_level: n_tests must be >= 1, got {n_tests}")
    # -expm1(log1p(-alpha) / n) is the same number without cancellation for large n.
    return float(-np.expm1(np.log1p(-alpha) / n_tests))


def chi2_p_value(stat: float, dof: int) -> float:
    """P(X >= stat) for X ~ chi-square(dof): the upper regularised incomplete
    gamma Q(dof / 2, stat / 2), which pbrt computes as 1 - RLGamma."""
    if dof < 1:
        return float("nan")
    return float(_st.chi2.sf(stat, dof))


def binomial_p_value(k: int, n: int, p: float) -> float:
    """Two-sided exact binomial p-value of k successes in n trials of
    probability p (scipy's binomtest: sum of the outcomes no more likely than k)."""
    p = min(max(float(p), 0.0), 1.0)
    if n == 0:
        return 1.0
    if p == 0.0:
        return 1.0 if k == 0 else 0.0
    if p == 1.0:
        return 1.0 if k == n else 0.0
    return float(_st.binomtest(int(k), int(n), p).pvalue)


def pearson_chi2(observed, expected, min_expected: float = 5.0, zero_tolerance: float = 0.0):
    """Pearson's statistic sum (O - E)^2 / E over pooled bins.

    Bins are sorted by expected count; every bin below `min_expected` goes
    into one pool, which then takes the next-smallest bins until its expected
    count reaches `min_expected` (pbrt-v4's Chi2Test, Mitsuba's math.chi2).
    Bins of expected count 0 are left out; observations in them beyond
    `zero_tolerance` are reported as `zero_violations`.
    Returns a dict: stat, dof (bins - 1), p_value, bins, pooled_in (bins
    merged into the pool), zero_count (observations in bins expecting 0),
    zero_violations (bool)."""
    o = np.asarray(observed, np.float64).ravel()
    e = np.asarray(expected, np.float64).ravel()
    if o.shape != e.shape:
        raise ValueError(f"pearson_chi2: observed {o.shape} and expected {e.shape} differ")
    if np.any(e < 0) or not np.all(np.isfinite(e)):
        raise ValueError("pearson_chi2: expected counts must be finite and >= 0")
    zero = e <= 0
    zero_count = float(o[zero].sum())
    o, e = o[~zero], e[~zero]
    order = np.argsort(e, kind="stable")
    o, e = o[order], e[order]
    # Bins [0, k) are pooled: all bins under min_expected, then more until
    # the pool's expected count reaches min_expected.
    small = int(np.searchsorted(e, min_expected, side="left"))
    k = small
    if k > 0:
        csum = np.cumsum(e)
        if csum[k - 1] < min_expected:
            k = min(int(np.searchsorted(csum, min_expected, side="left")) + 1, e.size)
    stat = 0.0
    bins = e.size - k
    if bins > 0:
        stat += float(np.sum((o[k:] - e[k:]) ** 2 / e[k:]))
    if k > 0:
        po, pe = float(o[:k].sum()), float(e[:k].sum())
        stat += (po - pe) ** 2 / pe
        bins += 1
    dof = bins - 1
    return {"stat": stat, "dof": dof, "p_value": chi2_p_value(stat, dof), "bins": bins, "pooled_in": k,
            "zero_count": zero_count, "zero_violations": zero_count > zero_tolerance}


# ---------------------------------------------------------------------------
# The grid over the sphere and the cell integrals of a pdf


@dataclass(frozen=True)
class SphereGrid:
    """Cells over the sphere: `n_theta` rows in theta (domain "theta", pbrt) or
    in cos theta (domain "cos_theta", Mitsuba; equal solid angle per cell) and
    `n_phi` columns in phi in [0, 2 pi). Row 0 is around +z. An even n_theta
    puts the horizon on a row edge."""
    n_theta: int = 32
    n_phi: int = 64
    domain: str = "theta"

    def __post_init__(self):
        if self.domain not in ("theta", "cos_theta"):
            raise ValueError(f"SphereGrid: domain must be 'theta' or 'cos_theta', got {self.domain!r}")
        if self.n_theta < 1 or self.n_phi < 1:
            raise ValueError("SphereGrid: n_theta and n_phi must be >= 1")

    @property
    def shape(self):
        return (self.n_theta, self.n_phi)

    # The parameter y of a row runs over [0, 1): theta / pi, or (1 - cos theta) / 2.
    def y_of(self, d):
        z = np.clip(d[:, 2], -1.0, 1.0)
        if self.domain == "theta":
            return np.arccos(z) / np.pi
        return 0.5 * (1.0 - z)

    def directions(self, x, y):
        """(x = phi / 2 pi, y) in [0,1]^2 -> unit directions, and the Jacobian
        d omega / (dx dy). x and y broadcast against each other; the
        trigonometry is done on each before broadcasting (for tensor grids)."""
        phi = 2.0 * np.pi * np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        if self.domain == "theta":
            theta = np.pi * y
            cos_t, sin_t = np.cos(theta), np.sin(theta)
            jac = 2.0 * np.pi * np.pi * sin_t
        else:
            cos_t = 1.0 - 2.0 * y
            sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
            jac = np.full_like(cos_t, 4.0 * np.pi)
        cos_p, sin_p = np.cos(phi), np.sin(phi)
        shape = np.broadcast_shapes(phi.shape, y.shape)
        d = np.empty(shape + (3,))
        d[..., 0] = sin_t * cos_p
        d[..., 1] = sin_t * sin_p
        d[..., 2] = np.broadcast_to(cos_t, shape)
        return d, np.broadcast_to(jac, shape)

    def cell_of(self, d):
        """Row and column of each direction (N, 3)."""
        d = np.asarray(d, np.float64)
        y = self.y_of(d)
        phi = np.arctan2(d[:, 1], d[:, 0])
        x = np.mod(phi / (2.0 * np.pi), 1.0)
        row = np.clip(np.floor(y * self.n_theta).astype(np.int64), 0, self.n_theta - 1)
        col = np.clip(np.floor(x * self.n_phi).astype(np.int64), 0, self.n_phi - 1)
        return row, col


def histogram_directions(grid: SphereGrid, d) -> np.ndarray:
    """Counts of directions (N, 3) per cell, shape grid.shape."""
    row, col = grid.cell_of(d)
    h = np.bincount(row * grid.n_phi + col, minlength=grid.n_theta * grid.n_phi)
    return h.reshape(grid.shape).astype(np.float64)


def integrate_pdf(pdf_func, grid: SphereGrid, scale: float = 1.0, order: int = 3, min_depth: int = 1,
                  max_depth: int = 7, atol: float = 1e-3, rtol: float = 1e-4, points=None,
                  point_level: float = 1e-3, max_point_depth: int = 16, max_evals: int = 40_000_000,
                  jitter: int = 4, seed: int = 0):
    """scale * (integral of pdf_func over each cell), shape grid.shape, and an
    error estimate in the same units (see below).

    Adaptive cubature on a quadtree per cell: each rectangle is integrated with
    an order x order Gauss-Legendre rule and again as its four children; it is
    accepted when |children - parent| <= max(atol * (its share of its cell's
    area), rtol * |children|) (scale units: with scale = N, atol is in
    expected samples), else its children are refined, down to max_depth.
    `min_depth` splits are always made so that a lobe narrower than the first
    node spacing is not missed.

    Both estimates can agree on 0 where the pdf is non-zero only in a sliver
    between the nodes (the support edge of rough transmission, a few hundredths
    of a degree wide next to a grid line). `points` (the histogrammed samples,
    (M, 3) directions, with scale = their total count N) guard against that: a
    rectangle holding k samples whose expected count E makes k implausible
    (Poisson P(K >= k | E) < point_level) is refined further, down to
    max_point_depth, until the nodes find what the samples came from. Before
    a cell can make the test reject, its integral is thus looked at closely.
    This changes only how accurately a cell's integral is computed, never what
    is integrated: a pdf that is 0 where samples lie still integrates to 0.

    Rectangles still unresolved at max_depth straddle a jump (the horizon of
    the GGX half vector in rough transmission is one, its pdf falls from ~4/sr
    to 0). Where such a line runs along a grid line, every straddling leaf
    sees the jump at the same relative position and the Gauss-Legendre errors
    add up instead of cancelling (measured: 1.2% of a row, 2.4% of the
    off-histogram probability for GGX alpha 1 at 80 deg). Those leaves are
    therefore integrated with jittered stratified sampling, jitter x jitter
    points (unbiased for any integrable pdf; Owen 2013, "Monte Carlo theory,
    methods and examples", ch. 10), so that their errors have mean 0 and
    cancel. The error estimate returned is sqrt(sum over those leaves of
    (stratified - Gauss-Legendre)^2): the scale of what is left.

    pdf_func takes (M, 3) float64 directions and returns (M,) densities per
    steradian."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    nodes = 0.5 * (nodes + 1.0)  # on [0, 1]
    weights = 0.5 * weights
    wxy = np.outer(weights, weights).ravel()  # (order^2,), y major as the nodes in rule()
    evals = [0]
    n_cells = grid.n_theta * grid.n_phi
    w0, h0 = 1.0 / grid.n_phi, 1.0 / grid.n_theta

    def rule(cell, level, ix, iy):
        """Integral over rectangle (ix, iy) of a cell split 2^level x 2^level."""
        size = 0.5 ** level
        w, h = w0 * size, h0 * size
        x0 = ((cell % grid.n_phi) + ix * size) * w0
        y0 = ((cell // grid.n_phi) + iy * size) * h0
        px = x0[:, None, None] + w * nodes[None, None, :]  # (R, 1, order): x varies fastest
        py = y0[:, None, None] + h * nodes[None, :, None]  # (R, order, 1)
        d, jac = grid.directions(px, py)
        d = d.reshape(-1, 3)
        f = np.asarray(pdf_func(d), np.float64).reshape(-1)
        if f.shape[0] != d.shape[0]:
            raise ValueError(f"integrate_pdf: pdf_func returned {f.shape[0]} values for {d.shape[0]} directions")
        evals[0] += f.shape[0]
        f = np.where(np.isfinite(f), f, np.nan)  # a NaN/Inf pdf poisons its cell visibly
        return (f * jac.reshape(-1)).reshape(-1, order * order) @ wxy * (w * h * scale)

    # Samples as (cell, position inside the cell in [0, 1)^2), for the point guard.
    if points is not None and len(points):
        pts = np.asarray(points, np.float64)
        py_ = grid.y_of(pts) * grid.n_theta
        px_ = np.mod(np.arctan2(pts[:, 1], pts[:, 0]) / (2.0 * np.pi), 1.0) * grid.n_phi
        prow = np.clip(np.floor(py_), 0, grid.n_theta - 1)
        pcol = np.clip(np.floor(px_), 0, grid.n_phi - 1)
        pcell = (prow * grid.n_phi + pcol).astype(np.int64)
        plx = np.clip(px_ - pcol, 0.0, np.nextafter(1.0, 0.0))
        ply = np.clip(py_ - prow, 0.0, np.nextafter(1.0, 0.0))
    else:
        pcell = None

    def key(cell, level, ix, iy):
        return (cell.astype(np.int64) << (2 * level)) + (iy.astype(np.int64) << level) + ix.astype(np.int64)

    def point_counts(cell, level, ix, iy):
        """Samples in each rectangle; drops the tracked samples outside them."""
        nonlocal pcell, plx, ply
        s = 1 << level
        rk = key(cell, level, ix, iy)
        order_ = np.argsort(rk)
        rks = rk[order_]
        pk = key(pcell, level, np.floor(plx * s), np.floor(ply * s))
        pos = np.clip(np.searchsorted(rks, pk), 0, max(rks.size - 1, 0))
        inside = rks[pos] == pk if rks.size else np.zeros(pk.size, bool)
        pcell, plx, ply, pos = pcell[inside], plx[inside], ply[inside], pos[inside]
        counts = np.zeros(cell.size)
        counts[order_] = np.bincount(pos, minlength=rks.size)
        return counts

    cell = np.arange(n_cells)
    ix = np.zeros(n_cells, np.int64)
    iy = np.zeros(n_cells, np.int64)
    est = rule(cell, 0, ix, iy)
    out = np.zeros(n_cells)
    err2_left = 0.0
    jrng = np.random.default_rng(seed)

    def stratified(cell, level, ix, iy):
        """Jittered stratified estimate over each rectangle (jitter^2 points)."""
        size = 0.5 ** level
        w, h = w0 * size, h0 * size
        x0 = ((cell % grid.n_phi) + ix * size) * w0
        y0 = ((cell // grid.n_phi) + iy * size) * h0
        j = np.arange(jitter)
        ux = (j[None, None, :] + jrng.random((cell.size, jitter, jitter))) / jitter
        uy = (j[None, :, None] + jrng.random((cell.size, jitter, jitter))) / jitter
        d, jac = grid.directions(x0[:, None, None] + w * ux, y0[:, None, None] + h * uy)
        f = np.asarray(pdf_func(d.reshape(-1, 3)), np.float64).reshape(-1)
        evals[0] += f.shape[0]
        f = np.where(np.isfinite(f), f, np.nan)
        return (f * jac.reshape(-1)).reshape(cell.size, -1).mean(axis=1) * (w * h * scale)

    depth_limit = max(max_depth, max_point_depth if pcell is not None else 0)
    for depth in range(1, depth_limit + 1):
        m = cell.size
        cc = np.tile(cell, 4)
        cix = np.concatenate([2 * ix, 2 * ix + 1, 2 * ix, 2 * ix + 1])
        ciy = np.concatenate([2 * iy, 2 * iy, 2 * iy + 1, 2 * iy + 1])
        cest = rule(cc, depth, cix, ciy)
        fine = cest.reshape(4, m).sum(axis=0)
        err = np.abs(fine - est)
        area_share = 0.25 ** (depth - 1)
        tol = np.maximum(atol * area_share, rtol * np.abs(fine))
        refine = (err > tol) | (depth < min_depth)
        refine &= depth < max_depth
        if pcell is not None and pcell.size and depth < max_point_depth:
            counts = point_counts(cell, depth - 1, ix, iy)
            with np.errstate(divide="ignore", invalid="ignore"):
                implausible = (counts > 0) & (_st.poisson.sf(counts - 1, np.maximum(fine, 0.0)) < point_level)
            refine |= implausible
        if evals[0] + 4 * order * order * 4 * int(np.count_nonzero(refine)) > max_evals:
            refine[:] = False
        unresolved = ~refine & (err > tol)
        if jitter > 0 and np.any(unresolved):
            sv = stratified(cell[unresolved], depth - 1, ix[unresolved], iy[unresolved])
            err2_left += float(np.nansum((sv - fine[unresolved]) ** 2))
            fine[unresolved] = sv
        elif np.any(unresolved):
            err2_left += float(np.nansum(err[unresolved]) ** 2)
        done = ~refine
        np.add.at(out, cell[done], fine[done])
        keep = np.tile(refine, 4)
        if not keep.any():
            break
        cell, ix, iy, est = cc[keep], cix[keep], ciy[keep], cest[keep]
    return out.reshape(grid.shape), float(np.sqrt(err2_left))


# ---------------------------------------------------------------------------
# The test


@dataclass
class Chi2Result:
    passed: bool
    p_value: float
    level: float  # the level of the test: Pearson p and off-count p are each compared with level / 2
    stat: float
    dof: int
    n_samples: int
    n_hist: int  # samples in the histogram (non-delta, not failed)
    n_delta: int
    n_failed: int
    off_expected: float  # N (1 - integral of the pdf): expected delta + failed samples
    p_off: float  # two-sided binomial p of n_delta + n_failed against off_expected / N
    pdf_integral: float  # integral of the pdf over the sphere
    integration_error: float  # estimated error of the expected counts (samples), all cells together
    pooled_in: int
    zero_count: float  # samples in cells where the pdf integrates to 0
    observed: np.ndarray  # histogram, grid.shape
    expected: np.ndarray  # N * integral of the pdf per cell, grid.shape
    grid: SphereGrid
    messages: list = field(default_factory=list)
    label: str = ""

    def residuals(self) -> np.ndarray:
        """(O - E) / sqrt(E) per cell (0 where E == 0), grid.shape: for plots."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.expected > 0, (self.observed - self.expected) / np.sqrt(self.expected), 0.0)

    def summary(self) -> str:
        head = f"{self.label + ': ' if self.label else ''}{'PASS' if self.passed else 'FAIL'}"
        lines = [
            f"{head} p = {self.p_value:.4g} (level {self.level:.3g} / 2), chi2 = {self.stat:.1f}, dof = {self.dof}, "
            f"{self.pooled_in} cells pooled",
            f"  N = {self.n_samples}: {self.n_hist} histogrammed, {self.n_delta} delta, {self.n_failed} failed; "
            f"off cell observed {self.n_delta + self.n_failed} vs expected {self.off_expected:.1f} "
            f"(binomial p {self.p_off:.3g}); pdf integral {self.pdf_integral:.6f} "
            f"(integration error ~{self.integration_error:.2g} samples)",
        ]
        if self.zero_count:
            lines.append(f"  {self.zero_count:g} samples in cells of zero expected count")
        if self.dof > 0:
            # The worst cells help to see what is wrong (where the pdf and the sampler disagree).
            e, o = self.expected.ravel(), self.observed.ravel()
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(e > 0, (o - e) / np.sqrt(np.maximum(e, 1e-300)), 0.0)
            worst = np.argsort(-np.abs(r))[:3]
            cells = ", ".join(f"(row {i // self.grid.n_phi}, col {i % self.grid.n_phi}): O {o[i]:g} E {e[i]:.1f}"
                              for i in worst if e[i] >= 5)
            if cells:
                lines.append(f"  largest residuals {cells}")
        lines += [f"  {m}" for m in self.messages]
        return "\n".join(lines)

    __str__ = summary


def _unpack(ret, n):
    """A sampler returns wo, or (wo, is_delta), or (wo, is_delta, valid)."""
    if isinstance(ret, tuple):
        wo = np.asarray(ret[0], np.float64)
        is_delta = np.asarray(ret[1], bool) if len(ret) > 1 and ret[1] is not None else np.zeros(n, bool)
        valid = np.asarray(ret[2], bool) if len(ret) > 2 and ret[2] is not None else np.ones(n, bool)
    else:
        wo = np.asarray(ret, np.float64)
        is_delta, valid = np.zeros(n, bool), np.ones(n, bool)
    if wo.shape != (n, 3) or is_delta.shape != (n,) or valid.shape != (n,):
        raise ValueError(f"chi2_test: sampler returned wo {wo.shape}, is_delta {is_delta.shape}, "
                         f"valid {valid.shape} for {n} samples")
    return wo, is_delta, valid


def chi2_test(sample_func, pdf_func, n_samples: int = 200_000, grid: SphereGrid | None = None, seed: int = 0,
              level: float = 0.01, min_expected: float = 5.0, label: str = "", order: int = 3,
              max_depth: int = 7, atol: float = 1e-3, rtol: float = 1e-4, min_depth: int = 1) -> Chi2Result:
    """Samples n_samples directions with sample_func(rng, n) (rng a numpy
    Generator seeded with `seed`; returns wo, or (wo, is_delta), or (wo,
    is_delta, valid)), histograms the valid non-delta ones on `grid`, integrates
    pdf_func over the cells (integrate_pdf) and runs Pearson's test with one
    extra bin for the delta and failed samples (see the module docstring).
    Passes when both the Pearson p and the binomial p of the off-histogram
    count are >= level / 2 (so the pair has level `level`; pass
    sidak_level(alpha, n_tests) for a family of tests) and nothing else was
    found wrong (messages say what)."""
    grid = grid or SphereGrid()
    rng = np.random.default_rng(seed)
    n = int(n_samples)
    wo, is_delta, valid = _unpack(sample_func(rng, n), n)
    messages = []
    finite = np.all(np.isfinite(wo), axis=1)
    hist_sel = valid & ~is_delta & finite
    if np.any(valid & ~finite):
        messages.append(f"{int(np.count_nonzero(valid & ~finite))} valid samples have non-finite directions")
    if np.any(hist_sel):
        norms = np.linalg.norm(wo[hist_sel], axis=1)
        if np.max(np.abs(norms - 1.0)) > 1e-3:
            messages.append(f"sampled directions are not unit length (|wo| in [{norms.min():.4g}, {norms.max():.4g}])")
    observed = histogram_directions(grid, wo[hist_sel])
    n_hist = int(np.count_nonzero(hist_sel))
    n_delta = int(np.count_nonzero(valid & is_delta))
    n_failed = n - n_hist - n_delta

    expected, int_err = integrate_pdf(pdf_func, grid, scale=float(n), order=order, min_depth=min_depth,
                                      max_depth=max_depth,
                                      atol=atol, rtol=rtol, points=wo[hist_sel], seed=seed + 1)
    if not np.all(np.isfinite(expected)):
        messages.append(f"the pdf is NaN or Inf in {int(np.count_nonzero(~np.isfinite(expected)))} cells")
        expected = np.where(np.isfinite(expected), expected, 0.0)
    if np.min(expected) < 0:
        messages.append(f"the pdf is negative somewhere (most negative cell integral {np.min(expected) / n:.3g})")
    integral = float(expected.sum() / n)
    # Expected delta + failed samples. A pdf integrating to more than 1 (beyond
    # the integration error) is an error of its own; within it, clamp to 0.
    off_expected = n - float(expected.sum())
    # The cubature's own error estimate is optimistic where a light's outline
    # or a support edge cuts cells (measured: a rectangle light integrated to
    # 1.0020 at min_depth 1 and 1.00002 at min_depth 4, both claiming ~0.05
    # samples): allow 1e-4 N, far below the counting noise sqrt(N).
    if off_expected < -max(3.0 * int_err, 1e-4 * n, 1.0):
        messages.append(f"the pdf integrates to {integral:.6f} > 1")
    off_expected = max(off_expected, 0.0)
    n_off = n_delta + n_failed
    if off_expected > 0:
        p_off = binomial_p_value(n_off, n, off_expected / n)
    else:  # nothing expected off the histogram: pbrt's rounding allowance, as for any empty cell
        p_off = 1.0 if n_off <= 1e-5 * n else 0.0

    obs_all = np.append(observed.ravel(), n_off)
    exp_all = np.append(np.maximum(expected.ravel(), 0.0), off_expected)
    # pbrt's allowance for samples that rounding puts into a cell of expected count 0.
    pr = pearson_chi2(obs_all, exp_all, min_expected, zero_tolerance=1e-5 * n)
    if pr["zero_violations"]:
        messages.append(f"{pr['zero_count']:g} samples fell where the pdf integrates to 0 "
                        f"(more than the 1e-5 N allowed for rounding)")
    if pr["dof"] < 1:
        messages.append(f"too few degrees of freedom ({pr['dof']}): refine the grid or take more samples")
    p = pr["p_value"]
    # Two tests at level / 2 each (Bonferroni): Pearson over all bins, and the
    # binomial test of the off count alone, which sees a small error in the
    # pdf's normalisation (a lobe-selection probability) that hundreds of
    # degrees of freedom would dilute.
    passed = not messages and np.isfinite(p) and p >= 0.5 * level and p_off >= 0.5 * level
    return Chi2Result(passed=bool(passed), p_value=p, level=level, stat=pr["stat"], dof=pr["dof"], n_samples=n,
                      n_hist=n_hist, n_delta=n_delta, n_failed=n_failed, off_expected=off_expected, p_off=p_off,
                      pdf_integral=integral, integration_error=int_err, pooled_in=pr["pooled_in"],
                      zero_count=pr["zero_count"], observed=observed, expected=expected, grid=grid,
                      messages=messages, label=label)


# ---------------------------------------------------------------------------
# Adapter for radiometer._core.Bsdf (vectorised sample / pdf in the local frame)


def bsdf_adapter(bsdf, wi, adjoint: bool = False):
    """(sample_func, pdf_func) for a `_core.Bsdf` and a fixed incident
    direction wi (local frame, unit length). A sample with pdf 0 counts as
    failed (the C++ side zeroes a failed sample entirely)."""
    wi = np.asarray(wi, np.float64)
    wi = (wi / np.linalg.norm(wi)).astype(np.float32)

    def sample_func(rng, n):
        u1 = rng.random(n, dtype=np.float32)
        u2 = rng.random((n, 2), dtype=np.float32)
        s = bsdf.sample(np.broadcast_to(wi, (n, 3)), u1, u2, adjoint)
        valid = s["pdf"] > 0
        return s["wo"], s["is_delta"] > 0, valid

    def pdf_func(wo):
        wo = np.asarray(wo, np.float32)
        return bsdf.pdf(np.broadcast_to(wi, wo.shape), wo, adjoint)

    return sample_func, pdf_func
