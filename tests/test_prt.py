"""`prt`, precomputed radiance transfer (renderer/estimators/prt.cpp; Sloan,
Kautz and Snyder 2002), and its spherical harmonics (renderer/core/sh.h).

- The SH basis against scipy.special.sph_harm_y (an independent
  implementation), orthonormal under the projection quadrature.
- Projection and reconstruction of known lighting: constant, directional
  (E y_i(d)), an envmap of a band-limited function (its coefficients from
  numpy quadrature of the function itself) reconstructed pointwise.
- Rotation: an envmap rotated by its to_world has the coefficients D(R) L
  (D from scipy's SH by quadrature), band energies preserved; a wrong
  rotation is told apart (power).
- Ramamoorthi and Hanrahan 2001's nine-coefficient irradiance (their eq. 13)
  against quadrature of the lighting, and prt's unshadowed transfer on a
  plane against it (z-test at ALPHA, power check).
- Shadowed transfer under a constant environment (exact at one band) equals
  the ambient occlusion `path` renders at max_depth 2 (blocked z-test at
  ALPHA, 3 % power check); unshadowed under a constant is exactly albedo x L.
- Low-frequency lighting: prt at k = 1 .. 8 bands against `path`, each pixel
  within the a-priori band-limit bound ||T|| ||L - L_k|| plus noise
  (Bonferroni over pixels and bands at ALPHA); at 8 bands the blocked
  z-test passes and rejects a 3 % bias; the error against k is printed.
- Relighting from the kept transfer equals a new render; threads 1, 2, 3
  give the same bytes; degenerate and enclosed geometry stay finite;
  refusals name the emitter, shape or parameter.

ALPHA = 0.01 for every statistical test (refcompare's blocked z-test splits
it over its views). 8 to 13 s on 2 shared cores (42 s at load 14).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from refcompare import ALPHA, assert_clean, assert_same_bytes_whatever_threads, blocked_z, lookat
from scipy import special
from scipy import stats as st

import radiometer as rm
from radiometer import _core
from radiometer.prt import Transfer, latlong_envmap

STRESS = Path(__file__).resolve().parents[1] / "reference_scenes" / "stress"
ALBEDO_FLOOR = [0.7, 0.6, 0.5]
ALBEDO_BALL = [0.3, 0.6, 0.8]


# --- independent SH: scipy's complex harmonics made real ---------------------


def real_sh_scipy(dirs, bands):
    """Real orthonormal SH (core/sh.h's convention: no Condon-Shortley
    phase, m < 0 the sine terms) from scipy's complex ones."""
    d = np.asarray(dirs, np.float64)
    theta = np.arccos(np.clip(d[:, 2], -1, 1))
    phi = np.arctan2(d[:, 1], d[:, 0])
    out = np.zeros((len(d), bands * bands))
    for deg in range(bands):
        for m in range(-deg, deg + 1):
            y = special.sph_harm_y(deg, abs(m), theta, phi)
            if m > 0:
                v = math.sqrt(2) * (-1) ** m * y.real
            elif m < 0:
                v = math.sqrt(2) * (-1) ** m * y.imag
            else:
                v = y.real
            out[:, deg * (deg + 1) + m] = v
    return out


def gauss_sphere(n):
    """numpy's Gauss-Legendre nodes in cos theta times the midpoint rule in
    phi: directions (N, 3) and weights, independent of core/sh.cpp's."""
    z, wz = np.polynomial.legendre.leggauss(n)
    phi = (np.arange(2 * n) + 0.5) * np.pi / n
    Z, P = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - Z ** 2)
    d = np.stack([s * np.cos(P), s * np.sin(P), Z], -1).reshape(-1, 3)
    w = (wz[:, None] * np.full(2 * n, np.pi / n)[None, :]).reshape(-1)
    return d, w


