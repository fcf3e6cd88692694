"""radiosity (renderer/estimators/radiosity/): the finite-element estimator
on diffuse scenes. Deterministic checks (no noise: the solver draws no
random numbers; only the display's camera samples and the final gather's
rays do):

- the books balance: emitted = absorbed + escaped + unshot to rounding,
  the unshot part at most `residual` of the emission, and a closed box
  lets nothing escape;
- the closed furnace: the exact constant radiosity pi Le / (1 - rho)
  (and the truncated sum at finite max_depth), per element and in the image;
- the analytic configuration factor (the area_lights scenes): the floor's
  direct radiosity against rho E(x) from the closed-form irradiance at the
  patch centres, to a stated tolerance, with a power check;
- the Cornell box: more patches, less error against the Mitsuba reference
  (the study benchmarks/studies/radiosity_convergence.py measures the slope);
- refusals by name (non-diffuse BSDFs, non-area emitters, bad parameters);
- stability: degenerate and sliver triangles, coplanar and touching
  shapes, an emitter inside a closed box: finite, non-negative; the same
  bytes whatever the thread count.
Every estimator against the canonical scenes: tests/test_estimator_matrix.py."""
from __future__ import annotations

import math

import numpy as np
import pytest

import radiometer as rm
from radiometer import _core
from radiometer.reference_scenes import references, registry
from radiometer.reference_scenes.area_lights import analytic as al
from radiometer.render import _core_integrator, _integrator_desc

from refcompare import assert_clean, assert_same_bytes_whatever_threads
from test_bdpt import AREA, CORNELL, GLOSSY, _rgb, small_room, small_scene

FURNACE = registry.get("furnace").xml


def solve(scene, threads=1, **params):
    spec = _integrator_desc({"type": "radiosity", **params}, scene.desc.integrator)
    return _core.radiosity_solution(scene.core(), _core_integrator(spec), threads)


def _balance(st):
    return abs(st["emitted_power"] - (st["absorbed_power"] + st["escaped_power"] + st["unshot_power"]))


@pytest.mark.parametrize("max_depth", [-1, 4])
def test_energy_balance(max_depth):
    """Open room (floor, wall, cube, a rectangle light): every watt emitted
    is absorbed, escapes or is still unshot, to double rounding (1e-9
    relative); progressive shooting stops at the stated residual."""
    scene = small_scene(AREA, res=8)
    st = solve(scene, max_patches=300, residual=1e-3, max_depth=max_depth)["stats"]
    assert st["emitted_power"] > 0
    assert _balance(st) <= 1e-9 * st["emitted_power"], st
    assert st["escaped_power"] > 0.05 * st["emitted_power"], st  # an open room loses light
    assert st["absorbed_power"] > 0.05 * st["emitted_power"], st
    if max_depth < 0:
        assert st["residual"] <= 1e-3 and st["unshot_power"] <= 1e-3 * st["emitted_power"], st


def test_escaped_power_matches_analytic_rect():
    """The books against an independent answer: under the rectangle light
    at max_depth 2 (one shot) the power escaping is the emitted power times
    1 - F(light -> floor), F = 0.9431 from Lambert's closed form integrated
    over the 6 x 6 floor (60 x 60 Gauss-Legendre nodes per unit cell); the
    floor absorbs 1 - rho of the rest and keeps rho unshot. Measured
    relative error of the escaped power -7.7e-4, -3.4e-4, -1.2e-4 at
    max_patches 150, 600, 2400; bound 2e-3 at 600, and a 1 % error in F is
    rejected."""
    xml = al.RECT_XML
    p = al.scene_params(xml)
    scene = rm.load_file(xml, res=8)
    st = solve(scene, max_patches=600, max_depth=2)["stats"]
    verts = al.rect_vertices(float(p["a"]), float(p["b"]), float(p["angle"]), float(p["lx"]), float(p["ly"]),
                             float(p["h"]))
    t, w = np.polynomial.legendre.leggauss(60)
    nodes = np.concatenate([0.5 * (t + 1) + k for k in range(-3, 3)])  # 6 unit cells of 60 nodes
    wts = np.tile(0.5 * w, 6)
    X, Y = np.meshgrid(nodes, nodes, indexing="ij")
    e_int = float((al.polygon_irradiance(X, Y, verts) * wts[:, None] * wts[None, :]).sum())
    F = e_int / (math.pi * 4 * float(p["a"]) * float(p["b"]))
    want = st["emitted_power"] * (1 - F)
    assert abs(st["escaped_power"] / want - 1) < 2e-3, (st["escaped_power"], want, F)
    want_off = st["emitted_power"] * (1 - 1.01 * F)
    assert abs(st["escaped_power"] / want_off - 1) > 2e-3
    assert _balance(st) <= 1e-9 * st["emitted_power"], st


