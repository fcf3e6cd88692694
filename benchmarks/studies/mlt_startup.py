"""Study (not a test): the error of Metropolis renders against the number of
mutations per pixel, for a small and a large bootstrap (docs/mlt.md,
"Error against mutations").

    python -m radiometer.benchmarks.studies.mlt_startup [--seeds 4] [--spp 1,2,4,...,256]

Each chain starts from its own bootstrap (a share of `bootstrap_samples`)
and weighs its splats by its own estimate b_c of b = E[f]. So a render's
error has two parts: the chains' histogram noise, which falls like 1 / the
mutations, and b_c's error, which the mutations do not touch. With a small
bootstrap the curve flattens at that floor; with a large one it keeps
falling. The start itself leaves no start-up bias (the start is drawn from
the bootstrap in proportion to f: tests/test_mlt.py::test_no_start_up_bias),
so even one mutation per pixel is unbiased, just noisy.

Scenes with an exact reference (analytic, registry.py): relMSE (eps 1e-2,
analysis/metrics.py) against the exact image, mean over `seeds` renders
with its standard error; `path` at the same samples per pixel as the
baseline. Writes benchmarks/results/mlt_startup.json and .png (one panel
per scene: relMSE against mutations per pixel, log-log, one line per
estimator and bootstrap, the band one standard error).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from radiometer.benchmarks.studies import record

VARIANTS = {"pssmlt (path)": {"type": "pssmlt", "bidirectional": False},
            "pssmlt (bdpt)": {"type": "pssmlt"}, "mmlt": {"type": "mmlt"}}


def measure(scene_name, spp_list, seeds, boots, threads, max_depth):
    import radiometer as rm
    from radiometer.analysis.metrics import relmse
    from radiometer.reference_scenes import references, registry

    spec = registry.get(scene_name)
    p = registry.scene_params(spec, {"res": 16})
    scene = rm.load_file(spec.xml, **p)
    ref = references.reference(scene_name, p).image
    configs = [("path", None, {"type": "path", "max_depth": max_depth})]
    configs += [(name, b, {**v, "max_depth": max_depth, "bootstrap_samples": b})
                for name, v in VARIANTS.items() for b in boots]
    rows = []
    for label, boot, integ in configs:
        for spp in spp_list:
            errs, t = [], time.perf_counter()
            for k in range(seeds):
                r = rm.render(scene, integrator=integ, spp=spp, seed=5000 + 97 * k + spp, threads=threads)
                errs.append(relmse(r.image, ref))
            secs = (time.perf_counter() - t) / seeds
            e, se = float(np.mean(errs)), float(np.std(errs, ddof=1) / np.sqrt(seeds)) if seeds > 1 else 0.0
            rows.append({"scene": scene_name, "estimator": label, "bootstrap": boot, "mutations_per_pixel": spp,
                         "relmse": e, "relmse_se": se, "seconds": secs})
            print(f"{scene_name:<18}{label:<15}{str(boot):>8}{spp:>6}{e:>12.3e} +- {se:<10.2e}{secs:>8.2f} s",
                  flush=True)
    return rows


def plot(results, png):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(results["scenes"])
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.2 * len(scenes), 4.2), dpi=110, squeeze=False)
    for ax, name in zip(axes[0], scenes):
        rows = results["scenes"][name]
        for key in dict.fromkeys((r["estimator"], r["bootstrap"]) for r in rows):
            rs = [r for r in rows if (r["estimator"], r["bootstrap"]) == key]
            x = np.array([r["mutations_per_pixel"] for r in rs], float)
            y = np.array([r["relmse"] for r in rs])
            s = np.array([r["relmse_se"] for r in rs])
            label = key[0] if key[1] is None else f"{key[0]}, bootstrap {key[1]}"
            style = "k--" if key[1] is None else ("-" if key[1] == max(results["bootstraps"]) else ":")
            (line,) = ax.plot(x, y, style, marker="o", ms=3, label=label)
            ax.fill_between(x, np.maximum(y - s, y * 1e-3), y + s, color=line.get_color(), alpha=0.15)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("mutations per pixel (path: samples per pixel)")
        ax.set_ylabel("relMSE against the exact image")
        ax.set_title(f"{name}, 16 x 16, mean over {results['seeds']} seeds")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="area_lights_disk,mirror_caustic", help="analytic scenes (exact reference)")
    ap.add_argument("--spp", default="1,2,4,8,16,32,64,128,256")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--bootstraps", default="256,65536")
    ap.add_argument("--max-depth", type=int, default=4)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--out", default=str(record.default_path("mlt_startup")))
    a = ap.parse_args(argv)
    spp = [int(x) for x in a.spp.split(",")]
    boots = [int(x) for x in a.bootstraps.split(",")]
    results = {"seeds": a.seeds, "bootstraps": boots, "scenes": {}}
    for name in a.scenes.split(","):
        results["scenes"][name] = measure(name, spp, a.seeds, boots, a.threads, a.max_depth)
    path = record.write("mlt_startup", record.params_of(a), results, out=a.out, plot=lambda png: plot(results, png))
    print(f"wrote {path} and its .png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
