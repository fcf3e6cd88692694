"""What Mitsuba 3's own scene files need from the XML front end, beyond
the subset of test_loader.py: every version from 2.0.0 on (and older ones
after Mitsuba's upgrade rules), <path>, <include> (cycles, file:line of
errors inside included files), the `moment` integrator, and the film's
crop window and sample_border. The crop renders are compared byte for
byte with the window of the full render: a pixel of the window keeps its
film index and with it its random streams (camera samples and light paths
alike), so with the box filter every number is the same, not just its
distribution; a z-test would pass a wrong crop whose error hides in noise.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import radiometer as rm
from radiometer.loader import SceneError, load_dict, load_file

SUITE = Path(__file__).resolve().parents[1].parent / "shared" / "peers" / "mitsuba-data"

TRI_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _scene(version, body):
    return f'<scene version="{version}">\n{body}\n</scene>\n'


# -- versions -------------------------------------------------------------------


@pytest.mark.parametrize("version", ["2.0.0", "2.1.0", "3.0.0", "3.5.2", "4.0.0"])
def test_versions_from_2_load(tmp_path, version):
    body = '<shape type="sphere"><float name="radius" value="2"/></shape>'
    desc = load_file(_write(tmp_path / "s.xml", _scene(version, body)))
    assert desc.shapes[0].radius == 2.0


def test_version_0x_is_upgraded_as_mitsuba_does(tmp_path):
    """Mitsuba 3's upgrade_tree for files older than 2.0.0: camelCase names to
    underscore_case, <lookAt> to <lookat>, diffuse's diffuse_reflectance to
    reflectance; the file then means what its 3.x form means."""
    old = """<integrator type="path"><integer name="maxDepth" value="3"/></integrator>
<sensor type="perspective"><float name="nearClip" value="0.5"/>
  <transform name="toWorld"><lookAt origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
</sensor>
<shape type="sphere"><bsdf type="diffuse"><rgb name="diffuseReflectance" value="0.2 0.3 0.4"/></bsdf></shape>
<shape type="sphere"><subsurface type="dipole"><rgb name="sigmaA" value="0.1"/><rgb name="sigmaS" value="1"/>
    <float name="intIOR" value="1.4"/></subsurface></shape>"""
    new = """<integrator type="path"><integer name="max_depth" value="3"/></integrator>
<sensor type="perspective"><float name="near_clip" value="0.5"/>
  <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