def test_closed_box_lets_nothing_escape():
    """A sphere light inside a closed two-sided white cube: no power
    escapes, the books balance, every radiosity is finite; the camera
    outside sees the (dark) box."""
    d = small_room(AREA, res=8)
    d["light"] = {"type": "sphere", "center": [0.0, 0.0, 1.3], "radius": 0.1,
                  "emitter": {"type": "area", "radiance": _rgb(5.0)}}
    d["box"] = {"type": "cube", "to_world": np.diag([0.5, 0.5, 0.5, 1.0]) + np.array(
        [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1.3], [0, 0, 0, 0]]),
        "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb(0.5)}}}
    scene = rm.load_dict(d)
    sol = solve(scene, max_patches=400, residual=1e-4)
    st = sol["stats"]
    assert st["escaped_power"] <= 1e-9 * st["emitted_power"], st
    assert _balance(st) <= 1e-9 * st["emitted_power"], st
    for k in ("emitted", "direct", "indirect"):
        assert np.all(np.isfinite(sol[k])) and np.all(sol[k] >= 0), k
    res = rm.render(scene, integrator={"type": "radiosity", "max_patches": 400}, spp=2, seed=1)
    assert_clean(res, "closed box")


@pytest.mark.parametrize("max_depth,exact", [(-1, 1.0), (3, 0.875)])
def test_furnace_exact_constant_radiosity(max_depth, exact):
    """Closed furnace (le = rho = 0.5): B = pi Le sum_k rho^k on every
    inner element, so L = B / pi = 1 (unbounded; residual 1e-7) or 0.875
    (max_depth 3); per element to 1e-5 and in the patch, vertex and gather
    images to 1e-4 (float image rounding; the vertex display averages equal
    values and interpolates with weights summing to 1, so it keeps the
    constant). Power: 0.1 % off would be rejected."""
    scene = rm.load_file(FURNACE, res=8, max_depth=max_depth)
    sol = solve(scene, max_patches=200, residual=1e-7, max_depth=max_depth)
    inner = slice(0, None, 2)  # front sides (flip_normals: inward)
    L = (sol["emitted"][inner] + sol["direct"][inner] + sol["indirect"][inner]) / math.pi
    err = np.abs(L / exact - 1).max()
    assert err < 1e-5, f"furnace radiosity off by {err:.2e} relative"
    assert np.abs(L / (exact * 1.001) - 1).min() > 1e-5
    for display in ("patch", "vertex", "gather"):
        res = rm.render(scene, integrator={"type": "radiosity", "max_patches": 200, "residual": 1e-7,
                                           "max_depth": max_depth, "display": display}, spp=2, seed=3)
        assert_clean(res, display)
        assert np.abs(res.image / exact - 1).max() < 1e-4, (display, res.image.min(), res.image.max())
        assert np.abs(res.image / (exact * 1.001) - 1).min() > 1e-4


