"""Performance measurement (not a test): the majorant grid of grid media
(renderer/scene/medium.h). Delta tracking and (residual) ratio tracking per
cell of a coarse grid of local majorants, against one global majorant per
channel (a gridvolume's `accel` = false, the code path of the renderer
before the majorant grid: same image bytes as that build).

Two scenes, each rendered with accel = true and accel = false:
- sparse: reference_scenes/stress/media_grid_sparse.xml (8^3, spikes of
  100 in an almost empty grid);
- smooth: the same set-up with a smooth 32^3 grid (a Gaussian blob, peak
  4, plus low-frequency ripples), written next to a copy of the scene.
Per estimator (volpath, bdpt), 32 x 32, one thread, each timed render in a
fresh process, the variants interleaved (A B A B ...) so that load from
other processes hits both alike. Reported: sigma_t lookups (tentative
collisions of delta and ratio tracking) per sample, and seconds per spp
(wall and CPU, medians). With --base (a folder holding an earlier build's
`radiometer` package with its compiled _core), that build is timed too
(accel is then ignored by it: always the global majorant).

    python -m radiometer.benchmarks.studies.majorant_grid [--spp 64] [--repeats 5] [--base DIR]

Writes benchmarks/results/majorant_grid.json (the studies' layout,
studies/record.py) and prints a table.
"""
from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from radiometer.benchmarks.studies import record

STRESS = record.REPO / "reference_scenes" / "stress"

CHILD = r"""
import sys, time
base = sys.argv[1]
if base != "-":
    sys.meta_path = [f for f in sys.meta_path if "editable" not in repr(f).lower() and "skbc" not in repr(f)]
    sys.path.insert(0, base)
import numpy as np
import radiometer as rm
from radiometer import _core
scene = rm.load_file(sys.argv[2])
est, spp = sys.argv[3], int(sys.argv[4])
rm.render(scene, integrator=est, spp=1, seed=0, threads=1)
has_counter = hasattr(_core, "medium_tracking_lookups")
if has_counter:
    _core.reset_medium_tracking_lookups()
t0, c0 = time.perf_counter(), time.process_time()
r = rm.render(scene, integrator=est, spp=spp, seed=1, threads=1)
dt, dc = time.perf_counter() - t0, time.process_time() - c0
n = _core.medium_tracking_lookups() if has_counter else -1
print(dt, dc, n, r.image.shape[0] * r.image.shape[1], float(r.image.mean()))
"""


def _smooth_grid(n=32):
    z, y, x = np.meshgrid(*(((np.arange(n) + 0.5) / n) for _ in range(3)), indexing="ij")
    r2 = (x - 0.5) ** 2 + (y - 0.5) ** 2 + (z - 0.5) ** 2
    g = 4.0 * np.exp(-r2 / (2 * 0.18 ** 2)) * (1.0 + 0.3 * np.sin(7 * x) * np.cos(5 * y))
    return np.clip(g, 0, None).astype(np.float32)[..., None].repeat(3, axis=-1) * np.array([1.0, 0.8, 0.6], np.float32)


def _scenes(tmp: Path):
    """{(scene, variant): xml path}; variant 'grid' (accel true) or 'global'."""
    from radiometer.loader import write_vol

    xml = (STRESS / "media_grid_sparse.xml").read_text()
    shutil.copy(STRESS / "media_grid_sparse.vol", tmp / "media_grid_sparse.vol")
    write_vol(tmp / "smooth.vol", _smooth_grid())
    out = {}
    for scene, vol in (("sparse", "media_grid_sparse.vol"), ("smooth", "smooth.vol")):
        for variant, accel in (("grid", "true"), ("global", "false")):
            s = xml.replace('value="media_grid_sparse.vol"', f'value="{vol}"')
            s = s.replace('<boolean name="use_grid_bbox" value="true"/>',
                          '<boolean name="use_grid_bbox" value="true"/>'
                          f'<boolean name="accel" value="{accel}"/>')
            if vol == "smooth.vol":  # the .vol's own box is the unit cube at 0..1: centre it in the null cube
                s = s.replace('<boolean name="use_grid_bbox" value="true"/>',
                              '<transform name="to_world"><translate x="-0.5" y="-0.5" z="-0.5"/></transform>')
            p = tmp / f"{scene}_{variant}.xml"
            p.write_text(s)
            out[(scene, variant)] = p
    return out


def _run(base, xml, est, spp):
    out = subprocess.run([sys.executable, "-c", CHILD, base, str(xml), est, str(spp)],
                         capture_output=True, text=True, check=True).stdout.split()
    return {"wall": float(out[0]), "cpu": float(out[1]), "lookups": int(out[2]), "pixels": int(out[3]),
            "mean": float(out[4])}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--estimators", default="volpath,bdpt")
    ap.add_argument("--base", default=None, help="folder with an earlier build's radiometer package")
    ap.add_argument("--out", default=str(record.default_path("majorant_grid")))
    a = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="majorant_grid_"))
    xmls = _scenes(tmp)
    variants = [("grid", "-"), ("global", "-")] + ([("base", a.base)] if a.base else [])
    rows = []
    for scene in ("sparse", "smooth"):
        for est in a.estimators.split(","):
            runs = {v: [] for v, _ in variants}
            for _ in range(a.repeats):
                for v, base in variants:  # interleaved
                    xml = xmls[(scene, "global" if v == "base" else v)]
                    runs[v].append(_run(base, xml, est, a.spp))
            for v, _ in variants:
                rs = runs[v]
                samples = rs[0]["pixels"] * a.spp
                rows.append({
                    "scene": scene, "estimator": est, "variant": v,
                    "lookups_per_sample": None if rs[0]["lookups"] < 0 else rs[0]["lookups"] / samples,
                    "wall_s_per_spp": statistics.median(r["wall"] for r in rs) / a.spp,
                    "cpu_s_per_spp": statistics.median(r["cpu"] for r in rs) / a.spp,
                    "image_mean": rs[0]["mean"], "wall_s": [r["wall"] for r in rs],
                })
    result = {
        "what": "majorant grid (accel true) vs one global majorant (accel false) for grid media",
        "resolution": "32x32", "threads": 1, "rows": rows,
    }
    record.write("majorant_grid", record.params_of(a), result, out=a.out)
    print(f"{'scene':7} {'estimator':9} {'variant':7} {'lookups/sample':>14} {'ms/spp wall':>12} {'ms/spp cpu':>11}"
          f" {'speed-up':>8} {'mean':>8}")
    for r in rows:
        ref = next(x for x in rows if x["scene"] == r["scene"] and x["estimator"] == r["estimator"]
                   and x["variant"] == "global")
        lk = "-" if r["lookups_per_sample"] is None else f"{r['lookups_per_sample']:.2f}"
        print(f"{r['scene']:7} {r['estimator']:9} {r['variant']:7} {lk:>14} {1e3 * r['wall_s_per_spp']:12.3f}"
              f" {1e3 * r['cpu_s_per_spp']:11.3f} {ref['cpu_s_per_spp'] / r['cpu_s_per_spp']:8.2f}"
              f" {r['image_mean']:8.4f}")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
