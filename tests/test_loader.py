"""Scene loader: Mitsuba 3 dicts and XML -> SceneDesc, checked against what
Mitsuba 3 itself builds from the same input where Mitsuba is installed.

Pure Python: nothing here needs the C++ module radiometer._core.
"""
import dataclasses
import math
import struct

import numpy as np
import pytest

from radiometer.loader import NAMED_IOR, load_dict, load_file
from radiometer.scene_desc import SceneDesc, SceneError


@pytest.fixture(scope="module")
def mi():
    mitsuba = pytest.importorskip(
        "mitsuba", reason="mitsuba (the reference renderer) is not installed")
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


def assert_same(a, b, where="desc", atol=1e-5):
    """Field-by-field equality of two descriptions (ids and sources, which
    name places, excluded); arrays and floats to atol."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            if f.name not in ("id", "source"):
                assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}", atol)
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert a is not None and b is not None, where
        np.testing.assert_allclose(a, b, atol=atol, err_msg=where)
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]", atol)
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            assert_same(a[k], b[k], f"{where}[{k!r}]", atol)
    elif isinstance(a, float) or isinstance(b, float):
        assert a == pytest.approx(b, abs=atol), where
    else:
        assert a == b, where


def shape_by_key(desc, key):
    matches = [s for s in desc.shapes if s.id == f"scene[{key!r}]"]
    assert len(matches) == 1, key
    return matches[0]


def shape_bbox(s):
    if s.type == "sphere":
        c = np.array(s.center)
        return c - s.radius, c + s.radius
    return s.positions.min(axis=0), s.positions.max(axis=0)


# ---------------------------------------------------------------------------
# (a) mitsuba.cornell_box() loads unchanged and agrees with Mitsuba
# ---------------------------------------------------------------------------


def test_cornell_box_dict_matches_mitsuba(mi):
    d = mi.cornell_box()
    keys_before = list(d)
    desc = load_dict(d)
    assert list(d) == keys_before  # the dict is not modified
    ref = mi.load_dict(mi.cornell_box())

    assert len(desc.shapes) == 8
    area = [s for s in desc.shapes if s.emitter is not None]
    assert len(area) + len(desc.emitters) == len(ref.emitters()) == 1
    assert area[0].emitter.radiance == pytest.approx((18.387, 13.9873, 6.75357))

    # Mitsuba 3.9 merges the shapes that share a BSDF inside a scene, so each
    # shape is compared with Mitsuba's instance of it alone (its bsdf ref dropped).
    for key in ("light", "floor", "ceiling", "back", "green-wall", "red-wall",
                "small-box", "large-box"):
        s = shape_by_key(desc, key)
        rs = mi.load_dict({k: v for k, v in d[key].items() if k != "bsdf"})
        lo, hi = shape_bbox(s)
        bb = rs.bbox()
        np.testing.assert_allclose(lo, np.array(bb.min), atol=1e-5, err_msg=key)
        np.testing.assert_allclose(hi, np.array(bb.max), atol=1e-5, err_msg=key)
        if d[key]["type"] == "cube":  # Mitsuba's own mesh buffers
            compare_with_mitsuba_mesh(s, mi.traverse(rs))

    sensor = ref.sensors()[0]
    np.testing.assert_allclose(desc.sensor.to_world,
                               np.array(sensor.world_transform().matrix), atol=1e-6)
    assert desc.sensor.fov_x == pytest.approx(mi.traverse(sensor)["x_fov"], abs=1e-4)
    assert (desc.sensor.width, desc.sensor.height) == tuple(sensor.film().size())
    assert desc.sensor.spp == sensor.sampler().sample_count() == 64
    assert desc.sensor.near_clip == pytest.approx(sensor.near_clip())
    assert desc.sensor.far_clip == pytest.approx(sensor.far_clip())
    assert desc.sensor.rfilter == "gaussian"
    assert desc.sensor.filter_radius == pytest.approx(sensor.film().rfilter().radius())
    assert desc.integrator.type == "path" and desc.integrator.params == {"max_depth": 8}

    white = shape_by_key(desc, "floor").bsdf
    assert white is shape_by_key(desc, "back").bsdf  # a ref shares one description
    assert white.reflectance == pytest.approx((0.885809, 0.698859, 0.666422))


# ---------------------------------------------------------------------------
# (b) the same scene as XML gives the same SceneDesc
# ---------------------------------------------------------------------------

CORNELL_XML = """<?xml version="1.0"?>
<scene version="3.0.0">
    <default name="spp" value="64"/>
    <default name="res" value="256"/>
    <integrator type="path">
        <integer name="max_depth" value="8"/>
    </integrator>
    <sensor type="perspective" id="sensor">
        <string name="fov_axis" value="smaller"/>
        <float name="near_clip" value="0.001"/>
        <float name="far_clip" value="100.0"/>
        <float name="focus_distance" value="1000"/>
        <float name="fov" value="39.3077"/>
        <transform name="to_world">
            <lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="$spp"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="$res"/>
            <integer name="height" value="$res"/>
            <rfilter type="gaussian"/>
            <string name="pixel_format" value="rgb"/>
            <string name="component_format" value="float32"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="white">
        <rgb name="reflectance" value="0.885809, 0.698859, 0.666422"/>
    </bsdf>
    <bsdf type="diffuse" id="green">
        <rgb name="reflectance" value="0.105421 0.37798 0.076425"/>
    </bsdf>
    <bsdf type="diffuse" id="red">
        <rgb name="reflectance" value="0.570068, 0.0430135, 0.0443706"/>
    </bsdf>
    <shape type="rectangle" id="light">
        <transform name="to_world">
            <scale x="0.23" y="0.19" z="0.19"/>
            <rotate x="1" angle="90"/>
            <translate x="0" y="0.99" z="0.01"/>
        </transform>
        <ref id="white"/>
        <emitter type="area">
            <rgb name="radiance" value="18.387, 13.9873, 6.75357"/>
        </emitter>
    </shape>
    <shape type="rectangle" id="floor">
        <transform name="to_world">
            <rotate x="1" angle="-90"/>
            <translate y="-1"/>
        </transform>
        <ref name="bsdf" id="white"/>
    </shape>
    <shape type="rectangle" id="ceiling">
        <transform name="to_world">
            <rotate value="1 0 0" angle="90"/>
            <translate value="0 1 0"/>
        </transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle" id="back">
        <transform name="to_world">
            <translate z="-1"/>
        </transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle" id="green-wall">
        <transform name="to_world">
            <rotate y="1" angle="-90"/>
            <translate x="1"/>
        </transform>
        <ref id="green"/>
    </shape>
    <shape type="rectangle" id="red-wall">
        <transform name="to_world">
            <rotate y="1" angle="90"/>
            <translate x="-1"/>
        </transform>
        <ref id="red"/>
    </shape>
    <shape type="cube" id="small-box">
        <transform name="to_world">
            <scale value="0.3"/>
            <rotate y="1" angle="-17"/>
            <translate x="0.335" y="-0.7" z="0.38"/>
        </transform>
        <ref id="white"/>
    </shape>
    <shape type="cube" id="large-box">
        <transform name="to_world">
            <scale x="0.3" y="0.61" z="0.3"/>
            <rotate y="1" angle="18.25"/>
            <translate x="-0.33" y="-0.4" z="-0.28"/>
        </transform>
        <ref id="white"/>
    </shape>