def _triangle_average(func, tri, m=12):
    """The mean of func(x, y) over each triangle (T, 3, 3): the centroids
    of its m^2 similar sub-triangles (midpoint rule, error O(1 / m^2))."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    pts = []
    for i in range(m):
        for j in range(m - i):
            pts.append(((i + 1 / 3) / m, (j + 1 / 3) / m))
            if i + j <= m - 2:
                pts.append(((i + 2 / 3) / m, (j + 2 / 3) / m))
    u = np.array(pts)
    p = a[:, None, :] + u[None, :, 0, None] * (b - a)[:, None, :] + u[None, :, 1, None] * (c - a)[:, None, :]
    return func(p[..., 0], p[..., 1]).mean(axis=1)


def _floor_direct(light, max_patches, ff_samples=2):
    """(radiosity's direct radiosity on the floor patches, rho E averaged
    over each patch from the closed form)."""
    xml = al.RECT_XML if light == "rect" else al.DISK_XML
    p = al.scene_params(xml)
    sol = solve(rm.load_file(xml, res=8), max_patches=max_patches, ff_samples=ff_samples, residual=1e-6)
    c, n = sol["centre"], sol["normal"]
    floor = (np.abs(c[:, 2]) < 1e-6) & (n[:, 2] > 0.99)
    tri = sol["corners"][floor].reshape(-1, 4, 3)[:, :3]
    if light == "rect":
        verts = al.rect_vertices(float(p["a"]), float(p["b"]), float(p["angle"]), float(p["lx"]), float(p["ly"]),
                                 float(p["h"]))
        e = _triangle_average(lambda x, y: al.polygon_irradiance(x, y, verts), tri)
    else:
        e = _triangle_average(lambda x, y: al.disk_irradiance(x, y, float(p["lx"]), float(p["ly"]),
                                                                float(p["radius"]), float(p["h"])), tri)
    exact = al._rgb(p["rho"])[None, :] * al._rgb(p["radiance"])[None, :] * e[:, None]
    idx = np.flatnonzero(floor) * 2
    assert sol["indirect"][idx].max() == 0.0  # the black light reflects nothing back
    return sol["direct"][idx], exact


# The floor's direct radiosity per patch against the closed-form irradiance
# (Lambert's polygon formula, the disk's configuration factor) averaged
# over the patch, at the default ff_samples = 2: the discretisation error
# of the light's and the floor's patches. Measured max relative error over
# the floor patches (2026-12-02): rect 4.33e-3 at max_patches 600, 1.61e-3
# at 2400; disk 5.11e-3 and 1.53e-3 (ff_samples 1: rect 1.8e-2, disk
# 2.0e-2 at 600). Bounds: 1.5 x the measurement at 600, and the finer mesh
# at least 2 x better (4 x the patches; measured 2.7 x and 3.3 x).
CONFIG_TOL = {"rect": 6.5e-3, "disk": 7.5e-3}


@pytest.mark.parametrize("light", ["rect", "disk"])
def test_configuration_factor_matches_analytic(light):
    got, exact = _floor_direct(light, 600)
    rel = np.abs(got / exact - 1).max()
    tol = CONFIG_TOL[light]
    assert rel < tol, f"{light}: max relative error {rel:.2e} (tol {tol:g})"
    assert np.abs(got / (exact * (1 + 2 * tol)) - 1).max() > tol  # power: a 2 x tol bias is seen
    got_f, exact_f = _floor_direct(light, 2400)
    rel_f = np.abs(got_f / exact_f - 1).max()
    assert rel_f < rel / 2, f"{light}: 4 x the patches gave {rel_f:.2e}, from {rel:.2e}"


# The vertex display against the exact image of the area_lights scenes
# (max_depth 2: direct light only; res 32, 16 spp, box filter): relative L1
# error over the image and the maximum relative error over pixels, patch and
# vertex display on the same mesh (600 patches). Measured 2026-12-03:
#   rect: L1 patch 0.0944, vertex 0.0804 (ratio 0.85); max 0.629, 0.241 (0.38)
#   disk: L1 patch 0.0807, vertex 0.0682 (ratio 0.85); max 0.443, 0.190 (0.43)
# Bounds: L1 ratio < 0.92, max ratio < 0.55. Power: the vertex image scaled
# by 0.97 fails the L1 bound (measured ratios 1.01 and 1.05).
VERTEX_L1_RATIO, VERTEX_MAX_RATIO = 0.92, 0.55


def _area_light_display_error(light, display, max_patches):
    xml = al.RECT_XML if light == "rect" else al.DISK_XML
    scene = rm.load_file(xml, res=32)
    ref, _ = al.reference(light, res=32)
    res = rm.render(scene, integrator={"type": "radiosity", "display": display, "max_patches": max_patches,
                                       "max_depth": 2}, spp=16, seed=4)
    assert_clean(res, f"{light} {display}")
    img = res.image.astype(np.float64)
    return float(np.abs(img - ref).mean() / ref.mean()), float((np.abs(img - ref) / ref).max()), img, ref


@pytest.mark.parametrize("light", ["rect", "disk"])
def test_vertex_display_beats_patch_display(light):
    """On the analytic area-light scenes the vertex-interpolated display
    is closer to the exact image than the per-patch one on the same mesh
    (figures above VERTEX_L1_RATIO): a little in L1 (the averaging to the
    vertices flattens the peak under the light), much in the worst pixel
    (no facets). Power: 3 % too dark is rejected."""
    l1_p, max_p, _, _ = _area_light_display_error(light, "patch", 600)
    l1_v, max_v, img, ref = _area_light_display_error(light, "vertex", 600)
    assert l1_v < VERTEX_L1_RATIO * l1_p, (light, l1_v, l1_p)
    assert max_v < VERTEX_MAX_RATIO * max_p, (light, max_v, max_p)
    assert float(np.abs(0.97 * img - ref).mean() / ref.mean()) > VERTEX_L1_RATIO * l1_p


def _cells(extent, size):
    return max(1, math.ceil(extent / size - 1e-9))


def test_vertex_display_shares_vertices():
    """The vertices of the vertex display, counted (res.stats["vertices"]):
    a rectangle (two triangles, each cut n x n, n from the diagonal) has
    (n + 1)^2, its diagonal shared; a sphere of nz bands and nphi sectors
    (nz - 1) nphi + 2 (the seam at phi = 2 pi and each pole one vertex). A
    vertex shared across the rectangle and the sphere, or a seam not
    merged, changes the count."""
    scene = rm.load_file(FURNACE, res=8)
    st = rm.render(scene, integrator={"type": "radiosity", "max_patches": 200, "display": "vertex"}, spp=1,
                   seed=1).stats
    size = st["patch_size"]
    nz, nphi = _cells(2.0, size), max(3, _cells(2 * math.pi, size))
    assert st["patches"] == nz * nphi, (st["patches"], nz, nphi)
    assert st["vertices"] == (nz - 1) * nphi + 2, (st["vertices"], nz, nphi)
    xml = al.RECT_XML
    st = rm.render(rm.load_file(xml, res=8), integrator={"type": "radiosity", "max_patches": 300, "display": "vertex",
                                                          "max_depth": 2}, spp=1, seed=1).stats
    size = st["patch_size"]
    p = al.scene_params(xml)
    n_floor = _cells(math.hypot(6.0, 6.0), size)
    n_light = _cells(math.hypot(2 * float(p["a"]), 2 * float(p["b"])), size)
    assert st["patches"] == 2 * n_floor**2 + 2 * n_light**2, st["patches"]
    assert st["vertices"] == (n_floor + 1) ** 2 + (n_light + 1) ** 2, (st["vertices"], n_floor, n_light)
    assert "vertices" not in rm.render(scene, integrator={"type": "radiosity", "max_patches": 200,
                                                          "display": "patch"}, spp=1, seed=1).stats


def test_display_leaves_the_solution_alone():
    """The display reads the solution and never changes it: the books
    (emitted, absorbed, escaped, unshot) are the same bytes under every
    display."""
    scene = small_scene(AREA, res=8)
    keys = ("emitted_power", "absorbed_power", "escaped_power", "unshot_power", "shots", "patches")
    books = []
    for display in ("patch", "vertex", "gather"):
        st = rm.render(scene, integrator={"type": "radiosity", "max_patches": 150, "display": display}, spp=1,
                       seed=1).stats
        books.append(tuple(float(st[k]) for k in keys))
        assert _balance(st) <= 1e-9 * st["emitted_power"], st
    assert books[0] == books[1] == books[2], books


def _cornell_error(max_patches, display="patch"):
    """Relative L1 error of the per-patch display against the Mitsuba
    reference, without the light and a 2-pixel border (its edge is
    camera-sample noise under the gaussian filter)."""
    params = dict(registry.get("cornell_box").fixed_params)
    scene = rm.load_file(CORNELL, **params)
    ref = references.reference("cornell_box", params).image.astype(np.float64)
    light = ref.max(axis=2) > 2.0
    for _ in range(2):
        light = light | np.roll(light, 1, 0) | np.roll(light, -1, 0) | np.roll(light, 1, 1) | np.roll(light, -1, 1)
    res = rm.render(scene, integrator={"type": "radiosity", "display": display, "max_patches": max_patches,
                                       "max_depth": params["max_depth"]}, spp=16, seed=2)
    assert_clean(res, f"cornell {max_patches}")
    keep = ~light
    return float(np.abs(res.image - ref)[keep].mean() / ref[keep].mean())


def test_cornell_more_patches_less_error():
    """The per-patch display's error against the Mitsuba reference falls
    as the patch count grows (measured at 64 spp in the study
    benchmarks/studies/radiosity_convergence.py: 0.357 at max_patches 50,
    0.101 at 400; log-log slope -0.57 up to 3200), and so does the vertex
    display's (0.351 and 0.134 at 16 spp)."""
    for display in ("patch", "vertex"):
        coarse, fine = _cornell_error(50, display), _cornell_error(400, display)
        assert fine < 0.8 * coarse, (display, coarse, fine)


