"""Writes reference_scenes/many_lights/scene.xml: a two-room hall lit by
10 000 emitters whose powers span five decades (card.md says what the scene
isolates). Deterministic (numpy's default_rng(SEED)); the committed XML is
this script's output, and tests/test_many_lights.py checks that it still is.

    python -m radiometer.reference_scenes.many_lights.generate [--check]

The emitters (every one a separate emitter element: Mitsuba and our
renderer select among emitters, then sample a point on the chosen one):

- N_POINTS point lights, uniform in the air of both rooms (at least
  CLEARANCE from every surface), intensity log-uniform over four decades
  (Mitsuba's `point`, I in W/sr; power 4 pi I);
- N_DOWN "downlights": 8 cm squares just under the ceiling facing down,
  radiance log-uniform over three decades (power pi L A);
- N_UP "uplights": the same squares 10 cm under the ceiling facing up, so
  that they light only the ceiling (a light tree's orientation cones
  reject them for every point below; selection by power does not);
- two meshed area lights: the triangle mesh tube.obj (a hexagonal prism,
  12 side triangles and 12 on its caps) placed twice, one along the front
  room's left wall, one along the back room's far wall.

60 % of the points and squares are in the back room, behind a full-height
partition with a doorway: from most of what the camera sees they are
occluded, lighting it only through the doorway and by interreflection.

`sampling_weights=True` (scene_xml) adds to every emitter Mitsuba's
`sampling_weight` (Mitsuba 3 picks emitter i with probability w_i / sum w)
equal to its power, for the Mitsuba reference only
(reference_scenes/make_reference.py through the registry's
`mitsuba_xml`): it changes which emitter a sample picks, never the
expectation, and our loader does not take the parameter.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
XML = HERE / "scene.xml"
OBJ = HERE / "tube.obj"
SEED = 17
N_POINTS = 9000
N_DOWN = 499
N_UP = 499
N_TUBES = 2
N_EMITTERS = N_POINTS + N_DOWN + N_UP + N_TUBES

# The hall: x in [-X, X], z in [-Z, Z], floor y = 0, ceiling y = H; the
# partition at z = ZP (thickness 2 T) with a doorway |x| < DOOR_W / 2,
# y < DOOR_H.
X, Z, H = 5.0, 5.0, 3.0
ZP, T = -1.0, 0.05
DOOR_W, DOOR_H = 1.2, 2.2
CLEARANCE = 0.25
BACK_FRACTION = 0.6
# Boxes on the front room's floor (centre, half-extents): occluders that
# cast the shadows of many lights at once.
BOXES = [((-2.2, 0.6, 1.6), (0.5, 0.6, 0.5)), ((1.9, 0.9, 0.6), (0.35, 0.9, 0.35)),
         ((0.4, 0.3, 2.6), (0.7, 0.3, 0.3)), ((-3.0, 1.25, -3.0), (0.4, 1.25, 0.4))]
# Powers: point intensity I = POINT_I * 10^U(-4, 0) W/sr; squares' radiance
# L = SQUARE_L * 10^U(-3, 0); half-side of a square.
POINT_I = 0.05
SQUARE_L = 40.0
SQUARE_HALF = 0.04
TUBE_L = 5.0
TUBE_R, TUBE_HALF_LEN = 0.03, 1.2


def _f(x):
    s = f"{x:.3f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _c(x):
    """A light's coordinate, to the centimetre."""
    s = f"{x:.2f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _g(x):
    return f"{x:.3g}"


def tube_obj() -> str:
    """A hexagonal prism of radius TUBE_R and half-length TUBE_HALF_LEN along
    x, closed by fan caps: 24 triangles, wound outwards."""
    k = 6
    v = []
    for side in (-1, 1):
        for i in range(k):
            a = 2 * math.pi * i / k
            v.append((side * TUBE_HALF_LEN, TUBE_R * math.cos(a), TUBE_R * math.sin(a)))
    v += [(-TUBE_HALF_LEN, 0.0, 0.0), (TUBE_HALF_LEN, 0.0, 0.0)]
    f = []
    for i in range(k):
        j = (i + 1) % k
        a0, a1, b0, b1 = i + 1, j + 1, k + i + 1, k + j + 1
        f += [(a0, a1, b1), (a0, b1, b0)]  # outward for a ring ordered counter-clockwise about +x
        f += [(2 * k + 1, a1, a0), (2 * k + 2, b0, b1)]
    lines = ["# many_lights: the meshed area light (generate.py)"]
    lines += [f"v {_f(a)} {_f(b)} {_f(c)}" for a, b, c in v]
    lines += [f"f {a} {b} {c}" for a, b, c in f]
    return "\n".join(lines) + "\n"


