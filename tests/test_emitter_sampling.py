"""Emitter sampling for next event estimation: the directions an emitter
sample takes from a reference point follow the density that MIS assigns to
the same directions when a BSDF sample finds the emitter (Pearson chi-square,
analysis/chi2.py), for every emitter type that has a density."""
import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.chi2 import SphereGrid, chi2_test, sidak_level

CASES = {
    # name: (shape dict with an area emitter, or a non-area emitter dict, reference point)
    "sphere": ({"type": "sphere", "center": [0.0, 0.0, 2.0], "radius": 0.8}, [0.1, -0.2, 0.0]),
    "sphere_close": ({"type": "sphere", "center": [0.0, 0.0, 1.0], "radius": 0.9}, [0.0, 0.0, 0.0]),
    "disk": ({"type": "disk", "to_world": [[0.7, 0, 0, 0.3], [0, -0.7, 0, 0], [0, 0, -1, 1.0], [0, 0, 0, 1]]},
             [0.0, 0.0, 0.0]),
    # rotated 135 degrees about x (faces the origin), scaled 0.707 along its y
    "rectangle": ({"type": "rectangle", "to_world": [[1.0, 0, 0, 0], [0, -0.5, -0.7071, 0.2], [0, 0.5, -0.7071, 1.5],
                                                     [0, 0, 0, 1]]}, [0.0, 0.0, 0.0]),
    "cube": ({"type": "cube", "to_world": [[0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 0.5, 2.0], [0, 0, 0, 1]]},
             [0.3, 0.0, 0.0]),
    "constant": (None, [0.0, 0.0, 0.0]),
}
LEVEL = sidak_level(0.01, len(CASES))  # overall significance 0.01 across this file's chi-square tests