def test_refuses_non_diffuse_and_non_area():
    with pytest.raises(ValueError, match="radiosity.*shape .*glass.*not diffuse"):
        rm.render(small_scene(AREA, res=8, extra=GLOSSY), integrator={"type": "radiosity"}, spp=1)
    point = {"type": "point", "position": [0.6, -0.5, 1.5], "intensity": _rgb(3.0)}
    with pytest.raises(ValueError, match="radiosity.*emitter.*not an area emitter|radiosity.*only area"):
        rm.render(small_scene(point, res=8), integrator={"type": "radiosity"}, spp=1)
    for bad in ({"display": "vertices"}, {"max_patches": 0}, {"residual": 0.0}, {"ff_samples": 9}):
        with pytest.raises(rm.SceneError, match=f"radiosity.*{next(iter(bad))}"):
            rm.render(small_scene(AREA, res=8), integrator={"type": "radiosity", **bad}, spp=1)
    with pytest.raises(ValueError, match="patch_size.*max_patches"):
        rm.render(small_scene(AREA, res=8), integrator={"type": "radiosity", "patch_size": 1e-3}, spp=1)


def _degenerate_scene(tmp_path):
    d = small_room(AREA, res=16)
    # A mesh with a zero-area triangle (repeated vertex), a collinear one and
    # a 1e-4-wide sliver; a rectangle coplanar with the floor overlapping it;
    # a cube resting on the floor (touching).
    pos = np.array([[-0.5, 0.5, 0.3], [0.5, 0.5, 0.3], [0.5, 0.5, 0.3], [0, 0.5, 0.3], [1.0, 0.5, 0.3],
                    [-0.9, 0.2, 0.4], [0.9, 0.2, 0.4], [-0.9, 0.2001, 0.4]], float)
    idx = np.array([[0, 1, 2], [0, 3, 1], [5, 6, 7], [0, 1, 4]], np.uint32)
    obj = tmp_path / "junk.obj"
    obj.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in pos) +
                   "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in idx))
    d["junk"] = {"type": "obj", "filename": str(obj), "face_normals": True,
                 "bsdf": {"type": "diffuse", "reflectance": _rgb(0.7)}}
    d["coplanar"] = {"type": "rectangle", "to_world": np.diag([0.6, 0.6, 1.0, 1.0]),
                     "bsdf": {"type": "diffuse", "reflectance": _rgb(0.3)}}
    d["resting"] = {"type": "cube", "to_world": np.array([[0.2, 0, 0, -0.7], [0, 0.2, 0, 0.6], [0, 0, 0.2, 0.2],
                                                          [0, 0, 0, 1.0]]),
                    "bsdf": {"type": "diffuse", "reflectance": _rgb(0.6)}}
    return rm.load_dict(d)