def _tube_area() -> float:
    k = 6
    side = 2 * TUBE_R * math.sin(math.pi / k)
    return k * side * 2 * TUBE_HALF_LEN + 2 * (0.5 * k * TUBE_R * TUBE_R * math.sin(2 * math.pi / k))


def _in_box(p, pad):
    for c, h in BOXES:
        if all(abs(p[i] - c[i]) < h[i] + pad for i in range(3)):
            return True
    return False


def _draw(rng, n, y_lo, y_hi, pad):
    """n positions: a BACK_FRACTION of them behind the partition, none
    within `pad` of a wall, the partition or a box."""
    out = []
    n_back = int(round(BACK_FRACTION * n))
    for k in range(n):
        back = k < n_back
        z_lo, z_hi = (-Z + pad, ZP - T - pad) if back else (ZP + T + pad, Z - pad)
        while True:
            p = (rng.uniform(-X + pad, X - pad), rng.uniform(y_lo, y_hi), rng.uniform(z_lo, z_hi))
            if not _in_box(p, pad):
                out.append(p)
                break
    return out


def emitters(seed=SEED):
    """[(kind, position, value, power)] in the XML's order: 'point'
    (intensity), 'down' / 'up' (radiance), 'tube' (radiance)."""
    # Generator(PCG64(seed)) is default_rng(seed)'s stream; named so that
    # the tests' seed offset, which re-rolls default_rng, leaves the
    # committed scene its generator's output.
    rng = np.random.Generator(np.random.PCG64(seed))
    out = []
    for p in _draw(rng, N_POINTS, CLEARANCE, H - CLEARANCE, CLEARANCE):
        i = POINT_I * 10.0 ** rng.uniform(-4.0, 0.0)
        out.append(("point", p, float(_g(i)), 4 * math.pi * float(_g(i))))
    area = (2 * SQUARE_HALF) ** 2
    for kind, n, y in (("down", N_DOWN, H - 0.02), ("up", N_UP, H - 0.10)):
        for p in _draw(rng, n, y, y, 0.1):
            le = float(_g(SQUARE_L * 10.0 ** rng.uniform(-3.0, 0.0)))
            out.append((kind, p, le, math.pi * le * area))
    ta = _tube_area()
    out.append(("tube", (-X + 0.15, 2.2, 2.5), TUBE_L, math.pi * TUBE_L * ta))
    out.append(("tube", (0.0, 2.4, -Z + 0.15), TUBE_L, math.pi * TUBE_L * ta))
    return out


def _cube(name, c, h, bsdf):
    return (f'    <shape type="cube" id="{name}"><transform name="to_world"><scale x="{_f(h[0])}" y="{_f(h[1])}" '
            f'z="{_f(h[2])}"/><translate value="{_f(c[0])} {_f(c[1])} {_f(c[2])}"/></transform>'
            f'<ref id="{bsdf}"/></shape>')


def _wall(name, scale, rot, t, bsdf):
    rs = "".join(f'<rotate {ax}="1" angle="{a}"/>' for ax, a in rot)
    return (f'    <shape type="rectangle" id="{name}"><transform name="to_world"><scale x="{_f(scale[0])}" '
            f'y="{_f(scale[1])}"/>{rs}<translate value="{_f(t[0])} {_f(t[1])} {_f(t[2])}"/></transform>'
            f'<ref id="{bsdf}"/></shape>')


