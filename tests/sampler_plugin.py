"""A pytest plugin that renders every test with another default sampler:

    RADIOMETER_SAMPLER=sobol PYTHONPATH=tests python -m pytest -p sampler_plugin tests/test_x.py

rm.render then gets `sampler=RADIOMETER_SAMPLER` wherever a test names none,
so the suite's references check the estimators with that sampler (fresh
noise for every statistical test, as a seed offset gives). Estimators that
do not draw on the sampler (photon passes, sppm, vcm) render as before; their
warning is silenced. Not loaded by default.
"""
from __future__ import annotations

import os
import warnings

import radiometer as rm

SAMPLER = os.environ.get("RADIOMETER_SAMPLER", "")

if SAMPLER:
    _render = rm.render

    def _with_sampler(*args, **kwargs):
        kwargs.setdefault("sampler", SAMPLER)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r".*sampler '.*' (is not used|draws the camera passes)")
            return _render(*args, **kwargs)

    _with_sampler.__wrapped__ = _render
    rm.render = _with_sampler


def pytest_report_header(config):
    return f"sampler_plugin: default sampler {SAMPLER or '(unset: the scenes own)'}"
