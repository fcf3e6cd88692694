"""The seed offset and the two-stage rule of tests/conftest.py, on a tiny
suite of their own run in a subprocess: a chance rejection (one that fails
only under the seeds as written) is cleared by a rerun under a fresh offset
and reported, a rejection that every offset repeats fails, and an error
that is not an assertion fails at once, without reruns."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from conftest import confirm_offset, reroll

SUITE = '''
import numpy as np
from conftest import reroll


def test_chance():
    assert reroll(5) != 5, "fails only under the seeds as written"


def test_always():
    assert np.random.default_rng(3).random() < 0, "fails under every offset"


def test_error():
    raise ValueError("not an assertion")
'''


def test_two_stage_rule_clears_chance_and_keeps_real_failures(tmp_path):
    shutil.copy(Path(__file__).with_name("conftest.py"), tmp_path / "conftest.py")
    (tmp_path / "test_suite.py").write_text(SUITE)
    env = {k: v for k, v in os.environ.items()
           if k not in ("RADIOMETER_SEED_OFFSET", "RADIOMETER_CONFIRM", "RADIOMETER_CONFIRMING")}
    r = subprocess.run([sys.executable, "-m", "pytest", str(tmp_path), "-q", "-p", "no:cacheprovider", "-rf"],
                       cwd=tmp_path, capture_output=True, text=True, env=env)
    out = r.stdout + r.stderr
    assert r.returncode == 1, out
    assert "2 failed, 1 passed" in out, out
    assert f"NOT CONFIRMED (passes) test_suite.py::test_chance [offset 0; rerun offsets [{confirm_offset(0, 1)}]]" \
        in out, out
    assert (f"CONFIRMED (fails) test_suite.py::test_always [offset 0; rerun offsets "
            f"[{confirm_offset(0, 1)}, {confirm_offset(0, 2)}]]") in out, out
    assert "FAILED test_suite.py::test_error - ValueError" in out and "test_error [offset" not in out, out


def test_seed_offset_rerolls_render_and_numpy_seeds(monkeypatch):
    """Under an offset every valid seed maps to another one, the same each
    time, and anything else goes through untouched; at offset 0 nothing
    changes."""
    import conftest

    assert reroll(5) == 5 or conftest.SEED_OFFSET
    monkeypatch.setattr(conftest, "SEED_OFFSET", 7)
    a = [reroll(s) for s in range(100)]
    assert len(set(a)) == 100 and a == [reroll(s) for s in range(100)] and a != list(range(100))
    assert all(0 <= s < 1 << 63 for s in a)
    for bad in (-1, 1 << 64, True, 1.5, "3", None):
        assert reroll(bad) is bad
    assert reroll(np.uint64(5)) == reroll(5)
    monkeypatch.setattr(conftest, "SEED_OFFSET", 0)
    assert reroll(5) == 5
