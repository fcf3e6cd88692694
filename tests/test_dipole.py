"""The dipole BSSRDF (renderer/scene/dipole.h): Jensen,
Marschner, Levoy and Hanrahan 2001 ("J01"), "A Practical Model for
Subsurface Light Transport", as Mitsuba 0.6's `dipole` subsurface plugin,
rendered by `path` / `volpath`.

- The profile Rd(r) (J01 eq. 4) integrates over the plane to J01's closed
  form of the total diffuse reflectance R_d, computed here independently
  from the paper's formulas, for albedos 0.1 .. 0.999 and several IORs.
- The exit lobe (Sw): chi-square, weight == eval / pdf, integral 1.
- The radial sampler draws r with the density it reports: Pearson
  chi-square (radiometer.analysis.chi2) at ALPHA = 0.01, Sidak over the
  cases, with a power check (5 % larger radii must be rejected).
- End to end, analytic: a large flat dipole plane under a uniform
  environment, seen along its normal, reflects exactly Fr(0) specularly and
  Ft(0) R_d by subsurface (the normalised exit lobe integrates to 1), per
  pixel z-test with var_b = 0; the same through `volpath` (a scene with a
  medium elsewhere) -- a direct check of the probe-ray exit-point weights.
- Energy: a white (non-absorbing) dipole sphere in a uniform environment
  reflects no more than it receives; its exact expectation (the dipole
  integrated over the sphere's chords) is met per pixel.
- Loader errors name the element; other estimators refuse a dipole scene
  naming themselves; absurd coefficients (1e4, 1e-6) and thin objects give
  no NaN, Inf or negative values.
Fixed seeds throughout; every z-test is two-sided at ALPHA over channels.
"""
import math

import numpy as np
import pytest
from scipy.integrate import quad

import radiometer as rm
from radiometer import _core
from radiometer.analysis.chi2 import SphereGrid, bsdf_adapter, chi2_test, pearson_chi2, sidak_level
from radiometer.analysis.stats import z_test
from radiometer.scene_desc import SceneError

ALPHA = 0.01


def _rgb(v):
    return {"type": "rgb", "value": list(v) if np.ndim(v) else [v] * 3}


def dipole(sigma_a, sigma_s, eta=1.5, g=0.0):
    d = _core.DipoleDesc()
    d.sigma_a = tuple(np.broadcast_to(np.asarray(sigma_a, float), 3))
    d.sigma_s = tuple(np.broadcast_to(np.asarray(sigma_s, float), 3))
    d.g, d.int_ior, d.ext_ior = g, eta, 1.0
    return _core.Dipole(d)


def j01_total_rd(alpha_p, eta):
    """J01 sec. 2.4: R_d = (alpha'/2) (1 + exp(-(4/3) A sqrt(3 (1 - alpha'))))
    exp(-sqrt(3 (1 - alpha'))), A = (1 + F_dr) / (1 - F_dr) and the fit
    F_dr = -1.440 / eta^2 + 0.710 / eta + 0.668 + 0.0636 eta."""
    fdr = -1.440 / eta ** 2 + 0.710 / eta + 0.668 + 0.0636 * eta
    A = (1 + fdr) / (1 - fdr)
    s = math.sqrt(3 * (1 - alpha_p))
    return 0.5 * alpha_p * (1 + math.exp(-4.0 / 3.0 * A * s)) * math.exp(-s)


# -- the profile ----------------------------------------------------------------


@pytest.mark.parametrize("eta", [1.0, 1.3, 1.5])
def test_profile_integrates_to_total_diffuse_reflectance(eta):
    # alpha' = sigma_s / (sigma_a + sigma_s) for sigma_t' = 10 (g = 0), and
    # the same albedos with g = 0.5 (sigma_s twice as large: same sigma_s').
    for g in (0.0, 0.5):
        for alpha_p in (0.1, 0.5, 0.9, 0.99, 0.999):
            ssp = 10.0 * alpha_p
            dp = dipole(10.0 - ssp, ssp / (1 - g), eta=eta, g=g)
            want = j01_total_rd(alpha_p, eta)
            assert dp.total_rd[0] == pytest.approx(want, rel=1e-5)
            zr, zv, s = dp.z_r[0], dp.z_v[0], dp.sigma_tr[0]
            # J01 eq. 4 written out here, against the renderer's Rd(r).
            def rd(r):
                dr, dv = math.hypot(r, zr), math.hypot(r, zv)
                return alpha_p / (4 * math.pi) * (zr * (1 + s * dr) * math.exp(-s * dr) / dr ** 3
                                                  + zv * (1 + s * dv) * math.exp(-s * dv) / dv ** 3)
            for r in (0.0, 0.01, 0.1, 1.0):
                assert dp.rd(np.array([r]))[0, 0] == pytest.approx(rd(r), rel=1e-5)
            # The renderer's profile integrated numerically over the plane.
            def f(r):
                return 2 * math.pi * r * dp.rd(np.array([r]))[0, 0]

            num = sum(quad(f, a, b, limit=400, epsabs=0)[0] for a, b in ((0, zr), (zr, 10 * zv), (10 * zv, np.inf)))
            assert num == pytest.approx(want, rel=1e-4), (alpha_p, g, num, want)


