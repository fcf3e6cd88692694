"""Spectra in scenes: wavelength:value lists, spectrum files (.spd) and named
conductor materials become the RGB values Mitsuba 3's RGB variants make of
them (radiometer/loader/spectra.py), checked against mitsuba.load_dict and
mitsuba.load_string in scalar_rgb, read back with mitsuba.traverse.

The conversion itself needs no Mitsuba: the tests of bad input and of the
quadrature's own properties run without it.
"""
import numpy as np
import pytest

from radiometer.loader import load_dict, load_file
from radiometer.loader.spectra import DATA_DIR, conductor_ior, conductor_materials, to_rgb
from radiometer.scene_desc import SceneError

TOL = 1e-4  # the issue's bound on |ours - Mitsuba| per channel

# name -> (wavelength, value) pairs: regular and irregular spacing, values
# outside [0, 1] (negative, large), support narrower than and reaching past
# the CIE range 360 .. 830 nm, and the radiance of Mitsuba's own test scenes.
SPECTRA = {
    "regular": [(400 + 50 * i, v) for i, v in enumerate([0.1, 0.3, 0.5, 0.7, 0.9, 0.6, 0.2])],
    "irregular": [(380, 0.05), (412.5, 0.4), (455, 0.2), (530, 0.8), (541, 0.75), (610, 0.3), (777, 0.6)],
    "large": [(400, 3.0), (500, 0.2), (600, 1.5), (700, 2.5)],
    "negative": [(420, -0.3), (480, 0.6), (560, -0.1), (650, 0.9), (720, -0.5)],
    "wide": [(300, 0.9), (500, 0.1), (900, 0.7)],
    "narrow": [(540, 0.5), (560, 2.0)],
    "suite_radiance": [(400, 0), (500, 8), (600, 15.6), (700, 18.4)],
    "flat": [(400, 0.78), (500, 0.78), (600, 0.78), (700, 0.78)],
}


@pytest.fixture(scope="module")
def mi():
    mitsuba = pytest.importorskip("mitsuba", reason="mitsuba (the reference renderer) is not installed")
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


def _spd_text(pairs, comments=True):
    head = "# a spectrum file\n# wavelength (nm)  value\n\n" if comments else ""
    return head + "".join(f"{w:.6f} {v:.6f}\n" for w, v in pairs)


@pytest.fixture(scope="module")
def spd_files(tmp_path_factory):
    root = tmp_path_factory.mktemp("spectra")
    out = {}
    for name, pairs in SPECTRA.items():
        path = root / f"{name}.spd"
        path.write_text(_spd_text(pairs))
        out[name] = path
    return out


# -- where each kind of parameter lives: (Mitsuba plugin dict, traverse key),
#    and (our scene dict, the value in our SceneDesc) ---------------------------

def _bsdf(t, name):
    return (lambda s: ({"type": t, name: s}, f"{name}.value"),
            lambda s: ({"type": "scene", "o": {"type": "sphere", "bsdf": {"type": t, name: s}}},
                       lambda d: getattr(d.shapes[0].bsdf, name)))


def _emitter(t, name):
    def ours(s):
        e = {"type": t, name: s}
        if t == "area":
            return {"type": "scene", "o": {"type": "sphere", "emitter": e}}, lambda d: d.shapes[0].emitter.radiance
        return {"type": "scene", "e": e}, lambda d: getattr(d.emitters[0], name)
    return (lambda s: ({"type": t, name: s}, f"{name}.value"), ours)


def _medium(name, t="homogeneous"):
    def ours(s):
        m = {"type": t, name: s}
        return ({"type": "scene", "o": {"type": "sphere", "bsdf": {"type": "null"}, "interior": m}},
                lambda d: getattr(d.shapes[0].interior, name))
    return (lambda s: ({"type": t, name: s}, f"{name}.value.value"), ours)


def _constvolume():
    def ours(s):
        m = {"type": "heterogeneous", "sigma_t": {"type": "constvolume", "value": s}}
        return ({"type": "scene", "o": {"type": "sphere", "bsdf": {"type": "null"}, "interior": m}},
                lambda d: d.shapes[0].interior.sigma_t)
    return (lambda s: ({"type": "constvolume", "value": s}, "value.value"), ours)