</sensor>
<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.2 0.3 0.4"/></bsdf></shape>
<shape type="sphere"><subsurface type="dipole"><rgb name="sigma_a" value="0.1"/><rgb name="sigma_s" value="1"/>
    <float name="int_ior" value="1.4"/></subsurface></shape>"""
    a = load_file(_write(tmp_path / "old.xml", _scene("0.6.0", old)))
    b = load_file(_write(tmp_path / "new.xml", _scene("3.0.0", new)))
    assert a.integrator == b.integrator and a.integrator.params == {"max_depth": 3}
    assert np.array_equal(a.sensor.to_world, b.sensor.to_world) and a.sensor.near_clip == 0.5
    assert a.shapes[0].bsdf.reflectance == b.shapes[0].bsdf.reflectance == (0.2, 0.3, 0.4)
    sa, sb = a.shapes[1].subsurface, b.shapes[1].subsurface
    assert sa.sigma_a == sb.sigma_a and sa.sigma_s == sb.sigma_s and sa.int_ior == 1.4
    # A 3.x file is not upgraded: the 0.x name is an unknown parameter there.
    with pytest.raises(SceneError, match=r"new2.xml:2: .*unknown parameter 'nearClip'"):
        load_file(_write(tmp_path / "new2.xml", _scene("3.0.0", '<sensor type="perspective">'
                                                        '<float name="nearClip" value="0.5"/></sensor>')))


@pytest.mark.parametrize("text", ["2.0", "3", "2.0.0.1", "x.0.0", "3.0.0-rc1", ""])
def test_bad_version_strings(tmp_path, text):
    with pytest.raises(SceneError, match=r"s.xml:1: <scene>: cannot parse version"):
        load_file(_write(tmp_path / "s.xml", _scene(text, "")))


# -- <path> ---------------------------------------------------------------------


def test_path_resolves_relative_names(tmp_path):
    """A <path> folder is searched before the scene's own; a later <path>
    before an earlier one; a relative <path> is taken from the folder of
    the file declaring it (as Mitsuba's Tag::Resource)."""
    _write(tmp_path / "assets" / "a" / "m.obj", TRI_OBJ)
    _write(tmp_path / "assets" / "b" / "m.obj", TRI_OBJ.replace("v 1 0 0", "v 2 0 0"))
    _write(tmp_path / "scenes" / "m.obj", TRI_OBJ.replace("v 1 0 0", "v 3 0 0"))
    mesh = '<shape type="obj"><string name="filename" value="m.obj"/></shape>'

    def xmax(paths):
        body = "".join(f'<path value="{p}"/>' for p in paths) + mesh
        desc = load_file(_write(tmp_path / "scenes" / "s.xml", _scene("2.0.0", body)))
        return float(np.asarray(desc.shapes[0].positions)[:, 0].max())

    assert xmax([]) == 3.0  # the scene's folder
    assert xmax(["../assets/a"]) == 1.0
    assert xmax(["../assets/a", "../assets/b"]) == 2.0  # the later <path> first
    assert xmax([str(tmp_path / "assets" / "b")]) == 2.0  # absolute
    # A name found in none of them: the error says where it looked last (the scene's folder).
    body = '<path value="../assets/a"/>\n<shape type="obj"><string name="filename" value="nope.obj"/></shape>'
    with pytest.raises(SceneError, match=r"s.xml:3: shape 'obj': mesh file not found: 'nope.obj'"):
        load_file(_write(tmp_path / "scenes" / "s.xml", _scene("3.0.0", body)))


def test_path_errors_carry_the_place(tmp_path):
    with pytest.raises(SceneError, match=r"s.xml:3: <path>: folder 'missing' not found"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", '\n<path value="missing"/>')))
    with pytest.raises(SceneError, match=r"s.xml:2: <path>: unknown attribute 'name'"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", '<path value="." name="x"/>')))
    with pytest.raises(SceneError, match=r"s.xml:3: <path> is allowed only at the top level"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", '<shape type="sphere">\n<path value="."/>\n'
                                                               '</shape>')))


# -- <include> ------------------------------------------------------------------


def test_include_splices_the_included_scene(tmp_path):
    """An included <scene>'s children join the including scene where the
    <include> stands: its <default>s, its <path>s, its plugins; an included
    non-scene root is that one element (here a bsdf nested in a shape)."""
    _write(tmp_path / "inc" / "preamble.xml", _scene("2.0.0", '<default name="res" value="24"/>'))
    _write(tmp_path / "inc" / "bsdf.xml", '<bsdf type="diffuse"><rgb name="reflectance" value="0.25"/></bsdf>')
    _write(tmp_path / "inc" / "cam.xml", _scene("2.0.0", '<sensor type="perspective"><film type="hdrfilm">'
                                                            '<integer name="width" value="$res"/>'
                                                            '<integer name="height" value="$res"/></film></sensor>'))
    body = """<include filename="inc/preamble.xml"/>
<include filename="inc/cam.xml"/>
<shape type="sphere"><include filename="inc/bsdf.xml"/></shape>"""
    desc = load_file(_write(tmp_path / "s.xml", _scene("2.0.0", body)))
    assert (desc.sensor.width, desc.sensor.height) == (24, 24)
    assert desc.shapes[0].bsdf.reflectance == (0.25, 0.25, 0.25)
    # The caller's value overrides the included <default>.
    assert load_file(tmp_path / "s.xml", res=8).sensor.width == 8
    # A <scene> included inside a plugin gives that plugin its children; a
    # <path> there is not at the top level.
    _write(tmp_path / "inc" / "parts.xml", _scene("2.0.0", '<float name="radius" value="3"/><bsdf type="null"/>'))
    desc = load_file(_write(tmp_path / "s2.xml", _scene("3.0.0", '<shape type="sphere">'
                                                                  '<include filename="inc/parts.xml"/></shape>')))
    assert desc.shapes[0].radius == 3.0 and desc.shapes[0].bsdf.type == "null"
    _write(tmp_path / "inc" / "path.xml", _scene("2.0.0", '<path value="."/>'))
    with pytest.raises(SceneError, match=r"path.xml:2: <path> is allowed only at the top level"):
        load_file(_write(tmp_path / "s3.xml", _scene("3.0.0", '<shape type="sphere">'
                                                              '<include filename="inc/path.xml"/></shape>')))


def test_errors_inside_included_files_name_that_file_and_line(tmp_path):
    _write(tmp_path / "frag.xml", _scene("2.0.0", '<shape type="sphere">\n'
                                                  '<float name="radius" value="-1"/>\n</shape>'))
    with pytest.raises(SceneError) as info:
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", '<include filename="frag.xml"/>')))
    assert str(info.value).startswith(f"{tmp_path / 'frag.xml'}:3: shape 'sphere'"), str(info.value)
    _write(tmp_path / "bad.xml", _scene("2.0.0", "<shape type='sphere'>"))
    with pytest.raises(SceneError, match=r"bad.xml:\d+: malformed XML"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", '<include filename="bad.xml"/>')))
    with pytest.raises(SceneError, match=r"s.xml:3: <include>: file 'none.xml' not found"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", '\n<include filename="none.xml"/>')))


def test_include_cycles_are_refused(tmp_path):
    _write(tmp_path / "a.xml", _scene("3.0.0", '<include filename="b.xml"/>'))
    _write(tmp_path / "b.xml", _scene("3.0.0", '\n<include filename="a.xml"/>'))
    with pytest.raises(SceneError) as info:
        load_file(tmp_path / "a.xml")
    msg = str(info.value)
    assert msg.startswith(f"{tmp_path / 'b.xml'}:3: <include>: include cycle"), msg
    assert f"{tmp_path / 'a.xml'}:2 includes" in msg and "already being read" in msg, msg
    # A file including itself, through a symbolic link to it.
    os.symlink(tmp_path / "c.xml", tmp_path / "c_link.xml")
    _write(tmp_path / "c.xml", _scene("3.0.0", '<include filename="c_link.xml"/>'))
    with pytest.raises(SceneError, match="include cycle"):
        load_file(tmp_path / "c.xml")
    # The same file twice, without a cycle, is fine (and ids then clash as they would written out).
    _write(tmp_path / "sphere.xml", _scene("3.0.0", '<shape type="sphere"/>'))
    _write(tmp_path / "twice.xml", _scene("3.0.0", '<include filename="sphere.xml"/><include filename="sphere.xml"/>'))
    assert len(load_file(tmp_path / "twice.xml").shapes) == 2


def test_include_depth_is_bounded(tmp_path):
    for i in range(20):
        _write(tmp_path / f"i{i}.xml", _scene("3.0.0", f'<include filename="i{i + 1}.xml"/>'))
    _write(tmp_path / "i20.xml", _scene("3.0.0", ""))
    with pytest.raises(SceneError, match="includes nested deeper than 15 levels"):
        load_file(tmp_path / "i0.xml")


def test_untrusted_include_and_path_stay_inside(tmp_path):
    _write(tmp_path / "outside" / "frag.xml", _scene("3.0.0", '<shape type="sphere"/>'))
    _write(tmp_path / "scene" / "frag.xml", _scene("3.0.0", '<shape type="sphere"/>'))
    s = _write(tmp_path / "scene" / "s.xml", _scene("3.0.0", '<include filename="../outside/frag.xml"/>'))
    assert len(load_file(s).shapes) == 1
    with pytest.raises(SceneError, match="outside the scene's folder"):
        load_file(s, base_dir_only=True)
    s = _write(tmp_path / "scene" / "s.xml", _scene("3.0.0", '<path value="../outside"/>'))
    with pytest.raises(SceneError, match="outside the scene's folder"):
        load_file(s, base_dir_only=True)
    s = _write(tmp_path / "scene" / "s.xml", _scene("3.0.0", '<include filename="frag.xml"/>'))
    assert len(load_file(s, base_dir_only=True).shapes) == 1


# -- moment ---------------------------------------------------------------------


def test_moment_is_its_nested_integrator(tmp_path):
    body = ('<integrator type="moment"><integrator type="volpath"><integer name="max_depth" value="6"/>'
            '</integrator></integrator>')
    desc = load_file(_write(tmp_path / "s.xml", _scene("2.0.0", body)))
    assert desc.integrator.type == "volpath" and desc.integrator.params == {"max_depth": 6}
    d = load_dict({"type": "scene", "i": {"type": "moment", "nested": {"type": "path", "max_depth": 2}}})
    assert d.integrator.type == "path" and d.integrator.params == {"max_depth": 2}
    two = '<integrator type="moment">\n<integrator type="path"/><integrator type="direct"/></integrator>'
    with pytest.raises(SceneError, match=r"s.xml:2: integrator 'moment': needs exactly one nested integrator"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", two)))
    param = '<integrator type="moment">\n<integer name="max_depth" value="2"/><integrator type="path"/></integrator>'
    with pytest.raises(SceneError, match=r"s.xml:3: integrator 'moment': unknown parameter 'max_depth'"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", param)))
    # The nested integrator's own checks keep their place.
    bad = '<integrator type="moment"><integrator type="path">\n<integer name="max_depth" value="-5"/>' \
          '</integrator></integrator>'
    with pytest.raises(SceneError, match=r"s.xml:3: .*max_depth"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", bad)))


# -- film: crop window and sample_border ---------------------------------------------


def _crop_scene(rfilter="box", **film):
    cam = np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1.0]])
    floor = np.diag([3.0, 3.0, 1.0, 1.0]) @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -2], [0, 0, 0, 1.0]])
    rf = {"type": rfilter}
    return rm.Scene(load_dict({
        "type": "scene",
        "ball": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]}},
        "floor": {"type": "rectangle", "to_world": floor},
        "glass": {"type": "sphere", "center": [1.2, 0.8, 1], "radius": 0.5, "bsdf": {"type": "dielectric"}},
        "lamp": {"type": "point", "position": [0, 1, 4], "intensity": 20},
        "cam": {"type": "perspective", "to_world": cam,
                "film": {"type": "hdrfilm", "width": 16, "height": 12, "rfilter": rf, **film}}}))


