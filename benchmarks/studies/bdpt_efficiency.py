"""Efficiency benchmark of the bidirectional estimators (not a test): error
against wall-clock time, equal time for every contender.

Part `scenes`: `path`, `bdpt` and `ptracer` on the scenes bidirectional
transport is for, glass_sphere_caustic (caustics seen on a diffuse floor)
and ajar_door (a room lit through a narrow gap), against their Mitsuba
references (64 x 64). Part `mis`: `bdpt` on veach_mis with the power
heuristic (beta 2, 1 = balance, 3), the balance heuristic and uniform
weights, plus `path` for scale: the seed's point that the choice of the
weights w_ij is substantial.

    python -m radiometer.benchmarks.studies.bdpt_efficiency [--part scenes|mis|all]
        [--seconds 2 4 8] [--seeds 3] [--threads 0] [--clock wall|cpu]
        [--scenes ajar_door ...]

Each (scene, contender, budget, seed) is one render under a wall-clock
budget (`seconds=`). With `--clock cpu` the budget is this process's CPU
time instead (all render threads together), for a machine shared with
other work, where wall-clock budgets would hand each contender whatever
the other loads leave: a short render per (scene, contender) measures its
CPU seconds per sample, the budget's renders get that many samples, and
their measured CPU time is what the efficiency divides by. Error: relMSE (eps 1e-2) over the whole image and over
the scene's effect region (card.md boxes), minus the reference's own
contribution (the reference is noisy: E[(a - r)^2] = (a - L)^2 + Var[a] +
Var[r], so mean(Var[r] / (r^2 + eps)) is subtracted; printed as `floor`).
Efficiency is 1 / (relMSE x seconds); the ratio column is bdpt's (or each
weighting's) efficiency over path's at the same budget. Writes a table to
stdout, benchmarks/results/bdpt_efficiency_<part>.json (the studies' layout,
studies/record.py) and a log-log plot of error against time per scene next
to it.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

import radiometer as rm
from radiometer.analysis.blocks import region_mask
from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry

EPS = 1e-2

# Effect regions (card.md boxes at 64 x 64); the scenes render with their
# references' parameters (max_depth included, reference_scenes/registry.py).
SCENE_CFG = {
    "glass_sphere_caustic": {"region": ("caustic focus and shadow", [(20, 29, 58, 47)])},
    "ajar_door": {"region": ("near room (lit through the gap only)", None)},
    "veach_mis": {"region": ("light sampling wins | BSDF sampling wins", [(0, 48, 16, 53), (48, 28, 64, 34)])},
}
CONTENDERS = {
    "scenes": {"path": {"type": "path"}, "bdpt": {"type": "bdpt"}, "ptracer": {"type": "ptracer"}},
    "mis": {"path": {"type": "path"},
            "bdpt power beta=2": {"type": "bdpt", "mis": "power", "beta": 2.0},
            "bdpt power beta=3": {"type": "bdpt", "mis": "power", "beta": 3.0},
            "bdpt balance": {"type": "bdpt", "mis": "balance"},
            "bdpt uniform": {"type": "bdpt", "mis": "uniform"}},
}
PART_SCENES = {"scenes": ["glass_sphere_caustic", "ajar_door"], "mis": ["veach_mis"]}


def _mask(name):
    if name == "ajar_door":  # everything but the doorway view and the beam (card.md)
        return ~region_mask((64, 64), [(28, 15, 40, 41), (54, 18, 64, 40)])
    return region_mask((64, 64), SCENE_CFG[name]["region"][1])


def rel_mse(a, ref, ref_var, mask=None):
    """relMSE minus the reference's own share, and that share (the floor)."""
    a, r, v = (np.asarray(x, np.float64) for x in (a, ref, ref_var))
    sel = np.ones(r.shape[:2], bool) if mask is None else mask
    err = ((a - r) ** 2 / (r * r + EPS))[sel]
    floor = (v / (r * r + EPS))[sel]
    return float(err.mean() - floor.mean()), float(floor.mean())


def _cpu_render(scene, integ, budget, seed, threads, per_spp):
    """A render of about `budget` CPU seconds, given the measured CPU seconds
    per sample; returns it and its CPU seconds."""
    spp = max(1, int(round(budget / per_spp)))
    t0 = time.process_time()
    r = rm.render(scene, integrator=integ, spp=spp, seed=seed, threads=threads)
    return r, time.process_time() - t0


