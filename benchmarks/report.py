"""`radiometer report RUN`: reads one run from a results store and writes
its HTML report (the page itself: radiometer.analysis.report)."""
from __future__ import annotations

from pathlib import Path

from radiometer.analysis.report import write_page

from .store import Store


def write(store_path, run_id=None, out_dir=None, log=print) -> Path:
    """The report of run `run_id` (default: the latest) of the store at
    `store_path`, into `out_dir` (default: <store's folder>/reports/RUN).
    Returns index.html's path."""
    store_path = Path(store_path)
    root = store_path.parent
    with Store(store_path) as st:
        rid = st.resolve_run(run_id)
        run = st.run(rid)
        recs = st.jobs(rid)
    out = Path(out_dir) if out_dir else root / "reports" / rid
    return write_page(run, recs, root, out, store_path, log=log)
