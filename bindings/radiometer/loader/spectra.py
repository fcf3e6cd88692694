"""Spectra to linear sRGB, as Mitsuba 3's RGB variants convert them when a
scene is loaded: wavelength:value lists, spectrum files (.spd) and the
measured (eta, k) tables of named conductors.

The rule (Mitsuba 3.9.1, `spectrum_list_to_srgb` in src/core/spectrum.cpp,
and `Properties::get_texture` in src/core/properties.cpp, which chooses its
flags) is a fixed quadrature, not an exact integral; this module writes it
down from its definition:

- 1000 wavelengths w_i = 360 + 470 i / 999 nm, i = 0 .. 999;
- the spectrum s(w): linear between the given points, 0 outside them;
- CIE 1931 2-degree colour-matching functions (x, y, z)(w): linear between
  their values at 5 nm steps from 360 to 830 nm (Mitsuba tabulates only
  these 95 nodes; colour-science's 1 nm table holds the same values there.
  Interpolating colour-science's full 1 nm table instead would move the
  named conductors' eta and k by up to 3.4e-3, beyond the 1e-4 we promise,
  so we follow Mitsuba's 5 nm rule with colour-science's numbers);
- XYZ = (470 / 1000) * sum_i (x, y, z)(w_i) s(w_i) W(w_i), where W is
    * for an emitter's radiance, intensity or irradiance, and for a
      conductor's eta and k read from files: 1 / N_Y, with N_Y the same
      quadrature of y alone (106.7502; Mitsuba's MI_CIE_Y_NORMALIZATION is
      1 / 106.75026, the float32 rounding of the same sum);
    * for any other parameter (reflectances, and also unbounded ones such
      as a medium's sigma_t): D(w) / (N_D65 N_Y), with D the CIE D65
      illuminant, linear between its 5 nm values, and N_D65 = 98.99742
      (Mitsuba's MI_CIE_D65_NORMALIZATION, a constant of its source: this
      quadrature gives 98.88779, so a unit reflectance maps to Y = 0.99890,
      not 1; we keep Mitsuba's constant to match its numbers);
- RGB = M XYZ with M the ITU-R BT.709 (sRGB primaries, D65 white) matrix
  at the 6-digit precision Mitsuba uses (C. Poynton, "Frequently asked
  questions about color", 1997, the XYZ to Rec. 709 RGB matrix);
- negative components are clamped to 0; a bounded parameter (a
  reflectance) also has components above 1 clamped to 1.

Data: colour-science's CIE 1931 2-degree observer (CVRL / CIE 018:2019)
and CIE D65 (CIE S 014-2) tables. colour-science's D65 table stops at
780 nm; from 785 to 830 nm we use its CIE D-series reconstruction at the
D65 correlated colour temperature (6500 K * 1.4388 / 1.4380), which gives
the CIE table's values to within their rounding (5e-5 of values near 60).
"""
from __future__ import annotations

import functools
import os

import numpy as np

CIE_MIN, CIE_MAX = 360.0, 830.0
_N_QUAD = 1000
# Mitsuba 3.9.1's D65 normalisation (include/mitsuba/core/spectrum.h).
N_D65 = 98.99741751876255
# XYZ to linear Rec. 709 RGB (Poynton's Color FAQ, as Mitsuba's xyz_to_srgb).
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])

DATA_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "ior")


@functools.lru_cache(maxsize=1)
def _tables():
    """(quadrature wavelengths, xyz there (n, 3), D65 there (n,), N_Y),
    from colour-science's data at the 5 nm nodes 360 .. 830."""
    import colour  # colour-science: imported only where a scene has a spectrum

    nodes = np.arange(CIE_MIN, CIE_MAX + 2.5, 5.0)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz_nodes = np.asarray(cmfs[nodes], dtype=np.float64)
    d65_sd = colour.SDS_ILLUMINANTS["D65"]
    table = nodes <= d65_sd.wavelengths[-1]
    d65_nodes = np.empty(len(nodes))
    d65_nodes[table] = d65_sd[nodes[table]]
    if not table.all():
        xy = colour.temperature.CCT_to_xy_CIE_D(6500.0 * 1.4388 / 1.4380)
        series = colour.sd_CIE_illuminant_D_series(xy)
        d65_nodes[~table] = np.round(series[nodes[~table]], 4)
    w = CIE_MIN + (np.arange(_N_QUAD) / (_N_QUAD - 1)) * (CIE_MAX - CIE_MIN)
    xyz = np.stack([np.interp(w, nodes, xyz_nodes[:, c]) for c in range(3)], axis=1)
    d65 = np.interp(w, nodes, d65_nodes)
    dw = (CIE_MAX - CIE_MIN) / _N_QUAD
    n_y = dw * xyz[:, 1].sum()
    return w, xyz, d65, n_y


