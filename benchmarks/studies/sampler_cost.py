"""Performance benchmark (not a test): what each sampler costs per sample of
`path`, against the independent stream and, optionally, against another
build of the renderer (docs/samplers.md, "Cost per sample").

    python -m radiometer.benchmarks.studies.sampler_cost [--base OLD_CORE.so]
        [--scenes cornell_box,veach_mis,glass_sphere_caustic,fog_room]
        [--samplers independent,stratified,multijitter,sobol,zsobol]
        [--res 64] [--spp 16] [--rounds 4] [--reps 2] [--instructions]

Samples per CPU second (the process's CPU time: one render thread, and
less sensitive than wall time to other jobs on a shared machine, though
not immune: caches and memory are shared). Each round runs one child
process per build (this
tree's `_core` and --base's, their order alternating between rounds), which
loads every scene (res x res, box filter where the scene names a filter;
the scene's own integrator: `path`, `volpath` on fog_room), renders once
untimed, then renders every sampler `reps` times (one thread, seeds 1..)
interleaved; reported: the median samples per CPU second of each (build,
scene, sampler), each sampler's over independent's of the same build (the
same processes, so the machine's load hits both alike), and this tree's
over the base's.

--instructions: instructions instead of seconds (valgrind callgrind, one
run per build, scene and sampler at --cg-res and --cg-spp, independent of
the machine's load): per sample, the render's (the camera rays, their
packets and the estimator's paths, inclusive) and the structured source's
share of them (PixelSampleSource::get_1d and get_2d, inclusive).

Writes benchmarks/results/sampler_cost.json (studies/record.py).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from radiometer.benchmarks.studies import record

SCENES = "cornell_box,veach_mis,glass_sphere_caustic,fog_room"
SAMPLERS = "independent,stratified,multijitter,sobol,zsobol"

# The child: loads `so` as radiometer._core (before the package imports its
# own), then times or runs the renders it is told to.
CHILD = r"""
import importlib.util, json, sys, time
so, mode, scenes, samplers, res, spp, reps = sys.argv[1:8]
if so != "-":
    spec = importlib.util.spec_from_file_location("radiometer._core", so)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    sys.modules["radiometer._core"] = mod
import radiometer as rm
from radiometer.reference_scenes import registry
res, spp, reps = int(res), int(spp), int(reps)
out = {}
for name in scenes.split(","):
    xml = registry.get(name).xml
    params = {"res": res, **({"rfilter": "box"} if 'name="rfilter"' in xml.read_text() else {})}
    scene = rm.load_file(xml, **params)
    if mode == "time":
        rm.render(scene, spp=1, seed=99, threads=1)
    for k in range(reps):
        for s in samplers.split(","):
            t0 = time.process_time()
            rm.render(scene, spp=spp, seed=1 + k, threads=1, sampler=s)
            out.setdefault(name, {}).setdefault(s, []).append(res * res * spp / (time.process_time() - t0))
print(json.dumps(out))
"""

# The render's work per sample, and the structured source's (callgrind's
# inclusive counts, by function name).
RENDER_FNS = r"^rm::\w*Integrator::sample_from_hit\(|^rm::\w*Integrator::sample\(|^rm::sample_camera_ray\(|" \
             r"^rm::Scene::intersect_packet\("
SOURCE_FNS = r"^rm::PixelSampleSource::get_(1|2)d\("


def _child(so, mode, scenes, samplers, res, spp, reps, wrap=()):
    cmd = [*wrap, sys.executable, "-c", CHILD, so, mode, scenes, samplers, str(res), str(spp), str(reps)]
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"child failed: {out.stderr[-2000:]}")
    return out


def _inclusive(path):
    text = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", str(path)],
                          capture_output=True, text=True, check=True).stdout
    fns = {}
    for line in text.splitlines():
        m = re.match(r"\s*([\d,]+) \(.*?\)\s+\S*?:(.*?) \[", line)
        if m:
            fns[m.group(2)] = fns.get(m.group(2), 0) + int(m.group(1).replace(",", ""))
    return fns


def instructions(builds, scenes, samplers, res, spp):
    rows = []
    for label, so in builds.items():
        for name in scenes:
            for s in samplers:
                with tempfile.TemporaryDirectory() as tmp:
                    cg = Path(tmp) / "cg.out"
                    _child(so, "count", name, s, res, spp, 1,
                           wrap=("valgrind", "--tool=callgrind", f"--callgrind-out-file={cg}"))
                    fns = _inclusive(cg)
                n = res * res * spp
                total = sum(v for k, v in fns.items() if re.search(RENDER_FNS, k))
                source = sum(v for k, v in fns.items() if re.search(SOURCE_FNS, k))
                rows.append({"build": label, "scene": name, "sampler": s, "instructions_per_sample": round(total / n),
                             "source_instructions_per_sample": round(source / n)})
                print(f"{label:5s} {name:22s} {s:12s} {total / n:9.0f} per sample, source {source / n:7.0f}",
                      flush=True)
    return rows


def timings(builds, scenes, samplers, res, spp, rounds, reps):
    acc = {label: {} for label in builds}
    labels = list(builds)
    for r in range(rounds):
        for label in (labels if r % 2 == 0 else labels[::-1]):
            out = _child(builds[label], "time", ",".join(scenes), ",".join(samplers), res, spp, reps)
            for name, per in json.loads(out.stdout.strip().splitlines()[-1]).items():
                for s, v in per.items():
                    acc[label].setdefault(name, {}).setdefault(s, []).extend(v)
        print(f"round {r + 1}/{rounds} done", flush=True)
    rows = []
    for name in scenes:
        for s in samplers:
            row = {"scene": name, "sampler": s}
            for label in labels:
                med = statistics.median(acc[label][name][s])
                row[f"{label}_samples_per_s"] = round(med)
                if "independent" in acc[label][name]:
                    base = statistics.median(acc[label][name]["independent"])
                    row[f"{label}_over_independent"] = round(med / base, 3)
            if "base" in builds:
                row["this_over_base"] = round(row["this_samples_per_s"] / row["base_samples_per_s"], 3)
            rows.append(row)
            print("  ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="another build's _core .so to compare against (e.g. main's, saved aside)")
    ap.add_argument("--scenes", default=SCENES)
    ap.add_argument("--samplers", default=SAMPLERS)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--instructions", action="store_true", help="callgrind instruction counts instead of seconds")
    ap.add_argument("--cg-res", type=int, default=32)
    ap.add_argument("--cg-spp", type=int, default=16)
    ap.add_argument("-o", "--out")
    a = ap.parse_args(argv)
    builds = {"this": "-"}
    if a.base:
        builds["base"] = os.path.abspath(a.base)
    scenes, samplers = a.scenes.split(","), a.samplers.split(",")
    if a.instructions:
        results = {"instructions": instructions(builds, scenes, samplers, a.cg_res, a.cg_spp)}
    else:
        results = {"timings": timings(builds, scenes, samplers, a.res, a.spp, a.rounds, a.reps)}
    print("wrote", record.write("sampler_cost", record.params_of(a), results, out=a.out))


if __name__ == "__main__":
    main()
