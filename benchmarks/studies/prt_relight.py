"""Performance measurement (not a test): what precomputation buys. `prt`
(renderer/estimators/prt.cpp) precomputes a scene's per-pixel transfer once,
then relights it under each new environment by a projection and a dot
product (radiometer.prt.Transfer); `path` renders the scene anew each time.

The scene: a diffuse ball on a diffuse floor (tests/test_prt.py's), res x
res, box filter; interreflected transfer with one bounce, so `path` at
max_depth 3 estimates the same light. Environments, all but the last
low-frequency: a sky of exp lobes (test_prt.py's `lobe`), the same sky
rotated by 120 degrees about z, a quadratic (band-limited) sky, a constant,
and constant + a directional sun (a delta: the band limit shows).

Measured:
- the precomputation at `--bands` (and at 2, 4, 8 bands for the scaling):
  seconds, transfer bytes, the process's peak RSS;
- per environment: the relighting (loading the emitter dict, the envmap
  read and a scene made, ms; its SH projection, ms; the dot products, ms;
  medians of 5), its relMSE against a `--ref-spp` path reference, and the time
  `path` needs to reach the same relMSE (from a checkpointed render, the
  log-log interpolation of analysis/metrics.py time_to_error; None when
  it does not get there within --path-spp), with the reference's own noise
  floor (relmse_floor) beside it;
- on the lobe sky, relMSE against the reference per band count 1..bands
  from the one precomputation (relight(bands=k)).

    python -m radiometer.benchmarks.studies.prt_relight [--res 64] [--spp 256] [--bands 6] [--ref-spp 2048]

Writes benchmarks/results/prt_relight.json (studies/record.py) and .png (the
scene relit under each environment, prt above path's reference), and prints a table.
"""
from __future__ import annotations

import argparse
import resource
import statistics
import tempfile
from pathlib import Path

import numpy as np

import radiometer as rm
from radiometer.analysis.metrics import relmse, relmse_floor, time_to_error
from radiometer.benchmarks.studies import record
from radiometer.loader.transforms import _look_at
from radiometer.prt import Transfer, latlong_envmap

SUN = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])


def lobe_sky(sun):
    def fn(d):
        c = d @ sun
        return np.stack([0.2 + 1.5 * np.exp(2 * (c - 1)), 0.3 + 1.2 * np.exp(2 * (c - 1)),
                         0.5 + 0.5 * np.exp(d[:, 1] - 1)], -1)
    return fn


def quadratic_sky(d):
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([1.0 + 0.3 * x + 0.2 * z * z, 0.8 + 0.4 * y + 0.3 * x * y, 0.6 - 0.3 * z + 0.2 * x * z], -1)


