"""Checks of the analytic references, independent of our renderer.

    python -m radiometer.reference_scenes.check_analytic [--mitsuba] [--spp N] [--runs K]

1. Quadrature accuracy: each analytic image at Gauss-Legendre order n against
   order 2n (largest relative difference).
2. Closed forms against brute-force quadrature: the disk's and the
   rectangle's irradiance at scattered floor points against scipy's adaptive
   2-D quadrature of L cos(theta) cos(theta') / d^2 over the light's area
   (the definition of irradiance from an area source), relative difference.
3. With --mitsuba: Mitsuba 3 renders of the same XML files (mean over `runs`
   seeds, variance of that mean across runs, via make_mitsuba_reference)
   z-tested against the analytic images in 4 x 4 pixel blocks per channel
   (alpha 0.01 each), plus the relative difference of the image means. For
   the mirror caustic, Mitsuba at max_depth 2 (direct only) and 3 (direct +
   caustic) give the direct and total images. The furnace is left out:
   Mitsuba 3.9.1's analytic sphere is off by itself (DESIGN.md section 4;
   furnace/card.md has the numbers).
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from radiometer.reference_scenes.area_lights import analytic as area
from radiometer.reference_scenes.mirror_caustic import analytic as mirror

HERE = Path(__file__).resolve().parent


def quadrature_accuracy(res=64, order=area.GL_ORDER):
    out = dict(area.check_accuracy(res=res, order=order))
    for k in ("direct", "caustic"):
        a = mirror.effects(order=order, res=res)[k]
        b = mirror.effects(order=2 * order, res=res)[k]
        out[f"mirror {k}"] = float(np.max(np.abs(a - b) / np.abs(b)))
    return out


def _brute_disk(x, y, cx, cy, radius, h):
    """E at (x, y, 0) from a unit-radiance disk facing down, by quadrature
    over the disk in polar coordinates: int cos cos' / d^2 dA."""
    from scipy import integrate

    def f(r, phi):
        dx, dy = cx + r * math.cos(phi) - x, cy + r * math.sin(phi) - y
        d2 = dx * dx + dy * dy + h * h
        return h * h / (d2 * d2) * r  # cos = cos' = h / d

    v, _ = integrate.dblquad(f, 0.0, 2.0 * math.pi, 0.0, radius, epsabs=0, epsrel=1e-12)
    return v


def _brute_polygon(x, y, verts):
    """E at (x, y, 0) from a unit-radiance parallelogram facing down (verts
    0, 1, 3 span it), by quadrature over its parameter square."""
    from scipy import integrate

    v0, v1, v3 = (np.asarray(verts[i], float) for i in (0, 1, 3))
    e1, e2 = v1 - v0, v3 - v0
    jac = np.linalg.norm(np.cross(e1, e2))
    h = v0[2]

    def f(s, t):
        q = v0 + s * e1 + t * e2
        d2 = (q[0] - x) ** 2 + (q[1] - y) ** 2 + h * h
        return h * h / (d2 * d2) * jac

    v, _ = integrate.dblquad(f, 0.0, 1.0, 0.0, 1.0, epsabs=0, epsrel=1e-12)
    return v