def run(part, budgets, seeds, threads, progress=True, clock="wall", only=None):
    rows = []
    for name in PART_SCENES[part]:
        if only and name not in only:
            continue
        spec = registry.get(name)
        ref = rm.read_exr(spec.reference_exr)
        scene = rm.load_file(spec.xml, **spec.fixed_params)
        mask = _mask(name)
        for label, contender in CONTENDERS[part].items():
            integ = {**contender, "max_depth": registry.max_depth(spec)}
            if clock == "cpu":  # CPU seconds per sample, from a render of ~1/4 the smallest budget
                _, c = _cpu_render(scene, integ, 0, 99, threads, 1.0)  # 1 spp: warms caches, sizes the next
                probe_spp = max(1, int(0.25 * min(budgets) / max(c, 1e-4)))
                t0 = time.process_time()
                rm.render(scene, integrator=integ, spp=probe_spp, seed=98, threads=threads)
                per_spp = (time.process_time() - t0) / probe_spp
            for sec in budgets:
                errs, region_errs, spps, times = [], [], [], []
                for k in range(seeds):
                    if clock == "cpu":
                        r, t = _cpu_render(scene, integ, sec, 1000 * k + 7, threads, per_spp)
                    else:
                        r = rm.render(scene, integrator=integ, seconds=sec, seed=1000 * k + 7, threads=threads)
                        t = sec
                    times.append(t)
                    e, floor = rel_mse(r.image, ref.image, ref.variance)
                    er, floor_r = rel_mse(r.image, ref.image, ref.variance, mask)
                    errs.append(e)
                    region_errs.append(er)
                    spps.append(r.spp)
                row = {"scene": name, "contender": label, "seconds": sec, "clock": clock,
                       "time": statistics.mean(times), "spp": statistics.median(spps),
                       "relmse": statistics.mean(errs), "relmse_region": statistics.mean(region_errs),
                       "relmse_sd": statistics.stdev(errs) if seeds > 1 else None,
                       "floor": floor, "floor_region": floor_r, "seeds": seeds}
                rows.append(row)
                if progress:
                    print(f"  {name:22s} {label:20s} {row['time']:5.2f} s  {row['spp']:7.0f} spp  "
                          f"relMSE {row['relmse']:.3e}"
                          f"  region {row['relmse_region']:.3e}", flush=True)
    return rows


def table(rows, part):
    base = {(r["scene"], r["seconds"]): r for r in rows if r["contender"] == "path"}
    lines = [f"{'scene':22s} {'contender':20s} {'s':>5s} {'spp':>7s} {'relMSE':>10s} {'x path':>7s} "
             f"{'region':>10s} {'x path':>7s} {'floor':>9s}"]
    for r in rows:
        b = base.get((r["scene"], r["seconds"]))
        # efficiency 1 / (relMSE x time) over path's: at equal wall-clock time
        # path's error over this one's; with CPU budgets, the measured CPU
        # times (close to each other, not equal) enter too.
        t, tb = r.get("time", r["seconds"]), (b or {}).get("time", (b or {}).get("seconds"))
        ratio = b["relmse"] * tb / (r["relmse"] * t) if b and r["relmse"] > 0 else float("nan")
        ratio_r = b["relmse_region"] * tb / (r["relmse_region"] * t) if b and r["relmse_region"] > 0 else float("nan")
        r["efficiency_vs_path"], r["efficiency_vs_path_region"] = ratio, ratio_r
        lines.append(f"{r['scene']:22s} {r['contender']:20s} {r['seconds']:5.1f} {r['spp']:7.0f} {r['relmse']:10.3e} "
                     f"{ratio:7.2f} {r['relmse_region']:10.3e} {ratio_r:7.2f} {r['floor']:9.1e}")
    return "\n".join(lines)


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    fig, axes = plt.subplots(1, len(scenes), figsize=(5 * len(scenes), 4), squeeze=False)
    for ax, sc in zip(axes[0], scenes):
        for c in dict.fromkeys(r["contender"] for r in rows if r["scene"] == sc):
            pts = sorted((r.get("time", r["seconds"]), r["relmse"]) for r in rows
                         if r["scene"] == sc and r["contender"] == c)
            pts = [p for p in pts if p[1] > 0]
            if pts:
                ax.loglog(*zip(*pts), "o-", label=c)
        ax.set_title(sc)
        ax.set_xlabel("CPU seconds" if rows[0].get("clock") == "cpu" else "seconds")
        ax.set_ylabel("relMSE (reference floor removed)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(str(path), dpi=100)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", choices=["scenes", "mis", "all"], default="all")
    ap.add_argument("--seconds", type=float, nargs="+", default=[2.0, 4.0, 8.0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--out", type=Path, default=record.RESULTS, help="folder of the results")
    ap.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                    help="budgets in wall-clock seconds (default) or in this process's CPU seconds")
    ap.add_argument("--scenes", nargs="+", help="only these scenes of the part")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    for part in (["scenes", "mis"] if a.part == "all" else [a.part]):
        print(f"== part {part}: budgets {a.seconds} {a.clock} s, {a.seeds} seeds, "
              f"threads {a.threads or os.cpu_count()}")
        rows = run(part, a.seconds, a.seeds, a.threads, clock=a.clock, only=a.scenes)
        if not rows:
            continue
        print(table(rows, part))
        stem = "_".join([f"bdpt_efficiency_{part}"] + sorted(a.scenes or []) + ([a.clock] if a.clock != "wall" else []))
        out = record.write(stem, dict(record.params_of(a), part=part),
                           {"threads_used": a.threads or os.cpu_count(), "rows": rows}, out=a.out / f"{stem}.json",
                           plot=lambda png, rows=rows: plot(rows, png))
        print(f"wrote {out} and the .png beside it")


if __name__ == "__main__":
    main()