def _scene(shape):
    d = {"type": "scene",
         "sensor": {"type": "radiancemeter", "origin": [0, 0, -5], "direction": [0, 0, 1],
                    "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}}
    if shape is None:
        d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [1, 1, 1]}}
    else:
        s = dict(shape)
        if "to_world" in s:
            s["to_world"] = np.array(s["to_world"], float)
        s["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [1, 2, 3]}}
        d["light"] = s
    return rm.load_dict(d).core()


@pytest.mark.parametrize("name", sorted(CASES))
def test_emitter_direction_sampling_chi2(name):
    shape, ref = CASES[name]
    core = _scene(shape)
    ref = np.asarray(ref, np.float32)

    def sample(rng, n):
        s = core.sample_emitter_direction(np.broadcast_to(ref, (n, 3)), rng.random((n, 4), dtype=np.float32))
        return s["d"], s["is_delta"] > 0, s["pdf"] > 0

    def pdf(d):
        return core.pdf_emitter_direction(ref[None, :], np.asarray(d, np.float32))

    # The densities are indicator-like (a light's outline cuts through cells):
    # deeper refinement keeps the cell integrals' error well under the noise.
    # min_depth 6: a sphere sampled by its cone has a constant density that
    # ends at the silhouette; at min_depth 4 the cubature missed slivers of
    # the cone whose nodes all fell outside it (integral 0.99908, the exact
    # 1 within 1e-6 at min_depth 6; a 2e6-direction Monte Carlo estimate
    # of the integral: 1.0008 +- 0.0011).
    r = chi2_test(sample, pdf, n_samples=100_000, grid=SphereGrid(n_theta=20, n_phi=40), seed=7, level=LEVEL,
                  label=name, min_depth=6, max_depth=10, rtol=1e-5, atol=1e-4)
    assert r.passed, r.summary()


def test_emitter_sample_pdf_matches_pdf_of_its_direction():
    """The density a sample reports equals the density of its direction
    (what MIS uses for BSDF-sampled hits), and the radiance it carries is
    the emitter's."""
    core = _scene(CASES["rectangle"][0])
    n = 2000
    ref = np.zeros((n, 3), np.float32)
    s = core.sample_emitter_direction(ref, np.random.default_rng(0).random((n, 4), dtype=np.float32))
    ok = s["pdf"] > 0
    assert ok.mean() > 0.9
    p = core.pdf_emitter_direction(ref[:1], s["d"][ok])
    np.testing.assert_allclose(p, s["pdf"][ok], rtol=2e-3)
    np.testing.assert_array_equal(s["radiance"][ok], np.broadcast_to([1, 2, 3], (int(ok.sum()), 3)))


def test_wrong_emitter_pdf_is_rejected():
    """The test can fail: uniform area sampling of a sphere judged against a
    density 10 % too high on one side is rejected."""
    shape, ref = CASES["sphere"]
    core = _scene(shape)
    ref = np.asarray(ref, np.float32)

    def sample(rng, n):
        s = core.sample_emitter_direction(np.broadcast_to(ref, (n, 3)), rng.random((n, 4), dtype=np.float32))
        return s["d"], s["is_delta"] > 0, s["pdf"] > 0

    def wrong_pdf(d):
        d = np.asarray(d, np.float32)
        p = core.pdf_emitter_direction(ref[None, :], d)
        return np.where(d[:, 0] > 0, p * 1.1, p * 0.9)

    r = chi2_test(sample, wrong_pdf, n_samples=100_000, grid=SphereGrid(n_theta=20, n_phi=40), seed=7, level=0.01)
    assert not r.passed


@pytest.mark.parametrize("count", [5, 60])
def test_mesh_triangle_choice_is_the_binary_search_of_the_area_cdf(tmp_path, count):
    """Mesh::sample_position finds its triangle by a scan of a short area
    CDF (5 triangles) or through a guide table in front of a long one (60:
    the cutpoint method, a scan or a binary search inside the bucket; a run
    of 12 small triangles fills one bucket past the scan's length); it must
    pick the triangle an upper_bound over the whole CDF picks, for every
    u_extra: here at each CDF entry and the floats either side of it, at 0
    and just below 1, and at random. The triangles (one degenerate, areas
    dyadic, so the CDF and the targets u_extra * total are exact in
    float32) lie apart along x in the plane z = 1, facing the reference
    point, so the sampled direction names the triangle."""
    rng = np.random.default_rng(3)
    areas = list(2.0 ** -rng.integers(0, 6, size=count - 1))
    areas[2] = 0.0  # degenerate: never picked
    if count > 20:
        areas[18:30] = [2.0 ** -7] * 12
    total = 2.0 ** np.ceil(np.log2(sum(areas) + 1.0))
    areas.append(total - sum(areas))  # the total a power of 2: u_extra * total is exact
    lines = []
    for i, a in enumerate(areas):
        x, h = 3.0 * i, 2.0 * a  # right triangle of legs 1 and h, normal -z
        lines += [f"v {x} 0 1", f"v {x} {h} 1", f"v {x + 1} 0 1"]
    lines += [f"f {3 * i + 1} {3 * i + 2} {3 * i + 3}" for i in range(len(areas))]
    obj = tmp_path / "strips.obj"
    obj.write_text("\n".join(lines) + "\n")
    core = _scene({"type": "obj", "filename": str(obj)})

    total = np.float32(total)
    cdf = np.cumsum(np.asarray(areas, np.float64)).astype(np.float32)
    u_extra = [np.float32(0.0), np.nextafter(np.float32(1.0), np.float32(0.0))]
    for c in cdf:
        u = np.float32(c / total)
        u_extra += [np.nextafter(u, np.float32(0.0)), u, np.nextafter(u, np.float32(1.0))]
    u_extra = np.asarray(u_extra, np.float32)
    u_extra = u_extra[(u_extra >= 0) & (u_extra < 1)]
    u_extra = np.concatenate([u_extra, rng.random(20000, dtype=np.float32)])
    n = len(u_extra)
    u = np.zeros((n, 4), np.float32)
    u[:, 1:3] = 0.25  # barycentrics (0.75, 0.125, 0.125): inside each triangle
    u[:, 3] = u_extra
    s = core.sample_emitter_direction(np.zeros((n, 3), np.float32), u)
    assert np.all(s["pdf"] > 0)
    x = s["d"][:, 0] / s["d"][:, 2]  # where the direction crosses z = 1
    picked = np.rint((x - 0.125) / 3.0).astype(int)
    target = u_extra * total
    expected = np.minimum(np.searchsorted(cdf, target, side="right"), len(areas) - 1)
    np.testing.assert_array_equal(picked, expected)
    assert 2 not in picked
