"""Bias report (not a test): irrcache's interpolation bias on the indirect
class against record density, gradients, neighbour clamping and the weight;
and radcache's error against the order of its harmonics on a glossy floor
(reference_scenes/caching.py's glossy_box).

    python -m radiometer.benchmarks.studies.irrcache_bias [--seeds 3] [--res 32]

Per scene and setting: `seeds` renders of the indirect class (1 spp: the
cached part has no per-sample noise apart from cache misses), against a
long `path` render of the same class. The figure is the RMS over 4 x 4
block means of (mean over seeds - reference) with the noise of both (the
seeds' spread, the reference's variance) subtracted, relative to the
reference's mean; also the signed mean error, the record count and the
seconds per render. radcache: the RMS error of the block means (noise not
subtracted), 4 spp per seed, `path` at 4096 spp. Writes a table to stdout and
benchmarks/results/irrcache_bias.json (the studies' layout, studies/record.py).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import radiometer as rm
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry
from radiometer.reference_scenes.caching import glossy_box

SETTINGS = [
    ("kappa 4 (4x denser)", {"kappa": 4.0}),
    ("defaults (kappa 1)", {}),
    ("kappa 0.5", {"kappa": 0.5}),
    ("kappa 0.25 (4x coarser)", {"kappa": 0.25}),
    ("no gradients", {"gradients": False}),
    ("kappa 0.5, no gradients", {"kappa": 0.5, "gradients": False}),
    ("no neighbour clamping", {"neighbour_clamping": False}),
    ("kappa 0.5, no clamping", {"kappa": 0.5, "neighbour_clamping": False}),
    ("ward, a 0.2", {"weight": "ward"}),
    ("ward, a 0.8", {"weight": "ward", "ward_a": 0.8}),
]
SCENES = ("cornell_box", "ajar_door")
BLOCK = 4


def blocks(a, k=BLOCK):
    h, w, c = a.shape
    return a.reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--out", default=str(record.default_path("irrcache_bias")))
    args = ap.parse_args(argv)
    rows = []
    for name in SCENES:
        spec = registry.get(name)
        params = dict(spec.fixed_params, res=args.res)
        scene = rm.load_file(spec.xml, **params)
        md = registry.max_depth(spec, params)
        base = {"max_depth": md} if md is not None else {}
        ref = rm.render(scene, integrator={"type": "path", **base}, spp=args.ref_spp, seed=1000,
                        effects=["indirect"], threads=args.threads)
        rb, rv = blocks(ref.image), blocks(ref.variance) / BLOCK ** 2
        scale = float(ref.image.mean())
        for label, extra in SETTINGS:
            imgs, recs, secs = [], [], []
            for s in range(args.seeds):
                t = time.time()
                r = rm.render(scene, integrator={"type": "irrcache", **base, **extra}, spp=1, seed=s,
                              effects=["indirect"], threads=args.threads)
                secs.append(time.time() - t)
                imgs.append(blocks(r.image))
                recs.append(len(r.arrays["irrcache_records"]))
            b = np.array(imgs)
            m, vm = b.mean(0), b.var(0, ddof=1) / len(b)
            b2 = float(np.mean((m - rb) ** 2) - np.mean(vm + rv))
            row = {"scene": name, "setting": label, "params": extra, "records": float(np.mean(recs)),
                   "rms_bias": float(np.sqrt(max(b2, 0.0)) / scale),
                   "noise": float(np.sqrt(np.mean(vm + rv)) / scale),
                   "signed": float((m - rb).mean() / scale), "seconds": float(np.mean(secs))}
            rows.append(row)
            print(f"{name:12s} {label:26s} records {row['records']:7.0f}  RMS bias {row['rms_bias'] * 100:6.2f} %"
                  f"  (noise {row['noise'] * 100:5.2f} %)  mean {row['signed'] * 100:+6.2f} %  {row['seconds']:.2f} s")
    scene = rm.load_dict(glossy_box(24))
    ref = rm.render(scene, integrator={"type": "path"}, spp=args.ref_spp, seed=1000, effects=["indirect"],
                    threads=args.threads)
    rb, scale = blocks(ref.image), float(ref.image.mean())
    orders = []
    for order in (0, 1, 2, 4, 6, 8):
        imgs, secs = [], []
        for s in range(args.seeds):
            t = time.time()
            r = rm.render(scene, integrator={"type": "radcache", "order": order}, spp=4, seed=s + 1,
                          effects=["indirect"], threads=args.threads)
            secs.append(time.time() - t)
            imgs.append(blocks(r.image))
        m = np.mean(imgs, 0)
        row = {"scene": "glossy_box", "order": order, "records": float(r.stats["radcache_computed"]),
               "rms_error": float(np.sqrt(np.mean((m - rb) ** 2)) / scale),
               "signed": float((m - rb).mean() / scale), "seconds": float(np.mean(secs))}
        orders.append(row)
        print(f"glossy_box radcache order {order}: RMS error {row['rms_error'] * 100:6.2f} %  mean "
              f"{row['signed'] * 100:+6.2f} %  {row['seconds']:.2f} s")
    out = record.write("irrcache_bias", record.params_of(args), {"rows": rows, "radcache_order": orders},
                       out=args.out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