CROP = {"crop_offset_x": 3, "crop_offset_y": 2, "crop_width": 7, "crop_height": 5}
WINDOW = (slice(2, 7), slice(3, 10))


# Merging-only estimators get enough light paths per iteration that the
# window is lit whatever the seed (at the default, the pixel count, some
# seeds left it black under fresh seed offsets: merges are found by chance).
MERGE_ONLY = {"light_paths": 8192}


@pytest.mark.parametrize("integrator", ["path", "ptracer", "bdpt", "sppm", "vcm", "bpm", "ppm"])
def test_crop_is_the_window_of_the_full_render(integrator):
    if integrator in ("bpm", "ppm"):
        integrator = dict(MERGE_ONLY, type=integrator)
    full = rm.render(_crop_scene(), integrator=integrator, spp=4, seed=3, threads=2)
    crop = rm.render(_crop_scene(**CROP), integrator=integrator, spp=4, seed=3, threads=2)
    assert crop.image.shape == (5, 7, 3) and crop.variance.shape == (5, 7, 3)
    assert np.array_equal(crop.image, full.image[WINDOW])
    assert np.array_equal(crop.variance, full.variance[WINDOW], equal_nan=True)
    for k, img in crop.effects.items():
        assert np.array_equal(img, full.effects[k][WINDOW]), k
    assert crop.image.max() > 0  # the window sees the lit ball: the comparison compares something


