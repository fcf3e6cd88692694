"""Runs a benchmark matrix: a local process pool by default, or a Dask
distributed cluster (`scheduler=ADDRESS`), with the same job function.

Each job loads its scene, renders it with its estimator and budget (keeping
power-of-two checkpoints for the error-against-time curve), measures every
metric of analysis/metrics.py against the scene's reference, per effect
class against the per-effect reference, writes its EXR and returns one
record; the parent inserts it in the store at once (one transaction per
job). A job whose scene or estimator refuses the combination (SceneError /
ValueError) is recorded as "unsupported" with the message; any other
exception as "failed" with its traceback; a worker process that dies takes
only the jobs it was running (each retried once) and the rest go on.
"""
from __future__ import annotations

import datetime as _dt
import os
import platform
import socket
import subprocess
import sys
import time
import traceback
import uuid
from pathlib import Path
from typing import Optional

from radiometer.analysis import verdict as _verdict
from radiometer.reference_scenes import references as _references
from radiometer.reference_scenes import registry as _scenes

from . import effect_refs as _effect_refs
from . import matrix as _matrix
from .store import Store

REPO = Path(__file__).resolve().parents[1]
DEFAULT_ROOT = Path("out") / "results"
STORE_NAME = "bench.sqlite"
# Arrays of res.arrays kept beside a job's EXR as .npy (the report draws them).
RECORD_ARRAYS = ("irrcache_records", "radcache_records")


