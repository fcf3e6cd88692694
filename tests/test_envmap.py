"""The `envmap` emitter (renderer/scene/emitter.cpp EnvMapEmitter): its
direction sampling against its density (Pearson chi-square, analysis/chi2.py,
overall significance 0.01 over this file's two chi-square tests, with a
power check), its radiance against Mitsuba 3's own plugin, a constant image
against `constant` in every estimator (blocked z-test with a power check),
and a small envmap scene against Mitsuba 3's path tracer."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from refcompare import assert_agrees, assert_clean, blocked_z

import radiometer as rm
from radiometer.analysis.chi2 import SphereGrid, chi2_test, sidak_level
from radiometer.exr import write_exr
from radiometer.loader import SceneError, load_dict, load_file

LEVEL = sidak_level(0.01, 2)
MUSEUM = Path(__file__).resolve().parents[1].parent / "shared/peers/mitsuba-data/common/textures/museum.exr"
# A rotation about (0.6, 0, 0.8) by 70 degrees, with a translation (which a direction ignores).
_C, _S = np.cos(np.radians(70)), np.sin(np.radians(70))
_A = np.array([0.6, 0.0, 0.8])
_K = np.array([[0, -_A[2], _A[1]], [_A[2], 0, -_A[0]], [-_A[1], _A[0], 0]])
ROT = np.eye(4)
ROT[:3, :3] = np.eye(3) + _S * _K + (1 - _C) * (_K @ _K)
ROT[:3, 3] = [1.0, -2.0, 0.5]


def _image(h=12, w=24):
    """A lat-long image with a bright spot, a gradient and a black band."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack([0.2 + x / w, 0.5 + 0.5 * np.sin(y), 0.3 + 0 * x], axis=-1).astype(np.float32)
    img[2:4, 5:7] = [40.0, 30.0, 20.0]
    img[7:9] = 0.0
    return img


@pytest.fixture(scope="module")
def env_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("env") / "sky.exr"
    write_exr(path, image=_image())
    return path