def test_crop_with_a_wider_filter_truncates_at_the_window():
    """sample_border = false (Mitsuba's default): samples stay inside the crop
    window, so pixels whose tent footprint crosses the window's edge differ
    from the full render, and the rest are the same bytes."""
    full = rm.render(_crop_scene("tent"), integrator="path", spp=4, seed=1, threads=2)
    crop = rm.render(_crop_scene("tent", **CROP), integrator="path", spp=4, seed=1, threads=2)
    win = full.image[WINDOW]
    assert np.array_equal(crop.image[1:-1, 1:-1], win[1:-1, 1:-1])
    assert not np.array_equal(crop.image[0], win[0])


def test_crop_checks_and_sample_border(tmp_path):
    desc = _crop_scene(**CROP).desc.sensor
    assert (desc.width, desc.height, desc.crop_x, desc.crop_y, desc.crop_width, desc.crop_height) == \
        (16, 12, 3, 2, 7, 5)
    # Mitsuba's defaults: the full film (stored as 0: the full film whatever its size).
    assert (_crop_scene().desc.sensor.crop_width, _crop_scene(crop_offset_x=0).desc.sensor.crop_width) == (0, 0)
    with pytest.raises(SceneError, match=r"crop_offset_y \+ crop_height = 2 \+ 11 exceeds the film's height 12"):
        _crop_scene(crop_offset_y=2, crop_height=11)
    with pytest.raises(SceneError, match=r"crop_offset_x \+ crop_width = 4 \+ 16 exceeds"):
        _crop_scene(crop_offset_x=4)  # crop_width defaults to the film's width, as in Mitsuba
    # sample_border: no border for the box filter (as Mitsuba), refused for the others.
    a = rm.render(_crop_scene(sample_border=True, **CROP), spp=2, threads=1)
    b = rm.render(_crop_scene(**CROP), spp=2, threads=1)
    assert np.array_equal(a.image, b.image)
    film = ('<sensor type="perspective"><film type="hdrfilm">\n<boolean name="sample_border" value="true"/>'
            '<rfilter type="gaussian"/></film></sensor>')
    with pytest.raises(SceneError, match=r"s.xml:3: film 'hdrfilm': sample_border = true with the 'gaussian'"):
        load_file(_write(tmp_path / "s.xml", _scene("3.0.0", film)))