def closed_forms_vs_quadrature(n=12, seed=0):
    """Largest relative difference between the closed forms and brute-force
    quadrature at n random floor points in [-1, 1]^2 (scene defaults)."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1, 1, size=(n, 2))
    dp = area.scene_params(area.DISK_XML)
    cx, cy, rad, h = (float(dp[k]) for k in ("lx", "ly", "radius", "h"))
    rp = area.scene_params(area.RECT_XML)
    verts = area.rect_vertices(float(rp["a"]), float(rp["b"]), float(rp["angle"]), float(rp["lx"]),
                               float(rp["ly"]), float(rp["h"]))
    mp = area.scene_params(mirror.XML)
    mx, my, mr, mh = (float(mp[k]) for k in ("lx", "ly", "radius", "h"))
    worst = {"disk": 0.0, "rect": 0.0, "mirror image disk": 0.0}
    for x, y in pts:
        a = area.disk_irradiance(x, y, cx, cy, rad, h)
        worst["disk"] = max(worst["disk"], abs(a / _brute_disk(x, y, cx, cy, rad, h) - 1))
        a = area.polygon_irradiance(x, y, verts)
        worst["rect"] = max(worst["rect"], abs(a / _brute_polygon(x, y, verts) - 1))
        ix = 2 * mirror.MIRROR_X - mx
        a = area.disk_irradiance(x, y, ix, my, mr, mh)
        worst["mirror image disk"] = max(worst["mirror image disk"], abs(a / _brute_disk(x, y, ix, my, mr, mh) - 1))
    return worst


def _block(img, k=4):
    h, w, c = img.shape
    return np.asarray(img, np.float64).reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def _block_var(var, k=4):
    """Variance of a block mean of independent pixels. Mitsuba's box filter
    (radius 0.5) splats each sample into the one pixel it lies in, so its
    pixels are independent too."""
    h, w, c = var.shape
    return np.asarray(var, np.float64).reshape(h // k, k, w // k, k, c).sum(axis=(1, 3)) / k ** 4


def mitsuba_vs_analytic(spp=1024, runs=8, variant="llvm_ad_rgb", alpha=0.01):
    """Mitsuba renders of each scene against its analytic image."""
    from radiometer.analysis.stats import z_test
    from radiometer.reference_scenes.make_reference import make_mitsuba_reference

    cases = [
        ("area_lights/disk_light.xml", {}, area.reference_disk()[0]),
        ("area_lights/rect_light.xml", {}, area.reference_rect()[0]),
        ("mirror_caustic/scene.xml (max_depth 2: direct)", {"max_depth": 2}, mirror.effects(max_depth=2)["direct"]),
        ("mirror_caustic/scene.xml (max_depth 3: total)", {"max_depth": 3}, mirror.reference()[0]),
    ]
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, params, ref) in enumerate(cases):
            xml = HERE / name.split(" ")[0]
            mean, var, meta = make_mitsuba_reference(xml, Path(tmp) / f"{i}.exr", runs=runs, spp=spp,
                                                     variant=variant, progress=False, **params)
            # The variance is measured run to run (make_mitsuba_reference).
            bm, bv, br = _block(mean), _block_var(var), _block(ref)
            res = [z_test(bm[..., c], bv[..., c], br[..., c], alpha=alpha) for c in range(3)]
            rel = mean.mean(axis=(0, 1)) / ref.mean(axis=(0, 1)) - 1
            se = np.sqrt(var.sum(axis=(0, 1))) / var[..., 0].size / ref.mean(axis=(0, 1))
            out.append((name, meta["variant"], spp * runs, rel, se, res))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m radiometer.reference_scenes.check_analytic")
    ap.add_argument("--mitsuba", action="store_true", help="also compare Mitsuba 3 renders with the analytic images")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    a = ap.parse_args(argv)
    print("1. Gauss-Legendre order 6 vs 12, largest relative difference per pixel:")
    for k, v in quadrature_accuracy().items():
        print(f"   {k:16s} {v:.2e}")
    print("2. closed form vs scipy dblquad (epsrel 1e-12) at 12 random floor points, largest relative difference:")
    for k, v in closed_forms_vs_quadrature().items():
        print(f"   {k:18s} {v:.2e}")
    if a.mitsuba:
        print(f"3. Mitsuba ({a.variant}, {a.runs} runs x {a.spp} spp) against the analytic images:")
        for name, variant, total, rel, se, res in mitsuba_vs_analytic(a.spp, a.runs, a.variant):
            print(f"   {name} [{variant}, {total} spp]: mean(mitsuba) / mean(analytic) - 1 = "
                  + ", ".join(f"{r:+.2e} (se {s:.1e})" for r, s in zip(rel, se)))
            for c, r in enumerate(res):
                print(f"      {'RGB'[c]} 4x4 blocks: {r.summary()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