</scene>
"""


def test_cornell_box_xml_equals_dict(mi, tmp_path):
    path = tmp_path / "cornell.xml"
    path.write_text(CORNELL_XML)
    from_xml = load_file(path)
    from_dict = load_dict(mi.cornell_box())
    # Same shapes in the same order (XML order = the dict's key order here).
    order = [s.id.split("'")[1] for s in from_dict.shapes]
    assert order == ["light", "floor", "ceiling", "back", "green-wall", "red-wall",
                     "small-box", "large-box"]
    assert_same(from_xml, from_dict)
    assert from_xml.source == str(path)
    light_line = next(i for i, line in enumerate(CORNELL_XML.splitlines(), 1)
                      if 'id="light"' in line)
    assert from_xml.shapes[0].id == f"{path}:{light_line}"

    # And Mitsuba reads our XML the same way (transform composition order).
    # Mitsuba merges the shapes that share a BSDF, so compare the shapes it
    # keeps apart one by one and the whole scene's bounding box.
    ref = mi.load_file(str(path))
    kept = [rs for rs in ref.shapes() if rs.id() in order]
    assert {rs.id() for rs in kept} >= {"light", "red-wall", "green-wall"}
    for rs in kept:
        lo, hi = shape_bbox(from_xml.shapes[order.index(rs.id())])
        np.testing.assert_allclose(lo, np.array(rs.bbox().min), atol=1e-5, err_msg=rs.id())
        np.testing.assert_allclose(hi, np.array(rs.bbox().max), atol=1e-5, err_msg=rs.id())
    lo = np.min([shape_bbox(s)[0] for s in from_xml.shapes], axis=0)
    hi = np.max([shape_bbox(s)[1] for s in from_xml.shapes], axis=0)
    np.testing.assert_allclose(lo, np.array(ref.bbox().min), atol=1e-5)
    np.testing.assert_allclose(hi, np.array(ref.bbox().max), atol=1e-5)
    np.testing.assert_allclose(from_xml.sensor.to_world,
                               np.array(ref.sensors()[0].world_transform().matrix), atol=1e-6)


def test_xml_params_override_defaults(tmp_path):
    path = tmp_path / "cornell.xml"
    path.write_text(CORNELL_XML)
    desc = load_file(path, spp=16, res=128)
    assert desc.sensor.spp == 16 and desc.sensor.width == desc.sensor.height == 128
    with pytest.raises(SceneError, match="never used.*bogus"):
        load_file(path, bogus=3)


SMALL_XML = """<scene version="3.0.0">
    <integrator type="bdpt">
        <integer name="max_depth" value="5"/>
        <boolean name="hide_emitters" value="true"/>
        <string name="mis" value="power"/>
        <float name="beta" value="2"/>
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="30"/>
        <string name="fov_axis" value="y"/>
        <transform name="to_world">
            <matrix value="1 0 0 0.5  0 1 0 0  0 0 1 -3  0 0 0 1"/>
        </transform>
        <film type="hdrfilm">
            <integer name="width" value="64"/>
            <integer name="height" value="32"/>
            <rfilter type="tent"><float name="radius" value="1.5"/></rfilter>
        </film>
    </sensor>
    <emitter type="point">
        <point name="position" x="0" y="2" z="0"/>
        <rgb name="intensity" value="5"/>
    </emitter>
    <emitter type="directional">
        <vector name="direction" value="0 -2 0"/>
        <spectrum name="irradiance" value="3"/>
    </emitter>
    <emitter type="spot">
        <rgb name="intensity" value="1 2 3"/>
        <float name="cutoff_angle" value="40"/>
    </emitter>
    <emitter type="constant"><rgb name="radiance" value="0.1"/></emitter>
    <shape type="sphere">
        <point name="center" value="0 0 1"/>
        <float name="radius" value="0.5"/>
        <bsdf type="twosided">
            <bsdf type="roughconductor">
                <string name="distribution" value="ggx"/>
                <float name="alpha_u" value="0.2"/>
                <float name="alpha_v" value="0.3"/>
                <rgb name="eta" value="0.2 0.9 1.1"/>
                <rgb name="k" value="3.9 2.4 2.2"/>
            </bsdf>
        </bsdf>
    </shape>
    <shape type="disk">
        <transform name="to_world"><scale x="2" y="3"/></transform>
        <bsdf type="plastic"><string name="int_ior" value="water"/></bsdf>
        <boolean name="flip_normals" value="true"/>
    </shape>
    <shape type="cube">
        <bsdf type="roughdielectric"><float name="alpha" value="0.05"/></bsdf>
    </shape>