def test_bindings_refuse_a_bad_channel():
    """Channel arguments are checked (r_max once read past its array and
    crashed the interpreter for a large channel)."""
    dp = dipole([0.01, 0.3, 3.0], 10.0, eta=1.5)
    for bad in (-1, 3, 7, 2 ** 30):
        for call in (lambda c: dp.r_max(c), lambda c: dp.sample_r(c, np.array([0.5])),
                     lambda c: dp.pdf_a(c, np.array([0.1]))):
            with pytest.raises(ValueError, match="channel must be 0, 1 or 2"):
                call(bad)
    assert all(dp.r_max(c) > 0 for c in range(3))


def test_radial_sampler_matches_its_density():
    """r ~ sample_r(ch, u) histogrammed against the integral of 2 pi r pdf_a
    over each bin; the pdf integrates to 1 on [0, r_max]. Three channels of
    very different diffusion lengths; Sidak over the 3 x 2 tests."""
    cases = [dipole([0.01, 0.3, 3.0], 10.0, eta=1.5), dipole([1e-4, 1.0, 100.0], [2.0, 50.0, 100.0], eta=1.33)]
    rng = np.random.default_rng(7)
    n, bins = 100_000, 60
    level = sidak_level(ALPHA, 6)
    for dp in cases:
        for ch in range(3):
            rmax = dp.r_max(ch)
            # Bins finer near 0, where the profile peaks.
            edges = rmax * np.linspace(0, 1, bins + 1) ** 3
            def dens(r):
                return 2 * math.pi * r * dp.pdf_a(ch, np.array([r]))[0]

            cell = np.array([quad(dens, a, b, limit=200, epsabs=0)[0] for a, b in zip(edges[:-1], edges[1:])])
            assert cell.sum() == pytest.approx(1.0, rel=1e-6)
            r = dp.sample_r(ch, rng.random(n))
            assert np.all((r >= 0) & (r <= rmax))
            obs = np.histogram(r, edges)[0]
            res = pearson_chi2(obs, n * cell)
            assert res["p_value"] > level, (ch, res)
            # Power: radii 5 % too large are rejected.
            bad = pearson_chi2(np.histogram(np.minimum(r * 1.05, rmax), edges)[0], n * cell)
            assert bad["p_value"] < level, (ch, bad)


@pytest.mark.parametrize("eta", [1.0, 1.33, 1.5, 2.4])
def test_exit_lobe_samples_its_density_and_integrates_to_one(eta):
    """The exit lobe cos Sw = Ft cos / (c pi) (PBR3 sec. 11.4.1): directions
    by chi-square against its pdf (Sidak over the 4 IORs), weight ==
    eval / pdf per sample, and its integral over the hemisphere (the mean
    weight of cosine samples) is 1 -- c normalises it -- to within 4
    standard errors, which a c taken from the Fdr fit (~1e-3 off) would
    still pass; the J01 form without c (0.91 at eta 1.5) would not."""
    lobe = dipole(0.1, 1.0, eta=eta).exit_lobe()
    wi = np.array([0.0, 0.0, 1.0])
    sample, pdf = bsdf_adapter(lobe, wi)
    r = chi2_test(sample, pdf, n_samples=100_000, grid=SphereGrid(16, 32, "cos_theta"), seed=11,
                  level=sidak_level(ALPHA, 4))
    assert r.passed, r.summary()
    n = 200_000
    rng = np.random.default_rng(12)
    s = lobe.sample(np.broadcast_to(wi.astype(np.float32), (n, 3)), rng.random(n, dtype=np.float32),
                    rng.random((n, 2), dtype=np.float32), False)
    ok = s["pdf"] > 0
    f = lobe.eval(np.broadcast_to(wi.astype(np.float32), (int(ok.sum()), 3)), s["wo"][ok], False).astype(np.float64)
    np.testing.assert_allclose(s["weight"][ok], f / s["pdf"][ok][:, None], rtol=1e-4)
    w = np.where(ok, s["weight"][:, 0], 0.0)
    assert abs(w.mean() - 1.0) < 4 * w.std() / math.sqrt(n) + 1e-6, (w.mean(), w.std() / math.sqrt(n))


