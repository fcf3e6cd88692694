"""The majorant grid of grid media (renderer/scene/medium.h: Grid's
majorant cells, MajorantIterator, the local-majorant delta and ratio
tracking; `accel` of a gridvolume, false keeping one global majorant).

- Bound: sigma_t(p) <= the majorant of p's cell, every channel, at random
  points (uniform in the grid and just either side of cell borders) of
  grids with sparse spikes, non-power-of-two resolutions (cells that cut
  voxels), one and three channels, `scale`, rotated / sheared boxes; the
  grid must also be useful (most of a sparse grid's cells far below the
  global majorant).
- Ratio tracking along random rays through a sparse hot-spike grid against
  exp(-int sigma_t), the integral of a Python re-implementation of the
  trilinear lookup by Gauss-Legendre quadrature between the voxel-centre
  planes (exact: the lookup is a cubic polynomial along the ray there);
  per ray and channel z-tests, and exact x 1.02 rejected on the pooled mean.
- volpath, ptracer and bdpt on a sparse grid scene with the majorant grid
  against the same scene with accel = false (the global majorant: the code
  path of the renderer before the majorant grid, bytes unchanged), blocked
  z-tests with power checks (2 % volpath, 3 % ptracer and bdpt), and the
  sigma_t lookups of tracking (tentative collisions) at most half.

Every z-test is two-sided at ALPHA = 0.01 (Bonferroni over rays and
channels where there are several), fixed seeds.
"""
import numpy as np
import pytest
from scipy.stats import norm

import radiometer as rm
from radiometer.loader import write_vol
from refcompare import assert_agrees, assert_clean
from test_media import _rgb, small_light_slab

ALPHA = 0.01


def _medium(path, to_world, accel=True, scale=None, albedo=0.9):
    vol = {"type": "gridvolume", "filename": str(path), "to_world": to_world}
    if not accel:
        vol["accel"] = False
    m = {"type": "heterogeneous", "albedo": albedo, "phase": {"type": "hg", "g": 0.3}, "sigma_t": vol}
    if scale is not None:
        m["scale"] = scale
    return m


