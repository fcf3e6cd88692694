"""The results store: one SQLite file (Python's sqlite3, no server).

Tables:
  runs(run_id, matrix, matrix_path, matrix_text, commit, machine, started, finished)
  jobs(uid, run_id, job_key, config_key, scene, estimator, integrator, scene_params,
       budget, seed, status, error, spp, seconds, relmse, commit, machine, finished, record)

`record` is the whole job record as JSON (every metric, the per-effect
metrics, the error-against-time curve, render stats, EXR paths); the other
columns repeat what queries need. Each job is inserted in its own
transaction with the journal in WAL mode and synchronous=FULL, so a job
is on disk before the next one is counted, and a run killed with SIGKILL
loses no finished job. `uid` is unique worldwide (uuid4) and (run_id,
job_key) unique within a store, so stores from several machines merge by
INSERT OR IGNORE (`merge`).
"""
from __future__ import annotations

import json
import sqlite3
import uuid
from pathlib import Path
from typing import Optional

SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    run_id TEXT PRIMARY KEY,
    matrix TEXT NOT NULL,
    matrix_path TEXT,
    matrix_text TEXT,
    commit_id TEXT,
    machine TEXT,
    started TEXT,
    finished TEXT
);
CREATE TABLE IF NOT EXISTS jobs (
    uid TEXT PRIMARY KEY,
    run_id TEXT NOT NULL REFERENCES runs(run_id),
    job_key TEXT NOT NULL,
    config_key TEXT NOT NULL,
    scene TEXT NOT NULL,
    estimator TEXT NOT NULL,
    integrator TEXT,
    scene_params TEXT,
    budget TEXT,
    seed INTEGER,
    status TEXT NOT NULL,
    error TEXT,
    spp INTEGER,
    seconds REAL,
    relmse REAL,
    commit_id TEXT,
    machine TEXT,
    finished TEXT,
    record TEXT NOT NULL,
    UNIQUE (run_id, job_key)
);
CREATE INDEX IF NOT EXISTS jobs_run ON jobs(run_id);
"""

STATUSES = ("ok", "failed", "unsupported")


TABLES = {"runs", "jobs"}


class Store:
    """A results store. `readonly=True` (compare, report, runs) opens an
    existing store without writing to it: an empty file or someone else's
    database is refused as it is, never given our tables. A writer (bench,
    merge) creates a missing or empty file, and also refuses a database
    that holds other tables."""

    def __init__(self, path, readonly: bool = False):
        self.path = Path(path)
        self.readonly = readonly
        if readonly:
            if not self.path.is_file():
                what = "a folder" if self.path.is_dir() else "no such file"
                raise FileNotFoundError(f"{self.path}: {what}, not a results store")
            # mode=ro: SQLite itself refuses every write through this connection.
            self.conn = sqlite3.connect(self.path.resolve().as_uri() + "?mode=ro", uri=True, timeout=60)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.conn = sqlite3.connect(str(self.path), timeout=60)
        try:
            self._check_tables()
            if not readonly:
                self.conn.execute("PRAGMA journal_mode=WAL")
                self.conn.execute("PRAGMA synchronous=FULL")
                with self.conn:
                    self.conn.executescript(SCHEMA)
        except BaseException:
            self.conn.close()
            raise
        self.conn.row_factory = sqlite3.Row

    def _check_tables(self):
        try:
            names = {r[0] for r in self.conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        except sqlite3.DatabaseError as e:
            raise ValueError(f"{self.path}: not an SQLite database, so not a results store ({e})") from None
        if TABLES <= names or (not names and not self.readonly):
            return
        if not names:
            why = "an empty file" if self.path.stat().st_size == 0 else "an SQLite database without tables"
        else:
            why = f"an SQLite database with other tables: {', '.join(sorted(names))}"
        raise ValueError(f"{self.path}: not a results store ({why}; a store has tables runs and jobs)")

    def close(self):
        self.conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- runs ---------------------------------------------------------------

    def add_run(self, run_id, matrix, matrix_path, matrix_text, commit, machine, started):
        with self.conn:
            self.conn.execute("INSERT INTO runs VALUES (?, ?, ?, ?, ?, ?, ?, NULL)",
                              (run_id, matrix, matrix_path, matrix_text, commit, json.dumps(machine), started))

    def finish_run(self, run_id, finished):
        with self.conn:
            self.conn.execute("UPDATE runs SET finished = ? WHERE run_id = ?", (finished, run_id))

    def runs(self) -> list:
        rows = self.conn.execute("SELECT r.*, (SELECT COUNT(*) FROM jobs j WHERE j.run_id = r.run_id) AS n_jobs "
                                 "FROM runs r ORDER BY started, run_id").fetchall()
        return [dict(r) for r in rows]

    def run(self, run_id: str) -> dict:
        r = self.conn.execute("SELECT * FROM runs WHERE run_id = ?", (run_id,)).fetchone()
        if r is None:
            known = ", ".join(x["run_id"] for x in self.runs()[-5:])
            raise KeyError(f"{self.path}: no run '{run_id}' (latest: {known or 'none'})")
        d = dict(r)
        d["machine"] = json.loads(d["machine"] or "{}")
        return d

    def latest_run(self, matrix: Optional[str] = None) -> Optional[str]:
        q = ("SELECT run_id FROM runs" + (" WHERE matrix = ?" if matrix else "")
             + " ORDER BY started DESC, run_id DESC LIMIT 1")
        r = self.conn.execute(q, (matrix,) if matrix else ()).fetchone()
        return None if r is None else r["run_id"]

    def resolve_run(self, run: Optional[str]) -> str:
        """A run id, a unique prefix of one, or None / "latest"."""
        if run in (None, "latest"):
            r = self.latest_run()
            if r is None:
                raise KeyError(f"{self.path}: the store holds no run")
            return r
        rows = self.conn.execute("SELECT run_id FROM runs WHERE run_id LIKE ?", (run + "%",)).fetchall()
        if len(rows) == 1:
            return rows[0]["run_id"]
        if not rows:
            known = ", ".join(x["run_id"] for x in self.runs()[-5:])
            raise KeyError(f"{self.path}: no run '{run}' (latest: {known or 'none'})")
        raise KeyError(f"{self.path}: '{run}' matches {len(rows)} runs; give more of the id")

    # -- jobs ---------------------------------------------------------------

    def add_job(self, run_id: str, rec: dict) -> str:
        """Inserts one job record, atomically (its own transaction)."""
        if rec.get("status") not in STATUSES:
            raise ValueError(f"job record: status must be one of {STATUSES}, got {rec.get('status')!r}")
        uid = rec.get("uid") or uuid.uuid4().hex
        rec = dict(rec, uid=uid, run_id=run_id)
        with self.conn:
            self.conn.execute(
                "INSERT INTO jobs VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (uid, run_id, rec["key"], rec["config_key"], rec["scene"], rec["estimator"],
                 json.dumps(rec.get("integrator"), sort_keys=True), json.dumps(rec.get("scene_params"), sort_keys=True),
                 json.dumps(rec.get("budget"), sort_keys=True), rec.get("seed"), rec["status"], rec.get("error"),
                 rec.get("spp"), rec.get("seconds"), (rec.get("metrics") or {}).get("relmse"), rec.get("commit"),
                 json.dumps(rec.get("machine")), rec.get("finished"), json.dumps(rec, default=_json_default)))
        return uid

    def update_job(self, rec: dict):
        """Replaces a stored job's record (by its uid), atomically: the
        matrix's terms of the error budget, filled after the run's jobs."""
        with self.conn:
            cur = self.conn.execute("UPDATE jobs SET record = ? WHERE uid = ?",
                                    (json.dumps(rec, default=_json_default), rec["uid"]))
        if cur.rowcount != 1:
            raise KeyError(f"{self.path}: no job with uid {rec.get('uid')!r}")

    def job_keys(self, run_id: str) -> set:
        return {r["job_key"] for r in self.conn.execute("SELECT job_key FROM jobs WHERE run_id = ?", (run_id,))}

    def jobs(self, run_id: str) -> list:
        rows = self.conn.execute("SELECT record FROM jobs WHERE run_id = ? ORDER BY scene, estimator, seed",
                                 (run_id,)).fetchall()
        return [json.loads(r["record"]) for r in rows]

    def history(self, matrix: str) -> list:
        """Every job of every run of `matrix`, oldest run first, as dicts of
        the query columns only (run_id, started, commit_id, scene, estimator,
        budget as a dict, seed, status, relmse, seconds): what the report's
        history view plots, without parsing each record."""
        rows = self.conn.execute(
            "SELECT j.run_id, r.started, r.commit_id, j.scene, j.estimator, j.budget, j.seed, j.status, j.relmse, "
            "j.seconds FROM jobs j JOIN runs r ON r.run_id = j.run_id WHERE r.matrix = ? "
            "ORDER BY r.started, j.run_id", (matrix,)).fetchall()
        return [dict(r, budget=json.loads(r["budget"] or "{}")) for r in rows]

    # -- merging ------------------------------------------------------------

    def merge(self, other) -> tuple:
        """Copies every run and job of store `other` (a path) that this one
        lacks; returns (runs added, jobs added). Safe to repeat."""
        other = Path(other)
        if not other.exists():
            raise FileNotFoundError(f"merge: {other} does not exist")
        if other.resolve() == self.path.resolve():
            raise ValueError(f"merge: {other} is this store")
        Store(other, readonly=True).close()  # refuses anything but a results store, naming it
        before_r = self.conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        before_j = self.conn.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
        self.conn.execute("ATTACH DATABASE ? AS other", (str(other),))
        try:
            with self.conn:
                self.conn.execute("INSERT OR IGNORE INTO runs SELECT * FROM other.runs")
                self.conn.execute("INSERT OR IGNORE INTO jobs SELECT * FROM other.jobs")
        finally:
            self.conn.execute("DETACH DATABASE other")
        after_r = self.conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        after_j = self.conn.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
        return after_r - before_r, after_j - before_j


def _json_default(o):
    import numpy as np

    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