def now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def commit_id() -> str:
    """`git describe`-like: the commit hash, "-dirty" when the tree has edits."""
    try:
        h = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                           text=True, timeout=10).stdout.strip()
        if not h:
            return "unknown"
        dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return h + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def cpu_name() -> str:
    """The CPU's model name (Linux /proc/cpuinfo; else platform's guess)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or ""


def machine_info() -> dict:
    import radiometer

    return {"host": socket.gethostname(), "cpu": cpu_name(), "cores": os.cpu_count(), "system": platform.system(),
            "release": platform.release(), "python": platform.python_version(), "radiometer": radiometer.__version__}


def _budget_label(b: dict) -> str:
    return f"{b['spp']}spp" if "spp" in b else f"{b['seconds']:g}s"


def run_job(job: dict, root: str, run_id: str, commit: str, machine: dict) -> dict:
    """Runs one job (a Job.to_dict()) and returns its record. Never raises
    for a job's own failure: that is what the record's status says."""
    t_start = time.time()
    rec = dict(job, status="ok", error=None, commit=commit, machine=machine, worker_pid=os.getpid(),
               started=now(), metrics={}, effect_metrics={}, curve=[], exr=None)
    try:
        _run_job(job, rec, Path(root), run_id)
    except Exception as e:  # a job's failure is data; keep going
        unsupported = rec.get("_stage") in ("load", "render") and isinstance(e, ValueError)
        rec["status"] = "unsupported" if unsupported else "failed"
        rec["error"] = f"{type(e).__name__}: {e}" if unsupported else traceback.format_exc(limit=8)
    rec.pop("_stage", None)
    rec["finished"] = now()
    rec["wall_seconds"] = time.time() - t_start
    return rec


def _run_job(job, rec, root: Path, run_id: str):
    import numpy as np

    import radiometer as rm
    from radiometer.analysis import metrics as M

    spec = _scenes.get(job["scene"])
    rec["_stage"] = "load"
    scene = rm.load_file(spec.xml, **job["scene_params"])
    rec["_stage"] = "render"
    b = job["budget"]
    res = rm.render(scene, integrator=job["integrator"], spp=b.get("spp"), seconds=b.get("seconds"),
                    seed=job["seed"], threads=job["threads"],
                    checkpoints=True if job.get("checkpoints", True) else None, effect_variance=True)
    rec["_stage"] = "metrics"
    rec["spp"], rec["seconds"] = int(res.spp), float(res.seconds)
    rec["stats"] = {k: v for k, v in res.stats.items() if isinstance(v, (int, float, str, bool))}
    ref = _references.reference(job["scene"], job["scene_params"], job.get("effect_ref"))
    rec["reference"] = {"kind": ref.kind, "effects": job.get("effect_note") or ref.effects_kind, "spp": ref.spp}
    if ref.image.shape != res.image.shape:
        raise ValueError(f"reference shape {ref.image.shape} differs from the render's {res.image.shape}")
    m = {}
    for name in M.METRICS:
        try:
            m[name] = M.all_metrics(res.image, ref.image, which=(name,))[name]
        except Exception as e:  # e.g. FLIP on a 1 x 1 film: record why, keep the others
            m[name] = None
            rec.setdefault("metric_errors", {})[name] = f"{type(e).__name__}: {e}"
    if ref.variance is not None:
        m["relmse_floor"] = M.relmse_floor(ref.image, ref.variance)
    m["relmse_noise"] = _verdict.noise_relmse(res.variance, ref.image)
    # Image means per channel (the error budget's terms of the image mean,
    # and the matrix's seeds against the reference: verdict.matrix_terms).
    m["image_mean"] = [float(x) for x in np.asarray(res.image, np.float64).reshape(-1, 3).mean(axis=0)]
    ref_px = np.asarray(ref.image, np.float64).reshape(-1, 3)
    m["reference_mean"] = [float(x) for x in ref_px.mean(axis=0)]
    m["reference_mean_se"] = (None if ref.variance is None else
                              [float(x) for x in np.sqrt(np.asarray(ref.variance, np.float64).reshape(-1, 3)
                                                         .sum(axis=0)) / ref_px.shape[0]])
    if spec.model_of:
        rec["model_of"] = spec.model_of
    # Convergence: relMSE at each checkpoint against the same reference.
    curve = M.error_curve(res.checkpoints, ref.image, "relmse") if res.checkpoints else []
    rec["curve"] = curve
    m["slope"] = M.loglog_slope([c[1] for c in curve], [c[2] for c in curve])
    target = job.get("target_relmse")
    m["time_to_target"] = M.time_to_error(curve, target) if target else None
    m["efficiency"] = M.efficiency(m.get("relmse"), rec["seconds"])
    rec["metrics"] = m
    rec["verdict"] = _verdict.verdict(rec, target or _matrix.DEFAULT_TARGET_RELMSE)
    # Per effect class, against the per-effect reference (where there is one).
    em = {}
    if ref.effects is not None:
        exposure = M.display_exposure(ref.image)
        zero = np.zeros_like(ref.image)
        for eff in rm.EFFECTS:
            mine = res.effects.get(eff)
            theirs = ref.effects.get(eff)
            mine = zero if mine is None else np.asarray(mine, np.float64)
            theirs = zero if theirs is None else np.asarray(theirs, np.float64)
            if not (np.any(mine != 0) or np.any(theirs != 0)):
                continue
            d = {"relmse": M.relmse(mine, theirs), "mse": M.mse(mine, theirs), "smape": M.smape(mine, theirs)}
            for name in ("flip", "ciede2000"):
                try:
                    d[name] = float(M.metric(name)(mine, theirs, exposure=exposure))
                except Exception:
                    d[name] = None
            d["reference_mean"] = float(theirs.mean())
            d["mean"] = float(mine.mean())
            # The effect's noise term, from its own per-pixel variance (camera estimators' films keep it).
            ev = (res.effect_variance or {}).get(eff)
            d["noise"] = None if ev is None else _verdict.noise_relmse(ev, theirs)
            em[eff] = d
    rec["effect_metrics"] = em
    # The render itself, with every effect layer.
    rel = Path("runs") / run_id / job["scene"] / f"{job['estimator']}-{_budget_label(b)}-s{job['seed']}.exr"
    out = root / rel
    out.parent.mkdir(parents=True, exist_ok=True)
    budget = dict(res.error_budget, target_relmse=rec["verdict"]["target"] if rec["verdict"] else None,
                  terms=rec["verdict"]["terms"] if rec["verdict"] else None, terms_how=_verdict.TERM_HOW,
                  effect_noise_relmse={e: d.get("noise") for e, d in em.items()})
    rec["error_budget"] = budget
    # The rest of the verdict's terms come from the render's own budget (truncation, discretisation).
    if rec["verdict"]:
        rec["verdict"] = _verdict.verdict(rec, rec["verdict"]["target"])
        budget["terms"] = rec["verdict"]["terms"]
    layers = {k: res.arrays[k] for k in ("radius_bias",) if k in (res.arrays or {})}
    from radiometer.exr import write_exr

    write_exr(out, res, scene=job["scene"], run_id=run_id, job_key=job["key"], error_budget=budget,
              layers=layers or None)
    rec["exr"] = str(rel)
    # A cache's records (irrcache, radcache: one row per record), beside the
    # EXR, for the report's view of them.
    saved = {}
    for k in RECORD_ARRAYS:
        a = (res.arrays or {}).get(k)
        if a is not None and np.ndim(a) == 2 and len(a):
            npy = rel.with_name(f"{rel.stem}.{k}.npy")
            np.save(root / npy, np.asarray(a, np.float64))
            saved[k] = {"npy": str(npy), "rows": int(len(a)), "columns": list(res.stats.get(f"{k}_columns") or [])}
    if saved:
        rec["arrays"] = saved


# -- executors ----------------------------------------------------------------


class _LocalPool:
    """concurrent.futures process pool (spawn: the parent has render threads)."""

    def __init__(self, workers):
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        self.ex = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"))

    def submit(self, fn, *args):
        return self.ex.submit(fn, *args)

    def wait_any(self, futures):
        from concurrent.futures import FIRST_COMPLETED, wait

        done, _ = wait(futures, return_when=FIRST_COMPLETED)
        return done

    def shutdown(self):
        self.ex.shutdown(wait=True, cancel_futures=True)


class _DaskPool:
    def __init__(self, address):
        from distributed import Client
        from distributed.comm.addressing import resolve_address

        # The address is parsed first: a Client given a malformed one fails
        # half-built and its finaliser then prints a traceback of its own.
        try:
            resolve_address(address)
        except (ValueError, OSError) as e:
            raise ValueError(f"--scheduler {address}: {e}") from None
        self.address = address
        try:  # waits up to distributed.comm.timeouts.connect (30 s by default)
            self.client = Client(address, set_as_default=False)
        except OSError as e:
            raise ConnectionError(f"--scheduler {address}: cannot reach the Dask scheduler ({e})") from None
        info = self.client.scheduler_info()
        self.workers = max(1, sum(w.get("nthreads", 1) for w in info.get("workers", {}).values()))

    def submit(self, fn, *args):
        return self.client.submit(fn, *args, pure=False)

    def wait_any(self, futures):
        # distributed.wait needs a default client; this one is not (the
        # caller's own Dask set-up stays untouched), so poll the futures.
        while True:
            done = {f for f in futures if f.done()}
            if done:
                return done
            time.sleep(0.02)

    def shutdown(self):
        if self.client.status not in ("closing", "closed"):
            self.client.close()


def fill_matrix_terms(store, run_id: str) -> int:
    """The error budget's terms that come from the matrix (verdict.matrix_terms:
    the discretisation term of estimators without a same-render estimate,
    from their seeds against the reference; the model term of a model
    variant's jobs), filled into the run's records in the store, with their
    verdicts recomputed; the job's EXR metadata gets the same budget. Run
    after the jobs (again on --resume: it recomputes over all seeds).
    Returns the number of records changed."""
    recs = store.jobs(run_id)
    changed = _verdict.matrix_terms(recs)
    root = store.path.parent
    for r in changed:
        if r.get("verdict"):
            r["verdict"] = _verdict.verdict(r, r["verdict"]["target"])
            r["error_budget"]["terms"] = r["verdict"]["terms"]
        store.update_job(r)
        if r.get("exr") and (root / r["exr"]).exists():
            _rewrite_budget(root / r["exr"], r["error_budget"])
    return len(changed)


def _rewrite_budget(path: Path, budget: dict):
    """Rewrites an EXR's error_budget metadata (its pixels unchanged)."""
    from radiometer.exr import read_exr, write_exr

    e = read_exr(path)
    meta = dict(e.metadata, error_budget=budget)
    write_exr(path, image=e.image, variance=e.variance, effects=e.effects, layers=dict(e.layers) or None, **meta)