# Each with how Mitsuba converts it: D65-weighted and clamped to [0, 1]
# (reflectances, and, in Mitsuba 3.9.1, a medium's sigma_t given as a value);
# D65-weighted, unclamped above (eta, k, a constvolume's value); no D65,
# unclamped (emitters).
KINDS = {
    "diffuse.reflectance": _bsdf("diffuse", "reflectance"),
    "plastic.diffuse_reflectance": _bsdf("plastic", "diffuse_reflectance"),
    "dielectric.specular_transmittance": _bsdf("dielectric", "specular_transmittance"),
    "conductor.eta": _bsdf("conductor", "eta"),
    "conductor.k": _bsdf("conductor", "k"),
    "roughconductor.specular_reflectance": _bsdf("roughconductor", "specular_reflectance"),
    "area.radiance": _emitter("area", "radiance"),
    "constant.radiance": _emitter("constant", "radiance"),
    "point.intensity": _emitter("point", "intensity"),
    "spot.intensity": _emitter("spot", "intensity"),
    "directional.irradiance": _emitter("directional", "irradiance"),
    "homogeneous.sigma_t": _medium("sigma_t"),
    "homogeneous.albedo": _medium("albedo"),
    "heterogeneous.sigma_t": _medium("sigma_t", "heterogeneous"),
    "constvolume.value": _constvolume(),
}


def _theirs(mi, d, key):
    return np.array(mi.traverse(mi.load_dict(d))[key], dtype=np.float64)


def _ours(d, get):
    return np.array(get(load_dict(d)), dtype=np.float64)


def _pairs(name):
    return {"type": "spectrum", "value": SPECTRA[name]}


@pytest.mark.parametrize("kind", KINDS)
def test_inline_spectra_match_mitsuba(mi, kind):
    theirs_of, ours_of = KINDS[kind]
    worst = 0.0
    for name in SPECTRA:
        d, key = theirs_of(_pairs(name))
        o, get = ours_of(_pairs(name))
        a, b = _theirs(mi, d, key), _ours(o, get)
        assert a.shape == (3,) and np.allclose(a, b, rtol=0, atol=TOL), (kind, name, a, b)
        worst = max(worst, float(np.abs(a - b).max()))
    print(f"{kind}: max |ours - Mitsuba| over {len(SPECTRA)} spectra = {worst:.2e}")


@pytest.mark.parametrize("kind", KINDS)
def test_uniform_spectra_match_mitsuba(mi, kind):
    """A single-valued spectrum: on an emitter Mitsuba's RGB variants make it
    XYZ = (v, v, v) in sRGB (not grey); everywhere else it stays v. Tested
    for each parameter kind, and the grey reading of an emitter's is caught."""
    theirs_of, ours_of = KINDS[kind]
    for v in (0.5,) if kind.endswith("albedo") else (0.5, 3.0):  # an albedo above 1 is refused by name
        d, key = theirs_of({"type": "spectrum", "value": v})
        o, get = ours_of({"type": "spectrum", "value": v})
        a, b = _theirs(mi, d, key), _ours(o, get)
        if a.shape == ():
            a = np.full(3, float(a))
        assert np.allclose(a, b, rtol=0, atol=TOL * max(1.0, v)), (kind, v, a, b)
        if kind.split(".")[0] in ("area", "constant", "point", "spot", "directional"):
            assert not np.allclose(a, v, rtol=0, atol=1e-2), (kind, a)  # the power check: grey would fail


@pytest.mark.parametrize("kind", ["diffuse.reflectance", "conductor.k", "area.radiance", "constvolume.value"])
def test_spd_files_match_mitsuba(mi, spd_files, kind):
    theirs_of, ours_of = KINDS[kind]
    for name, path in spd_files.items():
        spec = {"type": "spectrum", "filename": str(path)}
        d, key = theirs_of(spec)
        o, get = ours_of(spec)
        a, b = _theirs(mi, d, key), _ours(o, get)
        assert np.allclose(a, b, rtol=0, atol=TOL), (kind, name, a, b)
        # a file and the same pairs inline give the same colour
        o2, get2 = ours_of(_pairs(name))
        assert np.allclose(b, _ours(o2, get2), rtol=0, atol=1e-9)


