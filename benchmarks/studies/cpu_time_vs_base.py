"""Performance benchmark (not a test): CPU time per render of this tree's
renderer against a build of an earlier commit, side by side on the same
machine, interleaved (A B A B ...) so that load from other processes hits
both alike. Our estimators on the Cornell box (256 x 256, 16 spp, max_depth
8, one thread by default).

    python -m radiometer.benchmarks.studies.cpu_time_vs_base --base /path/to/base/pkg \
        [--integrators path,bdpt] [--repeats 7] [--study NAME]

`--base` is a folder holding the earlier commit's `radiometer` package with
its compiled `_core` module next to its Python files (e.g. `git archive
<commit>` unpacked, `cmake --build` of its `_core` target, the .so copied
into bindings/radiometer, analysis/ benchmarks/ reference_scenes/ copied
inside it as the wheel lays them out). Each timed render runs in a fresh
process (scene load and first-touch costs excluded: the process loads the
scene, renders once untimed at 1 spp, then times one render). Reports, per
estimator, the median of each side and their ratio (this tree / base), and
writes benchmarks/results/<study>.json. Also says whether the two builds
give the same image bytes for the same seed.

`--instructions` counts instructions instead (valgrind's cachegrind, one
run per side and budget, no repeats needed: the count does not depend on
the machine's load): each side renders at 1 spp and at 1 + spp, and the
difference, the instructions of `spp` samples per pixel, is compared; the
1 spp runs' totals (imports, scene load, photon maps) are reported beside
it. Use a small --res (32): valgrind runs about 50 times slower. The
count is not exactly repeatable (threads that wait, Embree's among them,
count what they spin): the same build measured 1.614e9 and 1.524e9
instructions for sppm's 8 spp in two runs, and photonmapper without final
gathering 3.61e8 and 3.74e8, so a ratio within a few percent of 1 needs
repeats. `--settings` merges parameters into an estimator's (e.g. final
gathering off).

`--render-only` (with --instructions) counts only the render itself:
valgrind's callgrind with collection switched on inside rm::render and
the render's worker threads (the Python interpreter, the scene load and
the poll callback left out), so the count no longer depends on threads
that wait or on how long the machine took; the same build measured to
within 0.004 % over 3 repeats (sppm on the Cornell box, 8 spp; 0.02 %
photonmapper). The render
then runs at 1 and at 1 + spp in fresh processes (each after an untimed
1 spp render), and the difference is the samples' count. Both packages
need their symbols (an unstripped build, e.g. CMake's RelWithDebInfo,
whose -O3 is the same code as the release build): pass this tree's as
--this. `--repeats` runs per side; the minimum and the spread are
reported.

Studies recorded with it: `media_free_when_absent` (path only: media
support must cost nothing in a scene without media) and
`plumbing_cpu_time` (every estimator across the registry / pass-loop /
light-walk refactor); `sppmperf2_sppm`, `sppmperf2_photonmapper_nofg`
and `sppmperf2_photonmapper_fg` (--render-only against 19af56f, the
commit before that refactor).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

from radiometer.benchmarks.studies import record
from radiometer.reference_scenes import registry

SCENE = registry.get("cornell_box").xml

CHILD = r"""
import sys, time, hashlib, json
base = sys.argv[1]
if base != "-":
    # Run the base package: drop this environment's editable finder so the
    # import resolves to `base` first.
    sys.meta_path = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
    sys.path.insert(0, base)