def _scene(env, **extra):
    d = {"type": "scene", "sky": env,
         "sensor": {"type": "radiancemeter", "origin": [0, 0, -5], "direction": [0, 0, 1],
                    "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}}
    d.update(extra)
    return rm.load_dict(d)


def _sampler(core, ref):
    def sample(rng, n):
        s = core.sample_emitter_direction(np.broadcast_to(ref, (n, 3)), rng.random((n, 4), dtype=np.float32))
        return s["d"], s["is_delta"] > 0, s["pdf"] > 0
    return sample


def test_envmap_direction_sampling_chi2(env_file):
    core = _scene({"type": "envmap", "filename": str(env_file), "scale": 2.0, "to_world": ROT}).core()
    ref = np.asarray([0.3, -0.1, 0.2], np.float32)

    def pdf(d):
        return core.pdf_emitter_direction(ref[None, :], np.asarray(d, np.float32))

    # The density is piecewise constant over the image's cells, rotated:
    # deep refinement keeps the cell integrals' error under the noise.
    r = chi2_test(_sampler(core, ref), pdf, n_samples=200_000, grid=SphereGrid(n_theta=24, n_phi=48), seed=5,
                  level=LEVEL, label="envmap", min_depth=5, max_depth=9, rtol=1e-5, atol=1e-4)
    assert r.passed, r.summary()


def test_wrong_envmap_pdf_is_rejected(env_file):
    """Power: the same samples judged against a density 5 % off on one side."""
    core = _scene({"type": "envmap", "filename": str(env_file), "to_world": ROT}).core()
    ref = np.zeros(3, np.float32)

    def wrong(d):
        d = np.asarray(d, np.float32)
        p = core.pdf_emitter_direction(ref[None, :], d)
        return np.where(d[:, 1] > 0, p * 1.05, p * 0.95)

    r = chi2_test(_sampler(core, ref), wrong, n_samples=200_000, grid=SphereGrid(n_theta=24, n_phi=48), seed=5,
                  level=LEVEL, min_depth=5, max_depth=9)
    assert not r.passed


def test_envmap_sample_pdf_and_radiance(env_file):
    """A sample's density is its direction's (what MIS uses on escape); no
    direction of the black band is drawn; scale multiplies the radiance."""
    core = _scene({"type": "envmap", "filename": str(env_file), "to_world": ROT}).core()
    core2 = _scene({"type": "envmap", "filename": str(env_file), "to_world": ROT, "scale": 3.0}).core()
    n = 4000
    ref = np.zeros((n, 3), np.float32)
    u = np.random.default_rng(0).random((n, 4), dtype=np.float32)
    s, s2 = core.sample_emitter_direction(ref, u), core2.sample_emitter_direction(ref, u)
    assert np.all(s["pdf"] > 0) and np.all(s["radiance"].max(axis=1) > 0)
    np.testing.assert_allclose(core.pdf_emitter_direction(ref[:1], s["d"]), s["pdf"], rtol=2e-3)
    np.testing.assert_allclose(s2["radiance"], 3.0 * s["radiance"], rtol=1e-3, atol=1e-6)  # float32 interpolation
    np.testing.assert_allclose(s2["d"], s["d"], atol=1e-6)  # scale changes no density (but its sums round)


@pytest.mark.skipif(not MUSEUM.exists(), reason="../shared/peers/mitsuba-data absent")
def test_envmap_radiance_and_frame_match_mitsuba():
    """Radiance along sampled directions equals Mitsuba 3's envmap plugin's
    (its lat-long convention, bilinear lookup and to_world), to float32
    precision of the interpolation."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    core = _scene({"type": "envmap", "filename": str(MUSEUM), "scale": 1.5, "to_world": ROT}).core()
    em = mi.load_dict({"type": "envmap", "filename": str(MUSEUM), "scale": 1.5,
                       "to_world": mi.ScalarTransform4f(ROT.tolist())})
    n = 1500
    s = core.sample_emitter_direction(np.zeros((n, 3), np.float32),
                                      np.random.default_rng(2).random((n, 4), dtype=np.float32))
    theirs = np.empty((n, 3))
    for i in range(n):
        si = mi.SurfaceInteraction3f()
        si.wi = -mi.ScalarVector3f(*map(float, s["d"][i]))
        theirs[i] = np.array(em.eval(si))
    err = np.abs(s["radiance"] - theirs).max(axis=1) / theirs.max(axis=1)
    assert err.max() < 1e-3, err.max()
    # The test can fail: Mitsuba's plugin without the to_world disagrees.
    em0 = mi.load_dict({"type": "envmap", "filename": str(MUSEUM), "scale": 1.5})
    off = 0
    for i in range(100):
        si = mi.SurfaceInteraction3f()
        si.wi = -mi.ScalarVector3f(*map(float, s["d"][i]))
        off += not np.allclose(np.array(em0.eval(si)), theirs[i], rtol=1e-2)
    assert off > 50, off


# -- every estimator: a constant image is `constant` ----------------------------------------


def _ball_scene(sky, tmp_path=None):
    cam = np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 4], [0, 0, 0, 1.0]])
    return rm.Scene(load_dict({
        "type": "scene", "sky": sky,
        "ball": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": [0.8, 0.6, 0.4]}},
        "glass": {"type": "sphere", "center": [0.9, 0.7, 1.2], "radius": 0.4, "bsdf": {"type": "dielectric"}},
        "floor": {"type": "rectangle", "to_world": np.diag([3.0, 3.0, 1.0, 1.0]) @ np.array(
            [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -1], [0, 0, 0, 1.0]]), "bsdf": {"type": "diffuse"}},
        "cam": {"type": "perspective", "fov": 50, "to_world": cam,
                "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}}}))


ESTIMATORS = {
    "path": ({"type": "path", "max_depth": 4}, 64),
    "volpath": ({"type": "volpath", "max_depth": 4}, 64),
    "direct": ({"type": "direct"}, 64),
    "ptracer": ({"type": "ptracer", "max_depth": 4}, 2048),
    "bdpt": ({"type": "bdpt", "max_depth": 4}, 32),
    "photonmapper": ({"type": "photonmapper", "max_depth": 4, "global_photons": 40000,
                      "caustic_photons": 40000}, 16),
    "sppm": ({"type": "sppm", "max_depth": 4, "photon_count": 20000}, 64),
}


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_constant_envmap_is_constant(name, tmp_path):
    """An image of one value c renders as `constant` of radiance c: NEE,
    emission on escape, light paths and photon emission all go through the
    envmap's sampling and density (uniform here, by the exact sin theta
    weights). Blocked z-test of the two renders, and a 3 % brighter image
    must be rejected."""
    c = np.array([0.7, 0.9, 1.2], np.float32)
    path = tmp_path / "flat.exr"
    write_exr(path, image=np.broadcast_to(c, (8, 16, 3)).copy())
    integ, spp = ESTIMATORS[name]
    env = rm.render(_ball_scene({"type": "envmap", "filename": str(path)}), integrator=integ, spp=spp, seed=1)
    const = rm.render(_ball_scene({"type": "constant", "radiance": {"type": "rgb", "value": c.tolist()}}),
                      integrator=integ, spp=spp, seed=2)
    assert_clean(env, name)
    if name in ("photonmapper", "sppm"):
        # Biased at any finite budget, and their variance is not reported:
        # totals to 3 % (measured: 0.981 to 1.002 over seeds; a wrong photon
        # weight of the envmap would be off by far more).
        assert abs(env.image.sum() / const.image.sum() - 1) < 0.03, (env.image.sum(), const.image.sum())
        return
    assert_agrees(env, const, power=1.03, what=f"{name}: envmap / constant")


def test_envmap_refusals(tmp_path, env_file):
    with pytest.raises(SceneError, match=r"environment map file not found: 'nope.exr'"):
        load_dict({"type": "scene", "e": {"type": "envmap", "filename": "nope.exr"}})
    bad = tmp_path / "sky.hdr"
    bad.write_bytes(b"#?RADIANCE\n")
    with pytest.raises(SceneError, match=r"image format '.hdr' is not supported"):
        load_dict({"type": "scene", "e": {"type": "envmap", "filename": str(bad)}})
    small = tmp_path / "small.exr"
    write_exr(small, image=np.ones((2, 4, 3), np.float32))
    with pytest.raises(SceneError, match="at least 2x3 pixels"):
        load_dict({"type": "scene", "e": {"type": "envmap", "filename": str(small)}})
    neg = tmp_path / "neg.exr"
    write_exr(neg, image=-np.ones((4, 8, 3), np.float32))
    with pytest.raises(SceneError, match="negative values"):
        load_dict({"type": "scene", "e": {"type": "envmap", "filename": str(neg)}})
    xml = tmp_path / "s.xml"
    xml.write_text(f'<scene version="3.0.0"><emitter type="envmap"><string name="filename" value="{env_file}"/>\n'
                   f'<boolean name="mis_compensation" value="true"/></emitter></scene>')
    with pytest.raises(SceneError, match=r"s.xml:2: emitter 'envmap': mis_compensation = true is not supported"):
        load_file(xml)
    with pytest.raises(SceneError, match="'scale'"):  # other emitters still take no scale
        load_dict({"type": "scene", "e": {"type": "constant", "scale": 2.0}})


# -- against Mitsuba 3 ----------------------------------------------------------------------


@pytest.mark.skipif(not MUSEUM.exists(), reason="../shared/peers/mitsuba-data absent")
def test_envmap_scene_against_mitsuba(tmp_path):
    """A diffuse ball and a glass ball under the museum envmap (rotated,
    scaled), `path`, against Mitsuba 3's path tracer in scalar_rgb: eight
    independent Mitsuba renders give its mean and variance; blocked z-test
    counting both variances, with a 3 % power check."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")

    def scene(to_world):
        return {"type": "scene",
                "sky": {"type": "envmap", "filename": str(MUSEUM), "scale": 0.8, "to_world": to_world},
                "integrator": {"type": "path", "max_depth": 5},
                "ball": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                                                    "value": [0.8, 0.6, 0.4]}}},
                "glass": {"type": "sphere", "center": [0.9, 0.7, 1.2], "radius": 0.4, "bsdf": {"type": "dielectric"}},
                "cam": {"type": "perspective", "fov": 60,
                        "to_world": (mi.ScalarTransform4f().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0])
                                     if not isinstance(to_world, np.ndarray) else
                                     np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 4], [0, 0, 0, 1.0]])),
                        "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}},
                        "sampler": {"type": "independent", "sample_count": 64}}}

    ms = mi.load_dict(scene(mi.ScalarTransform4f(ROT.tolist())))
    runs = np.stack([np.array(mi.render(ms, spp=64, seed=k)) for k in range(8)])
    theirs_mean, theirs_var = runs.mean(axis=0), runs.var(axis=0, ddof=1) / len(runs)
    ours = rm.render(rm.Scene(load_dict(scene(ROT))), spp=512, seed=4)
    passed, msg = blocked_z(ours.image, ours.variance, theirs_mean, theirs_var)
    print(f"envmap scene: ours / mitsuba = {ours.image.sum() / theirs_mean.sum():.5f}")
    assert passed, f"ours / mitsuba = {ours.image.sum() / theirs_mean.sum():.5f}\n{msg}"
    assert not blocked_z(ours.image, ours.variance, theirs_mean * 1.03, theirs_var * 1.03 ** 2)[0]


SUITE = MUSEUM.parents[2] / "tests" / "scenes"


@pytest.mark.skipif(not SUITE.is_dir(), reason="../shared/peers/mitsuba-data absent")
@pytest.mark.parametrize("scene", ["infinite_mirrors/scene_path.xml",
                                   "participating_media/test_homo_dielectric_envmap_volpath.xml"])
def test_suite_envmap_scenes_pass_mitsubas_test(scene):
    """Mitsuba 3's own envmap scenes under Mitsuba's own test protocol
    (benchmarks/studies/mitsuba_suite.py protocol: 2e6 samples, seed 0, XYZ,
    Sidak 0.01, at most 0.75 % of the pixels' channels rejected); and the
    protocol rejects the envmap 2 % too bright."""
    from radiometer.benchmarks.studies import mitsuba_suite as ms

    r = ms.protocol(SUITE / scene, threads=2)
    assert r["passes"], r

    def brighter(d):
        for e in d.emitters:
            if e.env is not None:
                e.env = e.env * np.float32(1.02)

    assert not ms.protocol(SUITE / scene, threads=2, change=brighter)["passes"]
