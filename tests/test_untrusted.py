"""Untrusted scenes: `load_file(path, base_dir_only=True)` and `radiometer
render --untrusted` confine every file a scene names (meshes, volumes) to
the scene's folder, through `..` and symbolic links, and quote nothing of
those files in errors. A trusted scene (the default) keeps Mitsuba's
behaviour: any readable file, parse errors quoting the offending line."""
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

from radiometer.loader import load_file
from radiometer.scene_desc import SceneError

SECRET = "hunter2-the-secret"
TRI = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _vol():
    return (b"VOL\x03" + struct.pack("<5i", 1, 2, 2, 2, 1) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
            + np.ones(8, "<f4").tobytes())


@pytest.fixture
def tree(tmp_path):
    """scene/ (the scene's folder, with meshes/ below it) and, beside it,
    outside/ holding a secret and a valid mesh; links from inside to outside."""
    scene, outside = tmp_path / "scene", tmp_path / "outside"
    (scene / "meshes").mkdir(parents=True)
    outside.mkdir()
    (scene / "tri.obj").write_bytes(TRI)
    (scene / "meshes" / "tri.obj").write_bytes(TRI)
    (scene / "grid.vol").write_bytes(_vol())
    (outside / "tri.obj").write_bytes(TRI)
    (outside / "grid.vol").write_bytes(_vol())
    # A line an OBJ parser tries to read (other statements it skips).
    (outside / "secret.txt").write_text(f"v {SECRET}\n")
    (scene / "link.obj").symlink_to(outside / "tri.obj")
    (scene / "secret_link.obj").symlink_to(outside / "secret.txt")
    (scene / "out").symlink_to(outside, target_is_directory=True)
    (scene / "inner_link.obj").symlink_to(scene / "meshes" / "tri.obj")  # a link that stays inside
    (scene / "local_secret.obj").write_text(f"password {SECRET}\n")
    return scene, outside


def _write(folder, body, name="scene.xml"):
    path = folder / name
    path.write_text(f'<scene version="3.0.0">\n{body}\n</scene>\n')
    return path


def _mesh(filename, kind="obj"):
    return f'<shape type="{kind}"><string name="filename" value="{filename}"/></shape>'


def _grid(filename):
    return ('<shape type="cube"><bsdf type="null"/><medium type="heterogeneous" name="interior">'
            f'<volume type="gridvolume" name="sigma_t"><string name="filename" value="{filename}"/></volume>'
            '</medium></shape>')


INSIDE = ["tri.obj", "meshes/tri.obj", "./meshes/../tri.obj", "inner_link.obj"]


@pytest.mark.parametrize("name", INSIDE)
def test_files_inside_the_folder_load_in_both_modes(tree, name):
    scene, _ = tree
    path = _write(scene, _mesh(name))
    for untrusted in (False, True):
        desc = load_file(path, base_dir_only=untrusted)
        assert desc.shapes[0].positions.shape == (3, 3)


def test_absolute_name_inside_the_folder_loads(tree):
    scene, _ = tree
    desc = load_file(_write(scene, _mesh(scene / "meshes" / "tri.obj")), base_dir_only=True)
    assert desc.shapes[0].positions.shape == (3, 3)


def _escapes(outside):
    return [("obj", "../outside/tri.obj"), ("obj", "link.obj"), ("obj", "out/tri.obj"),
            ("obj", "meshes/../../outside/tri.obj"), ("obj", str(outside / "tri.obj")),
            ("ply", "../outside/tri.obj"), ("vol", "../outside/grid.vol"), ("vol", "out/grid.vol")]


def test_every_escape_is_refused_when_untrusted_and_loads_when_trusted(tree):
    scene, outside = tree
    for kind, name in _escapes(outside):
        path = _write(scene, _grid(name) if kind == "vol" else _mesh(name, kind))
        with pytest.raises(SceneError) as info:
            load_file(path, base_dir_only=True)
        message = str(info.value)
        assert f"{path}:2:" in message and "lies outside the scene's folder" in message, (name, message)
        assert name in message, message
        if kind != "ply":  # a PLY reader given an OBJ refuses it either way
            load_file(path)  # trusted: Mitsuba's behaviour, any readable file


def test_refusal_says_nothing_about_whether_the_outside_file_exists(tree):
    scene, _ = tree
    there = str(load_file_error(scene, _mesh("../outside/tri.obj")))
    absent = str(load_file_error(scene, _mesh("../outside/absent.obj")))
    assert there.replace("tri.obj", "X") == absent.replace("absent.obj", "X")


def load_file_error(scene, body, **kw):
    with pytest.raises(SceneError) as info:
        load_file(_write(scene, body), base_dir_only=True, **kw)
    return info.value


