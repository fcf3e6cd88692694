"""The report's 3D view of a cache's records: the runner keeps an irrcache
job's records beside its EXR, the report draws them on the scene (pyvista
off screen) and links the figure; the view puts each record where it is
and colours it by its own irradiance. Small renders; no timing."""
from pathlib import Path

import numpy as np
import pytest

from radiometer.benchmarks import runner
from radiometer.benchmarks.store import Store

pytest.importorskip("pyvista")

TINY = """
name = "tinycache"
seeds = [0, 1]
budgets = [{ spp = 2 }]
[scenes.cornell_box]
[estimators.path]
[estimators.irrcache]
gather_resolution = 3
[effect_refs]
spp = 2
"""

COLUMNS = ["x", "y", "z", "nx", "ny", "nz", "radius", "E_r", "E_g", "E_b"]


def _png(path: Path) -> np.ndarray:
    import matplotlib.image as mpimg

    return np.asarray(mpimg.imread(str(path)), np.float64)[..., :3]


def _viridis_ends(img):
    """Masks of pixels near viridis' top (yellow) and bottom (dark purple)."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    yellow = (r > 0.7) & (g > 0.6) & (b < 0.4)
    purple = (r > 0.15) & (r < 0.45) & (g < 0.2) & (b > 0.25) & (b < 0.55)
    return yellow, purple


def _cornell():
    import radiometer as rm
    from radiometer.reference_scenes import registry as S

    return rm.load_file(S.get("cornell_box").xml, res=64, max_depth=8)


def test_records_view_puts_records_where_they_are_coloured_by_their_irradiance(tmp_path):
    """Records on a plane facing the camera, bright on the camera's left and
    dark on its right: in the view from the camera (the left panel) the left
    part shows the colour map's bright end and the right part its dark end.
    A view that mirrored the records, ignored their positions or coloured
    them by anything but their irradiance fails."""
    from radiometer.analysis.report import records_view

    desc = _cornell().desc
    m = np.asarray(desc.sensor.to_world, np.float64)
    o, fwd, up, left = m[:3, 3], m[:3, 2], m[:3, 1], m[:3, 0]
    s, v = np.meshgrid(np.linspace(-1, 1, 24), np.linspace(-1, 1, 24))
    keep = np.abs(s.ravel()) > 0.1
    s, v = s.ravel()[keep], v.ravel()[keep]
    pos = o + 2.0 * fwd + 0.5 * (s[:, None] * left + v[:, None] * up)
    e = np.where(s > 0, 1.0, 1e-3)
    rec = np.column_stack([pos, np.tile(-fwd, (len(s), 1)), np.full(len(s), 0.03), e, e, e])
    out = tmp_path / "records.png"
    assert records_view(desc, rec, COLUMNS, out, size=(800, 400)) is None
    img = _png(out)
    h, w = img.shape[:2]
    yellow, purple = _viridis_ends(img)
    cam = slice(0, w // 2)  # the view from the scene's camera
    lhs, rhs = (slice(0, w // 4), slice(w // 4, w // 2))
    assert yellow[:, lhs].sum() > 200 and purple[:, rhs].sum() > 200, (yellow[:, cam].sum(), purple[:, cam].sum())
    assert yellow[:, rhs].sum() < 0.1 * yellow[:, lhs].sum()
    assert purple[:, lhs].sum() < 0.1 * purple[:, rhs].sum()
    # The same records with their irradiance swapped swap the colours.
    rec[:, 7:] = np.where(s > 0, 1e-3, 1.0)[:, None]
    assert records_view(desc, rec, COLUMNS, out, size=(800, 400)) is None
    yellow, purple = _viridis_ends(_png(out))
    assert yellow[:, rhs].sum() > 200 and yellow[:, lhs].sum() < 0.1 * yellow[:, rhs].sum()


def test_records_view_says_why_when_there_are_no_records(tmp_path):
    from radiometer.analysis.report import records_view

    why = records_view(_cornell().desc, np.zeros((0, 10)), COLUMNS, tmp_path / "none.png")
    assert why and "no records" in why
    assert not (tmp_path / "none.png").exists()


@pytest.fixture(scope="module")
def cache_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("cacheview")
    mat = root / "tiny.toml"
    mat.write_text(TINY)
    run_id = runner.run(str(mat), root=root, workers=2, progress=False, log=lambda *a: None)
    with Store(root / runner.STORE_NAME) as st:
        recs = st.jobs(run_id)
    return root, run_id, recs


def test_runner_keeps_the_records_of_a_cache_job(cache_run):
    root, _, recs = cache_run
    by = {r["estimator"]: r for r in recs if r["seed"] == 0}
    assert by["path"]["status"] == by["irrcache"]["status"] == "ok"
    assert "arrays" not in by["path"]
    a = by["irrcache"]["arrays"]["irrcache_records"]
    assert a["columns"] == COLUMNS
    rec = np.load(root / a["npy"])
    assert rec.shape == (a["rows"], 10) and a["rows"] > 50
    assert a["rows"] == by["irrcache"]["stats"]["irrcache_computed"]
    # Records lie in the box with unit normals and positive radii.
    assert np.all(np.abs(rec[:, :3]) <= 1.0 + 1e-5)
    assert np.allclose(np.linalg.norm(rec[:, 3:6], axis=1), 1.0, atol=1e-5)
    assert np.all(rec[:, 6] > 0) and np.all(rec[:, 7:] >= 0)


def test_report_shows_the_records_of_irrcache_jobs_only(cache_run, tmp_path):
    import re

    from radiometer.benchmarks import report

    root, run_id, recs = cache_run
    index = report.write(root / runner.STORE_NAME, run_id, out_dir=tmp_path / "rep", log=lambda *a: None)
    page = index.read_text()
    imgs = re.findall(r"<img src='([^']+)'", page)
    assert "cornell_box-irrcache-records.png" in imgs, imgs
    assert not any("path-records" in i for i in imgs)
    img = _png(index.parent / "cornell_box-irrcache-records.png")
    assert img.shape[0] > 100 and float(img.std()) > 0.05
    yellow, purple = _viridis_ends(img)
    assert yellow.sum() > 0 and purple.sum() > 0  # the irradiance spans the colour map
    # The bias map of the two seeds' mean, for the cache estimator only.
    assert "cornell_box-irrcache-bias.png" in imgs and not any("path-bias" in i for i in imgs)
    assert float(_png(index.parent / "cornell_box-irrcache-bias.png").std()) > 0.05
    # Every image of the page decodes in a browser (the page's own load check).
    from test_bench import chromium_check

    console, dom = chromium_check(index)
    assert not console, console
    m = re.search(r'data-images-ok="(\d+)" data-images-total="(\d+)"', dom)
    assert m and int(m.group(1)) == int(m.group(2)) == len(imgs), dom[:2000]
    # Without the records file the report says so in the figure's place.
    irr = next(r for r in recs if r["estimator"] == "irrcache" and r["seed"] == 0)
    npy = root / irr["arrays"]["irrcache_records"]["npy"]
    kept = npy.read_bytes()
    npy.unlink()
    try:
        index = report.write(root / runner.STORE_NAME, run_id, out_dir=tmp_path / "rep2", log=lambda *a: None)
    finally:
        npy.write_bytes(kept)
    page = index.read_text()
    assert "cornell_box-irrcache-records.png" not in page
    assert "no view of irrcache" in page


# -- the study of what caching buys (benchmarks/studies/cache_wins.py) -------------------------


def test_cache_wins_matrix_parses():
    from radiometer.benchmarks import matrix as MX
    from radiometer.benchmarks.studies import cache_wins

    m = MX.load(str(cache_wins.MATRIX))
    assert {j.scene for j in m.jobs} == {"cornell_box", "ajar_door", "corner_room"}
    assert {j.estimator for j in m.jobs} == {"path", "photonmapper", "irrcache", "radcache"}
    assert len(m.jobs) == 3 * 4 * 2


@pytest.mark.parametrize("floor", [0.0, 1e-4, 3e-3])
def test_floor_fit_recovers_a_known_bias_and_noise(floor):
    """e(n) = B + V / n with a few per cent of multiplicative noise: the fit
    returns B and V, and the time path needs to reach B comes from its own
    curve (or its slope -1 past the last checkpoint)."""
    from radiometer.benchmarks.studies.cache_wins import fit_floor, resolved, time_to

    rng = np.random.default_rng(7)
    v = 0.2
    n = 2.0 ** np.arange(0, 13)
    curve = [(int(k), 0.01 * k, (floor + v / k) * float(np.exp(rng.normal(0, 0.03)))) for k in n]
    bb, vv = fit_floor(curve)
    assert abs(vv - v) < 0.1 * v
    assert abs(bb - floor) < 0.15 * floor + 5e-6
    ratio = curve[-1][2] / curve[-2][2]
    word = resolved([{"last_doubling_ratio": ratio}])
    assert word == ("falling" if floor == 0 else "flat" if floor == 3e-3 else "bending"), (word, ratio)
    path = [(int(k), 0.01 * k, v / k) for k in n]  # unbiased: 0.2 / spp, 0.01 s per spp
    t, extrapolated = time_to(path, 1e-3)
    assert not extrapolated and abs(t - 2.0) < 1e-9
    t, extrapolated = time_to(path, 1e-5)
    assert extrapolated and abs(t - 200.0) < 1e-6


def test_bias_maps_show_a_known_bias_and_average_noise_out_in_blocks():
    """Two 'seeds' = reference x 1.1 plus independent noise: the block map
    reads the +10 % (of luminance over luminance + eps) far more closely
    than the pixel map, and a bias of the other sign reads negative."""
    from radiometer.analysis.report import bias_maps

    rng = np.random.default_rng(3)
    ref = np.full((32, 32, 3), 0.5)
    want = 0.05 / (0.5 + 0.01)
    ims = [1.1 * ref + rng.normal(0, 0.1, ref.shape) for _ in range(2)]
    pix, blk = bias_maps(ims, ref)
    assert blk.shape == (8, 8) and pix.shape == (32, 32)
    assert abs(float(blk.mean()) - want) < 0.02
    assert np.sqrt(np.mean((blk - want) ** 2)) < 0.35 * np.sqrt(np.mean((pix - want) ** 2))
    _, blk = bias_maps([0.9 * ref, 0.9 * ref], ref)
    assert np.allclose(blk, -want)
