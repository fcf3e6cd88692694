"""Ctrl-C that arrives while the progress callback runs (where a Python
handler sees it first) cancels like any other Ctrl-C: RenderCancelled with
the finished passes, not a bare KeyboardInterrupt that loses them."""
import numpy as np
import pytest

import radiometer as rm


def test_interrupt_inside_progress_keeps_finished_passes(small_cornell):
    calls = []

    def progress(done, total):
        calls.append(done)
        if done >= 2 * 24 * 24:  # after two passes' worth of samples
            raise KeyboardInterrupt

    # Caught as KeyboardInterrupt (RenderCancelled's base): a bare one must
    # fail this test, not end the pytest session.
    try:
        rm.render(small_cornell, spp=1 << 20, seed=0, threads=1, progress=progress)
        caught = None
    except KeyboardInterrupt as e:
        caught = e
    assert isinstance(caught, rm.RenderCancelled), f"got {type(caught).__name__}, not RenderCancelled"
    r = caught.result
    assert 0 < r.spp < 1 << 20
    assert np.isfinite(r.image).all() and r.image.mean() > 0


def test_other_callback_errors_still_propagate(small_cornell):
    """The control: an ordinary exception in the callback is the caller's error."""
    def boom(done, total):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        rm.render(small_cornell, spp=4096, progress=boom)