def test_secret_through_a_link_is_neither_read_nor_quoted(tree):
    scene, _ = tree
    trusted = _write(scene, _mesh("secret_link.obj"))
    with pytest.raises(SceneError) as info:
        load_file(trusted)
    assert SECRET in str(info.value)  # trusted: the parse error quotes the line, as before
    with pytest.raises(SceneError) as info:
        load_file(trusted, base_dir_only=True)
    assert SECRET not in str(info.value) and "lies outside" in str(info.value)


@pytest.mark.parametrize("content", [
    f"vt {SECRET}\n",  # an unparsable line
    f"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {SECRET}\n",  # a bad face index
    f"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9{SECRET[:0]}99\n",  # an out-of-range index
    f"v 0 0 {SECRET}\nf 1 2 3\n",
])
def test_untrusted_errors_quote_no_file_content(tree, content):
    scene, _ = tree
    (scene / "local_secret.obj").write_text(content)
    path = _write(scene, _mesh("local_secret.obj"))
    untrusted = str(load_file_error(scene, _mesh("local_secret.obj")))
    assert "local_secret.obj:" in untrusted  # the file and line are named
    assert SECRET not in untrusted and "999" not in untrusted, untrusted
    with pytest.raises(SceneError) as info:
        load_file(path)
    if "999" in content:
        assert "'999'" in str(info.value)  # trusted: the token is quoted
    else:
        assert SECRET in str(info.value)


def test_untrusted_ply_and_vol_errors_quote_no_header(tree):
    scene, _ = tree
    (scene / "bad.ply").write_text(f"ply\nformat ascii 1.0\nelement {SECRET} 3\nend_header\n")
    message = str(load_file_error(scene, _mesh("bad.ply", "ply")))
    assert "cannot read PLY file" in message and SECRET not in message, message
    vol = bytearray(_vol())
    vol[4:8] = struct.pack("<i", 123456789)  # the encoding field
    (scene / "bad.vol").write_bytes(bytes(vol))
    message = str(load_file_error(scene, _grid("bad.vol")))
    assert "only version 3 float32" in message and "123456789" not in message, message
    with pytest.raises(SceneError, match="123456789"):
        load_file(_write(scene, _grid("bad.vol")))  # trusted: the header's value is named


def test_untrusted_refuses_a_doctype(tree):
    scene, _ = tree
    path = scene / "entities.xml"
    path.write_text('<!DOCTYPE scene [<!ENTITY a "aaaa">]>\n<scene version="3.0.0">\n</scene>\n')
    with pytest.raises(SceneError, match=r"entities\.xml:1: a DOCTYPE declaration is not allowed"):
        load_file(path, base_dir_only=True)
    load_file(path)  # trusted: as before


def test_parameters_cannot_smuggle_a_path_out(tree):
    scene, _ = tree
    path = _write(scene, '<default name="mesh" value="tri.obj"/>\n' + _mesh("$mesh"))
    assert load_file(path, base_dir_only=True).shapes
    with pytest.raises(SceneError, match="lies outside the scene's folder"):
        load_file(path, base_dir_only=True, mesh="../outside/tri.obj")


def test_scene_reached_through_a_link_is_confined_to_the_link_s_folder(tree, tmp_path):
    """The scene's folder is the folder the scene file is named in (where
    relative names resolve), resolved."""
    scene, outside = tree
    _write(scene, _mesh("tri.obj"))
    (outside / "linked_scene.xml").symlink_to(scene / "scene.xml")
    assert load_file(outside / "linked_scene.xml", base_dir_only=True).shapes  # outside/tri.obj is in its folder
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "s.xml").symlink_to(scene / "scene.xml")
    with pytest.raises(SceneError, match="mesh file not found"):
        load_file(tmp_path / "elsewhere" / "s.xml", base_dir_only=True)


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "radiometer.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONWARNINGS": "ignore"})


def test_cli_untrusted_flag(tree):
    scene, _ = tree
    body = (_mesh("secret_link.obj") + '\n<sensor type="perspective"><film type="hdrfilm">'
            '<integer name="width" value="2"/><integer name="height" value="2"/></film></sensor>')
    path = _write(scene, body)
    r = _cli("render", str(path), "--untrusted", "--spp", "1", "-o", str(scene / "out.exr"), cwd=scene)
    assert r.returncode != 0
    assert "lies outside the scene's folder" in r.stderr and SECRET not in r.stderr + r.stdout, r.stderr
    assert not (scene / "out.exr").exists()
    r = _cli("render", str(path), "--spp", "1", "-o", str(scene / "out.exr"), cwd=scene)
    assert r.returncode != 0 and SECRET in r.stderr, r.stderr  # trusted: Mitsuba's behaviour
    ok = _write(scene, body.replace("secret_link.obj", "meshes/tri.obj"), "ok.xml")
    r = _cli("render", str(ok), "--untrusted", "--spp", "1", "-o", str(scene / "ok.exr"), cwd=scene)
    assert r.returncode == 0, r.stderr
    assert (scene / "ok.exr").exists()
