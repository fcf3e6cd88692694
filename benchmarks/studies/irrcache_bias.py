"""Bias report (not a test): irrcache's interpolation bias on the indirect
class against record density, gradients, neighbour clamping and the weight,
on the Cornell box, ajar_door and corner_room (reference_scenes/caching.py,
many concave corners); and radcache's error against the order of its
harmonics on a glossy floor (caching.py's glossy_box).

    python -m radiometer.benchmarks.studies.irrcache_bias [--seeds N] [--res 32] [--scenes a,b]

Per scene and setting: its seeds' renders of the indirect class (1 spp: the
cached part has no per-sample noise apart from cache misses), against a
long unbiased render of the same class (SCENES: `path`, or `bdpt` on
ajar_door, where it converges about 6x faster per second than `path`). The
figure is the RMS over 4 x 4 block means of (mean over seeds - reference)
with the noise of both (the seeds' spread, the reference's variance)
subtracted, relative to the reference's mean, with its own standard
deviation (from the noise, blocks taken as independent); also the signed mean error,
the record count and the seconds per render. For every scene but the
Cornell box (whose maps cache_wins writes) the bias maps of the defaults and
of kappa 0.25 (analysis.report.bias_maps) go to
benchmarks/results/irrcache_bias_<scene>.png. radcache: the RMS error of the
block means (noise not subtracted), 4 spp per seed, `path` at 4096 spp.
Writes a table to stdout and benchmarks/results/irrcache_bias.json (the
studies' layout, studies/record.py).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import radiometer as rm
from radiometer.analysis.report import bias_map_panels, bias_maps
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry
from radiometer.reference_scenes.caching import corner_room, glossy_box

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
# scene: (its reference estimator, reference spp, seeds per setting, bias maps)
SCENES = {"cornell_box": ("path", 4096, 3, False),
          "ajar_door": ("bdpt", 16384, 8, True),
          "corner_room": ("path", 16384, 8, True)}
MAPPED = ("defaults (kappa 1)", "kappa 0.25 (4x coarser)")
BLOCK = 4


def blocks(a, k=BLOCK):
    h, w, c = a.shape
    return a.reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def plot_maps(scene, maps, n_seeds, ref_label, png):
    """The bias maps of each setting in `maps` (label: (pixel map, block
    map)), one row each, on one symmetric scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = max(max(float(np.percentile(np.abs(p), 99)) for p, _ in maps.values()), 1e-6)
    fig, axes = plt.subplots(len(maps), 2, figsize=(7.2, 3.2 * len(maps)), dpi=90, squeeze=False)
    for row, (label, (pix, blk)) in zip(axes, maps.items()):
        h = bias_map_panels(row, pix, blk, v, prefix=f"{label}, ", sep="\n", block=BLOCK)
    fig.colorbar(h, ax=axes.ravel().tolist(), shrink=0.8, label="(mean - ref) / (ref + 0.01), luminance")
    fig.suptitle(f"{scene}: irrcache's indirect class, mean of {n_seeds} seeds against {ref_label}", fontsize=9)
    fig.savefig(png)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=None, help="seeds per setting (default: SCENES' own)")
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--ref-spp", type=int, default=None, help="the references' spp (default: SCENES' own)")
    ap.add_argument("--scenes", default=",".join(SCENES) + ",glossy_box", help="glossy_box: radcache's part")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--out", default=str(record.default_path("irrcache_bias")))
    args = ap.parse_args(argv)
    rows = []
    for name in [n for n in args.scenes.split(",") if n != "glossy_box"]:
        ref_est, ref_spp, n_seeds, mapped = SCENES[name]
        ref_spp, n_seeds = args.ref_spp or ref_spp, args.seeds or n_seeds
        if name == "corner_room":
            scene, base = corner_room(args.res), {"max_depth": 8}
        else:
            spec = registry.get(name)
            params = dict(spec.fixed_params, res=args.res)
            scene = rm.load_file(spec.xml, **params)
            md = registry.max_depth(spec, params)
            base = {"max_depth": md} if md is not None else {}
        t = time.time()
        ref = rm.render(scene, integrator={"type": ref_est, **base}, spp=ref_spp, seed=1000,
                        effects=["indirect"], threads=args.threads)
        print(f"{name}: reference {ref_est} at {ref_spp} spp, {time.time() - t:.0f} s")
        rb, rv = blocks(ref.image), blocks(ref.variance) / BLOCK ** 2
        scale = float(ref.image.mean())
        maps = {}
        for label, extra in SETTINGS:
            imgs, recs, secs = [], [], []
            for s in range(n_seeds):
                t = time.time()
                r = rm.render(scene, integrator={"type": "irrcache", **base, **extra}, spp=1, seed=s,
                              effects=["indirect"], threads=args.threads)
                secs.append(time.time() - t)
                imgs.append(r.image)
                recs.append(len(r.arrays["irrcache_records"]))
            if mapped and label in MAPPED:
                maps[label] = bias_maps(imgs, ref.image)
            b = np.array([blocks(i) for i in imgs])
            m, vm = b.mean(0), b.var(0, ddof=1) / len(b)
            b2 = float(np.mean((m - rb) ** 2) - np.mean(vm + rv))
            n2 = float(np.mean(vm + rv))
            # the estimate's own spread, blocks and channels taken as independent: the variance of
            # the mean of (bias + noise)^2 over them, 2 n^4 + 4 b^2 n^2 per term (delta method for b)
            sd2 = np.sqrt((2 * n2 ** 2 + 4 * max(b2, 0.0) * n2) / m.size)
            sd = sd2 / (2 * np.sqrt(b2)) if b2 > sd2 else np.sqrt(sd2)
            row = {"scene": name, "setting": label, "params": extra, "seeds": n_seeds,
                   "reference": {"estimator": ref_est, "spp": ref_spp}, "records": float(np.mean(recs)),
                   "rms_bias": float(np.sqrt(max(b2, 0.0)) / scale),
                   "rms_bias_sd": float(sd / scale), "noise": float(np.sqrt(n2) / scale),
                   "reference_noise": float(np.sqrt(np.mean(rv)) / scale),
                   "signed": float((m - rb).mean() / scale), "seconds": float(np.mean(secs))}
            rows.append(row)
            print(f"{name:12s} {label:26s} records {row['records']:7.0f}  RMS bias {row['rms_bias'] * 100:6.2f}"
                  f" +- {row['rms_bias_sd'] * 100:4.2f} %"
                  f"  (noise {row['noise'] * 100:5.2f} %, reference's {row['reference_noise'] * 100:5.2f} %)"
                  f"  mean {row['signed'] * 100:+6.2f} %  {row['seconds']:.2f} s")
        if maps:
            png = record.RESULTS / f"irrcache_bias_{name}.png"
            plot_maps(name, maps, n_seeds, f"{ref_est} {ref_spp} spp", png)
            print(f"wrote {png}")
    orders = []
    if "glossy_box" in args.scenes.split(","):
        orders = radcache_orders(args)
    out = record.write("irrcache_bias", record.params_of(args), {"rows": rows, "radcache_order": orders},
                       out=args.out)
    print(f"wrote {out}")


def radcache_orders(args):
    scene = rm.load_dict(glossy_box(24))
    ref = rm.render(scene, integrator={"type": "path"}, spp=args.ref_spp or 4096, seed=1000, effects=["indirect"],
                    threads=args.threads)
    rb, scale = blocks(ref.image), float(ref.image.mean())
    orders = []
    for order in (0, 1, 2, 4, 6, 8):
        imgs, secs = [], []
        for s in range(args.seeds or 3):
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
    return orders


if __name__ == "__main__":
    main()