@pytest.mark.parametrize("display", ["patch", "vertex", "gather"])
def test_degenerate_and_touching_shapes_are_finite(display, tmp_path):
    scene = _degenerate_scene(tmp_path)
    sol = solve(scene, max_patches=500)
    for k in ("emitted", "direct", "indirect", "area"):
        assert np.all(np.isfinite(sol[k])) and np.all(sol[k] >= 0), k
    assert _balance(sol["stats"]) <= 1e-9 * sol["stats"]["emitted_power"]
    res = rm.render(scene, integrator={"type": "radiosity", "max_patches": 500, "display": display}, spp=2, seed=1)
    assert_clean(res, display)
    assert res.image.mean() > 0


@pytest.mark.parametrize("display", ["patch", "vertex", "gather"])
def test_same_bytes_whatever_threads(display):
    scene = small_scene(AREA, res=8)
    assert_same_bytes_whatever_threads(scene, {"type": "radiosity", "max_patches": 150, "display": display}, 2)
    a, b = (solve(scene, threads=t, max_patches=150) for t in (1, 3))
    for k in ("direct", "indirect"):
        assert a[k].tobytes() == b[k].tobytes(), k


def test_effects_sum_and_stats():
    scene = small_scene(AREA, res=8)
    res = rm.render(scene, integrator={"type": "radiosity", "max_patches": 150}, spp=2, seed=1)
    np.testing.assert_allclose(sum(res.effects.values()), res.image, rtol=1e-5, atol=1e-7)
    for k in ("caustic", "specular", "volume", "subsurface"):
        assert not res.effects[k].any(), k
    assert res.effects["indirect"].mean() > 0 and res.effects["direct"].mean() > 0
    for k in ("patches", "shots", "residual", "emitted_power", "absorbed_power", "escaped_power", "unshot_power"):
        assert k in res.stats, k


