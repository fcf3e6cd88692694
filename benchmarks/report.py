"""`radiometer report RUN`: reads one run from a results store and writes
its HTML report (the page itself: radiometer.analysis.report)."""
from __future__ import annotations

from pathlib import Path

from radiometer.analysis.report import write_page

from .matrix import plain_name
from .store import Store


def write(store_path, run_id=None, out_dir=None, log=print) -> Path:
    """The report of run `run_id` (default: the latest) of the store at
    `store_path`, into `out_dir` (default: <store's folder>/reports/RUN).
    Returns index.html's path."""
    store_path = Path(store_path)
    root = store_path.parent
    with Store(store_path, readonly=True) as st:
        rid = st.resolve_run(run_id)
        run = st.run(rid)
        recs = st.jobs(rid)
        history = st.history(run["matrix"])
    if not out_dir and not plain_name(rid):  # a merged store's run id may be anything, a path included
        raise ValueError(f"{store_path}: run id {rid!r} cannot name a folder of reports/; give the report's "
                         f"folder with -o")
    for r in recs:  # the page names its images after scenes and reads each job's EXR under the store's folder
        exr = r.get("exr")
        if not plain_name(r.get("scene")) or (exr and (Path(exr).is_absolute() or ".." in Path(exr).parts)):
            raise ValueError(f"{store_path}: run {rid}: job {r.get('key')!r} has scene {r.get('scene')!r} and EXR "
                             f"{exr!r}; a report reads and writes only under the results folder")
    out = Path(out_dir) if out_dir else root / "reports" / rid
    return write_page(run, recs, root, out, store_path, log=log, history=history)