</scene>
"""

SMALL_DICT = {
    "type": "scene",
    "integrator": {"type": "bdpt", "max_depth": 5, "hide_emitters": True,
                   "mis": "power", "beta": 2.0},
    "sensor": {
        "type": "perspective", "fov": 30.0, "fov_axis": "y",
        "to_world": [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, -3], [0, 0, 0, 1]],
        "film": {"type": "hdrfilm", "width": 64, "height": 32,
                 "rfilter": {"type": "tent", "radius": 1.5}},
    },
    "pt": {"type": "point", "position": [0, 2, 0], "intensity": {"type": "rgb", "value": 5}},
    "sun": {"type": "directional", "direction": np.array([0.0, -2.0, 0.0]),
            "irradiance": {"type": "spectrum", "value": 3.0}},
    "spot": {"type": "spot", "intensity": [1, 2, 3], "cutoff_angle": 40.0},
    "sky": {"type": "constant", "radiance": 0.1},
    "ball": {"type": "sphere", "center": [0, 0, 1], "radius": 0.5,
             "bsdf": {"type": "twosided", "inner": {
                 "type": "roughconductor", "distribution": "ggx", "alpha_u": 0.2,
                 "alpha_v": 0.3, "eta": {"type": "rgb", "value": [0.2, 0.9, 1.1]},
                 "k": [3.9, 2.4, 2.2]}}},
    "disk": {"type": "disk", "to_world": np.diag([2.0, 3.0, 1.0, 1.0]),
             "bsdf": {"type": "plastic", "int_ior": "Water"}, "flip_normals": True},
    "box": {"type": "cube", "bsdf": {"type": "roughdielectric", "alpha": 0.05}},
}


def test_xml_equals_dict_without_mitsuba(tmp_path):
    path = tmp_path / "small.xml"
    path.write_text(SMALL_XML)
    a, b = load_file(path), load_dict(SMALL_DICT)
    assert_same(a, b, atol=1e-12)
    assert a.integrator.params == {"max_depth": 5, "hide_emitters": True,
                                   "mis": "power", "beta": 2.0}
    s = a.sensor
    assert (s.width, s.height, s.rfilter, s.filter_radius, s.spp) == (64, 32, "tent", 1.5, 4)
    # fov 30 about y on a 2:1 film: tan(x/2) = 2 tan(15 deg)
    assert s.fov_x == pytest.approx(2 * math.degrees(math.atan(2 * math.tan(math.radians(15)))))
    pt, sun, spot, sky = a.emitters
    np.testing.assert_allclose(pt.to_world[:3, 3], [0, 2, 0])
    assert pt.intensity == (5.0, 5.0, 5.0)
    np.testing.assert_allclose(sun.to_world[:3, 2], [0, -1, 0])
    np.testing.assert_allclose(sun.to_world[:3, :3] @ sun.to_world[:3, :3].T, np.eye(3),
                               atol=1e-12)
    # a uniform spectrum on an emitter: Mitsuba's RGB variants read it as
    # XYZ = (3, 3, 3), i.e. 3 x the XYZ-to-sRGB matrix's row sums
    np.testing.assert_allclose(sun.irradiance, (3 * 1.204794, 3 * 0.948291, 3 * 0.908916), rtol=1e-6)
    assert (spot.cutoff_angle, spot.beam_width) == (40.0, 30.0)
    assert sky.radiance == (0.1, 0.1, 0.1)
    ball, disk, box = a.shapes
    assert ball.type == "sphere" and ball.center == (0, 0, 1) and ball.radius == 0.5
    np.testing.assert_allclose(ball.to_world, [[0.5, 0, 0, 0], [0, 0.5, 0, 0],
                                               [0, 0, 0.5, 1], [0, 0, 0, 1]])
    rc = ball.bsdf.nested[0]
    assert (ball.bsdf.type, rc.type, rc.distribution, rc.alpha_u, rc.alpha_v) == \
        ("twosided", "roughconductor", "ggx", 0.2, 0.3)
    assert disk.type == "disk" and disk.flip_normals
    assert disk.bsdf.int_ior == NAMED_IOR["water"] and disk.bsdf.ext_ior == NAMED_IOR["air"]
    assert box.bsdf.int_ior == 1.5046 and box.bsdf.alpha_u == box.bsdf.alpha_v == 0.05
    assert box.bsdf.distribution == "beckmann" and box.positions.shape == (24, 3)


def test_xml_transform_ops_match_mitsuba(mi, tmp_path):
    ops = """<scale x="2" y="0.5" z="3"/>
             <rotate x="0.36" y="-0.48" z="0.8" angle="33"/>
             <translate value="1, -2, 0.5"/>
             <matrix value="1 0.2 0 0  0 1 0 1  0 0 1 0  0 0 0 1"/>
             <rotate z="1" angle="-70"/>"""
    path = tmp_path / "ops.xml"
    path.write_text(f"""<scene version="3.0.0">
        <shape type="disk"><transform name="to_world">{ops}</transform></shape>
        <sensor type="perspective"><transform name="to_world">
            <lookat origin="1, 2, 3" target="0.5, 0, -1"/></transform></sensor>
        </scene>""")
    ours, ref = load_file(path), mi.load_file(str(path))
    np.testing.assert_allclose(ours.shapes[0].to_world,
                               np.array(mi.traverse(ref.shapes()[0])["to_world"].matrix),
                               atol=2e-6)
    np.testing.assert_allclose(ours.sensor.to_world,
                               np.array(ref.sensors()[0].world_transform().matrix), atol=2e-6)


@pytest.mark.parametrize("axis", ["x", "y", "diagonal", "smaller", "larger"])
@pytest.mark.parametrize("size", [(200, 100), (100, 200)])
def test_fov_axis_matches_mitsuba(mi, axis, size):
    film = {"type": "hdrfilm", "width": size[0], "height": size[1]}
    d = {"type": "perspective", "fov": 45.0, "fov_axis": axis, "film": film}
    ours = load_dict({"type": "scene", "cam": d}).sensor.fov_x
    assert ours == pytest.approx(mi.traverse(mi.load_dict(d))["x_fov"], abs=1e-4)
    d = {"type": "perspective", "focal_length": "35mm", "film": film}
    ours = load_dict({"type": "scene", "cam": d}).sensor.fov_x
    assert ours == pytest.approx(mi.traverse(mi.load_dict(d))["x_fov"], abs=1e-4)


def test_defaults_match_mitsuba(mi):
    desc = load_dict({"type": "scene"})  # no sensor: Mitsuba's default perspective
    cam = mi.load_dict({"type": "perspective"})
    s = desc.sensor
    assert (s.type, s.width, s.height) == ("perspective", *cam.film().size())
    assert s.fov_x == pytest.approx(mi.traverse(cam)["x_fov"], abs=1e-4)
    assert s.spp == cam.sampler().sample_count()
    assert s.filter_radius == pytest.approx(cam.film().rfilter().radius())
    assert s.near_clip == pytest.approx(cam.near_clip())
    np.testing.assert_array_equal(s.to_world, np.eye(4))
    assert desc.integrator.type == "path" and desc.integrator.params == {}
    for name, value in NAMED_IOR.items():
        eta = mi.traverse(mi.load_dict({"type": "dielectric", "int_ior": name,
                                        "ext_ior": 1.0}))["eta"]
        assert value == pytest.approx(eta, rel=1e-6), name
    for t, radius in (("box", 0.5), ("tent", 1.0), ("gaussian", 2.0)):
        sc = load_dict({"type": "scene", "cam": {"type": "perspective", "film": {
            "type": "hdrfilm", "rfilter": {"type": t}}}})
        assert sc.sensor.filter_radius == pytest.approx(
            mi.load_dict({"type": t}).radius()) == radius


ROUGHPLASTIC_XML = """<scene version="3.0.0">
<shape type="sphere" id="a"><bsdf type="roughplastic"/></shape>
<shape type="sphere" id="b">
    <bsdf type="roughplastic">
        <string name="distribution" value="ggx"/>
        <float name="alpha" value="0.3"/>
        <string name="int_ior" value="bk7"/>
        <float name="ext_ior" value="1.33"/>
        <rgb name="diffuse_reflectance" value="0.8 0.3 0.1"/>
        <spectrum name="specular_reflectance" value="0.7"/>
        <boolean name="nonlinear" value="true"/>
        <boolean name="sample_visible" value="false"/>
    </bsdf>