def _xml_scene(body):
    return f'<scene version="3.0.0">\n{body}\n</scene>\n'


@pytest.mark.parametrize("name", ["irregular", "negative", "suite_radiance"])
def test_xml_spectra_match_mitsuba(mi, tmp_path, spd_files, name):
    """<spectrum value="w:v, ..."/> and <spectrum filename=".."/> through
    Mitsuba's XML parser (load_string) and ours (load_file)."""
    text = ", ".join(f"{w}:{v}" for w, v in SPECTRA[name])
    for attr in (f'value="{text}"', f'filename="{spd_files[name]}"'):
        refl = f'<bsdf type="diffuse"><spectrum name="reflectance" {attr}/></bsdf>'
        lamp = f'<emitter type="area"><spectrum name="radiance" {attr}/></emitter>'
        a_refl = np.array(mi.traverse(mi.load_string(f'<bsdf version="3.0.0"{refl[5:]}'))["reflectance.value"])
        a_lamp = np.array(mi.traverse(mi.load_string(f'<emitter version="3.0.0"{lamp[8:]}'))["radiance.value"])
        path = tmp_path / f"{name}.xml"
        path.write_text(_xml_scene(f'<shape type="sphere">{refl}{lamp}</shape>'))
        s = load_file(path).shapes[0]
        assert np.allclose(a_refl, s.bsdf.reflectance, rtol=0, atol=TOL), (attr, a_refl, s.bsdf.reflectance)
        assert np.allclose(a_lamp, s.emitter.radiance, rtol=0, atol=TOL), (attr, a_lamp, s.emitter.radiance)


@pytest.mark.parametrize("bsdf", ["conductor", "roughconductor"])
def test_named_conductors_match_mitsuba(mi, bsdf):
    names = conductor_materials()
    assert len(names) == 71 and "Au" in names and "Cu_palik" in names
    worst = 0.0
    for m in names:
        p = mi.traverse(mi.load_dict({"type": bsdf, "material": m}))
        ours = load_dict({"type": "scene", "o": {"type": "sphere", "bsdf": {"type": bsdf, "material": m}}})
        b = ours.shapes[0].bsdf
        for part, value in (("eta", b.eta), ("k", b.k)):
            a = np.array(p[f"{part}.value"], dtype=np.float64)
            assert np.allclose(a, value, rtol=0, atol=TOL), (m, part, a, value)
            worst = max(worst, float(np.abs(a - np.array(value)).max()))
    print(f"{bsdf}: max |ours - Mitsuba| over {len(names)} materials' eta and k = {worst:.2e}")


def test_material_none_is_the_default_mirror(mi):
    b = load_dict({"type": "scene", "o": {"type": "sphere", "bsdf": {"type": "conductor", "material": "none"}}})
    p = mi.traverse(mi.load_dict({"type": "conductor", "material": "none"}))
    assert b.shapes[0].bsdf.eta == (0.0, 0.0, 0.0) and b.shapes[0].bsdf.k == (1.0, 1.0, 1.0)
    assert np.allclose(p["eta.value"], 0.0) and np.allclose(p["k.value"], 1.0)


# -- power: the comparison notices small errors -----------------------------------