# -- end to end -----------------------------------------------------------------

SIGMA_A = [0.05, 0.5, 2.0]
SIGMA_S = [20.0, 20.0, 20.0]


def plane_scene(integrator="path", medium_below=False, res=8, underlay=False):
    """A 400 x 400 dipole plane (z = 0, normal +z) under a constant
    environment of radiance 1, seen straight down by an orthographic camera.
    `underlay`: a black diffuse plane just below it, facing down (into the
    environment below), which every probe ray along the normal crosses:
    probes must take exit points on the dipole's own shape only (an exit
    lobe there sees the environment below: a bias that this test rejects)."""
    d = {"type": "scene", "integrator": {"type": integrator},
         "sensor": {"type": "orthographic",
                    "to_world": np.array([[0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, -1, 3], [0, 0, 0, 1]], float),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
         "plane": {"type": "rectangle", "to_world": np.diag([200.0, 200.0, 1.0, 1.0]),
                   "subsurface": {"type": "dipole", "sigma_a": _rgb(SIGMA_A), "sigma_s": _rgb(SIGMA_S),
                                  "int_ior": 1.5, "ext_ior": 1.0}},
         "env": {"type": "constant", "radiance": _rgb(1.0)}}
    if underlay:
        d["under"] = {"type": "rectangle", "to_world": np.diag([200.0, 200.0, 1.0, 1.0]) + np.array(
            [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, -0.05], [0, 0, 0, 0]]), "flip_normals": True,
            "bsdf": {"type": "diffuse", "reflectance": 0.0}}
    if medium_below:  # a scene with media (volpath's loop), the medium out of every path's way
        d["fog"] = {"type": "cube",
                    "to_world": np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5], [0, 0, 0, 1]], float),
                    "bsdf": {"type": "null"}, "interior": {"type": "homogeneous", "sigma_t": 1.0, "albedo": 0.5}}
    return d


def plane_expectation():
    """Fr(0) specular; subsurface Ft(0) times the profile integrated over the
    plane up to the largest channel's r_max (what the probe rays reach)."""
    dp = dipole(SIGMA_A, SIGMA_S, eta=1.5)
    fr0 = ((1.5 - 1) / (1.5 + 1)) ** 2
    reach = max(dp.r_max(c) for c in range(3))
    sub = [quad(lambda r: 2 * math.pi * r * dp.rd(np.array([r]))[0, c], 0, reach, limit=400,
                points=[dp.z_r[c], dp.z_v[c]])[0] for c in range(3)]
    assert np.allclose(sub, dp.total_rd, rtol=2e-3)  # ~all of R_d
    return fr0, (1 - fr0) * np.array(sub)


@pytest.mark.parametrize("integrator,medium,underlay", [("path", False, False), ("volpath", True, False),
                                                        ("path", False, True)])
def test_flat_plane_gives_total_diffuse_reflectance(integrator, medium, underlay):
    scene = rm.load_dict(plane_scene(integrator, medium, res=16, underlay=underlay))
    assert scene.features["has_dipole"] and scene.features["has_media"] == medium
    res = rm.render(scene, spp=2048, seed=3)
    fr0, sub = plane_expectation()
    for name, want in (("subsurface", sub), ("specular", np.full(3, fr0))):
        img = res.effects[name]
        # Per-effect variances are not kept: the image's variance bounds
        # each part's (the two parts come from disjoint random choices, so
        # var(part) <= var(image) + mean(part) * (other part's mean)); use it.
        t = z_test(img, res.variance + 1e-12, np.broadcast_to(want, img.shape).astype(np.float32), alpha=ALPHA)
        assert t.passed, f"{integrator} {name}: {t.summary()}"
    # The whole image: exactly Fr(0) + Ft(0) R_d, and power: 1 % more is rejected.
    want = np.broadcast_to(fr0 + sub, res.image.shape)
    t = z_test(res.image, res.variance, want, alpha=ALPHA)
    assert t.passed, t.summary()
    assert not z_test(res.image, res.variance, want * 1.01, alpha=ALPHA).passed


