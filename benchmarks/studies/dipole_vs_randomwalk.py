"""Error report (not a test): the dipole BSSRDF (Jensen et al. 2001,
renderer/scene/dipole.h) as the fast approximation of random-walk
subsurface scattering, measured per scene against the random walk.

    python -m radiometer.benchmarks.studies.dipole_vs_randomwalk [--rw-spp 256] [--converged-spp 1024]

Scenes: translucent_slab and translucent_object. The random walk is each
scene's scene.xml (a dense medium behind a smooth dielectric, rendered by
`volpath`); the dipole variant is dipole.xml next to it (same geometry,
IOR, sigma_a, sigma_s, g; a `dipole` subsurface instead of the medium,
rendered by `path`). The truth is the scene's reference.exr (Mitsuba 3's
volpath, thousands of spp; our volpath matches it, see the cards).
Per scene:
- time per spp of each (median of the timed renders; 2 threads);
- at a matched budget (the dipole given the wall-clock time our volpath
  took for --rw-spp, as a spp count from its measured time per spp):
  relMSE (eps 1e-2) of each against the reference;
- the dipole converged (--converged-spp): its relMSE against the reference
  is the model's error (bias) rather than noise; mean ratio to the
  reference per region of the card (RGB), with the random walk's own ratio
  beside it.
A third, generated case calibrates the model where its assumptions hold:
a half space (a 10 x 10 x 3 block, 60 mean free paths deep) of
translucent_slab's medium under a uniform environment, seen along the
normal (8 x 8 pixels of its centre): dipole and random walk (both ours,
--half-space-spp each) and the dipole's analytic value Fr(0) + Ft(0) R_d.
Writes benchmarks/results/dipole_vs_randomwalk.json (the studies' layout,
studies/record.py) and a PNG beside it, one row per scene: dipole
(converged) / random walk (reference) / relative difference (dipole -
reference) / reference, at one exposure per scene.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import radiometer as rm
from radiometer.analysis.metrics import display_exposure, relmse, relmse_floor
from radiometer.benchmarks.studies import record
from radiometer.exr import read_exr
from radiometer.reference_scenes import registry

THREADS = 2
# Regions (x0, y0, x1, y1), half-open, at 64 x 64: the scenes' card.md.
SCENES = {
    "translucent_slab": {"lit half": (44, 0, 64, 64), "edge band": (22, 0, 42, 64), "deep shadow": (0, 0, 16, 64)},
    "translucent_object": {"torus": (12, 6, 53, 48), "hole": (24, 19, 40, 36), "top of ring": (26, 6, 38, 14),
                           "floor behind/under": (10, 44, 56, 56), "open floor": (0, 52, 64, 64)},
}


def region_mean(img, box):
    x0, y0, x1, y1 = box
    return np.asarray(img, np.float64)[y0:y1, x0:x1].mean(axis=(0, 1))


def half_space(kind):
    """The calibration scene: `kind` 'dipole' or 'random_walk'."""
    def rgb(v):
        return {"type": "rgb", "value": [float(x) for x in np.broadcast_to(v, 3)]}

    st, albedo = 20.0, np.array([0.99, 0.95, 0.8])  # translucent_slab's medium
    block = {"type": "cube", "to_world": np.array([[5, 0, 0, 0], [0, 5, 0, 0], [0, 0, 1.5, -1.5], [0, 0, 0, 1]], float)}
    if kind == "dipole":
        block["subsurface"] = {"type": "dipole", "sigma_a": rgb(st * (1 - albedo)), "sigma_s": rgb(st * albedo),
                               "int_ior": 1.5, "ext_ior": 1.0}
    else:
        block["bsdf"] = {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}
        block["interior"] = {"type": "homogeneous", "sigma_t": st, "albedo": rgb(albedo)}
    return rm.load_dict({
        "type": "scene", "integrator": {"type": "path"}, "block": block,
        "sensor": {"type": "orthographic", "to_world": np.array([[0.2, 0, 0, 0], [0, 0.2, 0, 0], [0, 0, -1, 3],
                                                                  [0, 0, 0, 1]], float),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": rgb(1.0)}})


def calibrate(spp):
    from radiometer import _core

    out = {"scene": "half_space (generated; translucent_slab's medium, 60 mean free paths deep)", "spp": spp}
    for kind in ("dipole", "random_walk"):
        r, s = timed(half_space(kind), spp, 7)
        n = r.image[..., 0].size
        out[kind] = {"mean": r.image.mean(axis=(0, 1)).tolist(),
                     "standard_error": np.sqrt(r.variance.mean(axis=(0, 1)) / n).tolist(),
                     "seconds_per_spp": s / spp}
    d = _core.DipoleDesc()
    d.sigma_a, d.sigma_s, d.int_ior, d.ext_ior = (0.2, 1.0, 4.0), (19.8, 19.0, 16.0), 1.5, 1.0
    fr0 = 0.04  # ((1.5 - 1) / (1.5 + 1))^2
    out["dipole_analytic"] = (fr0 + (1 - fr0) * np.array(_core.Dipole(d).total_rd)).tolist()
    out["dipole_over_random_walk"] = (np.array(out["dipole"]["mean"]) / np.array(out["random_walk"]["mean"])).tolist()
    return out


def timed(scene, spp, seed):
    t = time.perf_counter()
    r = rm.render(scene, spp=spp, seed=seed, threads=THREADS)
    return r, time.perf_counter() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rw-spp", type=int, default=256, help="random walk (volpath) spp of the matched budget")
    ap.add_argument("--converged-spp", type=int, default=1024, help="dipole spp for its model error")
    ap.add_argument("--half-space-spp", type=int, default=1024)
    ap.add_argument("--out", default=str(record.default_path("dipole_vs_randomwalk")))
    args = ap.parse_args(argv)
    rows, panels = [], []
    t_all = time.perf_counter()
    for name, regions in SCENES.items():
        folder = registry.get(name).xml.parent
        ref = read_exr(folder / "reference.exr")
        rw_scene = rm.load_file(folder / "scene.xml")
        dp_scene = rm.load_file(folder / "dipole.xml")
        # Warm-up (scene build, first touch) outside the timings.
        rm.render(rw_scene, spp=1, seed=0, threads=THREADS)
        rm.render(dp_scene, spp=1, seed=0, threads=THREADS)
        rw, rw_s = timed(rw_scene, args.rw_spp, 1)
        probe, probe_s = timed(dp_scene, 32, 2)
        dp_spp = max(1, int(round(rw_s / (probe_s / 32))))
        dp, dp_s = timed(dp_scene, dp_spp, 3)
        conv, conv_s = timed(dp_scene, args.converged_spp, 4)
        row = {
            "scene": name,
            "random_walk": {"integrator": "volpath", "spp": args.rw_spp, "seconds": rw_s,
                            "seconds_per_spp": rw_s / args.rw_spp, "relmse": relmse(rw.image, ref.image)},
            "dipole_matched": {"integrator": "path", "spp": dp_spp, "seconds": dp_s,
                               "seconds_per_spp": dp_s / dp_spp, "relmse": relmse(dp.image, ref.image)},
            "dipole_converged": {"spp": args.converged_spp, "seconds": conv_s,
                                 "seconds_per_spp": conv_s / args.converged_spp,
                                 "relmse": relmse(conv.image, ref.image),
                                 "relmse_noise_part": relmse_floor(ref.image, conv.variance)},
            "reference_relmse_floor": relmse_floor(ref.image, ref.variance),
            "speedup_per_spp": (rw_s / args.rw_spp) / (dp_s / dp_spp),
            "image_mean_ratio": (region_mean(conv.image, (0, 0, 64, 64))
                                 / region_mean(ref.image, (0, 0, 64, 64))).tolist(),
            "regions": {},
        }
        for rname, box in regions.items():
            want = region_mean(ref.image, box)
            row["regions"][rname] = {
                "box": list(box), "reference": want.tolist(),
                "dipole_ratio": (region_mean(conv.image, box) / want).tolist(),
                "random_walk_ratio": (region_mean(rw.image, box) / want).tolist()}
        rows.append(row)
        panels.append((name, conv.image, ref.image))
        print(f"{name}: volpath {rw_s / args.rw_spp * 1e3:.2f} ms/spp, dipole {dp_s / dp_spp * 1e3:.2f} ms/spp "
              f"(x{row['speedup_per_spp']:.1f}); matched budget {rw_s:.1f} s: relMSE volpath "
              f"{row['random_walk']['relmse']:.4f}, dipole {row['dipole_matched']['relmse']:.4f} ({dp_spp} spp); "
              f"dipole converged ({args.converged_spp} spp) {row['dipole_converged']['relmse']:.4f}", flush=True)
        for rname, r in row["regions"].items():
            d, w = r["dipole_ratio"], r["random_walk_ratio"]
            print(f"    {rname:<20} dipole/ref {d[0]:.3f} {d[1]:.3f} {d[2]:.3f}   volpath/ref "
                  f"{w[0]:.3f} {w[1]:.3f} {w[2]:.3f}")
    cal = calibrate(args.half_space_spp)
    q = cal["dipole_over_random_walk"]
    print(f"half space: dipole {np.round(cal['dipole']['mean'], 4).tolist()} (analytic "
          f"{np.round(cal['dipole_analytic'], 4).tolist()}), "
          f"random walk {np.round(cal['random_walk']['mean'], 4).tolist()}"
          f" +- {np.round(cal['random_walk']['standard_error'], 4).tolist()}: ratio {q[0]:.3f} {q[1]:.3f} {q[2]:.3f}")
    out = {"threads": THREADS,
           "reference": "each scene's reference.exr (Mitsuba 3.9.1 volpath, see its card.md)",
           "relmse_eps": 1e-2, "total_seconds": time.perf_counter() - t_all, "rows": rows,
           "half_space_calibration": cal}
    path = record.write("dipole_vs_randomwalk", record.params_of(args), out, out=args.out,
                        plot=lambda png: save_png(panels, png))
    print(f"wrote {path} and the .png beside it")


def save_png(panels, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from radiometer.tonemap import to_srgb

    fig, axes = plt.subplots(len(panels), 3, figsize=(9, 3.1 * len(panels)), squeeze=False)
    for row, (name, dip, ref) in zip(axes, panels):
        ev = display_exposure(ref)

        def lum(a):
            return 0.2126 * a[..., 0] + 0.7152 * a[..., 1] + 0.0722 * a[..., 2]

        rel = (lum(dip) - lum(ref)) / np.maximum(lum(ref), 1e-3)
        row[0].imshow(to_srgb(dip, ev))
        row[0].set_title(f"{name}\ndipole (path)", fontsize=9)
        row[1].imshow(to_srgb(ref, ev))
        row[1].set_title("random walk (reference)", fontsize=9)
        im = row[2].imshow(np.clip(rel, -1, 1), cmap="RdBu_r", vmin=-1, vmax=1)
        row[2].set_title("(dipole - ref) / ref, luminance", fontsize=9)
        fig.colorbar(im, ax=row[2], fraction=0.046)
        for a in row:
            a.set_xticks([])
            a.set_yticks([])
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    main()