# -- the suite itself -----------------------------------------------------------------


@pytest.mark.skipif(not (SUITE / "tests" / "scenes").is_dir(), reason="../shared/peers/mitsuba-data absent")
def test_suite_scenes_get_past_the_format():
    """Every scene of Mitsuba's suite now loads or stops at a plugin feature
    (a SceneError naming it, at a file:line), never at the format: version,
    <path>, <include>, moment."""
    from radiometer.benchmarks.studies.mitsuba_suite import survey

    rows = survey(SUITE)
    assert len(rows) == 41
    for r in rows:
        assert not any(w in r["status"] for w in ("<scene>", "<path>", "<include>", "integrator 'moment'",
                                                  "integrator type 'moment'")), r
    loads = {r["scene"] for r in rows if r["status"] == "loads"}
    # Measured 2026-12-04: 7 of 41 load; roughplastic brought the two
    # bsdf_spheres/test_roughplastic_* scenes. Textures (checkerboard,
    # bitmap, textured roughconductor alphas, the spot's projected texture)
    # then brought 14 more, 21 of 41: the four textured bsdf_spheres /
    # texture_interp / spot_light scenes below and ten participating_media
    # scenes, which stopped at their checkerboard floor
    # (benchmarks/results/mitsuba_suite.json: 20 of the 21 pass Mitsuba's
    # protocol since volpath treats thindielectric's straight-through lobe
    # as a null event, as Mitsuba 3's volpath does (three media scenes with
    # thindielectric medium spheres, test_thindielectric_medium_boundaries_
    # as_mitsuba below: 265 / 1024 / 1444 rejected before, 3 / 2 / 2 now);
    # hetero_sigmat_albedo's 49 rejected of 17.3, image mean 0.9985, are
    # not explained). Shapegroup + instance and a constvolume's to_world
    # brought 2 more (both pass, tests/test_shapes.py); principled and
    # principledthin three more (each passes Mitsuba's protocol:
    # tests/test_principled.py); the projector, mesh_attribute, rawconstant
    # and textured area emitters with blendbsdf six more: the two projector
    # scenes, the three mesh_attributes scenes and various_emitters
    # (tests/test_emitter_textures.py); mask, normalmap, bumpmap eight
    # more: the four sphere-grid scenes with masked leaves and the four
    # normal- and bump-mapped spheres, each passing Mitsuba's protocol
    # (tests/test_normalmap.py: 0, 0, 0, 0 and 0, 2, 2, 0 rejected of
    # 17.3): 40 of 41.
    assert len(loads) >= 40, sorted(loads)
    assert {"bsdf_spheres/test_texturedprincipled1_path.xml",
            "bsdf_spheres/test_texturedprincipled2_path.xml",
            "bsdf_spheres/test_texturedprincipledthin_path.xml",
            "instancing/test_instancing_path.xml",
            "participating_media/test_hetero_spectral_sigmat_no_scattering_volpath.xml",
            "bsdf_spheres/test_roughplastic_linear_path.xml",
            "bsdf_spheres/test_roughplastic_nonlinear_path.xml",
            "bsdf_spheres/test_textured_diffuse_path.xml",
            "bsdf_spheres/test_textured_roughconductor_path.xml",
            "texture_interp/test_texture_interp_direct.xml",
            "spot_light/test_spot_direct.xml",
            "participating_media/test_surf_area_light_volpath.xml",
            "projector/test_projector_constant_direct.xml",
            "projector/test_projector_textured_direct.xml",
            "mesh_attributes/test_mesh_attributes_1_face_direct.xml",
            "mesh_attributes/test_mesh_attributes_3_face_direct.xml",
            "mesh_attributes/test_mesh_attributes_3_vertex_direct.xml",
            "various_emitters/test_various_emitters_ptracer.xml",
            "bsdf_spheres/test_arealight_path.xml", "bsdf_spheres/test_constant_path.xml",
            "bsdf_spheres/test_envmap_path.xml", "bsdf_spheres/test_pointlight_path.xml",
            "bsdf_spheres/test_normalmap_path.xml", "bsdf_spheres/test_normalmap_roughconductor_path.xml",
            "bsdf_spheres/test_normalmap_identity_roughconductor_path.xml",
            "bsdf_spheres/test_bumpmap_path.xml"} <= loads
    # various_shapes stops at its sdfgrid, refused by name (it also names
    # meshes outside the copied data: mitsuba-data's tests/serialized,
    # tests/obj and tests/ply).
    various = next(r for r in rows if r["scene"] == "various_shapes/test_various_shapes_path.xml")
    assert "shape type 'sdfgrid' is not supported" in various["status"]
    assert various["blockers"] == ["shape sdfgrid"]