def test_a_perturbed_spectrum_is_detected(mi):
    """Adding 1e-3 to every value moves the RGB by more than the tolerance,
    in each conversion mode; so do the wrong mode and a shifted wavelength."""
    for kind in ("diffuse.reflectance", "conductor.eta", "area.radiance"):
        theirs_of, ours_of = KINDS[kind]
        d, key = theirs_of(_pairs("irregular"))
        a = _theirs(mi, d, key)
        bumped = [(w, v + 1e-3) for w, v in SPECTRA["irregular"]]
        o, get = ours_of({"type": "spectrum", "value": bumped})
        assert np.abs(a - _ours(o, get)).max() > TOL, kind
        shifted = [(w + 2.0, v) for w, v in SPECTRA["irregular"]]
        o, get = ours_of({"type": "spectrum", "value": shifted})
        assert np.abs(a - _ours(o, get)).max() > TOL, kind
    wl, v = zip(*SPECTRA["irregular"])
    refl = _theirs(mi, *KINDS["diffuse.reflectance"][0](_pairs("irregular")))
    assert np.abs(refl - to_rgb(wl, v, d65=False, bounded=True)).max() > 10 * TOL  # D65 matters


def test_quadrature_properties():
    """Without Mitsuba: a unit spectrum over the CIE range has luminance 1
    as an emitter and 98.888 / 98.997 as a reflectance (Mitsuba's D65
    constant); clamping; linearity in the values."""
    wl = [360.0, 830.0]
    e = np.array(to_rgb(wl, [1.0, 1.0], d65=False, bounded=False))
    y = np.array([0.212671, 0.715160, 0.072169]) @ e  # RGB -> Y (Rec. 709)
    assert abs(y - 1.0) < 2e-5, y
    r = np.array(to_rgb(wl, [1.0, 1.0], d65=True, bounded=False))
    assert abs(np.array([0.212671, 0.715160, 0.072169]) @ r - 98.8878 / 98.99742) < 2e-5
    assert max(to_rgb(wl, [5.0, 5.0])) == 1.0 and min(to_rgb(wl, [-1.0, -1.0], bounded=False)) == 0.0
    pairs = SPECTRA["irregular"]
    w, v = zip(*pairs)
    a = np.array(to_rgb(w, v, bounded=False))
    b = np.array(to_rgb(w, [2 * x for x in v], bounded=False))
    assert np.allclose(2 * a, b, atol=1e-12)


def test_material_tables_are_the_cited_data():
    """Every material has both tables, each with its provenance header."""
    for m in conductor_materials():
        for part in ("eta", "k"):
            with open(f"{DATA_DIR}/{m}.{part}.spd") as f:
                assert f.readline().startswith("# data from www.luxpop.com database"), (m, part)
        eta, k = conductor_ior(m)
        assert all(x >= 0 for x in eta + k)


# -- bad input: SceneError with the place and the parameter ------------------------


def _bad_xml(tmp_path, body, marked, words):
    text = _xml_scene(body)
    line = next(i for i, s in enumerate(text.split("\n"), 1) if marked in s)
    path = tmp_path / "bad.xml"
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_file(path)
    msg = str(info.value)
    assert f"{path}:{line}:" in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


def _refl(attr):
    return f'<shape type="sphere"><bsdf type="diffuse">\n<spectrum name="reflectance" {attr}/>\n</bsdf></shape>'


@pytest.mark.parametrize("attr, words", [
    ('value="700:0.1, 400:0.5"', ["wavelengths must increase strictly: 400 follows 700"]),
    ('value="400:0.1, 400:0.5"', ["wavelengths must increase strictly"]),
    ('value="400:0.1"', ["at least two wavelength:value pairs"]),
    ('value="400:0.1, 700"', ["'700' is not a wavelength:value pair"]),
    ('value="400:0.1, 700:x"', ["cannot parse numbers from the pair '700:x'"]),
    ('value="400:0.1:3, 700:0.2"', ["'400:0.1:3' is not a wavelength:value pair"]),
    ('value="400 : 0.1, 700:0.2"', ["not a wavelength:value pair"]),
    ('value="400:nan, 700:0.2"', ["non-finite"]),
    ('value="-5:0.1, 700:0.2"', ["must be > 0"]),
    ('filename="missing.spd"', ["spectrum file 'missing.spd' not found"]),
    ('value="0.5" filename="x.spd"', ["give either value or filename"]),
    ("", ["give either value or filename"]),
])
def test_bad_xml_spectra(tmp_path, attr, words):
    _bad_xml(tmp_path, _refl(attr), "<spectrum", ["diffuse", "parameter 'reflectance'"] + words)