def sphere_scene(sigma_a, sigma_s, res=16, radius=1.0, integrator="path"):
    return {"type": "scene", "integrator": {"type": integrator},
            "sensor": {"type": "orthographic",
                       "to_world": np.array([[0.6, 0, 0, 0], [0, 0.6, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1]], float),
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
            "ball": {"type": "sphere", "radius": radius,
                     "subsurface": {"type": "dipole", "sigma_a": _rgb(sigma_a), "sigma_s": _rgb(sigma_s),
                                    "int_ior": 1.5, "ext_ior": 1.0}},
            "env": {"type": "constant", "radiance": _rgb(1.0)}}


def _fresnel(cos_i, eta):
    sin_t2 = (1 - cos_i ** 2) / eta ** 2
    cos_t = np.sqrt(np.maximum(0, 1 - sin_t2))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (cos_t - eta * cos_i) / (cos_t + eta * cos_i)
    return 0.5 * (rs ** 2 + rp ** 2)


def test_white_sphere_reflects_no_more_than_it_receives():
    """A non-absorbing dipole sphere (R_d = 1 on a plane) of radius 1 in an
    environment of radiance 1. On a sphere the profile integrated over the
    surface is exactly integral_0^{2R} Rd(c) 2 pi c dc (c the chord: dA =
    2 pi c dc), below R_d, so each pixel sees Fr + Ft * that <= 1: checked
    against that expectation per pixel (averaged over the pixel footprint),
    and the mean must not exceed 1."""
    res_px = 16
    res = rm.render(rm.load_dict(sphere_scene(0.0, 30.0, res_px)), spp=512, seed=5)
    dp = dipole(0.0, 30.0)
    reach = min(2.0, dp.r_max(0))
    inside = quad(lambda c: 2 * math.pi * c * dp.rd(np.array([c]))[0, 0], 0, reach, limit=400,
                  points=[dp.z_r[0], dp.z_v[0]])[0]
    assert 0.9 < inside < 1.0
    # Expectation per pixel: the camera looks down -z at x, y in [-0.6, 0.6].
    k = 16
    s = (np.arange(res_px * k) + 0.5) / (res_px * k) * 1.2 - 0.6
    x, y = np.meshgrid(s, s)
    cos_i = np.sqrt(1 - x ** 2 - y ** 2)
    fr = _fresnel(cos_i, 1.5)
    want = (fr + (1 - fr) * inside).reshape(res_px, k, res_px, k).mean(axis=(1, 3))
    want = np.repeat(want[..., None], 3, axis=2)
    t = z_test(res.image, res.variance, want, alpha=ALPHA)
    assert t.passed, t.summary()
    mean, se = res.image.mean(), math.sqrt(res.variance.mean() / res.image[..., 0].size)
    assert mean <= 1.0 + 3 * se, (mean, se)


# -- loader, refusals, robustness -----------------------------------------------


def _with_sub(sub, **shape):
    d = plane_scene()
    d["plane"]["subsurface"] = sub
    d["plane"].update(shape)
    return d


@pytest.mark.parametrize("sub,shape,match", [
    ({"type": "dipole", "sigma_a": -1.0, "sigma_s": 1.0}, {}, "subsurface 'dipole'.*negative value"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0, "sigmaa": 2.0}, {},
     "subsurface 'dipole'.*unknown parameter 'sigmaa'"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0, "sigmaA": 2.0}, {}, "'sigma_a' given twice"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_t": 1.0}, {}, "either sigma_a \\+ sigma_s or sigma_t"),
    ({"type": "dipole"}, {}, "needs sigma_a \\+ sigma_s"),
    ({"type": "dipole", "sigma_a": 0.0, "sigma_s": 0.0}, {}, "nothing to scatter"),
    ({"type": "dipole", "sigma_t": 1.0, "albedo": 1.5}, {}, "albedo must lie in"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0, "g": 1.0}, {}, "'g' must lie in"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0, "scale": -2.0}, {}, "'scale' must be > 0"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0, "int_ior": "unobtainium"}, {}, "unknown IOR name"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0}, {"bsdf": {"type": "diffuse"}},
     "no bsdf, a smooth 'dielectric'"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0, "int_ior": 1.49},
     {"bsdf": {"type": "plastic"}}, "'plastic' with a diffuse part"),
    ({"type": "dipole", "material": "skin1"}, {}, "material presets are not supported"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0, "int_ior": 1.5},
     {"bsdf": {"type": "dielectric", "int_ior": 1.33}}, "differ from the dipole's"),
    ({"type": "dipole", "sigma_a": 1.0, "sigma_s": 1.0},
     {"interior": {"type": "homogeneous"}}, "cannot also have an interior medium"),
])
def test_loader_errors_name_the_element(sub, shape, match):
    with pytest.raises(SceneError, match=match):
        rm.load_dict(_with_sub(sub, **shape)).core()