def random_dirs(n, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# --- lighting -----------------------------------------------------------------


def envmap_file(path, fn):
    return Path(latlong_envmap(path, fn))


def quadratic(d):
    """Band-limited to l <= 2: a colour per channel of 1, x, y, z, and z^2, xy."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([1.0 + 0.3 * x + 0.2 * z * z, 0.8 + 0.4 * y + 0.3 * x * y, 0.6 - 0.3 * z + 0.2 * x * z], -1)


SUN = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])


def lobe(d, k=2.0):
    """Smooth but not band-limited: a sky of exp(k (w.s - 1)) lobes."""
    c = d @ SUN
    return np.stack([0.2 + 1.5 * np.exp(k * (c - 1)), 0.3 + 1.2 * np.exp(k * (c - 1)), 0.5 + 0.5 * np.exp(
        0.5 * k * (d[:, 1] - 1))], -1)


def light_scene(light):
    return rm.load_dict({"type": "scene", "light": light})


def project(light, bands, env_samples=128):
    return np.asarray(_core.sh_project(light_scene(light).core(), bands, env_samples), np.float64)


def coeffs_by_quadrature(fn, bands, n=96):
    d, w = gauss_sphere(n)
    return real_sh_scipy(d, bands).T @ (fn(d) * w[:, None])


# --- scenes -------------------------------------------------------------------


def ball_on_floor(light, res=24, **extra):
    d = {"type": "scene", "light": light,
         "floor": {"type": "rectangle", "to_world": np.diag([2.0, 2.0, 1.0, 1.0]),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": ALBEDO_FLOOR}}},
         "ball": {"type": "sphere", "center": [0.0, 0.0, 0.5], "radius": 0.5,
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": ALBEDO_BALL}}},
         "cam": {"type": "perspective", "fov": 45, "to_world": lookat([0, -3.2, 2.4], [0, 0, 0.3], (0, 0, 1)),
                 "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}}
    d.update(extra)
    return rm.load_dict(d)


def prt(bands=3, transfer="interreflected", **kw):
    return {"type": "prt", "bands": bands, "transfer": transfer, **kw}


# --- the basis ----------------------------------------------------------------


def test_sh_basis_matches_scipy_and_is_orthonormal():
    dirs = random_dirs(400, 1)
    dirs = np.vstack([dirs, [[0, 0, 1], [0, 0, -1], [1, 0, 0]]])  # the poles too
    ours = _core.sh_eval(dirs, 12)
    ref = real_sh_scipy(dirs, 12)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    # R&H 2001's constants (their eq. 3) fix the sign convention.
    x, y, z = dirs[:5].T
    np.testing.assert_allclose(ours[:5, 1:4], 0.488603 * np.stack([y, z, x], -1), atol=1e-6)
    np.testing.assert_allclose(ours[:5, 8], 0.546274 * (x * x - y * y), atol=1e-6)
    # The quadrature prt projects with integrates products of bands < n exactly.
    d, w = _core.sphere_quadrature(8)
    Y = _core.sh_eval(d, 8)
    np.testing.assert_allclose((Y * w[:, None]).T @ Y, np.eye(64), atol=1e-10)
    assert abs(w.sum() - 4 * np.pi) < 1e-12


def test_projection_of_constant_directional_and_known_envmap(tmp_path):
    c = np.array([0.3, 0.5, 0.7])
    L = project({"type": "constant", "radiance": {"type": "rgb", "value": list(c)}}, 4)
    np.testing.assert_allclose(L[0], c * math.sqrt(4 * np.pi), rtol=1e-6)
    np.testing.assert_allclose(L[1:], 0, atol=1e-6)
    # Directional: radiance E delta(w - d), d = -direction (towards the light).
    E, direction = np.array([2.0, 1.0, 0.5]), np.array([0.2, -0.5, -0.8])
    L = project({"type": "directional", "direction": list(direction), "irradiance": {"type": "rgb", "value": list(E)}},
                5)
    d = -direction / np.linalg.norm(direction)
    np.testing.assert_allclose(L, real_sh_scipy(d[None], 5)[0][:, None] * E[None], rtol=1e-5, atol=1e-6)
    # A band-limited envmap: coefficients of the function, zero above l = 2,
    # and the three-band reconstruction equals it pointwise.
    path = envmap_file(tmp_path / "quad.exr", quadratic)
    L = project({"type": "envmap", "filename": str(path)}, 5)
    ref = coeffs_by_quadrature(quadratic, 5)
    np.testing.assert_allclose(L, ref, atol=2e-4)
    assert np.abs(L[9:]).max() < 2e-4
    dirs = random_dirs(200, 2)
    recon = _core.sh_eval(dirs, 3) @ L[:9]
    np.testing.assert_allclose(recon, quadratic(dirs), atol=1e-3)
    # Power: one band too few leaves an error far above that tolerance.
    assert np.abs(_core.sh_eval(dirs, 2) @ L[:4] - quadratic(dirs)).max() > 0.02


def rotation(axis, deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(deg)
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * (K @ K)


def sh_rotation(R, bands):
    """D[i, j] = int y_i(R w) y_j(w) dw (scipy SH, numpy quadrature): the
    coefficients of L(R^-1 w) are D L."""
    d, w = gauss_sphere(2 * bands + 4)
    return real_sh_scipy(d @ R.T, bands).T @ (real_sh_scipy(d, bands) * w[:, None])


def test_rotating_the_lighting_rotates_the_coefficients(tmp_path):
    bands = 6
    path = envmap_file(tmp_path / "lobe.exr", lobe)
    R = rotation([0.6, 0.0, 0.8], 70)
    M = np.eye(4)
    M[:3, :3] = R
    L = project({"type": "envmap", "filename": str(path)}, bands)
    LR = project({"type": "envmap", "filename": str(path), "to_world": M}, bands)
    D = sh_rotation(R, bands)
    np.testing.assert_allclose(LR, D @ L, atol=2e-4)
    # Band energies sum_m L_lm^2 are rotation invariant.
    for deg in range(bands):
        b = slice(deg * deg, (deg + 1) ** 2)
        np.testing.assert_allclose((LR[b] ** 2).sum(0), (L[b] ** 2).sum(0), rtol=1e-3, atol=1e-7)
    # Power: the inverse rotation is told apart.
    assert np.abs(LR - sh_rotation(R.T, bands) @ L).max() > 100 * 2e-4
    # The directional light rotates exactly.
    dl = {"type": "directional", "direction": [0.0, 0.0, -1.0]}
    Ld = project(dl, bands)
    Ldr = project({**dl, "direction": list(R @ [0.0, 0.0, -1.0])}, bands)
    np.testing.assert_allclose(Ldr, D @ Ld, atol=1e-5)


# --- irradiance: Ramamoorthi and Hanrahan 2001 ------------------------------------

RH_C = (0.429043, 0.511664, 0.743125, 0.886227, 0.247708)


def rh_irradiance(L, n):
    """Ramamoorthi and Hanrahan 2001, eq. 13: irradiance at normal n from
    the nine coefficients L (index l (l + 1) + m)."""
    c1, c2, c3, c4, c5 = RH_C
    x, y, z = n
    L00, L1m1, L10, L11, L2m2, L2m1, L20, L21, L22 = L[:9]
    return (c1 * L22 * (x * x - y * y) + c3 * L20 * z * z + c4 * L00 - c5 * L20
            + 2 * c1 * (L2m2 * x * y + L21 * x * z + L2m1 * y * z) + 2 * c2 * (L11 * x + L1m1 * y + L10 * z))


def irradiance_by_quadrature(fn, normals, nq=200):
    """int L(w) max(0, n.w) dw per normal (rows), numpy quadrature of fn itself."""
    d, w = gauss_sphere(nq)
    return np.maximum(normals @ d.T, 0) @ (fn(d) * w[:, None])


@pytest.mark.parametrize("which", ["quadratic", "lobe"])
def test_nine_coefficient_irradiance_against_quadrature(which, tmp_path):
    fn = quadratic if which == "quadratic" else lobe
    path = envmap_file(tmp_path / f"{which}.exr", fn)
    L = project({"type": "envmap", "filename": str(path)}, 9)
    normals = random_dirs(20, 3)
    for n, exact in zip(normals, irradiance_by_quadrature(fn, normals)):
        closed = rh_irradiance(L, n)
        if which == "quadratic":  # band-limited: the closed form is exact
            np.testing.assert_allclose(closed, exact, rtol=2e-4)
        else:
            # The truncation error sum_{l >= 4 even} A_l L_lm y_lm(n), bounded
            # by |A_l| ||L_l|| sqrt((2l + 1) / 4 pi) (the addition theorem),
            # with A_l of R&H's eq. 8 (Abramowitz and Stegun for the Legendre terms).
            bound = np.zeros(3)
            for deg in range(4, 9, 2):
                A = 2 * np.pi * (-1) ** (deg // 2 - 1) / ((deg + 2) * (deg - 1)) * math.factorial(deg) / (
                    2 ** deg * math.factorial(deg // 2) ** 2)
                band = np.linalg.norm(L[deg * deg:(deg + 1) ** 2], axis=0)
                bound += abs(A) * band * math.sqrt((2 * deg + 1) / (4 * np.pi))
            err = np.abs(closed - exact)
            assert np.all(err <= bound * 1.5 + 2e-4), (err, bound)
            assert np.all(err / exact < 0.03)  # R&H: a few per cent at most


def test_unshadowed_transfer_on_a_plane_is_the_closed_form(tmp_path):
    """A diffuse plane (normal +z) filling the view, unshadowed transfer at
    3 bands: each pixel estimates (rho / pi) E(n) with E of R&H's eq. 13."""
    path = envmap_file(tmp_path / "lobe.exr", lobe)
    light = {"type": "envmap", "filename": str(path)}
    rho = np.array([0.6, 0.5, 0.4])
    scene = rm.load_dict({
        "type": "scene", "light": light,
        "plane": {"type": "rectangle", "to_world": np.diag([50.0, 50.0, 1.0, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rho)}}},
        "cam": {"type": "perspective", "fov": 30, "to_world": lookat([0, 0, 3], [0, 0, 0]),
                "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}}})
    res = rm.render(scene, integrator=prt(3, "unshadowed", env_samples=128), spp=256, seed=4)
    assert_clean(res, "unshadowed plane")
    L = project(light, 3)
    exact = np.broadcast_to(rho / np.pi * rh_irradiance(L, np.array([0.0, 0.0, 1.0])), res.image.shape)
    passed, msg = blocked_z(res.image, res.variance, exact)
    assert passed, msg
    assert not blocked_z(res.image, res.variance, exact * 1.02)[0], "a 2 % bias went undetected"
    assert res.stats["clamped_values"] == 0


# --- against path ---------------------------------------------------------------


CONSTANT = {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 0.9, 0.8]}}


def test_unshadowed_constant_is_albedo_times_radiance():
    res = rm.render(ball_on_floor(CONSTANT, res=12), integrator=prt(2, "unshadowed"), spp=4, seed=1)
    L = np.array([1.0, 0.9, 0.8])
    direct = res.effects["direct"]
    lit = direct.sum(-1) > 0
    # Every pixel sees floor, ball or sky: albedo x L exactly (y_00 L_00 = L,
    # the weight f cos / pdf = albedo), or L itself.
    assert lit.any() and (~lit).any()
    vals = direct / L
    floor = np.isclose(vals, ALBEDO_FLOOR, rtol=1e-5).all(-1)
    ball = np.isclose(vals, ALBEDO_BALL, rtol=1e-5).all(-1)
    assert (floor | ball)[lit].mean() > 0.8 and floor.any() and ball.any()  # pixel edges mix floor and ball
    np.testing.assert_allclose(res.effects["emission"][~lit], np.broadcast_to(L, (int((~lit).sum()), 3)), rtol=1e-6)
    assert np.all(res.variance[floor] < 1e-10)


def test_shadowed_transfer_under_a_constant_is_path_ambient_occlusion():
    """Under a constant environment one band is exact, so prt's shadowed
    transfer renders albedo x L x AO, AO = (1/pi) int V cos: path at
    max_depth 2 (the camera segment and one to the sky) estimates the same."""
    scene = ball_on_floor(CONSTANT)
    a = rm.render(scene, integrator=prt(1, "shadowed"), spp=128, seed=11)
    b = rm.render(scene, integrator={"type": "path", "max_depth": 2}, spp=128, seed=12)
    assert_clean(a, "prt shadowed")
    passed, msg = blocked_z(a.image, a.variance, b.image, b.variance)
    assert passed, f"prt / path = {a.image.sum() / b.image.sum():.5f}\n{msg}"
    assert not blocked_z(a.image, a.variance, b.image * 1.03, b.variance * 1.03 ** 2)[0], "3 % went undetected"
    assert not a.effects["indirect"].any()
    # Occlusion is there: the floor beside the ball is darker than albedo x L.
    assert a.effects["direct"].min() < 0.5 * np.array(ALBEDO_FLOOR).min() * 0.8


def rho_bound(albedo_max, bounces):
    """||T|| for diffuse transfer: direct (rho / pi) cos+ has L2 norm
    rho sqrt(2 / (3 pi)); each further bounce is at most rho^k / pi
    pointwise (cos <= 1, V <= 1), L2 norm rho^k / pi sqrt(4 pi)."""
    b = albedo_max * math.sqrt(2 / (3 * np.pi))
    for k in range(2, bounces + 2):
        b += albedo_max ** k / np.pi * math.sqrt(4 * np.pi)
    return b


def test_low_frequency_lighting_matches_path_within_the_band_limit(tmp_path):
    path_file = envmap_file(tmp_path / "lobe.exr", lobe)
    light = {"type": "envmap", "filename": str(path_file)}
    scene = ball_on_floor(light, res=16)
    kmax = 8
    a = rm.render(scene, integrator=prt(kmax, "interreflected", bounces=1, hide_emitters=True, env_samples=128),
                  spp=256, seed=21)
    b = rm.render(scene, integrator={"type": "path", "max_depth": 3, "hide_emitters": True}, spp=512, seed=22)
    assert_clean(a, "prt low frequency")
    tr = Transfer(a)
    # ||L - L_k|| per channel from a 24-band projection (the rest is below the
    # envmap's bilinear-interpolation error, ~1e-4).
    Lfull = project(light, 24)
    tail = [np.sqrt((Lfull[k * k:] ** 2).sum(0)) for k in range(1, kmax + 1)]
    rho = np.maximum(ALBEDO_FLOOR, ALBEDO_BALL)
    zc = st.norm.isf(ALPHA / 2 / (a.image.size * kmax))
    sd = np.sqrt(a.variance + b.variance)
    rows = []
    full = tr.relight(light).image
    for k in range(1, kmax + 1):
        img = tr.relight(light, bands=k).image
        err = np.abs(img - b.image)
        bound = np.array([rho_bound(r, 1) for r in rho]) * tail[k - 1]
        over = err > bound + zc * sd + 1e-4
        assert not over.any(), f"{k} bands: {int(over.sum())} pixels beyond the band-limit bound"
        # Against path (its noise and prt's, RMS, beside it), and against the
        # same transfer at kmax bands (the same samples: the noise cancels,
        # what is left is the band limit between k and kmax).
        m = b.image.mean()
        rms_path = float(np.sqrt(((img - b.image) ** 2).mean())) / m
        rms_full = float(np.sqrt(((img - full) ** 2).mean())) / m
        rows.append((k, rms_path, rms_full, float(bound.max()) / m))
    noise = float(np.sqrt((a.variance + b.variance).mean())) / b.image.mean()
    print(f"\nrelative to the image mean; noise of prt - path, RMS: {noise:.4f}")
    print("bands  RMS prt_k - path  RMS prt_k - prt_8  bound ||T|| ||L - L_k||")
    for k, e, e8, bd in rows:
        print(f"{k:5d}  {e:16.4f}  {e8:17.2e}  {bd:.2e}")
    est = [r[2] for r in rows]
    assert est[0] > est[2] > est[4] > est[6], est  # the band-limit error falls with the band count
    assert rows[0][1] > 3 * noise, (rows[0], noise)  # and path sees it at one band
    np.testing.assert_allclose(tr.relight(light).image, a.image, rtol=1e-4, atol=1e-6)
    passed, msg = blocked_z(a.image, a.variance, b.image, b.variance)
    assert passed, f"{kmax} bands: prt / path = {a.image.sum() / b.image.sum():.5f}\n{msg}"
    assert not blocked_z(a.image, a.variance, b.image * 1.03, b.variance * 1.03 ** 2)[0], "3 % went undetected"


# --- relighting, determinism, stability, refusals -----------------------------------


def test_relighting_from_the_kept_transfer_equals_a_new_render(tmp_path):
    sky = {"type": "envmap", "filename": str(envmap_file(tmp_path / "q.exr", quadratic))}
    sun = {"type": "directional", "direction": [-0.3, 0.4, -0.8], "irradiance": {"type": "rgb", "value": [3, 2, 1]}}
    a = rm.render(ball_on_floor(CONSTANT, res=12), integrator=prt(4), spp=8, seed=5)
    tr = Transfer(a)
    assert tr.nbytes == 12 * 12 * 3 * 3 * 16 * 4 == a.stats["transfer_bytes"]
    for env in (sky, {"type": "scene", "a": sky, "b": sun}):
        new = rm.render(ball_on_floor(env["a"] if "a" in env else env, res=12, **({"sun": sun} if "a" in env else {})),
                        integrator=prt(4), spp=8, seed=5)
        relit = tr.relight(env)
        np.testing.assert_allclose(relit.image, new.image, rtol=1e-4, atol=1e-6)
        for k in ("emission", "direct", "indirect"):
            np.testing.assert_allclose(relit.effects[k], new.effects[k], rtol=1e-4, atol=1e-6)
    # Coefficients directly, and a truncation to fewer bands.
    L = project(sky, 4)
    np.testing.assert_allclose(tr.relight(L).image, tr.relight(sky).image, rtol=1e-5, atol=1e-7)
    assert tr.relight(L, bands=2).coefficients.shape == (4, 3)
    with pytest.raises(ValueError, match="bands must be in 1..4"):
        tr.relight(L, bands=5)
    with pytest.raises(ValueError, match="not a prt render"):
        Transfer(rm.render(ball_on_floor(CONSTANT, res=4), integrator="path", spp=1))


def test_deterministic_whatever_the_thread_count():
    scene = ball_on_floor(CONSTANT, res=12, sun={"type": "directional", "direction": [0.2, 0.3, -1.0]})
    assert_same_bytes_whatever_threads(scene, prt(3, bounces=2), 4)
    t = [rm.render(scene, integrator=prt(3, bounces=2), spp=4, seed=9, threads=n).arrays["prt_transfer"]
         for n in (1, 2)]
    assert t[0].tobytes() == t[1].tobytes()


def test_degenerate_coplanar_touching_and_enclosed_geometry_stay_finite():
    sun = {"type": "directional", "direction": [0.3, -0.2, -1.0], "irradiance": {"type": "rgb", "value": [4, 4, 4]}}
    diffuse = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}}
    red = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.9, 0.1, 0.1]}}
    scene = rm.load_dict({
        "type": "scene", "light": CONSTANT, "sun": sun,
        "degenerate": {"type": "obj", "filename": str(STRESS / "degenerate_object.obj"), "bsdf": diffuse},
        "floor": {"type": "rectangle", "to_world": np.diag([3.0, 3.0, 1.0, 1.0]), "bsdf": diffuse},
        "coplanar": {"type": "rectangle", "to_world": np.diag([1.0, 1.0, 1.0, 1.0]), "bsdf": red},
        "a": {"type": "sphere", "center": [1.0, 0.0, 0.3], "radius": 0.3, "bsdf": diffuse},
        "b": {"type": "sphere", "center": [1.6, 0.0, 0.3], "radius": 0.3, "bsdf": red},
        "cam": {"type": "perspective", "fov": 50, "to_world": lookat([0.5, -3, 2.5], [0.3, 0.3, 0], (0, 0, 1)),
                "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}}})
    for transfer in ("unshadowed", "shadowed", "interreflected"):
        res = rm.render(scene, integrator=prt(4, transfer, bounces=3), spp=8, seed=2)
        assert_clean(res, transfer)
        assert np.all(np.isfinite(res.arrays["prt_transfer"]))
        assert res.image.mean() > 0
    # A camera inside a closed box: no light reaches it, exactly 0.
    box = rm.load_dict({
        "type": "scene", "light": CONSTANT, "sun": sun,
        "box": {"type": "cube", "to_world": np.diag([2.0, 2.0, 2.0, 1.0]), "flip_normals": True, "bsdf": diffuse},
        "cam": {"type": "perspective", "fov": 60, "to_world": lookat([0, 0, 0], [1, 0.2, 0.1], (0, 0, 1)),
                "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}}})
    res = rm.render(box, integrator=prt(3, bounces=4), spp=4, seed=1)
    assert_clean(res, "closed box")
    assert not res.image.any()


def test_refusals_name_what_is_refused():
    area = rm.load_dict({
        "type": "scene",
        "lamp": {"type": "rectangle", "emitter": {"type": "area"}, "bsdf": {"type": "diffuse"}},
        "cam": {"type": "perspective", "to_world": lookat([0, 0, 3], [0, 0, 0]),
                "film": {"type": "hdrfilm", "width": 4, "height": 4}}})
    with pytest.raises(ValueError, match=r"integrator 'prt': emitter '.*' is a local light"):
        rm.render(area, integrator="prt", spp=1)
    assert "local light" in rm.refusal(area, "prt")
    assert rm.refusal(area, "path") is None
    glossy = ball_on_floor(CONSTANT, res=4, ball={"type": "sphere", "bsdf": {"type": "roughconductor"}})
    with pytest.raises(ValueError, match=r"shape '.*ball.*' has a non-diffuse BSDF"):
        rm.render(glossy, integrator="prt", spp=1)
    scene = ball_on_floor(CONSTANT, res=4)
    for bad, param in (({"transfer": "ambient"}, "transfer"), ({"bands": 0}, "bands"),
                       ({"env_samples": 0}, "env_samples"), ({"bounces": -1}, "bounces")):
        with pytest.raises(rm.SceneError, match=param):
            rm.render(scene, integrator={"type": "prt", **bad}, spp=1)
    with pytest.raises(ValueError, match="local light"):
        Transfer(rm.render(scene, integrator="prt", spp=1)).relight({"type": "point", "position": [0, 0, 1]})