THIN_MEDIA = ["participating_media/test_homo_area_light_volpath.xml",
              "participating_media/test_homo_emitter_inside_medium_volpath.xml",
              "participating_media/test_homo_obj_inside_medium_volpath.xml"]


@pytest.mark.skipif(not (SUITE / "tests" / "scenes").is_dir(), reason="../shared/peers/mitsuba-data absent")
@pytest.mark.parametrize("scene", THIN_MEDIA)
def test_thindielectric_medium_boundaries_as_mitsuba(scene):
    """Three media scenes whose medium spheres have thindielectric
    boundaries pass Mitsuba's protocol since volpath treats that BSDF's
    straight-through lobe as Mitsuba 3's volpath does, a null event (not a
    vertex, not counted towards max_depth; shadow rays pass with its
    transmission). Measured 2026-12-04: 3, 2 and 2 of 17.3 allowed
    pixel-channels rejected (image means 1.0021, 1.0014, 1.0003 of
    Mitsuba's), against 265, 1024 and 1444 before (0.90, 0.865, 0.87).
    Power: every emitter (area lights and envmaps) 10 % brighter fails the
    protocol (45, 153, 404 rejected; at 5 %: 11, 15, 28, so the protocol
    does not resolve 5 % on the first two)."""
    from radiometer.benchmarks.studies import mitsuba_suite as ms

    path = SUITE / "tests" / "scenes" / scene
    r = ms.protocol(path, threads=2)
    assert r["passes"], r

    def brighter(d):
        for s in d.shapes:
            if s.emitter is not None:
                s.emitter.radiance = tuple(1.1 * float(x) for x in s.emitter.radiance)
        for e in d.emitters:
            if e.env is not None:
                e.env = e.env * np.float32(1.1)

    bad = ms.protocol(path, threads=2, change=brighter)
    assert not bad["passes"], bad


# -- Mitsuba's protocol on every scene, and the second test ------------------------

SCENES = (sorted(str(p.relative_to(SUITE / "tests" / "scenes")) for p in (SUITE / "tests" / "scenes").glob("*/*.xml"))
          if (SUITE / "tests" / "scenes").is_dir() else [])
NOT_LOADING = {"various_shapes/test_various_shapes_path.xml"}  # test_suite_scenes_get_past_the_format
# Fails Mitsuba's protocol because our estimator is noisier there, not
# because it is wrong: test_second_test_counts_both_variances.
NOISIER = {"participating_media/test_hetero_sigmat_albedo_volpath.xml"}


