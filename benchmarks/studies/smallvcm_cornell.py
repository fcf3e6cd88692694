"""SmallVCM's Cornell box variants: relMSE at equal time of vcm, bpm, ppm,
bdpt, sppm and path. A benchmark, not a timed test.

    nice -n 10 python -m radiometer.benchmarks.studies.smallvcm_cornell [--seconds 4] [--res 64]

The scenes are our transcription of `Scene::LoadCornellBox` in SmallVCM's
src/scene.hxx (Davidovic 2012, github.com/SmallVCM/SmallVCM; read through
the code search, not copied): the box corners cb[0..7] (z up, open
front), the camera (position, forward, up, 45 degrees), the diffuse walls
(green left 0.156863 / 0.803922 / 0.172549, red right 0.803922 / 0.152941 /
0.152941, white floor, back wall and ceiling 0.803922), the mirror sphere
(reflectance 1: our conductor, material none) and the glass sphere (ior
1.6), the small spheres (radius 0.5, 2/7 of the box's width in from each
wall, on the floor) and the large one (radius 0.8, centred), the small
light (SmallVCM's light box: a 0.5 x 0.5 square at z = 1.26002 facing down,
radiance 25.03329895614464, with its four 0.02-high white side walls) and the
large light (the whole ceiling, radiance 0.95492965, SmallVCM's
ceiling-without-box branch). Max path length 10 (SmallVCM's config.hxx,
mMaxPathLength = 10; both count segments, as our max_depth). Left out:
SmallVCM's glossy (Phong) floor, its sun, point and background lights.

Variants: small light with both small spheres (SmallVCM's kDefault), small
light with the large mirror sphere, small light with the large glass
sphere, large light with both small spheres.

Reference: for each variant two long runs, vcm and bdpt, each `--ref-factor`
x the budget; relMSE (eps 1e-2, over the whole image) is reported against
both (a long vcm run shares vcm's bias, a long bdpt run has the
unbiased but noisy SDS paths; an estimator that wins against both is
measured to win). relMSE of a render against a noisy reference includes the
reference's own variance; the `floor` column (relMSE of the two references
against each other, halved) says how much of a figure that can be.
Writes benchmarks/results/smallvcm_cornell.json (studies/record.py layout).
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import radiometer as rm
from radiometer.benchmarks.studies import record

CB = [(-1.27029, 1.30455, -1.28002), (1.28975, 1.30455, -1.28002), (1.28975, 1.30455, 1.28002),
      (-1.27029, 1.30455, 1.28002), (-1.27029, -1.25549, -1.28002), (1.28975, -1.25549, -1.28002),
      (1.28975, -1.25549, 1.28002), (-1.27029, -1.25549, 1.28002)]
WHITE, GREEN, RED = (0.803922,) * 3, (0.156863, 0.803922, 0.172549), (0.803922, 0.152941, 0.152941)
VARIANTS = {
    "small_light_small_spheres": {"light": "small", "spheres": ("small_mirror", "small_glass")},
    "small_light_large_mirror": {"light": "small", "spheres": ("large_mirror",)},
    "small_light_large_glass": {"light": "small", "spheres": ("large_glass",)},
    "large_light_small_spheres": {"light": "large", "spheres": ("small_mirror", "small_glass")},
}
ESTIMATORS = ("vcm", "bpm", "ppm", "bdpt", "sppm", "path")


def _v(a):
    return np.asarray(a, np.float64)


def _rect_xml(c, u, w, n, bsdf, emit=None):
    """A rectangle centred at c, half-edges u and w (3-vectors), normal n."""
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u, w, n, c
    vals = " ".join(f"{x:.7g}" for x in m.reshape(-1))
    e = ""
    if emit is not None:
        e = f'<emitter type="area"><rgb name="radiance" value="{emit}, {emit}, {emit}"/></emitter>'
    return f'<shape type="rectangle"><transform name="to_world"><matrix value="{vals}"/></transform>{bsdf}{e}</shape>\n'


def _diffuse(rgb):
    return f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb[0]}, {rgb[1]}, {rgb[2]}"/></bsdf>'


def _wall(a, b, d, rgb, inner, emit=None):
    """The parallelogram a, b, d (corners a, b = a + e1, d = a + e2), facing
    `inner`."""
    a, b, d = _v(a), _v(b), _v(d)
    e1, e2 = b - a, d - a
    c = a + 0.5 * (e1 + e2)
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n)
    if np.dot(_v(inner) - c, n) < 0:
        e1, e2, n = e2, e1, -n  # swap the edges: the frame stays right-handed, the normal flips
    bsdf = _diffuse(rgb) if emit is None else _diffuse((0, 0, 0))
    return _rect_xml(c, 0.5 * e1, 0.5 * e2, n, bsdf, emit)


def scene_xml(variant: str, res: int, max_depth: int = 10) -> str:
    v = VARIANTS[variant]
    cb = [_v(p) for p in CB]
    mid = sum(cb) / 8.0
    out = []
    # floor (z = -1.28), back wall (y = 1.30), left (x = -1.27, green), right (x = 1.29, red)
    out.append(_wall(cb[4], cb[5], cb[0], WHITE, mid))
    out.append(_wall(cb[0], cb[1], cb[3], WHITE, mid))
    out.append(_wall(cb[4], cb[0], cb[7], GREEN, mid))
    out.append(_wall(cb[5], cb[1], cb[6], RED, mid))
    if v["light"] == "large":  # the whole ceiling emits
        out.append(_wall(cb[7], cb[6], cb[3], WHITE, mid, emit=0.95492965))
    else:
        out.append(_wall(cb[7], cb[6], cb[3], WHITE, mid))
        z0, z1 = 1.26002, 1.28002
        lc = _v((0.0, 0.0, z0))
        lo = [(-0.25, -0.25), (0.25, -0.25), (0.25, 0.25), (-0.25, 0.25)]
        out.append(_wall((-0.25, -0.25, z0), (0.25, -0.25, z0), (-0.25, 0.25, z0), WHITE, mid,
                         emit=25.03329895614464))
        for (x0, y0), (x1, y1) in zip(lo, lo[1:] + lo[:1]):  # the box's side walls, white, facing out
            outside = 2 * _v(((x0 + x1) / 2, (y0 + y1) / 2, z0)) - lc  # (light never gets inside the box)
            out.append(_wall((x0, y0, z0), (x1, y1, z0), (x0, y0, z1), WHITE, outside))
    large_c = (cb[0] + cb[1] + cb[4] + cb[5]) / 4 + _v((0, 0, 0.8))
    lw = (cb[0] + cb[4]) / 2 + _v((0, 0, 0.5))
    rw = (cb[1] + cb[5]) / 2 + _v((0, 0, 0.5))
    xlen = rw[0] - lw[0]
    spheres = {"small_mirror": (lw + _v((2 * xlen / 7, 0, 0)), 0.5, "mirror"),
               "small_glass": (rw - _v((2 * xlen / 7, 0, 0)), 0.5, "glass"),
               "large_mirror": (large_c, 0.8, "mirror"), "large_glass": (large_c, 0.8, "glass")}
    for s in v["spheres"]:
        c, r, kind = spheres[s]
        bsdf = ('<bsdf type="conductor"><string name="material" value="none"/></bsdf>' if kind == "mirror" else
                '<bsdf type="dielectric"><float name="int_ior" value="1.6"/><float name="ext_ior" value="1"/></bsdf>')
        out.append(f'<shape type="sphere"><point name="center" x="{c[0]:.7g}" y="{c[1]:.7g}" z="{c[2]:.7g}"/>'
                   f'<float name="radius" value="{r}"/>{bsdf}</shape>\n')
    pos = _v((-0.0439815, -4.12529, 0.222539))
    fwd = _v((0.00688625, 0.998505, -0.0542161))
    up = (3.73896e-4, 0.0542148, 0.998529)
    tgt = pos + fwd
    sensor = (f'<sensor type="perspective"><float name="fov" value="45"/><string name="fov_axis" value="x"/>'
              f'<transform name="to_world"><lookat origin="{pos[0]}, {pos[1]}, {pos[2]}" '
              f'target="{tgt[0]:.7g}, {tgt[1]:.7g}, {tgt[2]:.7g}" up="{up[0]}, {up[1]}, {up[2]}"/></transform>'
              f'<sampler type="independent"><integer name="sample_count" value="16"/></sampler>'
              f'<film type="hdrfilm"><integer name="width" value="{res}"/><integer name="height" value="{res}"/>'
              f'<rfilter type="box"/></film></sensor>\n')
    integ = f'<integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>\n'
    return '<scene version="3.0.0">\n' + integ + sensor + "".join(out) + "</scene>\n"


def relmse(a, r, eps=1e-2):
    a, r = _v(a), _v(r)
    return float(np.mean((a - r) ** 2 / (r * r + eps)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--ref-factor", type=float, default=8.0)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS))
    ap.add_argument("--out", default=str(record.default_path("smallvcm_cornell")))
    a = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for var in a.variants:
            path = Path(tmp) / f"{var}.xml"
            path.write_text(scene_xml(var, a.res))
            scene = rm.load_file(path)
            refs = {}
            for est in ("vcm", "bdpt"):
                r = rm.render(scene, integrator={"type": est, "max_depth": 10}, spp=1 << 20,
                              seconds=a.seconds * a.ref_factor, seed=1000, threads=a.threads)
                refs[est] = (np.asarray(r.image, np.float64), int(r.spp))
            floor = 0.5 * relmse(refs["vcm"][0], refs["bdpt"][0])
            print(f"{var}: references vcm {refs['vcm'][1]} spp, bdpt {refs['bdpt'][1]} spp; "
                  f"relMSE between them / 2 = {floor:.4g}", flush=True)
            for est in ESTIMATORS:
                integ = {"type": est, "max_depth": 10}
                r = rm.render(scene, integrator=integ, spp=1 << 20, seconds=a.seconds, seed=1, threads=a.threads)
                img = np.asarray(r.image, np.float64)
                row = {"variant": var, "estimator": est, "spp": int(r.spp), "seconds": float(r.seconds),
                       "relmse_vs_vcm_ref": relmse(img, refs["vcm"][0]),
                       "relmse_vs_bdpt_ref": relmse(img, refs["bdpt"][0]), "ref_floor": floor,
                       "ref_spp": {k: v[1] for k, v in refs.items()}}
                rows.append(row)
                print(f"  {est:5s} {row['spp']:6d} spp {row['seconds']:5.1f} s  relMSE vs vcm ref "
                      f"{row['relmse_vs_vcm_ref']:.4g}  vs bdpt ref {row['relmse_vs_bdpt_ref']:.4g}", flush=True)
    record.write("smallvcm_cornell", vars(a), {"rows": rows}, out=a.out)


if __name__ == "__main__":
    main()