@pytest.mark.parametrize("radius, bound", [(0.5, 0.25), (0.1, 0.05)])
def test_small_sphere_light_keeps_its_emission(radius, bound):
    """A sphere light smaller than half the patch size: its cells were one
    band from pole to pole, whose polygon is a segment, and every factor
    estimated against it was 0, so all its emission escaped (absorbed 0;
    found by the hierarchical mode's tests). Now at least two bands: at
    max_patches 100 (patch size 1.41) the absorbed fraction is within
    `bound` of the one at 1600 patches (measured 2026-12-04: radius 0.5
    0.254 against 0.297, radius 0.1 0.2906 against 0.2958) and the books
    balance."""
    d = small_room(AREA, res=8)
    d["light"] = {"type": "sphere", "center": [0.0, 0.0, 1.3], "radius": radius,
                  "emitter": {"type": "area", "radiance": _rgb(5.0)}}
    coarse, fine = (solve(rm.load_dict(d), max_patches=n, residual=1e-4)["stats"] for n in (100, 1600))
    assert coarse["patch_size"] > 2 * radius, coarse["patch_size"]
    got, want = (s["absorbed_power"] / s["emitted_power"] for s in (coarse, fine))
    assert abs(got / want - 1) < bound, (got, want)
    assert _balance(coarse) <= 1e-9 * coarse["emitted_power"], coarse