@pytest.mark.parametrize("scene", SCENES)
def test_every_suite_scene_passes_mitsubas_protocol(scene, request):
    """Every scene of Mitsuba 3's render test suite that loads, rendered with
    its own integrator at 2,000,000 / pixels spp, seed 0, passes Mitsuba's
    own test (benchmarks/studies/mitsuba_suite.py: Sidak alpha 0.01 over
    pixels, at most 0.75 % rejected). The power of each scene's protocol is
    checked where that scene's feature is tested (test_textures,
    test_normalmap, test_principled, test_roughplastic, test_shapes,
    test_emitter_textures, test_envmap, above)."""
    from radiometer.benchmarks.studies import mitsuba_suite as ms

    if scene in NOT_LOADING:
        pytest.skip("does not load: sdfgrid refused by name, and its meshes are not in the copied data")
    if scene in NOISIER:
        request.applymarker(pytest.mark.xfail(reason="our volpath is noisier here; the second test passes",
                                              strict=False))
    r = ms.protocol(SUITE / "tests" / "scenes" / scene, threads=2)
    assert r["passes"], r


@pytest.mark.skipif(not (SUITE / "tests" / "scenes").is_dir(), reason="../shared/peers/mitsuba-data absent")
def test_second_test_counts_both_variances(tmp_path):
    """The one loading scene that fails Mitsuba's protocol,
    hetero_sigmat_albedo_volpath (49 of 17.3 allowed pixel-channels
    rejected, 2026-12-06), fails it because our estimator is noisier there,
    not because it is wrong. Its medium has a grey sigma_t grid and an RGB
    albedo grid (means 0.80, 0.25, 0.15): our volpath absorbs by the hero
    channel's albedo and combines the channels by spectral MIS, so red
    light, which survives many more scatterings than the hero's green or
    blue, carries up to 3x weights; Mitsuba's volpath never absorbs and
    weighs each channel by its albedo. Measured at 8192 spp against a fresh
    Mitsuba render of 8 x 1024: our per-sample variance 3.7x Mitsuba's in
    red over the image (2-17x at the rejected pixels), 1.3x in green; the
    two images agree (z variance 1.03-1.06 per channel, mean z -0.03).
    Mitsuba's protocol divides every difference by Mitsuba's per-sample
    variance, so it rejects us there; Mitsuba itself passes it (1, 0, 0
    rejected at seeds 0, 1, 2).

    The second test counts both variances, each measured: a fresh Mitsuba
    render made by `radiometer refs --suite` (here 4 runs x 868 spp; the
    variance of its mean from the runs' spread) and ours (res.variance),
    Student's t with Welch-Satterthwaite degrees of freedom, each variance
    at least its 3 x 3 neighbourhood's mean (mitsuba_suite.py says why).
    It passes (2026-12-06: 0 rejected against a 4 x 1736 reference; 0 on
    every other loading scene of the suite, benchmarks/results/
    mitsuba_suite.json), and rejects the scene with its envmap 10 % darker
    (246 rejected of 17.3 allowed)."""
    pytest.importorskip("mitsuba", reason="the fresh reference is a Mitsuba 3 render")
    from radiometer.benchmarks.studies import mitsuba_suite as ms
    from radiometer.cli import main
    from radiometer.exr import read_exr

    scene = next(iter(NOISIER))
    path = SUITE / "tests" / "scenes" / scene
    assert main(["refs", "--suite", "--runs", "4", "--spp", "868", "--results", str(tmp_path), scene]) == 0
    ref = ms.fresh_path(tmp_path, path)
    meta = read_exr(ref).metadata
    assert int(meta["total_spp"]) == 4 * 868 and meta["seeds"] == "1000..1003", meta
    res = ms._render(path, threads=2)
    r = ms.both_variances(path, ref, res=res)
    assert r["passes"], r
    assert r["variance_ratio"] > 1.1, r  # ours noisier than Mitsuba's (1.44, median over pixel-channels)

    def darker(d):
        for e in d.emitters:
            if e.env is not None:
                e.env = e.env * np.float32(0.9)

    bad = ms.both_variances(path, ref, res=ms._render(path, threads=2, change=darker))
    assert not bad["passes"], bad