import numpy as np
import radiometer as rm
scene = rm.load_file(sys.argv[2], res=int(sys.argv[3]))
integ = json.loads(sys.argv[7])
rm.render(scene, integrator=integ, spp=1, seed=0)
threads = int(sys.argv[6])
t0, c0 = time.perf_counter(), time.process_time()
r = rm.render(scene, integrator=integ, spp=int(sys.argv[4]), seed=1, threads=threads)
dt, dc = time.perf_counter() - t0, time.process_time() - c0
print(dt, dc, hashlib.sha256(np.ascontiguousarray(r.image).tobytes()).hexdigest(), rm.__file__)
"""


# Estimator settings for the timing (photon counts sized like the default matrix's).
SETTINGS = {"photonmapper": {"global_photons": 50000, "caustic_photons": 50000},
            "sppm": {"photon_count": 20000}}
# Estimators without a max_depth parameter (one bounce by construction).
DEPTHLESS = {"direct"}


def _run(base, res, spp, max_depth, threads, integrator="path"):
    spec = dict(SETTINGS.get(integrator, {}), type=integrator)
    if integrator not in DEPTHLESS:
        spec["max_depth"] = max_depth
    spec = json.dumps(spec)
    out = subprocess.run([sys.executable, "-c", CHILD, base, str(SCENE), str(res), str(spp), str(max_depth),
                          str(threads), spec], capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), float(out[1]), out[2], out[3]


def _instructions(base, res, spp, max_depth, integrator):
    """Instructions of the whole child process under cachegrind."""
    import re
    import tempfile

    spec = dict(SETTINGS.get(integrator, {}), type=integrator)
    if integrator not in DEPTHLESS:
        spec["max_depth"] = max_depth
    with tempfile.NamedTemporaryFile(suffix=".cg") as tmp:
        out = subprocess.run(["valgrind", "--tool=cachegrind", "--cache-sim=no", f"--cachegrind-out-file={tmp.name}",
                              sys.executable, "-c", CHILD, base, str(SCENE), str(res), str(spp), str(max_depth),
                              "1", json.dumps(spec)], capture_output=True, text=True, check=True,
                             env=dict(os.environ, PYTHONHASHSEED="0"))  # the same Python work in every run
    m = re.search(r"I\s+refs:\s+([\d,]+)", out.stderr)
    if not m:
        raise RuntimeError(f"no instruction count in valgrind's output: {out.stderr[-500:]}")
    return int(m.group(1).replace(",", "")), out.stdout.split()[2]


# The render's own instructions: collection on inside rm::render (the
# calling thread) and the worker threads, off inside the poll callback.
CALLGRIND_RENDER = ["--collect-atstart=no", "--toggle-collect=rm::render(*",
                    "--toggle-collect=std::thread::_State_impl*_M_run*",
                    "--toggle-collect=std::_Function_handler<bool (unsigned long, unsigned long)*_M_invoke*"]


def _render_instructions(pkg, res, spp, max_depth, integrator):
    """Instructions of the render alone (callgrind, CALLGRIND_RENDER)."""
    import re
    import tempfile

    spec = dict(SETTINGS.get(integrator, {}), type=integrator)
    if integrator not in DEPTHLESS:
        spec["max_depth"] = max_depth
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run(["valgrind", "--tool=callgrind", *CALLGRIND_RENDER,
                              f"--callgrind-out-file={tmp}/cg.out", sys.executable, "-c", CHILD, pkg, str(SCENE),
                              str(res), str(spp), str(max_depth), "1", json.dumps(spec)],
                             capture_output=True, text=True, check=True, env=dict(os.environ, PYTHONHASHSEED="0"))
    m = re.search(r"Collected\s*:\s*(\d+)", out.stderr)
    if not m:
        raise RuntimeError(f"no instruction count in valgrind's output: {out.stderr[-500:]}")
    return int(m.group(1)), out.stdout.split()[2]


def _measure_render_instructions(a, integrator):
    from concurrent.futures import ThreadPoolExecutor

    sides = (("this", a.this), ("base", a.base))
    jobs = [(side, pkg, n, i) for i in range(a.repeats) for side, pkg in sides for n in (1, 1 + a.spp)]
    with ThreadPoolExecutor(max(1, a.jobs)) as ex:
        counts = list(ex.map(lambda j: (j, _render_instructions(j[1], a.res, j[2], a.max_depth, integrator)), jobs))
    row = {}
    for side, _ in sides:
        lo = [c for (s, _, n, _), (c, _) in counts if s == side and n == 1]
        hi = [c for (s, _, n, _), (c, _) in counts if s == side and n != 1]
        hashes = sorted({h for (s, _, n, _), (_, h) in counts if s == side and n != 1})
        samples = [h - lo_ for lo_, h in zip(lo, hi)]
        row[side] = {"render_1spp": lo, "render": hi, "samples": samples, "min": min(samples),
                     "spread": (max(samples) - min(samples)) / min(samples), "hash": hashes}
        print(f"{integrator:12s} {side:4s} render instructions of {a.spp} spp: min {min(samples):,}, "
              f"spread {row[side]['spread']:.2e} over {len(samples)}", flush=True)
    ratio = row["this"]["min"] / row["base"]["min"]
    print(f"{integrator}: render instructions per sample this / base {ratio:.4f}", flush=True)
    return {"render_instructions": row, "ratio_samples_this_over_base": ratio,
            "same_image_bytes": row["this"]["hash"] == row["base"]["hash"]}


def _measure_instructions(a, integrator):
    row = {}
    for side, base in (("this", "-"), ("base", a.base)):
        lo, _ = _instructions(base, a.res, 1, a.max_depth, integrator)
        hi, h = _instructions(base, a.res, 1 + a.spp, a.max_depth, integrator)
        row[side] = {"total_1spp": lo, "total": hi, "samples": hi - lo, "hash": h}
        print(f"{integrator:12s} {side:4s} instructions: 1 spp run {lo:,}, {1 + a.spp} spp run {hi:,}, "
              f"{a.spp} spp of samples {hi - lo:,}", flush=True)
    ratio = row["this"]["samples"] / row["base"]["samples"]
    ratio_setup = row["this"]["total_1spp"] / row["base"]["total_1spp"]
    print(f"{integrator}: instructions per sample this / base {ratio:.4f}; whole 1 spp run {ratio_setup:.4f}",
          flush=True)
    return {"instructions": row, "ratio_samples_this_over_base": ratio, "ratio_1spp_run_this_over_base": ratio_setup,
            "same_image_bytes": row["this"]["hash"] == row["base"]["hash"]}


def _measure(a, integrator):
    times = {"this": [], "base": []}
    cpu = {"this": [], "base": []}
    hashes, files = {}, {}
    for i in range(a.repeats):
        for side, base in (("base", a.base), ("this", "-")) if i % 2 else (("this", "-"), ("base", a.base)):
            dt, dc, h, f = _run(base, a.res, a.spp, a.max_depth, a.threads, integrator)
            times[side].append(dt)
            cpu[side].append(dc)
            hashes[side], files[side] = h, f
            print(f"{integrator:12s} {side:4s} wall {dt:.3f} s, cpu {dc:.3f} s  ({f})", flush=True)
    assert files["this"] != files["base"], "both sides imported the same package"
    med = {k: statistics.median(v) for k, v in times.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    ratio, ratio_cpu = med["this"] / med["base"], med_cpu["this"] / med_cpu["base"]
    same = hashes["this"] == hashes["base"]
    print(f"{integrator}: median wall this {med['this']:.3f} s, base {med['base']:.3f} s, ratio {ratio:.3f}; "
          f"median cpu this {med_cpu['this']:.3f} s, base {med_cpu['base']:.3f} s, ratio {ratio_cpu:.3f}; "
          f"same image bytes: {same}")
    return {"seconds": times, "cpu_seconds": cpu, "median_s": med, "median_cpu_s": med_cpu,
            "ratio_this_over_base": ratio, "ratio_cpu_this_over_base": ratio_cpu, "same_image_bytes": same}


TIMING_SECONDS = ("wall seconds (time.perf_counter) and process CPU seconds (time.process_time, all threads) of "
                  "one render per fresh process, after an untimed 1 spp render; sides interleaved")
TIMING_RENDER = ("instructions of the render alone (valgrind callgrind, collection on inside rm::render and its "
                 "worker threads, off in the poll callback) at 1 and 1 + spp spp, fresh processes; the difference "
                 "is the samples' cost; min over repeats")
TIMING_INSTRUCTIONS = ("instructions (valgrind cachegrind) of the child process at 1 and 1 + spp spp; the "
                       "difference is the samples' cost")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="folder with the earlier commit's radiometer package")
    ap.add_argument("--base-commit", default="", help="the earlier commit's hash, for the record")
    ap.add_argument("--integrators", default="path", help="comma-separated estimators (default: path)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--max-depth", type=int, default=8)
    ap.add_argument("--threads", type=int, default=1,
                    help="render threads (default 1: on a loaded shared machine one thread's CPU time is the "
                         "steadiest measure)")
    ap.add_argument("--study", default="cpu_time_vs_base", help="the results file's name")
    ap.add_argument("--out", default=None)
    ap.add_argument("--instructions", action="store_true",
                    help="count instructions under valgrind instead of timing (load-independent)")
    ap.add_argument("--render-only", action="store_true",
                    help="with --instructions: count the render alone (callgrind; packages with symbols)")
    ap.add_argument("--this", default="-",
                    help="this tree's package folder (default: the installed one); --render-only needs symbols")
    ap.add_argument("--jobs", type=int, default=2, help="--render-only: valgrind runs at once")
    ap.add_argument("--settings", default=None,
                    help='JSON object of estimator parameters merged into the defaults above, e.g. '
                         '\'{"photonmapper": {"final_gather": false}}\'')
    a = ap.parse_args(argv)
    for name, extra in json.loads(a.settings or "{}").items():
        SETTINGS[name] = dict(SETTINGS.get(name, {}), **extra)
    measure = _measure_instructions if a.instructions else _measure
    if a.instructions and a.render_only:
        measure = _measure_render_instructions
    rows = {name: measure(a, name) for name in a.integrators.split(",")}
    params = {"res": a.res, "spp": a.spp, "max_depth": a.max_depth, "repeats": a.repeats,
              "instructions": a.instructions, "render_only": a.render_only, "this": a.this,
              "integrators": list(rows), "threads": a.threads, "base": a.base, "base_commit": a.base_commit,
              "settings": {k: SETTINGS.get(k, {}) for k in rows}}
    rec = {
        "scene": "reference_scenes/cornell_box/scene.xml",
        "timing": (TIMING_RENDER if a.render_only else TIMING_INSTRUCTIONS) if a.instructions else TIMING_SECONDS,
        "estimators": rows,
    }
    print("wrote", record.write(a.study, params, rec, out=a.out))


if __name__ == "__main__":
    main()