def scene_xml(sampling_weights=False, seed=SEED) -> str:
    em = emitters(seed)
    slab = (X - DOOR_W / 2) / 2  # half-width of each slab beside the doorway
    head = f"""<!-- many_lights: {N_EMITTERS} emitters in a two-room hall (reference_scenes/many_lights/card.md).
     Written by generate.py (seed {seed}); do not edit by hand. -->
<scene version="3.0.0">
    <default name="spp" value="64"/>
    <default name="res" value="64"/>
    <default name="max_depth" value="4"/>
    <integrator type="path"><integer name="max_depth" value="$max_depth"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="70"/>
        <string name="fov_axis" value="x"/>
        <transform name="to_world"><lookat origin="0.3, 1.7, 4.8" target="0, 0.8, -1" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="$res"/>
            <integer name="height" value="$res"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf>
    <bsdf type="diffuse" id="floor_bsdf"><rgb name="reflectance" value="0.45, 0.4, 0.35"/></bsdf>
    <bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.6, 0.2, 0.15"/></bsdf>
    <bsdf type="diffuse" id="blue"><rgb name="reflectance" value="0.15, 0.25, 0.6"/></bsdf>
    <bsdf type="diffuse" id="grey"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
    <bsdf type="diffuse" id="lamp"><rgb name="reflectance" value="0.2, 0.2, 0.2"/></bsdf>
"""
    body = [
        # rectangles are [-1, 1]^2 with normal +z; every wall faces into the hall
        _wall("floor", (X, Z), [("x", -90)], (0, 0, 0), "floor_bsdf"),
        _wall("ceiling", (X, Z), [("x", 90)], (0, H, 0), "white"),
        _wall("wall_back", (X, H / 2), [], (0, H / 2, -Z), "white"),
        _wall("wall_front", (X, H / 2), [("y", 180)], (0, H / 2, Z), "white"),
        _wall("wall_left", (Z, H / 2), [("y", 90)], (-X, H / 2, 0), "red"),
        _wall("wall_right", (Z, H / 2), [("y", -90)], (X, H / 2, 0), "blue"),
        # the partition: two slabs beside the doorway and a lintel above it
        _cube("partition_left", (-(X + DOOR_W / 2) / 2, H / 2, ZP), (slab, H / 2, T), "white"),
        _cube("partition_right", ((X + DOOR_W / 2) / 2, H / 2, ZP), (slab, H / 2, T), "white"),
        _cube("lintel", (0, (H + DOOR_H) / 2, ZP), (DOOR_W / 2, (H - DOOR_H) / 2, T), "white"),
    ]
    body += [_cube(f"box{i}", c, h, "grey") for i, (c, h) in enumerate(BOXES)]
    lines = [head] + [b + "\n" for b in body]
    for kind, p, v, phi in em:
        w = f'<float name="sampling_weight" value="{phi:.6g}"/>' if sampling_weights else ""
        pos = f"{_c(p[0])} {_c(p[1])} {_c(p[2])}"
        if kind == "point":
            lines.append(f'<emitter type="point"><point name="position" value="{pos}"/>'
                         f'<float name="intensity" value="{_g(v)}"/>{w}</emitter>\n')
        elif kind in ("down", "up"):
            angle = 90 if kind == "down" else -90
            lines.append(f'<shape type="rectangle"><transform name="to_world"><scale value="{SQUARE_HALF}"/>'
                         f'<rotate x="1" angle="{angle}"/><translate value="{pos}"/></transform><ref id="lamp"/>'
                         f'<emitter type="area"><float name="radiance" value="{_g(v)}"/>{w}</emitter></shape>\n')
        else:
            rot = '<rotate y="1" angle="90"/>' if p[0] < -X + 1 else ""
            lines.append(f'<shape type="obj"><string name="filename" value="tube.obj"/><transform name="to_world">'
                         f'{rot}<translate value="{pos}"/></transform><ref id="lamp"/>'
                         f'<emitter type="area"><float name="radiance" value="{_g(v)}"/>{w}</emitter></shape>\n')
    lines.append("</scene>\n")
    return "".join(lines)


def write_weighted(path) -> Path:
    """scene.xml with every emitter's sampling_weight = its power (Mitsuba's copy).

    Writes it at `path` with tube.obj beside it; returns the path."""
    path = Path(path)
    path.write_text(scene_xml(sampling_weights=True))
    (path.parent / OBJ.name).write_text(tube_obj())
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description="writes reference_scenes/many_lights/scene.xml and tube.obj")
    ap.add_argument("--check", action="store_true", help="only check that the committed files are this output")
    a = ap.parse_args(argv)
    want = {XML: scene_xml(), OBJ: tube_obj()}
    if a.check:
        bad = [p.name for p, t in want.items() if not p.exists() or p.read_text() != t]
        print("differs: " + ", ".join(bad) if bad else "up to date")
        return 1 if bad else 0
    for p, t in want.items():
        p.write_text(t)
        print(f"wrote {p} ({p.stat().st_size / 1024:.0f} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