def scene(lights: dict, res: int):
    d = {"type": "scene", **lights,
         "floor": {"type": "rectangle", "to_world": np.diag([2.0, 2.0, 1.0, 1.0]),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.6, 0.5]}}},
         "ball": {"type": "sphere", "center": [0.0, 0.0, 0.5], "radius": 0.5,
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.6, 0.8]}}},
         "cam": {"type": "perspective", "fov": 45,
                 "to_world": _look_at([0, -3.2, 2.4], [0, 0, 0.3], (0, 0, 1), "prt_relight"),
                 "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}}
    return rm.load_dict(d)


def environments(tmp: Path) -> dict:
    rot = np.array([[np.cos(2.1), -np.sin(2.1), 0], [np.sin(2.1), np.cos(2.1), 0], [0, 0, 1]])
    const = {"type": "constant", "radiance": {"type": "rgb", "value": [0.8, 0.9, 1.0]}}
    def sky(name, fn):
        return {"light": {"type": "envmap", "filename": latlong_envmap(tmp / f"{name}.exr", fn)}}

    return {
        "lobe_sky": sky("lobe", lobe_sky(SUN)),
        "lobe_sky_rotated": sky("lobe_r", lobe_sky(rot @ SUN)),
        "quadratic_sky": sky("quad", quadratic_sky),
        "constant": {"light": const},
        "constant_and_sun": {"light": const, "sun": {"type": "directional", "direction": [-0.4, 0.3, -0.85],
                                                     "irradiance": {"type": "rgb", "value": [2.0, 1.8, 1.5]}}},
    }


def save_png(panels, path):
    """One scene relit under each environment: prt (from the one transfer)
    above, the path reference below, each column at its reference's exposure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from radiometer.analysis.metrics import display_exposure
    from radiometer.tonemap import to_srgb

    fig, axes = plt.subplots(2, len(panels), figsize=(2.4 * len(panels), 5.2), squeeze=False)
    for k, (name, relit, ref) in enumerate(panels):
        ev = display_exposure(ref)
        axes[0, k].imshow(to_srgb(relit, ev))
        axes[0, k].set_title(f"{name}\nprt, relit", fontsize=8)
        axes[1, k].imshow(to_srgb(ref, ev))
        axes[1, k].set_title("path reference", fontsize=8)
        for a in axes[:, k]:
            a.set_xticks([])
            a.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=256, help="prt's precomputation samples per pixel")
    ap.add_argument("--bands", type=int, default=6)
    ap.add_argument("--ref-spp", type=int, default=2048, help="the path reference's spp per environment")
    ap.add_argument("--path-spp", type=int, default=1024, help="path's checkpointed render, at most")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    integ = {"type": "prt", "bands": args.bands, "transfer": "interreflected", "bounces": 1, "env_samples": 64}
    with tempfile.TemporaryDirectory() as tmpdir:
        envs = environments(Path(tmpdir))
        first = scene(envs["lobe_sky"], args.res)
        scaling = []
        for b in sorted({2, 4, args.bands, 8}):
            r = rm.render(first, integrator={**integ, "bands": b}, spp=args.spp, seed=1)
            st = r.stats
            scaling.append({"bands": b, "seconds": r.seconds, "precompute_seconds": st["precompute_seconds"],
                            "transfer_bytes": st["transfer_bytes"]})
            if b == args.bands:
                res = r
        rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        tr = Transfer(res)
        rows, panels = [], []
        for name, lights in envs.items():
            sc = scene(lights, args.res)
            ref = rm.render(sc, integrator={"type": "path", "max_depth": 3}, spp=args.ref_spp, seed=100)
            env = {"type": "scene", **lights}
            times = [tr.relight(env).seconds for _ in range(5)]
            relit = tr.relight(env)
            err = relmse(relit.image, ref.image)
            pth = rm.render(sc, integrator={"type": "path", "max_depth": 3}, spp=args.path_spp, seed=200,
                            checkpoints=True)
            curve = [(s, t, relmse(img, ref.image)) for s, t, img, _ in pth.checkpoints if t > 0]
            t_eq = time_to_error(curve, err)
            panels.append((name, relit.image, ref.image))
            rows.append({"environment": name, "load_ms": 1e3 * statistics.median(t["load"] for t in times),
                         "project_ms": 1e3 * statistics.median(t["project"] for t in times),
                         "dot_ms": 1e3 * statistics.median(t["dot"] for t in times), "prt_relmse": err,
                         "ref_floor_relmse": relmse_floor(ref.image, ref.variance), "path_seconds_equal_error": t_eq,
                         "path_curve": curve, "clamped": relit.clamped})
            if name == "lobe_sky":
                by_bands = [{"bands": k, "relmse": relmse(tr.relight(env, bands=k).image, ref.image)}
                            for k in range(1, args.bands + 1)]
    out = record.write("prt_relight", record.params_of(args), {
        "precompute": {"seconds": res.seconds, "precompute_seconds": res.stats["precompute_seconds"],
                       "projection_seconds": res.stats["projection_seconds"],
                       "transfer_bytes": tr.nbytes, "peak_rss_mib": rss_mib, "scaling": scaling},
        "environments": rows, "lobe_sky_by_bands": by_bands,
        "note": "relMSE against a path reference at --ref-spp (its own noise floor beside it); "
                "path_seconds_equal_error: wall time for path to reach prt's relMSE (None: not within --path-spp)"},
        out=args.out, plot=lambda png: save_png(panels, png))
    print(f"precompute: {res.seconds:.2f} s at {args.bands} bands, {args.spp} spp, {args.res}^2; transfer "
          f"{tr.nbytes / 2 ** 20:.2f} MiB, peak RSS {rss_mib:.0f} MiB")
    print(f"{'environment':18s} {'load ms':>8s} {'project ms':>10s} {'dot ms':>7s} {'prt relMSE':>11s} "
          f"{'ref floor':>10s} {'path s @ equal':>14s}")
    for r in rows:
        teq = "-" if r["path_seconds_equal_error"] is None else f"{r['path_seconds_equal_error']:.2f}"
        print(f"{r['environment']:18s} {r['load_ms']:8.2f} {r['project_ms']:10.2f} {r['dot_ms']:7.2f} "
              f"{r['prt_relmse']:11.2e} {r['ref_floor_relmse']:10.2e} {teq:>14s}")
    print("lobe sky, relMSE by bands: " + ", ".join(f"{b['bands']}: {b['relmse']:.2e}" for b in by_bands))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
