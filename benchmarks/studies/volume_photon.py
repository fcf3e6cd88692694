"""Volume photon map report (not a test): photonmapper's bias and time in
scenes with media against volpath, as the volume map grows.

    python -m radiometer.benchmarks.studies.volume_photon [--seeds 3] [--res 32]

Scenes: fog_room (a homogeneous fog, camera inside it; regions: top and
bottom half) and translucent_slab (subsurface scattering behind a dielectric
boundary, by the photon map inside the slab and ray marching along the
refracted camera rays; regions: the lit half, x > 0, and the dark half that
light reaches only by diffusing under the mask's edge).

Reference: Mitsuba 3's reference.exr of each scene (mean and variance,
block-averaged to --res), which our volpath matches (tests/
test_canonical_mitsuba.py); a volpath render of ours is timed beside it,
since its own images have rare bright samples in fog_room (next event
estimation to the spot light from medium points next to it, a 1 / d^2
tail), and one at 16384 spp moved a half-image mean by 5 %.

Bias = mean over `seeds` photonmapper renders (independent photon maps)
minus the reference, relative to it; its standard error combines the seeds'
spread and the reference's. K: volume_boundary_rays (0: the seed's
Phi / (4/3 pi r^3); 16: the sphere's volume inside the medium measured with
16 rays). "volpath same-time se" is the relative standard
error our volpath reaches per region in the time of one photonmapper
render (the se of its own render, from its per-pixel variance, scaled by
sqrt(its seconds / render seconds)): the unbiased estimator's error to set
against the photon map's bias; "volpath err" is that volpath render's
deviation from the reference.

Writes a table to stdout and benchmarks/results/volume_photon.json (the
studies' layout, studies/record.py). About a minute on two cores.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import radiometer as rm
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry


def halves_rows(img):
    h = img.shape[0] // 2
    return {"top half": img[:h], "bottom half": img[h:], "whole image": img}


def halves_cols(img):
    w = img.shape[1] // 2
    return {"lit half (x > 0)": img[:, w:], "dark half (x < 0)": img[:, :w], "whole image": img}


SCENES = {
    # name: (regions, camera spp per photonmapper render, reference spp, photonmapper parameters)
    "fog_room": (halves_rows, 8, 1024, {"global_photons": 20000, "caustic_photons": 20000}),
    # every diffuse surface of translucent_slab is black: no surface maps
    "translucent_slab": (halves_cols, 4, 512, {"global_photons": 0, "caustic_photons": 0}),
}
# (volume photons, volume_boundary_rays): the seed's estimate at three
# budgets, then the boundary-corrected one (photonmapper.cpp) at two;
# volume_lookup_size stays at its default, 64.
CONFIGS = ((20000, 0), (80000, 0), (320000, 0), (80000, 16), (320000, 16))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--out", default=str(record.default_path("volume_photon")))
    args = ap.parse_args(argv)
    rows, refs_info = [], []
    print(f"{'scene':<18}{'photons':>8}{'K':>4}  {'region':<19}{'bias %':>8}{'se %':>6}{'s/render':>9}{'trace s':>8}"
          f"{'volpath same-time se %':>23}{'volpath err %':>14}")
    for name, (regions, spp, vp_spp, extra) in SCENES.items():
        spec = registry.get(name)
        scene = rm.load_file(spec.xml, res=args.res)
        mref = rm.read_exr(spec.reference_exr)
        f = mref.image.shape[0] // args.res
        blocks = lambda a: np.asarray(a, np.float64).reshape(args.res, f, args.res, f, 3)  # noqa: E731
        ref_img = blocks(mref.image).mean(axis=(1, 3))
        ref_var = blocks(mref.variance).sum(axis=(1, 3)) / f ** 4
        ref_reg = {k: float(v.mean()) for k, v in regions(ref_img).items()}
        ref_se = {k: float(np.sqrt(v.sum()) / v.size) for k, v in regions(ref_var).items()}
        t = time.perf_counter()
        vp = rm.render(scene, integrator="volpath", spp=vp_spp, seed=1000)
        vp_s = time.perf_counter() - t
        vp_reg = {k: float(v.mean()) for k, v in regions(vp.image.astype(np.float64)).items()}
        vp_se = {k: float(np.sqrt(v.sum()) / v.size) for k, v in regions(vp.variance.astype(np.float64)).items()}
        refs_info.append({"scene": name, "reference": "Mitsuba 3 reference.exr", "volpath_spp": vp_spp,
                          "volpath_seconds": vp_s,
                          "volpath_rel_err": {k: vp_reg[k] / ref_reg[k] - 1 for k in ref_reg}})
        for n_photons, k_rays in CONFIGS:
            renders, secs, trace = [], [], []
            for s in range(args.seeds):
                t = time.perf_counter()
                r = rm.render(scene, integrator=dict({"type": "photonmapper", "volume_photons": n_photons,
                                                      "volume_boundary_rays": k_rays, "direct_samples": 1,
                                                      "gather_rays": 8}, **extra),
                              spp=spp, seed=s)
                secs.append(time.perf_counter() - t)
                trace.append(r.stats["photon_maps"]["volume"]["trace_seconds"] +
                             r.stats["photon_maps"]["volume"]["build_seconds"])
                renders.append({k: float(v.mean()) for k, v in regions(r.image.astype(np.float64)).items()})
            sec = float(np.median(secs))
            for reg, want in ref_reg.items():
                got = np.array([x[reg] for x in renders])
                se = float(np.hypot(got.std(ddof=1) / np.sqrt(len(got)), ref_se[reg]))
                bias = float(got.mean() / want - 1)
                same_time = vp_se[reg] / vp_reg[reg] * np.sqrt(vp_s / sec)
                rows.append({"scene": name, "volume_photons": n_photons, "volume_boundary_rays": k_rays,
                             "region": reg, "reference": want,
                             "mean": float(got.mean()), "rel_bias": bias, "rel_se": se / want,
                             "seed_spread": float(got.std(ddof=1) / want), "seconds_per_render": sec,
                             "volume_map_seconds": float(np.median(trace)), "spp": spp,
                             "volpath_same_time_rel_se": float(same_time)})
                print(f"{name:<18}{n_photons:>8}{k_rays:>4}  {reg:<19}{100 * bias:>+8.2f}{100 * se / want:>6.2f}"
                      f"{sec:>9.2f}"
                      f"{float(np.median(trace)):>8.2f}{100 * same_time:>23.2f}"
                      f"{100 * (vp_reg[reg] / want - 1):>+14.2f}", flush=True)
    out = {"references": refs_info, "rows": rows}
    print(f"wrote {record.write('volume_photon', record.params_of(args), out, out=args.out)}")


if __name__ == "__main__":
    main()