@pytest.mark.parametrize("content, words", [
    ("# header\n400 0.1\n700 0.5 9\n", [":3: expected two numbers"]),
    ("400 0.1\nfoo bar\n", [":2: expected two numbers"]),
    ("700 0.1\n400 0.5\n", ["wavelengths must increase strictly"]),
    ("# only a comment\n", ["at least two"]),
    ("400 0.1\n  # indented comment\n700 0.2\n", []),  # loads: a comment after white space
])
def test_bad_spd_files(tmp_path, content, words):
    spd = tmp_path / "s.spd"
    spd.write_text(content)
    if not words:
        path = tmp_path / "ok.xml"
        path.write_text(_xml_scene(_refl(f'filename="{spd.name}"')))
        load_file(path)
        return
    msg = _bad_xml(tmp_path, _refl(f'filename="{spd.name}"'), "<spectrum", ["parameter 'reflectance'"] + words)
    assert f"{spd}:" in msg, msg


def test_untrusted_scene_spd_outside_folder_and_unquoted(tmp_path):
    inner = tmp_path / "scene"
    inner.mkdir()
    (tmp_path / "outside.spd").write_text("400 0.1\n700 0.2\n")
    path = inner / "a.xml"
    path.write_text(_xml_scene(_refl('filename="../outside.spd"')))
    with pytest.raises(SceneError, match="outside the scene's folder"):
        load_file(path, base_dir_only=True)
    (inner / "secret.spd").write_text("400 0.1\nsecret-words here\n")
    path.write_text(_xml_scene(_refl('filename="secret.spd"')))
    with pytest.raises(SceneError) as info:
        load_file(path, base_dir_only=True)
    assert "secret.spd:2:" in str(info.value) and "secret-words" not in str(info.value)


def test_unknown_material_lists_the_known(tmp_path):
    body = '<shape type="sphere"><bsdf type="conductor">\n<string name="material" value="Gold"/>\n</bsdf></shape>'
    msg = _bad_xml(tmp_path, body, '"material"', ["parameter 'material'", "unknown conductor material 'Gold'"])
    for m in ("none", "Ag", "Au", "Cu", "Cu_palik", "a-C"):
        assert m in msg


@pytest.mark.parametrize("spec, where, words", [
    ({"type": "spectrum", "value": [(700, 0.1), (400, 0.5)]}, "reflectance", ["wavelengths must increase"]),
    ({"type": "spectrum", "value": [(400, 0.1)]}, "reflectance", ["at least two"]),
    ({"type": "spectrum", "value": [(400, 0.1, 3), (700, 0.2, 1)]}, "reflectance", ["(wavelength, value) pairs"]),
    ({"type": "spectrum", "value": [400, 700]}, "reflectance", ["(wavelength, value) pairs"]),
    ({"type": "spectrum", "value": [("400", 0.1), (700, 0.2)]}, "reflectance", ["expected real numbers"]),
    ({"type": "spectrum", "filename": "/nonexistent/x.spd"}, "reflectance", ["spectrum file", "not found"]),
    ({"type": "spectrum", "filename": 3}, "reflectance", ["'filename': str"]),
    ({"type": "spectrum", "filename": "x.spd", "value": 1.0}, "reflectance", ["'filename': str"]),
])
def test_bad_dict_spectra(spec, where, words):
    with pytest.raises(SceneError) as info:
        load_dict({"type": "scene", "o": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": spec}}})
    msg = str(info.value)
    assert msg.startswith(f"scene['o']['bsdf']['{where}']"), msg
    for w in words:
        assert w in msg, msg


def test_dict_unknown_material():
    with pytest.raises(SceneError) as info:
        load_dict({"type": "scene", "o": {"type": "sphere", "bsdf": {"type": "roughconductor", "material": "au"}}})
    msg = str(info.value)
    assert msg.startswith("scene['o']['bsdf']['material']") and "unknown conductor material 'au'" in msg, msg
