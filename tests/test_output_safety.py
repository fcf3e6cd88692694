"""Outputs: nothing that is not an EXR file of ours is replaced, and an
output that cannot be written is refused before any render time is spent."""
import os

import numpy as np
import pytest

import radiometer as rm
from radiometer import cli


@pytest.fixture
def no_render(monkeypatch):
    """cli.render that fails the test if the CLI gets as far as rendering."""
    def boom(*a, **k):
        raise AssertionError("rendered although the output cannot be written")
    monkeypatch.setattr(cli, "render", boom)


def _img():
    return np.ones((2, 3, 3), np.float32)


def test_fifo_is_refused_and_kept(tmp_path):
    fifo = tmp_path / "pipe.exr"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="not a regular file"):
        rm.write_exr(fifo, None, image=_img())
    assert fifo.is_fifo()


def test_folder_as_output_is_refused(tmp_path):
    d = tmp_path / "out.exr"
    d.mkdir()
    with pytest.raises(ValueError, match="a folder"):
        rm.write_exr(d, None, image=_img())
    assert d.is_dir()


def test_symlink_is_written_through_and_kept(tmp_path):
    target = tmp_path / "real.exr"
    rm.write_exr(target, None, image=_img())
    link = tmp_path / "link.exr"
    link.symlink_to(target)
    rm.write_exr(link, None, image=2 * _img())
    assert link.is_symlink() and os.path.realpath(link) == str(target)
    assert float(rm.read_exr(target).image.mean()) == 2.0


def test_dangling_symlink_into_missing_folder_is_refused(tmp_path):
    link = tmp_path / "link.exr"
    link.symlink_to(tmp_path / "nowhere" / "x.exr")
    with pytest.raises(FileNotFoundError, match="nowhere"):
        rm.write_exr(link, None, image=_img())


@pytest.mark.parametrize("make", ["fifo", "folder"])
def test_cli_refuses_before_rendering(tmp_path, capsys, no_render, make):
    out = tmp_path / "o.exr"
    os.mkfifo(out) if make == "fifo" else out.mkdir()
    rc = cli.main(["render", "cornell-box", "--spp", "1", "-o", str(out)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "-o:" in err and str(out) in err


def test_cli_still_renders_to_a_plain_path(tmp_path, monkeypatch):
    """The guard lets an ordinary path through (the control for the test above)."""
    calls = []

    def fake(*a, **k):
        calls.append(1)
        raise SystemExit(0)
    monkeypatch.setattr(cli, "render", fake)
    with pytest.raises(SystemExit):
        cli.main(["render", "cornell-box", "--spp", "1", "-o", str(tmp_path / "fine.exr")])
    assert calls == [1]


def test_truncated_exr_names_the_file(tmp_path):
    p = tmp_path / "whole.exr"
    rng = np.random.default_rng(1)
    rm.write_exr(p, None, image=rng.random((64, 64, 3), dtype=np.float32))
    data = p.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="cut.exr is truncated or corrupt"):
        rm.read_exr(cut)
    assert rm.read_exr(p).image.shape == (64, 64, 3)