def to_rgb(wavelengths, values, d65=True, bounded=True):
    """Linear sRGB of a sampled spectrum (wavelengths increasing, in nm).
    d65: weight by the D65 illuminant (a reflectance-like parameter; false
    for an emitter's power or an IOR table); bounded: clamp to [0, 1] (else
    only negatives to 0)."""
    wl = np.asarray(wavelengths, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    w, xyz, d65_w, n_y = _tables()
    inside = (w >= wl[0]) & (w <= wl[-1])
    s = np.where(inside, np.interp(w, wl, v), 0.0)
    weight = (d65_w / N_D65 if d65 else 1.0) / n_y
    total = ((CIE_MAX - CIE_MIN) / _N_QUAD) * (xyz * (s * weight)[:, None]).sum(axis=0)
    rgb = XYZ_TO_SRGB @ total
    rgb = np.maximum(rgb, 0.0)
    if bounded:
        rgb = np.minimum(rgb, 1.0)
    return tuple(float(c) for c in rgb)


class Sampled:
    """A spectrum given as samples: wavelengths (nm, increasing) and values;
    `source` says where it came from, for messages."""

    __slots__ = ("wavelengths", "values", "source")

    def __init__(self, wavelengths, values, source):
        self.wavelengths = np.asarray(wavelengths, dtype=np.float64)
        self.values = np.asarray(values, dtype=np.float64)
        self.source = source

    def rgb(self, kind):
        """kind: 'bounded' (a reflectance), 'unbounded' (e.g. an IOR) or
        'emission' (an emitter's radiance, intensity or irradiance)."""
        return to_rgb(self.wavelengths, self.values, d65=kind != "emission", bounded=kind == "bounded")


def check_samples(wavelengths, values):
    """Why these samples are not a spectrum (Mitsuba's rules: at least two,
    wavelengths strictly increasing), or None; also refuses non-finite
    numbers and non-positive wavelengths."""
    if len(wavelengths) < 2:
        return f"a spectrum needs at least two wavelength:value pairs, got {len(wavelengths)}"
    for x in list(wavelengths) + list(values):
        if not np.isfinite(x):
            return f"non-finite number {x}"
    if wavelengths[0] <= 0:
        return f"wavelengths are in nm and must be > 0, got {wavelengths[0]:g}"
    for i in range(1, len(wavelengths)):
        if not wavelengths[i] > wavelengths[i - 1]:
            return (f"wavelengths must increase strictly: {wavelengths[i]:g} follows {wavelengths[i - 1]:g} "
                    f"(pair {i + 1})")
    return None


def parse_pairs(text, parse_float):
    """'w1:v1, w2:v2, ...' (separated by commas and/or white space) ->
    (wavelengths, values); ValueError with the reason."""
    tokens = [t for t in text.replace(",", " ").split() if t]
    wl, vals = [], []
    for t in tokens:
        parts = t.split(":")
        if len(parts) != 2:
            raise ValueError(f"'{t}' is not a wavelength:value pair")
        try:
            wl.append(parse_float(parts[0]))
            vals.append(parse_float(parts[1]))
        except ValueError:
            raise ValueError(f"cannot parse numbers from the pair '{t}'") from None
    why = check_samples(wl, vals)
    if why:
        raise ValueError(why)
    return wl, vals


def read_spd(path, shown, parse_float, quote=True):
    """A spectrum file: one 'wavelength value' pair per line; lines that are
    empty or start with '#' are skipped (Mitsuba's .spd format). `shown`: the
    file's name in messages; quote=False keeps the file's content out of
    them (an untrusted scene). ValueError with 'shown:line: reason'."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise ValueError(f"{shown}: cannot read the spectrum file ({e.strerror})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{shown}: the spectrum file is not UTF-8 text") from None
    wl, vals = [], []
    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        try:
            if len(parts) != 2:
                raise ValueError
            w, v = parse_float(parts[0]), parse_float(parts[1])
        except ValueError:
            got = f": '{s[:60]}'" if quote else ""
            raise ValueError(f"{shown}:{n}: expected two numbers (wavelength value){got}") from None
        wl.append(w)
        vals.append(v)
    why = check_samples(wl, vals)
    if why:
        raise ValueError(f"{shown}: {why}")
    return wl, vals


def conductor_materials():
    """The named conductors (Mitsuba's data/ior names), sorted."""
    names = {f.split(".")[0] for f in os.listdir(DATA_DIR) if f.endswith(".eta.spd")}
    return sorted(names, key=str.lower)


@functools.lru_cache(maxsize=None)
def conductor_ior(material):
    """(eta, k) RGB of a named conductor, from its measured tables, as
    Mitsuba's conductors read them in RGB mode (no D65 weight, unbounded);
    KeyError if the name is unknown."""
    if material not in conductor_materials():
        raise KeyError(material)
    out = []
    for part in ("eta", "k"):
        path = os.path.join(DATA_DIR, f"{material}.{part}.spd")
        wl, vals = read_spd(path, path, float)
        out.append(to_rgb(wl, vals, d65=False, bounded=False))
    return tuple(out)
