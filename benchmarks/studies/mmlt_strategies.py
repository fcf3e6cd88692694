"""Study (not a test): is each of mmlt's strategies unbiased? mmlt's b by
strategy against bdpt's strategy images (docs/mlt.md, "mmlt's strategies
against bdpt's").

    python -m radiometer.benchmarks.studies.mmlt_strategies [--scene veach_mis] [--seeds 16]

mmlt's sample is one strategy (s, t) of its chain's depth d = s + t - 1
(2 .. max_depth), its MIS-weighted contribution times d + 1; its bootstrap
evaluates every point of a depth with every strategy of that depth, and
res.stats["mlt_b_per_strategy"] holds each strategy's share of b, the mean
of f / (d + 1) over the points of its depth (with its variance,
"mlt_b_per_strategy_variance"). Depth 1 is mmlt's camera pass, not
sampled by strategy: its shares are NaN and are left out. Its expectation is the luminance sum of
bdpt's MIS-weighted strategy image (s, t) (both are E[L w] of that
strategy over the same paths), so a strategy whose share differs from it
by more than the two errors allow is biased in mmlt (or in bdpt's
strategy images), and the depth and strategy say where.

Per seed one mmlt render with `mutations_per_pixel` 1 (the bootstrap is
what is measured; the chains do not matter) and `--bootstrap` points;
bdpt with strategy_images = max_depth over `--bdpt-seeds` renders. Prints
per strategy: bdpt's share, mmlt's mean over seeds, their difference in
its standard error (from the spread over seeds, and from the renders'
own variances), and writes benchmarks/results/mmlt_strategies_<scene>.json.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from radiometer.benchmarks.studies import record

LUMA = np.array([0.212671, 0.715160, 0.072169])  # the renderer's luminance (core/spectrum.h)


def slots(max_depth):
    return [(d, s) for d in range(1, max_depth + 1) for s in range(d + 1)]


def load(scene_name, res, max_depth, extra=None):
    """The registered scene at `res` (our own comparison: any resolution)."""
    import radiometer as rm
    from radiometer.reference_scenes import registry

    spec = registry.get(scene_name)
    p = {**registry.scene_params(spec, {}), "res": res, "max_depth": max_depth, **(extra or {})}
    return rm.load_file(spec.xml, **p)


def bdpt_shares(scene, max_depth, seeds, spp, mis="power", threads=0, first_seed=7000):
    """Per strategy (d, s) of slots(max_depth): the luminance sum of bdpt's
    MIS-weighted strategy image, one row per seed (seeds x strategies)."""
    import radiometer as rm

    out = []
    for k in range(seeds):
        r = rm.render(scene, integrator={"type": "bdpt", "max_depth": max_depth, "strategy_images": max_depth,
                                         "mis": mis}, spp=spp, seed=first_seed + k, threads=threads)
        row = []
        for d, s in slots(max_depth):
            img = r.strategies.get((s, d + 1 - s))
            row.append(0.0 if img is None else float((np.asarray(img, np.float64) @ LUMA).sum()))
        out.append(row)
    return np.array(out)


def mmlt_shares(scene, max_depth, seeds, bootstrap, threads=0, first_seed=9000, log=None):
    """mmlt's b by strategy (res.stats mlt_b_per_strategy) and its variance,
    one row per seed (one bootstrap each; one mutation per pixel)."""
    import radiometer as rm

    share, var = [], []
    for k in range(seeds):
        r = rm.render(scene, integrator={"type": "mmlt", "max_depth": max_depth, "bootstrap_samples": bootstrap,
                                         "mutations_per_pixel": 1}, spp=1, seed=first_seed + k, threads=threads)
        share.append(np.asarray(r.stats["mlt_b_per_strategy"], np.float64))
        var.append(np.asarray(r.stats["mlt_b_per_strategy_variance"], np.float64))
        if log:
            log(f"  mmlt seed {k}: b {float(np.ravel(r.stats['mlt_b'])[0]):.5g}")
    return np.array(share), np.array(var)


def compare(max_depth, bd, mm, mm_var):
    """Rows per strategy: bdpt's mean share and its standard error (spread
    over seeds), mmlt's mean, its standard error from the spread over seeds
    and from its bootstrap points (all independent, so many degrees of
    freedom), and z = (mmlt - bdpt) / the two errors (mmlt's from its
    points)."""
    rows = []
    n = len(mm)
    for i, (d, s) in enumerate(slots(max_depth)):
        b = bd[:, i]
        b_mean = float(b.mean())
        b_se = float(b.std(ddof=1) / np.sqrt(len(b))) if len(b) > 1 else float("nan")
        m_mean = float(mm[:, i].mean())
        m_se = float(mm[:, i].std(ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
        m_se_own = float(np.sqrt(mm_var[:, i].sum()) / n)
        se = float(np.hypot(m_se_own, b_se))
        rows.append({"depth": d, "s": s, "t": d + 1 - s, "bdpt": b_mean, "bdpt_se": b_se, "mmlt": m_mean,
                     "mmlt_se_seeds": m_se, "mmlt_se_own": m_se_own, "z": (m_mean - b_mean) / se if se > 0 else 0.0})
    return rows


def measure(scene_name, res, max_depth, seeds, bootstrap, bdpt_seeds, bdpt_spp, threads, extra=None, mis="power"):
    scene = load(scene_name, res, max_depth, extra)
    t0 = time.perf_counter()
    bd = bdpt_shares(scene, max_depth, bdpt_seeds, bdpt_spp, mis, threads)
    t_bdpt = time.perf_counter() - t0
    t0 = time.perf_counter()
    mm, mm_var = mmlt_shares(scene, max_depth, seeds, bootstrap, threads, log=lambda m: print(m, flush=True))
    t_mmlt = time.perf_counter() - t0
    return compare(max_depth, bd, mm, mm_var), {"bdpt_seconds": t_bdpt, "mmlt_seconds": t_mmlt}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="veach_mis")
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--max-depth", type=int, default=8)
    ap.add_argument("--seeds", type=int, default=16, help="mmlt renders (one bootstrap each)")
    ap.add_argument("--bootstrap", type=int, default=1 << 18)
    ap.add_argument("--bdpt-seeds", type=int, default=8)
    ap.add_argument("--bdpt-spp", type=int, default=256)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--bdpt-mis", default="power", help="bdpt's heuristic (not mmlt's power: a power check)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a scene parameter (e.g. rfilter=box for a scene that declares it)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    extra = dict(kv.split("=", 1) for kv in args.set)
    rows, times = measure(args.scene, args.res, args.max_depth, args.seeds, args.bootstrap, args.bdpt_seeds,
                          args.bdpt_spp, args.threads, extra, args.bdpt_mis)
    print(f"{'d':>3}{'s':>3}{'t':>3}{'bdpt':>12}{'+-':>10}{'mmlt':>12}{'+- seeds':>10}{'+- own':>10}{'z':>8}")
    for r in rows:
        if (r["bdpt"] == 0 and r["mmlt"] == 0) or not np.isfinite(r["mmlt"]):
            continue
        print(f"{r['depth']:>3}{r['s']:>3}{r['t']:>3}{r['bdpt']:>12.5g}{r['bdpt_se']:>10.2g}{r['mmlt']:>12.5g}"
              f"{r['mmlt_se_seeds']:>10.2g}{r['mmlt_se_own']:>10.2g}{r['z']:>8.2f}")
    rows_m = [r for r in rows if np.isfinite(r["mmlt"])]  # depths 2 .. max_depth
    tot_b = sum(r["bdpt"] for r in rows_m)
    tot_m = sum(r["mmlt"] for r in rows_m)
    z = np.array([r["z"] for r in rows_m if r["bdpt"] > 0 or r["mmlt"] > 0])
    print(f"chi-square {float((z ** 2).sum()):.1f} over {len(z)} strategies, max |z| {float(np.abs(z).max()):.2f}")
    print(f"total: bdpt {tot_b:.5g}, mmlt {tot_m:.5g} (ratio {tot_m / tot_b:.4f}); "
          f"bdpt {times['bdpt_seconds']:.0f} s, mmlt {times['mmlt_seconds']:.0f} s")
    out = record.write(f"mmlt_strategies_{args.scene}", record.params_of(args), {"rows": rows, **times},
                       out=args.out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
