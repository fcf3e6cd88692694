"""EXR files (image, variance and effects as layers of one file) and the
`radiometer render` command."""
import subprocess
import sys

import numpy as np
import pytest

import radiometer as rm


def test_exr_round_trip_keeps_every_layer_and_metadata(tmp_path, small_cornell):
    res = rm.render(small_cornell, spp=4, seed=3)
    path = tmp_path / "r.exr"
    rm.write_exr(path, res, scene="cornell")
    back = rm.read_exr(path)
    np.testing.assert_array_equal(back.image, res.image)
    np.testing.assert_array_equal(back.variance, res.variance)
    assert set(back.effects) == set(rm.EFFECTS)
    for k in rm.EFFECTS:
        np.testing.assert_array_equal(back.effects[k], res.effects[k])
    assert back.metadata["spp"] == 4
    assert back.metadata["seed"] == res.seed  # 3, or what RADIOMETER_SEED_OFFSET made of it
    assert back.metadata["seconds"] == pytest.approx(res.seconds, rel=0, abs=0)
    assert back.metadata["scene"] == "cornell"
    # OpenEXR's header ints are 32-bit; a seed goes up to 2^64 and comes back exact.
    wide = tmp_path / "wide.exr"
    rm.write_exr(wide, res, seed=(1 << 64) - 1, small=-(1 << 31))
    assert rm.read_exr(wide).metadata["seed"] == (1 << 64) - 1
    assert rm.read_exr(wide).metadata["small"] == -(1 << 31)
    assert '"type": "path"' in back.metadata["integrator"]


def test_exr_non_contiguous_and_bad_input(tmp_path):
    a = np.random.default_rng(0).random((6, 5, 3), dtype=np.float32)
    v = np.asfortranarray(a * 2)  # a strided layout must still land right
    rm.write_exr(tmp_path / "a.exr", None, image=a[:, :, :], variance=v)
    back = rm.read_exr(tmp_path / "a.exr")
    np.testing.assert_array_equal(back.image, a)
    np.testing.assert_array_equal(back.variance, v)
    with pytest.raises(ValueError, match="image must have shape"):
        rm.write_exr(tmp_path / "b.exr", None, image=np.zeros((4, 4)))
    with pytest.raises(FileNotFoundError):
        rm.read_exr(tmp_path / "missing.exr")
    (tmp_path / "junk.exr").write_bytes(b"not an exr")
    with pytest.raises(ValueError, match="not a readable EXR"):
        rm.read_exr(tmp_path / "junk.exr")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        rm.write_exr(tmp_path / "no" / "dir.exr", None, image=a)


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "radiometer.cli", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_cli_render_writes_exr(tmp_path, cornell_path):
    small = tmp_path / "small.xml"
    small.write_text(cornell_path.read_text().replace('value="256"', 'value="16"'))
    out = tmp_path / "o.exr"
    r = _cli("render", str(small), "--spp", "4", "-i", '{"type": "path", "max_depth": 3}', "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "4 spp" in r.stdout and "NaN samples 0" in r.stdout
    img = rm.read_exr(out)
    assert img.image.shape == (16, 16, 3) and img.metadata["spp"] == 4
    assert '"max_depth": 3' in img.metadata["integrator"]


@pytest.mark.parametrize("args,match", [
    (["render", "no_such_scene"], "not a canonical scene"),
    (["render", "cornell-box", "-i", "nosuch"], "unknown estimator"),
    (["render", "cornell-box", "--spp", "-4"], "spp"),
    (["render", "cornell-box", "--effects", "glow"], "unknown effect class 'glow'"),
])
def test_cli_errors_are_clear(tmp_path, args, match):
    r = _cli(*args, "-o", str(tmp_path / "x.exr"))
    assert r.returncode == 2
    assert match in r.stderr
    assert "Traceback" not in r.stderr


def test_cli_bench_names_a_missing_matrix(tmp_path):
    """(The harness itself is tested in test_bench.py; here only that the
    command exists and fails clearly, without running the default matrix.)"""
    r = _cli("bench", "no_such_matrix", "--results", str(tmp_path))
    assert r.returncode == 2 and "no_such_matrix" in r.stderr and "smoke" in r.stderr
    assert "Traceback" not in r.stderr


def test_cli_refs_regenerates_a_reference(tmp_path):
    pytest.importorskip("mitsuba", reason="the references are made with Mitsuba 3")
    r = _cli("refs", "cornell_box", "--runs", "2", "--spp", "2", "--out-dir", str(tmp_path))
    assert r.returncode == 0, r.stderr
    ref = rm.read_exr(tmp_path / "cornell_box" / "reference.exr")
    assert ref.image.shape == (64, 64, 3) and ref.variance is not None
    assert ref.metadata["runs"] == 2 and ref.metadata["total_spp"] == 4
    assert ref.metadata["mitsuba_version"].startswith("3.")
    # A second resolution the registry declares: its own file, its own size.
    r = _cli("refs", "cornell_box", "--res", "128", "--runs", "2", "--spp", "1", "--out-dir", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert rm.read_exr(tmp_path / "cornell_box" / "reference_128.exr").image.shape == (128, 128, 3)
    listing = _cli("refs", "--list")
    assert "cornell_box" in listing.stdout and "'res': 128" in listing.stdout
    bad = _cli("refs", "no_such_scene")
    assert bad.returncode == 2 and "no Mitsuba reference is defined for no_such_scene" in bad.stderr
    bad = _cli("refs", "cornell_box", "--res", "96", "--out-dir", str(tmp_path))
    assert bad.returncode == 2 and "cornell_box: no Mitsuba reference at res = 96" in bad.stderr
    assert "Traceback" not in bad.stderr