def _core_with(medium):
    """The C++ scene of a scene holding `medium` (medium index 0)."""
    d = {"type": "scene",
         "sensor": {"type": "radiancemeter", "origin": [0, 0, 0], "direction": [1, 0, 0], "medium": medium,
                    "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}}
    core = rm.load_dict(d).core()
    assert core.medium_count == 1
    return core


def _random_affine(rng):
    """A random rotation x per-axis scale x shear plus a translation (maps
    the unit cube to a parallelepiped)."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    a = q @ np.diag(rng.uniform(0.5, 3.0, 3)) @ (np.eye(3) + np.triu(rng.uniform(-0.3, 0.3, (3, 3)), 1))
    m = np.eye(4)
    m[:3, :3] = a
    m[:3, 3] = rng.uniform(-2, 2, 3)
    return m


def _sparse(rng, shape, channels, spikes, spike=100.0, base=0.0):
    g = np.full(tuple(shape) + (channels,), base, np.float32)
    for _ in range(spikes):
        idx = tuple(int(rng.integers(0, n)) for n in shape)
        g[idx] = rng.uniform(0.2, 1.0, channels) * spike
    return g


GRIDS = {
    # (nz, ny, nx), channels, spikes, base
    "stress_like_8": ((8, 8, 8), 3, 12, 0.0),
    "odd_37x5x20": ((20, 5, 37), 3, 9, 0.05),  # 37 / 16, 5 / 16 and 20 / 16 voxels per cell: cells cut voxels
    "mono_40": ((40, 40, 40), 1, 30, 0.0),
    "thin_1x3x50": ((50, 3, 1), 3, 4, 0.5),
}


@pytest.mark.parametrize("name", sorted(GRIDS))
def test_majorant_grid_bounds_sigma_t(tmp_path, name):
    shape, ch, spikes, base = GRIDS[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    g = _sparse(rng, shape, ch, spikes, base=base)
    write_vol(tmp_path / "g.vol", g)
    m = _random_affine(rng)
    core = _core_with(_medium(tmp_path / "g.vol", m, scale=1.7))
    assert core.medium_has_majorant_grid(0)
    nz, ny, nx = shape
    res = np.where(np.array([nx, ny, nz]) == 1, 1, 16)
    # Uniform points in the unit cube, and points within 1e-5 of a cell
    # border (on either side) along a random axis.
    u = rng.uniform(0, 1, (200000, 3))
    v = rng.uniform(0, 1, (200000, 3))
    ax = rng.integers(0, 3, len(v))
    k = rng.integers(0, res[ax] + 1)
    v[np.arange(len(v)), ax] = np.clip(k / res[ax] + rng.uniform(-1e-5, 1e-5, len(v)), 0, 1)
    local = np.concatenate([u, v])
    world = local @ m[:3, :3].T + m[:3, 3]
    st = core.medium_sigma_t(0, world)
    mj = core.medium_majorant(0, world)
    bad = np.argwhere(st > mj)
    assert len(bad) == 0, f"{len(bad)} violations, first at local {local[bad[0][0]]}: {st[bad[0][0]]} > {mj[bad[0][0]]}"
    # Useful: the global majorant is scale x the largest voxel; for these
    # sparse grids most of the volume has a far lower local one.
    glob = 1.7 * g.reshape(-1, ch).max(axis=0)
    glob = np.broadcast_to(glob, (3,)) if ch == 1 else glob
    frac = float(np.mean(mj[: len(u)].max(axis=1) < 0.5 * glob.max()))
    assert frac > 0.3, f"only {frac:.2f} of the volume below half the global majorant"
    # accel = false: no majorant grid, the global majorant everywhere.
    core0 = _core_with(_medium(tmp_path / "g.vol", m, accel=False, scale=1.7))
    assert not core0.medium_has_majorant_grid(0)
    assert np.allclose(core0.medium_majorant(0, world[:10]), glob, rtol=1e-6)


# -- ratio tracking against exact transmittance --------------------------------


def _lookup(g, local):
    """Grid::eval in numpy: trilinear over voxel centres (i + 0.5) / n,
    clamped at the border; g (nz, ny, nx, ch), local (N, 3) -> (N, ch)."""
    nz, ny, nx, _ = g.shape
    n = np.array([nx, ny, nz], float)
    f = np.clip(local * n - 0.5, -1.0, n)
    f0 = np.floor(f)
    t = f - f0
    i0 = f0.astype(int)
    out = 0.0
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                ix = np.clip(i0[:, 0] + dx, 0, nx - 1)
                iy = np.clip(i0[:, 1] + dy, 0, ny - 1)
                iz = np.clip(i0[:, 2] + dz, 0, nz - 1)
                w = ((t[:, 0] if dx else 1 - t[:, 0]) * (t[:, 1] if dy else 1 - t[:, 1])
                     * (t[:, 2] if dz else 1 - t[:, 2]))
                out = out + w[:, None] * g[iz, iy, ix]
    return out


def _exact_optical_depth(g, m, o, d, t1):
    """int_0^t1 sigma_t(o + d t) dt inside the grid's box (vacuum outside):
    3-point Gauss-Legendre between the parameters where the ray crosses a
    voxel-centre plane (the lookup is a cubic in t between them)."""
    minv = np.linalg.inv(m)
    lo = minv[:3, :3] @ o + minv[:3, 3]
    ld = minv[:3, :3] @ d
    a, b = 0.0, t1
    for k in range(3):
        if ld[k] == 0:
            if not 0 <= lo[k] <= 1:
                return np.zeros(g.shape[-1])
            continue
        ta, tb = sorted(((0 - lo[k]) / ld[k], (1 - lo[k]) / ld[k]))
        a, b = max(a, ta), min(b, tb)
    if not a < b:
        return np.zeros(g.shape[-1])
    nz, ny, nx, _ = g.shape
    n = np.array([nx, ny, nz], float)
    cuts = [a, b]
    for k in range(3):
        if ld[k] == 0:
            continue
        planes = (np.arange(-1, n[k] + 1) + 0.5) / n[k]  # voxel centres, and the clamp planes
        ts = (planes - lo[k]) / ld[k]
        cuts.extend(ts[(ts > a) & (ts < b)])
    cuts = np.unique(cuts)
    x, w = np.polynomial.legendre.leggauss(3)
    t0, t1_ = cuts[:-1], cuts[1:]
    ts = (0.5 * (t1_ - t0)[:, None] * x[None, :] + 0.5 * (t1_ + t0)[:, None]).ravel()
    ws = (0.5 * (t1_ - t0)[:, None] * w[None, :]).ravel()
    pts = lo[None, :] + ts[:, None] * ld[None, :]
    return (ws[:, None] * _lookup(g, pts)).sum(axis=0)


def test_ratio_tracking_matches_exact_transmittance(tmp_path):
    """Random rays (fixed seed) through a sparse 3-channel 12^3 grid (spikes
    up to 60, a faint base, one channel empty in half the spikes) mapped to
    a sheared box: the mean of 20 000 ratio-tracking estimates of each ray's
    transmittance against exp(-tau) from quadrature, with the majorant grid
    and without (accel = false); per ray and channel at ALPHA / (3 x 12),
    and the pooled mean x 1.02 rejected."""
    rng = np.random.default_rng(11)
    g = _sparse(rng, (12, 12, 12), 3, 25, spike=60.0, base=0.02)
    g[::2, ..., 2] = np.minimum(g[::2, ..., 2], 0.02)
    write_vol(tmp_path / "g.vol", g)
    m = np.array([[2.0, 0.3, 0, -1.1], [0, 1.8, 0.2, -0.9], [0.1, 0, 2.2, -1.0], [0, 0, 0, 1]])
    rays = []
    for i in range(12):
        if i % 3 == 2:  # starts and ends inside the box
            o = m[:3, :3] @ rng.uniform(0.2, 0.8, 3) + m[:3, 3]
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            t1 = float(rng.uniform(0.3, 1.0))
        else:  # from outside, through a random point of the box, beyond it
            target = m[:3, :3] @ rng.uniform(0.1, 0.9, 3) + m[:3, 3]
            o = rng.normal(size=3)
            o = 5.0 * o / np.linalg.norm(o)
            d = (target - o) / np.linalg.norm(target - o)
            t1 = 20.0
        rays.append((o, d, t1))
    exact = np.array([np.exp(-_exact_optical_depth(g.astype(np.float64), m, o, d, t1)) for o, d, t1 in rays])
    assert np.sum(exact.min(axis=1) < 0.8) >= 4 and exact.max() > 0.05, exact  # some rays see spikes; not all black
    n = 20000
    for accel in (True, False):
        core = _core_with(_medium(tmp_path / "g.vol", m, accel=accel))
        means, ses = [], []
        for i, (o, d, t1) in enumerate(rays):
            s = core.medium_transmittance_samples(0, o.tolist(), d.tolist(), t1, n, seed=100 + i).astype(np.float64)
            assert np.all(s >= 0) and np.all(np.isfinite(s))
            mean, se = s.mean(axis=0), s.std(axis=0, ddof=1) / np.sqrt(n)
            means.append(mean)
            ses.append(se)
            # Cells of constant sigma_t are exact (residual ratio tracking):
            # a ray through such cells only has (nearly) zero variance; its
            # float error (1e-6 padding, float32 sums) is held to 1e-5.
            tol = np.maximum(se, 1e-5 * exact[i])
            p = 2 * norm.sf(np.abs(mean - exact[i]) / tol)
            assert np.all(p >= ALPHA / (3 * len(rays))), f"accel={accel} ray {i}: {mean} +- {se} vs exact {exact[i]}"
        means, ses = np.array(means), np.array(ses)
        tot, tot_se, ex = means.sum(), np.sqrt((ses ** 2).sum()), exact.sum()
        assert 2 * norm.sf(abs(tot - ex) / tot_se) >= ALPHA, f"accel={accel}: pooled {tot} +- {tot_se} vs {ex}"
        assert 2 * norm.sf(abs(tot - 1.02 * ex) / tot_se) < ALPHA, f"accel={accel}: 2 % undetected (se {tot_se / ex})"


# -- estimators: majorant grid against the global majorant ------------------------


def _sparse_slab(tmp_path, accel):
    """small_light_slab (16 x 16) with a sparse scattering grid medium in the
    slab's box (8^3, three channels, eight spikes of up to 40, a soft
    constant 0.3 base, the third channel's spikes 0) and a point light."""
    rng = np.random.default_rng(5)
    g = _sparse(rng, (8, 8, 8), 3, 8, spike=40.0, base=0.3)
    g[..., 2] = np.minimum(g[..., 2], 0.3)
    path = tmp_path / "s.vol"
    if not path.exists():
        write_vol(path, g)
    cube = np.array([[2, 0, 0, -1], [0, 2, 0, -1], [0, 0, 1, 0], [0, 0, 0, 1]], float)
    d = small_light_slab(_medium(path, cube, accel=accel, albedo=0.8))
    d["sun"] = {"type": "point", "position": [0.5, 0.3, 1.5], "intensity": _rgb(2.0)}
    return rm.load_dict(d)


@pytest.mark.parametrize("estimator,spp,power", [("volpath", 512, 1.02), ("ptracer", 512, 1.03),
                                                 ("bdpt", 128, 1.03)])
def test_estimators_agree_with_global_majorant(tmp_path, estimator, spp, power):
    from radiometer import _core

    _core.reset_medium_tracking_lookups()
    a = rm.render(_sparse_slab(tmp_path, True), integrator=estimator, spp=spp, seed=1)
    n_grid = _core.medium_tracking_lookups()
    _core.reset_medium_tracking_lookups()
    b = rm.render(_sparse_slab(tmp_path, False), integrator=estimator, spp=spp, seed=2)
    n_global = _core.medium_tracking_lookups()
    # What the grid is for: far fewer tentative collisions (counts, not time).
    assert 0 < n_grid < 0.5 * n_global, (n_grid, n_global)
    assert_clean(a, estimator)
    assert a.stats["nan_samples"] == 0 and a.image.min() >= 0
    assert_agrees(a, b, power, estimator)