def _crash_record(job: dict, commit, machine, err: str) -> dict:
    return dict(job, status="failed", error=err, commit=commit, machine=machine, started=None, finished=now(),
                metrics={}, effect_metrics={}, curve=[], exr=None)


def summary(records) -> tuple:
    """(exit status, message) of a finished run from its job records: 1 when
    no job ran or any failed (an exception in a job is a bug to look at),
    else 0; the message counts each status and quotes each distinct reason
    once."""
    counts = {k: 0 for k in ("ok", "unsupported", "failed")}
    reasons = {"unsupported": {}, "failed": {}}
    for r in records:
        counts[r["status"]] += 1
        if r["status"] in reasons:
            err = (r.get("error") or "").strip()
            last = err.splitlines()[-1] if err else "(no message)"  # a traceback's last line says what
            reasons[r["status"]][last] = reasons[r["status"]].get(last, 0) + 1
    n = len(records)
    head = f"{counts['ok']} ok, {counts['unsupported']} unsupported, {counts['failed']} failed"
    if n == 0:
        return 1, "no job in the run"
    lines = []
    for status in ("failed", "unsupported"):
        for why, k in reasons[status].items():
            lines.append(f"  {status} x{k}: {why}")
    if counts["ok"] == 0:
        return 1, f"no job ran: {head} of {n}\n" + "\n".join(lines)
    if counts["failed"]:
        return 1, f"{head} of {n}\n" + "\n".join(lines)
    return 0, head