</shape>
</scene>"""
ROUGHPLASTIC_DICT = {
    "type": "scene",
    "a": {"type": "sphere", "bsdf": {"type": "roughplastic"}},
    "b": {"type": "sphere", "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3, "int_ior": "bk7",
                                     "ext_ior": 1.33, "diffuse_reflectance": {"type": "rgb", "value": [0.8, 0.3, 0.1]},
                                     "specular_reflectance": 0.7, "nonlinear": True, "sample_visible": False}},
}


def test_roughplastic_xml_equals_dict_and_mitsuba(mi, tmp_path):
    """roughplastic from XML and from a dict: the same description, with
    Mitsuba 3's defaults (beckmann, alpha 0.1, polypropylene in air, 0.5
    diffuse, 1 specular, linear, visible normals) and the parameters Mitsuba
    itself builds (its traverse(): alpha, eta, diffuse_reflectance)."""
    path = tmp_path / "rp.xml"
    path.write_text(ROUGHPLASTIC_XML)
    a, b = load_file(path), load_dict(ROUGHPLASTIC_DICT)
    assert_same(a, b, atol=1e-12)
    d, g = b.shapes[0].bsdf, b.shapes[1].bsdf
    assert (d.type, d.distribution, d.alpha_u, d.alpha_v, d.nonlinear, d.sample_visible) == (
        "roughplastic", "beckmann", 0.1, 0.1, False, True)
    assert d.int_ior == NAMED_IOR["polypropylene"] and d.ext_ior == NAMED_IOR["air"]
    assert tuple(d.diffuse_reflectance) == (0.5, 0.5, 0.5) and tuple(d.specular_reflectance) == (1, 1, 1)
    assert (g.distribution, g.alpha_u, g.nonlinear, g.sample_visible) == ("ggx", 0.3, True, False)
    assert g.int_ior == NAMED_IOR["bk7"] and g.ext_ior == 1.33
    for key, ours in (("a", d), ("b", g)):
        params = mi.traverse(mi.load_dict(ROUGHPLASTIC_DICT[key]["bsdf"]))
        assert ours.alpha_u == pytest.approx(params["alpha"], rel=1e-6), key
        assert ours.int_ior / ours.ext_ior == pytest.approx(params["eta"], rel=1e-6), key
        np.testing.assert_allclose(ours.diffuse_reflectance, params["diffuse_reflectance.value"], rtol=1e-6)


def test_default_bsdf_is_black_on_emitters_as_in_mitsuba(mi):
    """A shape without a BSDF is a diffuse of reflectance 0.5, but an
    emitter without one reflects nothing (Mitsuba 3's Shape constructor).
    A radiance meter looks at square A (an emitter of radiance 1, no BSDF)
    while square B (radiance 2) faces it 1 away: with A black the meter
    reads exactly A's 1, as Mitsuba does; with the 0.5 default, B's light
    reflected off A adds 0.5 x 2 x F (F, the configuration factor from A's
    centre to B, about 0.55)."""
    def scene(bsdf_a=None):
        a = {"type": "rectangle", "emitter": {"type": "area", "radiance": 1.0}}
        if bsdf_a is not None:
            a["bsdf"] = bsdf_a
        return {"type": "scene",
                "integrator": {"type": "path", "max_depth": 3},
                "meter": {"type": "radiancemeter", "origin": [0, 0, 0.5], "direction": [0, 0, -1],
                          "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}},
                "a": a,
                "b": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 1]) @
                      mi.ScalarTransform4f().rotate([1, 0, 0], 180),
                      "emitter": {"type": "area", "radiance": 2.0}},
                # a plain shape without a BSDF keeps the 0.5 default
                "c": {"type": "sphere", "radius": 0.01, "center": [5, 5, 5]}}

    import radiometer as rm

    desc = load_dict(scene())
    assert desc.shapes[0].bsdf is None and desc.shapes[2].bsdf is None
    ours = float(np.asarray(rm.render(rm.load_dict(scene()), spp=4096, seed=1).image).mean())
    grey = float(np.asarray(rm.render(rm.load_dict(scene({"type": "diffuse"})), spp=4096, seed=1).image).mean())
    theirs = float(np.asarray(mi.render(mi.load_dict(scene()), spp=4096, seed=1)).mean())
    assert ours == pytest.approx(1.0, abs=1e-6)
    assert theirs == pytest.approx(ours, abs=1e-4)
    # the test sees the difference: A with the 0.5 default reflects B's light
    f = 2 / math.pi * math.sqrt(2) * math.atan(1 / math.sqrt(2))  # square of half-side 1 at distance 1
    assert grey == pytest.approx(1 + 0.5 * 2 * f, rel=0.01), grey


def test_sphere_transform_and_mirror(mi):
    m = mi.ScalarTransform4f().translate([1, 2, 3]) @ mi.ScalarTransform4f().rotate(
        [0, math.sqrt(0.5), math.sqrt(0.5)], 30) @ mi.ScalarTransform4f().scale(-2)
    d = {"type": "scene", "ball": {"type": "sphere", "to_world": m, "radius": 0.5,
                                   "center": [1, 0, 0]}}
    s = load_dict(d).shapes[0]
    ref = mi.load_dict(d).shapes()[0]
    np.testing.assert_allclose(shape_bbox(s)[0], np.array(ref.bbox().min), atol=1e-5)
    assert s.radius == pytest.approx(1.0)
    assert s.flip_normals  # a mirroring to_world turns the normals inward, as in Mitsuba
    np.testing.assert_allclose(np.linalg.det(s.to_world[:3, :3]), 1.0, atol=1e-5)


def test_meters(mi):
    d = {"type": "radiancemeter", "origin": [1, 2, 3], "direction": [0.3, -1, 0.5],
         "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"}}}
    s = load_dict({"type": "scene", "m": d}).sensor
    assert (s.type, s.width, s.height, s.rfilter, s.filter_radius) == \
        ("radiancemeter", 1, 1, "box", 0.5)
    np.testing.assert_allclose(s.to_world, np.array(mi.load_dict(d).world_transform().matrix),
                               atol=1e-6)
    scene = load_dict({"type": "scene", "s": {"type": "sphere", "sensor": {
        "type": "irradiancemeter", "film": {"type": "hdrfilm", "width": 1, "height": 1}}}})
    assert scene.sensor.type == "irradiancemeter" and scene.shapes[0].sensor is scene.sensor


def test_area_emitter_by_ref():
    scene = load_dict({"type": "scene", "e": {"type": "area", "radiance": 2.0},
                       "s": {"type": "rectangle", "emitter": {"type": "ref", "id": "e"}}})
    assert scene.shapes[0].emitter.radiance == (2.0, 2.0, 2.0) and scene.emitters == []


def test_non_unit_rotation_axis_is_refused(mi):
    # Mitsuba's rotate() uses the axis unnormalised and keeps an inverse
    # transpose that no longer matches the matrix; we refuse such transforms.
    bad = mi.ScalarTransform4f().rotate([1, 1, 0], 25)
    with pytest.raises(SceneError, match=r"scene\['c'\]\['to_world'\].*unit length"):
        load_dict({"type": "scene", "c": {"type": "cube", "to_world": bad}})


# ---------------------------------------------------------------------------
# (c) OBJ and PLY meshes
# ---------------------------------------------------------------------------

OBJ_TEXT = """# a quad and a triangle with separate uv and normal indices
o thing
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 2
vn 0 -1 0
g group
usemtl whatever
f 1/1/1 2/2/1 3/3/1 4/4/1
f 1/1/2 5/3/2 2/2/2
"""

M_MESH = np.array([[0.0, -2.0, 0.0, 1.0],
                   [1.0, 0.0, 0.0, 2.0],
                   [0.0, 0.0, 4.0, 3.0],
                   [0.0, 0.0, 0.0, 1.0]])


def world(p):
    return np.asarray(p, dtype=np.float64) @ M_MESH[:3, :3].T + M_MESH[:3, 3]


def world_normal(n):
    v = np.linalg.inv(M_MESH[:3, :3]).T @ np.asarray(n, dtype=np.float64)
    return v / np.linalg.norm(v)


def test_obj_mesh(tmp_path, monkeypatch):
    (tmp_path / "m.obj").write_text(OBJ_TEXT)
    monkeypatch.chdir(tmp_path)  # dict file names resolve against the working directory
    s = load_dict({"type": "scene", "m": {"type": "obj", "filename": "m.obj",
                                          "to_world": M_MESH.tolist()}}).shapes[0]
    # one vertex per distinct (v, vt, vn) triple, in order of first use
    corners = [(1, 1, 1), (2, 2, 1), (3, 3, 1), (4, 4, 1), (1, 1, 2), (5, 3, 2), (2, 2, 2)]
    v = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1)]
    vt = [(0, 0), (1, 0), (1, 1), (0, 1)]
    vn = [(0, 0, 1), (0, -1, 0)]
    assert s.type == "mesh" and s.positions.dtype == np.float32
    np.testing.assert_array_equal(s.indices, [[0, 1, 2], [0, 2, 3], [4, 5, 6]])
    np.testing.assert_allclose(s.positions, world([v[c[0] - 1] for c in corners]), atol=1e-6)
    np.testing.assert_allclose(s.normals, [world_normal(vn[c[2] - 1]) for c in corners],
                               atol=1e-6)
    # flip_tex_coords (default true): v -> 1 - v
    np.testing.assert_allclose(s.uvs, [(vt[c[1] - 1][0], 1 - vt[c[1] - 1][1]) for c in corners])
    np.testing.assert_array_equal(s.to_world, np.eye(4))  # meshes are in world space

    flat = load_dict({"type": "scene", "m": {"type": "obj", "filename": "m.obj",
                                             "face_normals": True,
                                             "flip_tex_coords": False}}).shapes[0]
    assert flat.normals is None
    np.testing.assert_allclose(flat.uvs, [vt[c[1] - 1] for c in corners])


def test_obj_without_normals_gets_angle_weighted_normals(tmp_path):
    (tmp_path / "n.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n"
                                    "f 1 2 3 4\nf 1 5 2\n")
    xml = tmp_path / "scene.xml"
    xml.write_text('<scene version="3.0.0"><shape type="obj">'
                   '<string name="filename" value="n.obj"/></shape></scene>')
    s = load_file(xml).shapes[0]  # file names resolve against the XML's folder
    # vertex 0: +z from two faces with angles 45 + 45 deg, +y from one face with 90 deg
    np.testing.assert_allclose(s.normals[0], [0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-6)
    np.testing.assert_allclose(s.normals[2], [0, 0, 1], atol=1e-6)
    assert s.uvs is None


def test_obj_matches_mitsuba(mi, tmp_path):
    (tmp_path / "m.obj").write_text(OBJ_TEXT)
    (tmp_path / "n.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n"
                                    "f 1 2 3 4\nf 1 5 2\n")
    for name in ("m.obj", "n.obj"):
        filename = str(tmp_path / name)
        ours = load_dict({"type": "scene", "m": {"type": "obj", "filename": filename,
                                                 "to_world": M_MESH}}).shapes[0]
        ref = mi.traverse(mi.load_dict({"type": "obj", "filename": filename,
                                        "to_world": mi.ScalarTransform4f(M_MESH)}))
        compare_with_mitsuba_mesh(ours, ref)


def compare_with_mitsuba_mesh(ours, ref):
    np.testing.assert_array_equal(ours.indices.ravel(), np.array(ref["faces"]))
    np.testing.assert_allclose(ours.positions.ravel(), np.array(ref["vertex_positions"]),
                               atol=1e-5)
    np.testing.assert_allclose(ours.normals.ravel(), np.array(ref["vertex_normals"]),
                               atol=1e-5)
    if ours.uvs is None:
        assert np.array(ref["vertex_texcoords"]).size == 0
    else:
        np.testing.assert_allclose(ours.uvs.ravel(), np.array(ref["vertex_texcoords"]),
                                   atol=1e-6)


PLY_VERTS = [  # x y z nx ny nz u v
    (0, 0, 0, 0, 0, 3, 0.0, 0.0),
    (1, 0, 0, 0, 0, 1, 1.0, 0.0),
    (1, 1, 0, 0, 1, 1, 1.0, 1.0),
    (0, 1, 0, 0, 0, 1, 0.0, 0.5),
]
PLY_FACES = [(0, 1, 2), (0, 2, 3)]


def write_ply(path, binary, uv_names=("u", "v"), normals=True):
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals else []) + list(uv_names)
    rows = [r[:3] + (r[3:6] if normals else ()) + r[6:] for r in PLY_VERTS]
    header = ["ply", "format " + ("binary_little_endian" if binary else "ascii") + " 1.0",
              "comment written by test_loader", f"element vertex {len(rows)}"]
    header += [f"property float {p}" for p in props]
    header += [f"element face {len(PLY_FACES)}", "property list uchar int vertex_indices",
               "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode())
        for r in rows:
            f.write(struct.pack(f"<{len(r)}f", *r) if binary
                    else (" ".join(map(str, r)) + "\n").encode())
        for face in PLY_FACES:
            f.write(struct.pack("<B3i", 3, *face) if binary
                    else ("3 " + " ".join(map(str, face)) + "\n").encode())


@pytest.mark.parametrize("binary", [False, True])
def test_ply_mesh(tmp_path, binary):
    write_ply(tmp_path / "m.ply", binary, uv_names=("s", "t") if binary else ("u", "v"))
    s = load_dict({"type": "scene", "m": {"type": "ply", "filename": str(tmp_path / "m.ply"),
                                          "to_world": M_MESH}}).shapes[0]
    np.testing.assert_array_equal(s.indices, PLY_FACES)
    np.testing.assert_allclose(s.positions, world([r[:3] for r in PLY_VERTS]), atol=1e-6)
    np.testing.assert_allclose(s.normals, [world_normal(r[3:6]) for r in PLY_VERTS], atol=1e-6)
    np.testing.assert_allclose(s.uvs, [r[6:] for r in PLY_VERTS])  # PLY uvs are not flipped

    write_ply(tmp_path / "plain.ply", binary, normals=False)
    plain = load_dict({"type": "scene", "m": {"type": "ply",
                                              "filename": str(tmp_path / "plain.ply")}})
    np.testing.assert_allclose(plain.shapes[0].normals, np.tile([0, 0, 1], (4, 1)), atol=1e-6)


@pytest.mark.parametrize("normals", [True, False])
def test_ply_matches_mitsuba(mi, tmp_path, normals):
    write_ply(tmp_path / "m.ply", True, normals=normals)
    filename = str(tmp_path / "m.ply")
    ours = load_dict({"type": "scene", "m": {"type": "ply", "filename": filename,
                                             "to_world": M_MESH}}).shapes[0]
    ref = mi.traverse(mi.load_dict({"type": "ply", "filename": filename,
                                    "to_world": mi.ScalarTransform4f(M_MESH)}))
    compare_with_mitsuba_mesh(ours, ref)


def test_cube_and_rectangle_match_mitsuba(mi):
    m = mi.ScalarTransform4f().translate([0.1, 0.2, 0.3]) @ mi.ScalarTransform4f().rotate(
        [0.6, 0.8, 0], 25) @ mi.ScalarTransform4f().scale([1, -2, 0.5])
    cube = load_dict({"type": "scene", "c": {"type": "cube", "to_world": m}}).shapes[0]
    compare_with_mitsuba_mesh(cube, mi.traverse(mi.load_dict({"type": "cube", "to_world": m})))
    rect = load_dict({"type": "scene", "r": {"type": "rectangle", "to_world": m}}).shapes[0]
    assert rect.normals is None and rect.indices.shape == (2, 3)
    # Mitsuba's analytic rectangle: hit point, uv and normal agree with our two triangles.
    ref = mi.load_dict({"type": "scene", "r": {"type": "rectangle", "to_world": m}})
    p = rect.positions.astype(np.float64)
    for (i, j, k), (b1, b2) in (((0, 1, 2), (0.3, 0.2)), ((2, 3, 0), (0.1, 0.6))):
        hit = (1 - b1 - b2) * p[i] + b1 * p[j] + b2 * p[k]
        n = np.cross(p[j] - p[i], p[k] - p[i])
        n /= np.linalg.norm(n)
        si = ref.ray_intersect(mi.Ray3f(hit + 2 * n, -n))
        np.testing.assert_allclose(np.array(si.p), hit, atol=1e-5)
        np.testing.assert_allclose(np.array(si.n), n, atol=1e-5)
        uv = (1 - b1 - b2) * rect.uvs[i] + b1 * rect.uvs[j] + b2 * rect.uvs[k]
        np.testing.assert_allclose(np.array(si.uv), uv, atol=1e-5)


# ---------------------------------------------------------------------------
# (d) bad scenes: SceneError naming the element and its place
# ---------------------------------------------------------------------------


def _scene(**entries):
    return {"type": "scene", **entries}


RECT = {"type": "rectangle"}
BAD_DICTS = [
    (_scene(floor={"type": "rectangle", "bsdf": {"type": "diffuse", "reflectanse": 0.5}}),
     ["scene['floor']['bsdf']['reflectanse']", "bsdf 'diffuse'", "unknown parameter"]),
    (_scene(floor={"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {
        "type": "rgb", "value": [0.5, -0.1, 0.5]}}}),
     ["scene['floor']['bsdf']['reflectance']", "negative value -0.1"]),
    (_scene(floor={"type": "rectangle", "bsdf": {"type": "hair"}}),
     ["scene['floor']['bsdf']", "'hair' is not supported"]),
    (_scene(floor={"type": "rectangle", "bsdf": {"type": "ref", "id": "nope"}}),
     ["scene['floor']['bsdf']", "unknown id 'nope'"]),
    (_scene(cam={"type": "perspective", "film": {"type": "hdrfilm", "width": 256.0}}),
     ["scene['cam']['film']['width']", "must be an integer"]),
    (_scene(cam={"type": "perspective", "film": {"type": "hdrfilm", "height": 20000}}),
     ["scene['cam']['film']['height']", "outside [1, 16384]"]),
    (_scene(cam={"type": "perspective", "film": {"type": "hdrfilm", "width": 16, "crop_width": 8,
                                                 "crop_offset_x": 9}}),
     ["scene['cam']['film']['crop_width']", "crop_offset_x + crop_width = 9 + 8 exceeds the film's width 16"]),
    (_scene(floor={"type": "rectangle", "to_world": np.diag([1.0, np.nan, 1.0, 1.0])}),
     ["scene['floor']['to_world']", "non-finite"]),
    (_scene(ball={"type": "sphere", "radius": 0.0}),
     ["scene['ball']['radius']", "must be > 0"]),
    (_scene(ball={"type": "sphere", "to_world": np.diag([1.0, 2.0, 1.0, 1.0])}),
     ["scene['ball']['to_world']", "non-uniformly"]),
    (_scene(mesh={"type": "obj", "filename": "/nonexistent/bunny.obj"}),
     ["scene['mesh']['filename']", "mesh file not found"]),
    (_scene(lamp={"type": "point", "scale": 2.0}),
     ["scene['lamp']['scale']", "emitter 'point'", "'scale'"]),
    (_scene(floor={"type": "rectangle", "bsdf": {"type": "conductor", "material": "Unobtainium"}}),
     ["scene['floor']['bsdf']['material']", "unknown conductor material 'Unobtainium'", "Au, Be"]),
    (_scene(a={"type": "perspective"}, b={"type": "orthographic"}),
     ["scene['b']", "more than one sensor"]),
    (_scene(meter={"type": "radiancemeter"}),
     ["scene['meter']", "1x1 film"]),
    (_scene(integrator={"type": "aov"}),
     ["scene['integrator']", "'aov' is not supported"]),
    (_scene(light={"type": "area"}),
     ["scene['light']", "must be nested in a shape"]),
    (_scene(floor={"type": "rectangle", "flip_normals": "yes"}),
     ["scene['floor']['flip_normals']", "must be a boolean"]),
    (_scene(g={"type": "roughconductor", "alpha_u": 0.1}),
     ["scene['g']", "alpha_u and alpha_v"]),
    (_scene(cam={"type": "perspective", "fov": 45.0, "focal_length": "50mm"}),
     ["scene['cam']", "either fov or focal_length"]),
    (_scene(cam={"type": "perspective", "to_world": np.diag([2.0, 2.0, 2.0, 1.0])}),
     ["scene['cam']['to_world']", "scale factors"]),
    (_scene(glass={"type": "dielectric", "int_ior": "unobtainium"}),
     ["scene['glass']['int_ior']", "unknown IOR name"]),
    (_scene(rp={"type": "roughplastic", "roughness": 0.2}),
     ["scene['rp']['roughness']", "bsdf 'roughplastic'", "unknown parameter"]),
    (_scene(rp={"type": "roughplastic", "alpha_u": 0.1, "alpha_v": 0.2}),
     ["scene['rp']['alpha_v']", "'alpha_u' and 'alpha_v' differ"]),
    (_scene(rp={"type": "roughplastic", "int_ior": 1.3, "ext_ior": 1.3}),
     ["scene['rp']", "'int_ior' and 'ext_ior' must differ"]),
    (_scene(rp={"type": "roughplastic", "distribution": "phong"}),
     ["scene['rp']['distribution']", "phong"]),
    ({"floor": RECT}, ["scene", "'type': 'scene'"]),
]


@pytest.mark.parametrize("scene,expected", BAD_DICTS,
                         ids=[e[0] for _, e in BAD_DICTS])
def test_bad_dict_scenes(scene, expected):
    with pytest.raises(SceneError) as info:
        load_dict(scene)
    for text in expected:
        assert text in str(info.value)


BAD_XML = [
    ("""<scene version="3.0.0">
<bsdf type="diffuse">
    <rgb name="reflectanse" value="0.5"/>
</bsdf>
</scene>""", 3, ["bsdf 'diffuse': unknown parameter 'reflectanse'"]),
    ("""<scene version="3.0.0">
<shape type="rectangle">
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5 -0.1 0.5"/></bsdf>
</shape>
</scene>""", 3, ["negative value -0.1"]),
    ("""<scene version="3.0.0">
<shape type="rectangle">
    <bsdf type="diffuse">
</shape>
</scene>""", 4, ["malformed XML"]),
    ("""<scene version="3.0.0">
<shape type="rectangle">
    <ref id="missing"/>
</shape>
</scene>""", 3, ["unknown id 'missing'"]),
    ("""<scene version="3.0.0">

<shape type="obj"><string name="filename" value="nothere.obj"/></shape>
</scene>""", 3, ["mesh file not found: 'nothere.obj'"]),
    ("""<scene version="3.0.0">
<sensor type="perspective">
    <float name="fov" value="$fov"/>
</sensor>
</scene>""", 3, ["undefined parameter $fov"]),
    ("""<scene version="3.0.0">
<shape type="sphere">
    <boolean name="flip_normals" value="1"/>
</shape>
</scene>""", 3, ["must be 'true' or 'false'"]),
    ("""<scene version="3.0.0">
<integrator type="path">
    <integer name="max_depth" value="3.5"/>
</integrator>
</scene>""", 3, ["cannot parse '3.5'"]),
    ("""<scene version="3.0.0">
<shape type="sphere">
    <float name="radius" value="inf"/>
</shape>
</scene>""", 3, ["non-finite"]),
    ("""<scene version="3.0.0">
<texture type="wood"/>
</scene>""", 2, ["texture type 'wood' is not supported"]),
    ("""<scene version="2.1">
</scene>""", 1, ["cannot parse version '2.1'"]),
    ("""<scene version="3.0.0">
<sensor type="perspective">
    <transform name="to_world">
        <skew value="1"/>
    </transform>
</sensor>
</scene>""", 4, ["unknown transform operation <skew>"]),
    ("""<scene version="3.0.0">
<shape type="cube">
    <transform name="to_world">
        <rotate x="1" y="1" angle="45"/>
    </transform>
</shape>
</scene>""", 4, ["<rotate>", "unit length"]),
    ("""<scene version="3.0.0">
<shape type="cube">
    <emitter type="point"/>
</shape>
</scene>""", 3, ["only an area emitter"]),
    ("""<scene version="3.0.0">
<shape type="sphere">
    <point name="center" x="1" y="2"/>
</shape>
</scene>""", 3, ["missing attribute 'z'"]),
    ("""<scene version="3.0.0">
<bsdf type="roughplastic">
    <float name="alpha" value="0.2"/>
    <float name="alpha_v" value="0.2"/>
</bsdf>
</scene>""", 2, ["bsdf 'roughplastic'", "alpha"]),
    ("""<scene version="3.0.0">
<bsdf type="roughplastic">
    <float name="alpha" value="0.2"/>
    <boolean name="sample_visibles" value="false"/>
</bsdf>
</scene>""", 4, ["bsdf 'roughplastic': unknown parameter 'sample_visibles'"]),
]


@pytest.mark.parametrize("text,line,expected", BAD_XML,
                         ids=[e[0] for _, _, e in BAD_XML])
def test_bad_xml_scenes(tmp_path, text, line, expected):
    path = tmp_path / "scene.xml"
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_file(path)
    message = str(info.value)
    assert f"{path}:{line}:" in message
    for t in expected:
        assert t in message


def test_missing_scene_file(tmp_path):
    with pytest.raises(SceneError, match="scene file not found"):
        load_file(tmp_path / "absent.xml")


def test_scene_desc_is_the_output_type():
    assert isinstance(load_dict({"type": "scene"}), SceneDesc)