def test_core_refuses_bad_values_without_aborting():
    for kw in ({"sigma_a": -1.0, "sigma_s": 1.0}, {"sigma_a": 1.0, "sigma_s": float("nan")},
               {"sigma_a": 1.0, "sigma_s": 1.0, "g": 1.0}, {"sigma_a": 1.0, "sigma_s": 1.0, "eta": 0.0}):
        with pytest.raises(ValueError, match="subsurface 'dipole'"):
            dipole(**kw)


def test_loader_forms_and_xml(tmp_path):
    # sigma_t + albedo, scale, g, Mitsuba 0.6 aliases, a matching dielectric.
    d = rm.load_dict(_with_sub({"type": "dipole", "sigmaT": _rgb([1, 2, 4]), "albedo": 0.75, "scale": 2.0,
                                "g": 0.5, "intIOR": 1.33, "extIOR": "vacuum"},
                               bsdf={"type": "dielectric", "int_ior": 1.33, "ext_ior": 1.0})).desc.shapes[0]
    s = d.subsurface
    assert s.sigma_a == pytest.approx((0.5, 1, 2)) and s.sigma_s == pytest.approx((1.5, 3, 6))
    assert (s.g, s.int_ior, s.ext_ior) == (0.5, 1.33, 1.0) and d.bsdf.type == "dielectric"
    good = """<scene version="3.0.0">
  <subsurface type="dipole" id="skin"><rgb name="sigma_a" value="0.1, 0.2, 0.3"/>
    <float name="sigma_s" value="5"/><float name="int_ior" value="1.4"/></subsurface>
  <shape type="sphere"><ref name="subsurface" id="skin"/></shape>
"""
    (tmp_path / "good.xml").write_text(good + "</scene>")
    sh = rm.load_file(tmp_path / "good.xml").desc.shapes[0]
    assert sh.subsurface.sigma_a == pytest.approx((0.1, 0.2, 0.3)) and sh.bsdf.int_ior == pytest.approx(1.4)
    # Mitsuba 0.6's documented set-up: a plastic without its diffuse part as the boundary.
    d = rm.load_dict(_with_sub({"type": "dipole", "sigmaA": 1.0, "sigmaS": 2.0, "intIOR": "water"},
                               bsdf={"type": "plastic", "int_ior": "water", "diffuse_reflectance": 0.0})).desc.shapes[0]
    assert d.bsdf.type == "dielectric" and d.bsdf.int_ior == pytest.approx(1.333)
    # Mitsuba 0.6's irradiance-cache density sets nothing here: refused, not ignored.
    with pytest.raises(SceneError, match="irrSamples.*does not apply"):
        rm.load_dict(_with_sub({"type": "dipole", "sigmaA": 1.0, "sigmaS": 2.0, "irrSamples": 64}))
    (tmp_path / "s.xml").write_text(good + """  <shape type="sphere"><float name="radius" value="0.5"/>
    <subsurface type="dipole"><float name="sigma_a" value="1"/><float name="sigma_s" value="1"/><float name="bogus" value="1"/></subsurface></shape>
</scene>""")  # noqa: E501
    with pytest.raises(SceneError, match=r"s\.xml:6: subsurface 'dipole': unknown parameter 'bogus'"):
        rm.load_file(tmp_path / "s.xml")


@pytest.mark.parametrize("estimator", [n for n, e in rm.estimators().items() if not e["capabilities"]["dipole"]])
def test_other_estimators_refuse(estimator):
    scene = rm.load_dict(plane_scene(res=4))
    with pytest.raises(ValueError, match=f"integrator '{estimator}' cannot render the dipole BSSRDF.*'plane'.*'path'"):
        rm.render(scene, integrator=estimator, spp=1, seed=0)