def run(matrix_arg: Optional[str] = None, root=DEFAULT_ROOT, scheduler: Optional[str] = None,
        workers: Optional[int] = None, resume=None, progress: bool = True, log=None) -> str:
    """Runs a matrix (a file, a name in benchmarks/ or a parsed Matrix), storing each job as
    it finishes in <root>/bench.sqlite. `resume`: None (a new run), "latest"
    (the latest run of this matrix in the store) or a run id; its recorded
    jobs are skipped. Returns the run id."""
    log = log or (lambda *a: print(*a, file=sys.stderr, flush=True))
    mat = matrix_arg if isinstance(matrix_arg, _matrix.Matrix) else _matrix.load(matrix_arg)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"--workers: expected an integer >= 1, got {workers!r}")
    # Connect to the cluster before anything is written: a scheduler that
    # cannot be reached leaves no empty run behind.
    cores = os.cpu_count() or 1
    pool = _DaskPool(scheduler) if scheduler else None
    try:
        return _run(mat, Path(root), pool, workers, cores, resume, progress, log)
    finally:
        if pool is not None:
            pool.shutdown()


def _run(mat, root: Path, pool, workers, cores, resume, progress, log) -> str:
    root.mkdir(parents=True, exist_ok=True)
    store = Store(root / STORE_NAME)
    commit, machine = commit_id(), machine_info()
    jobs = mat.jobs
    if resume:
        run_id = store.latest_run(mat.name) if resume == "latest" else store.resolve_run(resume)
        if run_id is None:
            raise KeyError(f"--resume: {store.path} holds no run of matrix '{mat.name}'")
        theirs = store.run(run_id)["matrix"]
        if theirs != mat.name:
            raise ValueError(f"--resume {resume}: run {run_id} in {store.path} is of matrix '{theirs}', not "
                             f"'{mat.name}' ({mat.path}); resume it with its own matrix")
        done = store.job_keys(run_id)
        todo = [j for j in jobs if j.key not in done]
        log(f"resuming run {run_id}: {len(jobs) - len(todo)} of {len(jobs)} jobs already recorded, {len(todo)} to run")
    else:
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d-%H%M%S")
        run_id = f"{stamp}-{mat.name}-{uuid.uuid4().hex[:6]}"
        store.add_run(run_id, mat.name, str(mat.path), mat.text, commit, machine, now())
        todo = list(jobs)
        log(f"run {run_id}: matrix {mat.path}, {len(jobs)} jobs, commit {commit}")
    # Per-effect references first (all cores; cached across runs).
    if todo:
        notes = _effect_refs.ensure(root, todo, mat.effect_ref_spp, threads=0, log=log)
        for scene, note in notes.items():
            if "rejected" in note:
                log(f"  {scene}: {note.splitlines()[0]}")
        unloadable = sorted(s for s, n in notes.items() if "does not load" in n)
        if unloadable:
            log(f"  scenes our loader refuses (their jobs are recorded as unsupported): {', '.join(unloadable)}")
    if pool is None:
        pool = _LocalPool(workers or max(1, cores // max(1, mat.threads or cores)))
    else:
        log(f"Dask scheduler {pool.address}: {pool.workers} worker threads")
    from tqdm import tqdm

    bar = tqdm(total=len(todo), desc=f"bench {mat.name}", unit="job", file=sys.stderr,
               disable=None if progress else True, dynamic_ncols=True)
    counts = {"ok": 0, "failed": 0, "unsupported": 0}
    queue = [j.to_dict() for j in todo]
    queue.reverse()
    running = {}
    attempts = {}
    try:
        while queue or running:
            while queue and len(running) < pool.workers:
                jd = queue.pop()
                running[pool.submit(run_job, jd, str(root.resolve()), run_id, commit, machine)] = jd
            for fut in pool.wait_any(set(running)):
                if fut not in running:  # re-queued after a pool crash
                    continue
                jd = running.pop(fut)
                try:
                    rec = fut.result()
                except Exception as e:  # the worker itself died (segfault, OOM kill, lost Dask worker)
                    attempts[jd["key"]] = attempts.get(jd["key"], 0) + 1
                    if isinstance(pool, _LocalPool):
                        from concurrent.futures.process import BrokenProcessPool

                        if isinstance(e, BrokenProcessPool):  # every in-flight job is lost with the pool
                            for f2, j2 in list(running.items()):
                                queue.append(j2)
                                running.pop(f2)
                            pool.shutdown()
                            pool = _LocalPool(pool.workers)
                    if attempts[jd["key"]] < 2:
                        queue.append(jd)
                        continue
                    rec = _crash_record(jd, commit, machine, f"worker died twice running this job: "
                                                            f"{type(e).__name__}: {e}")
                store.add_job(run_id, rec)
                counts[rec["status"]] += 1
                bar.update(1)
                bar.set_postfix(ok=counts["ok"], unsupported=counts["unsupported"], failed=counts["failed"],
                                refresh=False)
    finally:
        bar.close()
        pool.shutdown()
    fill_matrix_terms(store, run_id)
    store.finish_run(run_id, now())
    log(f"run {run_id}: {counts['ok']} ok, {counts['unsupported']} unsupported, {counts['failed']} failed "
        f"-> {store.path}")
    store.close()
    return run_id
