"""Bias report (not a test): photonmapper's bias per scene, effect class and
region, as the photon count N grows with the lookup size n ~ sqrt(N)
(Jensen 2001, sec. 7.2: the estimate converges when n -> inf and n / N -> 0).

    python -m radiometer.benchmarks.studies.photon_bias [--seeds 4] [--spp 16]

Bias = mean over `seeds` independent renders minus the reference, relative
to the reference, per region of the scene's card and per effect class; its
standard error combines the seeds' spread and the reference's own variance.
The reference per effect class is our unbiased `bdpt` (4 independent renders
of 2048 spp; bdpt matches Mitsuba's references of both scenes in
tests/test_canonical_mitsuba.py and samples caustics far better than
`path`), since Mitsuba's references hold only the total; its standard error
per region comes from the spread of its 4 renders. Both photonmapper modes: final gathering (the default) and the global
map seen directly (final_gather off), where the density estimate's bias is in
plain view. Writes a table to stdout and benchmarks/results/photon_bias.json
(the studies' layout, studies/record.py).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import radiometer as rm
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry

SCENES = {
    # name: (res, regions (x0, y0, x1, y1) at that res, effect classes to report); max_depth: the reference's
    "cornell_box": (32, {"whole image": (0, 0, 32, 32), "floor": (4, 26, 28, 32), "left wall": (0, 4, 6, 28),
                            "back wall": (8, 6, 24, 20)}, ("direct", "indirect")),
    "glass_sphere_caustic": (64, {"caustic focus": (32, 33, 42, 40), "shadow": (20, 29, 58, 47),
                                      "sphere": (16, 14, 41, 39), "open floor": (0, 48, 64, 64)},
                             ("direct", "caustic", "indirect", "specular")),
}
BUDGETS = [(25000, 30), (100000, 60), (400000, 120)]  # (photons per map, lookup_size n ~ sqrt(N))


def region(img, box):
    x0, y0, x1, y1 = box
    return float(np.asarray(img, np.float64)[y0:y1, x0:x1].mean())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--ref-runs", type=int, default=4)
    ap.add_argument("--out", default=str(record.default_path("photon_bias")))
    args = ap.parse_args(argv)
    rows = []
    print(f"{'scene':<22}{'mode':<8}{'N':>8}{'n':>5}  {'effect':<9}{'region':<15}{'bias %':>8}{'se %':>7}")
    for name, (res, regions, effects) in SCENES.items():
        spec = registry.get(name)
        md = registry.max_depth(spec)
        scene = rm.load_file(spec.xml, res=res)
        t = time.perf_counter()
        refs = [rm.render(scene, integrator={"type": "bdpt", "max_depth": md}, spp=args.ref_spp, seed=1000 + i)
                for i in range(args.ref_runs)]
        ref_s = time.perf_counter() - t
        for mode, fg in (("gather", True), ("direct", False)):
            for n_photons, n in BUDGETS:
                renders, secs = [], []
                for s in range(args.seeds):
                    t = time.perf_counter()
                    renders.append(rm.render(scene, integrator={
                        "type": "photonmapper", "max_depth": md, "final_gather": fg, "global_photons": n_photons,
                        "caustic_photons": n_photons, "lookup_size": n, "direct_samples": 1, "gather_rays": 8},
                        spp=args.spp, seed=s))
                    secs.append(time.perf_counter() - t)
                for eff in effects:
                    for rname, box in regions.items():
                        ref_runs = np.array([region(r.effects[eff], box) for r in refs])
                        want = float(ref_runs.mean())
                        if want <= 1e-3 * max(1e-12, np.mean([region(r.image, box) for r in refs])):
                            continue  # the class is (nearly) absent from this region
                        got = np.array([region(r.effects[eff], box) for r in renders])
                        ref_se = float(ref_runs.std(ddof=1) / np.sqrt(len(ref_runs)))
                        se = float(np.hypot(got.std(ddof=1) / np.sqrt(len(got)), ref_se))
                        bias = float(got.mean() / want - 1)
                        row = {"scene": name, "mode": mode, "photons": n_photons, "lookup_size": n, "effect": eff,
                               "region": rname, "reference": want, "mean": float(got.mean()), "rel_bias": bias,
                               "rel_se": se / want, "seconds_per_render": float(np.median(secs))}
                        rows.append(row)
                        print(f"{name:<22}{mode:<8}{n_photons:>8}{n:>5}  {eff:<9}{rname:<15}{100 * bias:>+8.2f}"
                              f"{100 * se / want:>7.2f}", flush=True)
        rows.append({"scene": name, "reference": "bdpt", "reference_seconds": ref_s, "reference_spp": args.ref_spp,
                     "reference_runs": args.ref_runs})
    print(f"wrote {record.write('photon_bias', record.params_of(args), {'rows': rows}, out=args.out)}")


if __name__ == "__main__":
    main()