def _sane(res, where):
    for name, a in [("image", res.image), ("variance", res.variance)] + list(res.effects.items()):
        assert np.all(np.isfinite(a)), f"{where}: {name} not finite"
        assert not np.any(a < 0), f"{where}: {name} negative"
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0, where


@pytest.mark.parametrize("sigma", [1e4, 1e-6])
def test_absurd_coefficients_and_thin_objects(sigma):
    """Coefficients 1e4 and 1e-6 per unit (mean free paths 1e-4 and 1e6 of a
    scene of size 1), on a sphere, a thin box (0.002 thick) and an open
    rectangle seen from both sides (its back is outside the model: black)."""
    for sa, ss in ((sigma, sigma), (0.0, sigma), (sigma, 0.0)):
        res = rm.render(rm.load_dict(sphere_scene(sa, ss, res=8)), spp=16, seed=1)
        _sane(res, f"sphere {sa} {ss}")
        if sa == 0.0 and sigma == 1e4:  # dense and white: almost all light comes back
            assert res.image.mean() > 0.8
        thin = sphere_scene(sa, ss, res=8)
        thin["ball"] = {"type": "cube", "to_world": np.diag([1.0, 1.0, 0.001, 1.0]),
                        "subsurface": thin["ball"]["subsurface"]}
        thin["sheet"] = {"type": "rectangle", "to_world": np.array(
            [[0.3, 0, 0, 0], [0, 0.3, 0, 0], [0, 0, -1, 0.5], [0, 0, 0, 1]], float),
            "subsurface": thin["ball"]["subsurface"]}
        res = rm.render(rm.load_dict(thin), spp=16, seed=2)
        _sane(res, f"thin {sa} {ss}")


def test_subsurface_is_filed_as_subsurface_and_deterministic():
    scene = rm.load_dict(sphere_scene([0.1, 0.2, 0.4], 10.0, res=8))
    a = rm.render(scene, spp=8, seed=4, threads=1)
    b = rm.render(scene, spp=8, seed=4, threads=2)
    assert np.array_equal(a.image, b.image)
    assert a.effects["subsurface"].mean() > 0.3
    for k, v in a.effects.items():
        if k not in ("subsurface", "specular"):
            assert not v.any(), k
    # Only the subsurface class asked for: the specular part is not simulated.
    c = rm.render(scene, spp=8, seed=4, effects=["subsurface"])
    assert not c.effects["specular"].any() and c.image.mean() > 0.3


def test_dipole_in_fog_through_volpath():
    """A dipole sphere inside a fog box that also holds the camera (volpath's
    loop, the shape's exterior medium): finite, non-negative; light is filed
    under subsurface (B, the dipole) and volume (V: fog scattering, which
    takes precedence); with a vanishing fog it is the fog-free image."""
    def fog_scene(sigma_t):
        d = sphere_scene([0.1, 0.2, 0.4], 10.0, res=8)
        fog = {"type": "homogeneous", "sigma_t": sigma_t, "albedo": 0.8}
        d["fog"] = fog
        # The fog fills a cube of half-size 6 around sphere and camera
        # (index-matched boundary); the environment lies outside it.
        d["fogbox"] = {"type": "cube", "to_world": np.diag([6.0, 6.0, 6.0, 1.0]), "bsdf": {"type": "null"},
                       "interior": {"type": "ref", "id": "fog"}}
        d["sensor"]["medium"] = {"type": "ref", "id": "fog"}
        d["ball"]["exterior"] = {"type": "ref", "id": "fog"}
        return d
    res = rm.render(rm.load_dict(fog_scene(0.1)), spp=64, seed=6)
    _sane(res, "dipole in fog")
    assert res.effects["subsurface"].mean() > 0.05 and res.effects["volume"].mean() > 0.005
    thin = rm.render(rm.load_dict(fog_scene(1e-7)), spp=256, seed=7)
    clear = rm.render(rm.load_dict(sphere_scene([0.1, 0.2, 0.4], 10.0, res=8)), spp=256, seed=8)
    t = z_test(thin.image, thin.variance, clear.image, clear.variance, alpha=ALPHA)
    assert t.passed, t.summary()
