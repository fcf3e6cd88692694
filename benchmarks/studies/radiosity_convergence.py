"""Discretisation error of `radiosity` (not a test): on the Cornell box,
the error against the Mitsuba reference as the patch count grows, for the
per-patch display, the vertex-interpolated display and the final gather,
with the log-log slope; on the
closed furnace, the error at every patch count (exact up to the residual).

    python -m radiometer.benchmarks.studies.radiosity_convergence [--patches 50,100,...] [--spp 4]
    python -m radiometer.benchmarks.studies.radiosity_convergence --hierarchical [--spp 16]

--hierarchical: instead, hierarchical refinement (Hanrahan et al. 1991)
against the uniform mesh: error, elements (leaves), form factors (links;
the uniform mesh's N (N - 1) / 2 pairs of its N elements) and solve seconds
on the area-light scenes (exact images; patch display, max_depth 2) and on
the Cornell box (patch and gather displays); writes
benchmarks/results/radiosity_hierarchical.json.

Error: relative L1, mean |image - reference| / mean reference, over the
64 x 64 reference image (max_depth 8, the reference's) without the light
and a 2-pixel border around it (the emitter's edge under the gaussian
filter is camera-sample noise, the same for every estimator, and it
dominated the unmasked error: reported too, `rel_l1_all`); `path` at the
same camera spp gives the noise floor of the metric. The slope is the
least-squares fit of log(error) on log(patches): for a piecewise-constant
solution, first order in the patch size h, so about -1/2 in the patch count
where the error is smooth, less steep where shadow boundaries and corners
(the classic artefacts: shadow leaks under the boxes, Mach bands at patch
edges) dominate. Writes benchmarks/results/radiosity_convergence.json,
.png (error against patches, with matplotlib), radiosity_convergence_maps.png
(the per-patch images at 50 and 400 patches beside their error maps and the
reference) and the EXR images of the coarsest and finest meshes.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import radiometer as rm
from radiometer.benchmarks.studies import record
from radiometer.exr import write_exr
from radiometer.reference_scenes import references, registry


def error_maps(png, scene, ref, md, counts=(50, 400), spp=16):
    """A PNG (PIL) of the per-patch display at each of `counts` beside its
    signed relative error (red: too bright, blue: too dark, saturated at
    +-50 %), and the reference, tone-mapped x / (1 + x), 4 x enlarged."""
    from PIL import Image

    def tone(x):
        return np.clip(x / (1 + x), 0, 1) ** (1 / 2.2)

    tiles = []
    for n in counts:
        res = rm.render(scene, integrator={"type": "radiosity", "display": "patch", "max_patches": n, "max_depth": md},
                        spp=spp, seed=1)
        img = res.image.astype(np.float64)
        e = np.clip(((img - ref) / np.maximum(ref, 0.02)).mean(axis=2), -0.5, 0.5) / 0.5
        tiles += [tone(img), np.stack([np.clip(e, 0, 1), np.zeros_like(e), np.clip(-e, 0, 1)], axis=-1)]
    tiles.append(tone(ref))
    im = np.concatenate(tiles, axis=1)
    Image.fromarray((im * 255).astype(np.uint8)).resize((im.shape[1] * 4, im.shape[0] * 4), Image.NEAREST).save(png)


def hierarchical_study(args):
    """The --hierarchical table (see the module docstring)."""
    import math

    from radiometer.reference_scenes.area_lights import analytic as al

    rows = []

    def row(scene_name, kind, setting, l1, st, **extra):
        n = st["elements"]
        r = {"scene": scene_name, "kind": kind, "setting": setting, "rel_l1": l1,
             "elements": int(st["hr_elements"] if kind == "hierarchical" else n),
             "form_factors": int(st["hr_links"] if kind == "hierarchical" else n * (n - 1) // 2),
             "solve_seconds": st["solve_seconds"], **extra}
        rows.append(r)
        print(f"{scene_name:<12}{kind:<14}{setting:<22}{l1:>9.4f}{r['elements']:>9}{r['form_factors']:>11}"
              f"{r['solve_seconds']:>9.2f}" + "".join(f"  {k} {v:.4f}" for k, v in extra.items()), flush=True)

    print(f"{'scene':<12}{'kind':<14}{'setting':<22}{'rel L1':>9}{'elements':>9}{'ff / links':>11}{'solve s':>9}")
    # Area lights: the 6 x 6 floor (diagonal D) cut n x n per triangle, or
    # one root per triangle refined to at most 5 levels (the 32 x 32 leaves).
    D = 6 * math.sqrt(2)
    for light in ("rect", "disk"):
        xml = al.RECT_XML if light == "rect" else al.DISK_XML
        scene = rm.load_file(xml, res=32)
        ref, _ = al.reference(light, res=32)

        def err(integ):
            res = rm.render(scene, integrator={"type": "radiosity", "display": "patch", "max_depth": 2, **integ},
                            spp=args.spp, seed=4)
            img = res.image.astype(np.float64)
            return float(np.abs(img - ref).mean() / ref.mean()), res.stats

        for n in (8, 16, 32):
            row(light, "uniform", f"n {n}", *err({"patch_size": D / n * (1 + 1e-6), "max_patches": 16000}))
        for eps in (1.0, 0.3, 0.1, 0.03):
            row(light, "hierarchical", f"eps {eps:g}", *err({"patch_size": D * 1.01, "max_patches": 100,
                                                             "hierarchical": True, "hr_epsilon": eps,
                                                             "min_area": 18 / 4**4 * 0.9}))
    # The Cornell box (max_depth 8): uniform meshes, and 40 root patches
    # refined down to min_area's default (1/256 of the largest triangle).
    spec = registry.get("cornell_box")
    params = dict(spec.fixed_params)
    scene = rm.load_file(spec.xml, **params)
    ref = references.reference("cornell_box", params).image.astype(np.float64)
    md = int(params["max_depth"])
    light = ref.max(axis=2) > 2.0
    for _ in range(2):
        light = light | np.roll(light, 1, 0) | np.roll(light, -1, 0) | np.roll(light, 1, 1) | np.roll(light, -1, 1)
    keep = ~light

    def cerr(integ, display):
        res = rm.render(scene, integrator={"type": "radiosity", "display": display, "max_depth": md, **integ},
                        spp=args.spp, seed=1)
        return float(np.abs(res.image - ref)[keep].mean() / ref[keep].mean()), res.stats

    settings = [("uniform", f"max_patches {n}", {"max_patches": n}) for n in (400, 800, 1500)]
    settings += [("hierarchical", f"40 roots, eps {eps:g}", {"max_patches": 40, "hierarchical": True,
                                                          "hr_epsilon": eps}) for eps in (0.1, 0.03, 0.01, 0.003)]
    for kind, setting, integ in settings:
        l1, st = cerr(integ, "patch")
        row("cornell_box", kind, setting, l1, st, gather_rel_l1=cerr(integ, "gather")[0])
    out = record.write("radiosity_hierarchical", record.params_of(args), {"rows": rows},
                       out=str(record.default_path("radiosity_hierarchical")))
    print(f"wrote {out}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patches", default="50,100,200,400,800,1600,3200")
    ap.add_argument("--spp", type=int, default=64, help="camera samples per pixel (patch display, path)")
    ap.add_argument("--gather-spp", type=int, default=64)
    ap.add_argument("--gather-rays", type=int, default=8)
    ap.add_argument("--displays", default="patch,vertex,gather", help="comma-separated subset of the displays")
    ap.add_argument("--out", default=str(record.default_path("radiosity_convergence")))
    ap.add_argument("--maps-only", action="store_true",
                    help="only write the error-map figure radiosity_convergence_maps.png beside --out")
    ap.add_argument("--hierarchical", action="store_true",
                    help="hierarchical refinement against the uniform mesh instead (radiosity_hierarchical.json)")
    args = ap.parse_args(argv)
    if args.hierarchical:
        hierarchical_study(args)
        return
    counts = [int(c) for c in args.patches.split(",")]
    spec = registry.get("cornell_box")
    params = dict(spec.fixed_params)
    scene = rm.load_file(spec.xml, **params)
    ref = references.reference("cornell_box", params).image.astype(np.float64)
    md = int(params["max_depth"])
    maps_png = Path(args.out).with_name("radiosity_convergence_maps.png")
    if args.maps_only:
        error_maps(maps_png, scene, ref, md)
        print(f"wrote {maps_png}")
        return
    light = ref.max(axis=2) > 2.0
    for _ in range(2):  # dilate by 2 pixels
        light = light | np.roll(light, 1, 0) | np.roll(light, -1, 0) | np.roll(light, 1, 1) | np.roll(light, -1, 1)
    keep = ~light

    def errors(img):
        a = float(np.abs(img - ref)[keep].mean() / ref[keep].mean())
        return a, float(np.abs(img - ref).mean() / ref.mean())

    t = time.perf_counter()
    base = rm.render(scene, integrator={"type": "path", "max_depth": md}, spp=args.spp, seed=1)
    path_l1, path_all = errors(base.image.astype(np.float64))
    path_s = time.perf_counter() - t
    print(f"path at {args.spp} spp (noise floor of the metric): rel L1 {path_l1:.4f} ({path_all:.4f} with the "
          f"light), {path_s:.1f} s")
    rows, maps, raw = [], {}, {}
    print(f"{'display':<8}{'max_patches':>12}{'patches':>9}{'rel L1':>9}{'noise':>8}{'rel RMSE':>10}{'shots':>8}"
          f"{'solve s':>9}{'total s':>9}")
    displays = [d for d in args.displays.split(",") if d]
    for display in displays:
        for n in counts:
            integ = {"type": "radiosity", "display": display, "max_patches": n, "max_depth": md}
            spp = args.spp
            if display == "gather":
                integ["gather_rays"] = args.gather_rays
                spp = args.gather_spp
            t = time.perf_counter()
            res = rm.render(scene, integrator=integ, spp=spp, seed=1)
            secs = time.perf_counter() - t
            img = res.image.astype(np.float64)
            l1, l1_all = errors(img)
            rmse = float(np.sqrt(((img - ref)[keep] ** 2).mean()) / ref[keep].mean())
            # The expected |noise| of the image itself (sqrt(2 / pi) sigma per
            # pixel, from its variance): the part of rel L1 that is not bias.
            noise = float(np.sqrt(2 / np.pi) * np.sqrt(res.variance.astype(np.float64))[keep].mean() / ref[keep].mean())
            st = res.stats
            rows.append({"scene": "cornell_box", "display": display, "max_patches": n,
                         "patches": int(st["patches"]), "rel_l1": l1, "rel_l1_all": l1_all, "rel_rmse": rmse,
                         "noise_l1": noise,
                         "shots": int(st["shots"]),
                         "residual": st["residual"], "solve_seconds": st["solve_seconds"], "seconds": secs,
                         "spp": spp})
            if display == "patch":
                maps[n] = (img - ref).mean(axis=2) / ref.mean()
                raw[n] = img
            print(f"{display:<8}{n:>12}{int(st['patches']):>9}{l1:>9.4f}{noise:>8.4f}{rmse:>10.4f}{int(st['shots']):>8}"
                  f"{st['solve_seconds']:>9.2f}{secs:>9.2f}", flush=True)
    slopes = {}
    for display in displays:
        r = [x for x in rows if x["display"] == display]
        k = np.polyfit(np.log([x["patches"] for x in r]), np.log([x["rel_l1"] for x in r]), 1)[0]
        slopes[display] = float(k)
        print(f"log-log slope of rel L1 against patches, {display}: {k:+.3f}")
    # The closed furnace (le = rho = 0.5, unbounded depth): exact at any count.
    furnace = []
    fscene = rm.load_file(registry.get("furnace").xml, res=16, max_depth=-1)
    for n in counts[:4]:
        res = rm.render(fscene, integrator={"type": "radiosity", "display": "patch", "max_patches": n,
                                            "residual": 1e-7}, spp=1, seed=1)
        err = float(np.abs(res.image / 1.0 - 1).max())
        furnace.append({"max_patches": n, "patches": int(res.stats["patches"]), "max_rel_error": err})
        print(f"furnace {n:>6} patches: max |L / L_exact - 1| = {err:.2e}")

    def plot(png):
        try:
            import matplotlib
        except ImportError:
            print("matplotlib is not installed: no figure")
            return

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
        for display, mk in (("patch", "o-"), ("vertex", "^-"), ("gather", "s-")):
            if display not in slopes:
                continue
            r = [x for x in rows if x["display"] == display]
            ax[0].loglog([x["patches"] for x in r], [x["rel_l1"] for x in r], mk,
                         label=f"{display} (slope {slopes[display]:+.2f})")
        ax[0].set_xlabel("patches")
        ax[0].set_ylabel("relative L1 error vs Mitsuba reference")
        ax[0].set_title("Cornell box, max_depth 8")
        ax[0].legend()
        lo, hi = min(maps), max(maps)
        v = max(np.abs(maps[lo]).max(), 1e-6) * 0.5
        for a, n in ((ax[1], lo), (ax[2], hi)):
            im = a.imshow(maps[n], cmap="RdBu_r", vmin=-v, vmax=v)
            a.set_title(f"patch display - reference, {n} patches")
            a.axis("off")
        fig.colorbar(im, ax=ax[1:], shrink=0.8, label="(radiosity - reference) / mean reference")
        fig.savefig(png, dpi=90)

    # The error maps as EXR beside the JSON (the per-patch images of the
    # coarsest and finest meshes, layer "error": image - reference), viewable
    # without matplotlib: shadow leaks under the boxes, Mach bands at patch edges.
    for n in (min(raw), max(raw)):
        write_exr(Path(args.out).with_name(f"radiosity_convergence_patch_{n}.exr"), image=raw[n].astype(np.float32),
                  layers={"error": (raw[n] - ref).astype(np.float32)})
    error_maps(maps_png, scene, ref, md)
    out = record.write("radiosity_convergence", record.params_of(args),
                       {"rows": rows, "slopes": slopes, "furnace": furnace,
                        "path_baseline": {"spp": args.spp, "rel_l1": path_l1, "rel_l1_all": path_all,
                                          "seconds": path_s}}, out=args.out, plot=plot)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
