"""radiometer.analysis.blocks on synthetic images with known answers: the
block test passes on draws from the reference's own distribution, rejects a
biased block, and `exclude` / `block_mask` / the variance floor act as
documented. Significance: every call at ALPHA = 0.01; the null cases use
fixed seeds."""
import numpy as np
import pytest

from radiometer.analysis.blocks import (block_mean, block_var_bound, block_var_independent, blocked_z_test,
                                        reference_variance_floor, region_mask)

H = W = 32


def _noisy(seed, mean=1.0, sd=0.1):
    rng = np.random.default_rng(seed)
    img = mean + sd * rng.standard_normal((H, W, 3))
    return img, np.full((H, W, 3), sd * sd)


def test_block_statistics():
    img = np.arange(H * W * 3, dtype=float).reshape(H, W, 3)
    bm = block_mean(img)
    assert bm.shape == (H // 4, W // 4, 3)
    assert bm[0, 0, 0] == pytest.approx(img[:4, :4, 0].mean())
    var = np.full((H, W, 3), 4.0)
    assert np.allclose(block_var_independent(var), 4.0 / 16)  # 16 independent pixels
    assert np.allclose(block_var_bound(var), 4.0)  # fully correlated bound


def test_null_passes_and_bias_is_rejected():
    ref = np.ones((H, W, 3))
    a, va = _noisy(1)
    assert blocked_z_test(a, va, ref)[0]
    biased = a.copy()
    biased[8:12, 8:12] += 0.2  # one block off by 8 of its standard errors
    passed, msg = blocked_z_test(biased, va, ref)
    assert not passed and "FAIL" in msg


def test_exclude_and_block_mask_leave_blocks_out():
    ref = np.ones((H, W, 3))
    a, va = _noisy(2)
    a[8:12, 8:12] += 0.2
    assert blocked_z_test(a, va, ref, exclude=[(9, 9, 10, 10)])[0]  # a box touching the block drops it
    assert not blocked_z_test(a, va, ref, exclude=[(12, 12, 16, 16)])[0]  # a neighbour's box does not
    keep = np.ones((H // 4, W // 4), bool)
    keep[2, 2] = False
    assert blocked_z_test(a, va, ref, block_mask=keep)[0]
    assert region_mask((H, W), [(9, 9, 10, 10)]).sum() == 1


def test_variance_floor_only_widens():
    ref = np.ones((H, W, 3))
    a, va = _noisy(3)
    a[8:12, 8:12] += 0.2
    # A floor below our own variance changes nothing; one 16x above it
    # (the reference saw that much more spread per sample) accepts.
    assert not blocked_z_test(a, va, ref, var_a_floor=va / 4)[0]
    assert blocked_z_test(a, va, ref, var_a_floor=va * 16)[0]
    assert np.allclose(reference_variance_floor(va, 1000, 10), va * 100)


def test_variance_floor_follows_a_correlated():
    """A floor stands in for a's pixel variances, so a's block rule applies to
    it: with a_correlated the Cauchy-Schwarz bound (k^2 times the independent
    sum on a block of equal floors), without it the independent sum."""
    ref = np.ones((H, W, 3))
    a = np.ones((H, W, 3))
    a[8:12, 8:12] += 0.08
    va = np.full((H, W, 3), 1e-8)
    floor = np.full((H, W, 3), 4e-3)  # independent block sd 0.016 (z 5.1); bound 0.063 (z 1.3)
    assert not blocked_z_test(a, va, ref, var_a_floor=floor)[0]
    assert blocked_z_test(a, va, ref, var_a_floor=floor, a_correlated=True)[0]


def test_small_or_odd_images_use_a_block_that_fits():
    """A 1 x 1 meter image and a 6 x 9 one: the block side drops to what
    divides both sides (1 and 3), instead of failing to reshape."""
    one = np.ones((1, 1, 3))
    passed, msg = blocked_z_test(one, np.full((1, 1, 3), 0.01), one * 1.001, np.full((1, 1, 3), 0.01))
    assert passed and "1x1 blocks" in msg
    odd, vodd = np.ones((6, 9, 3)), np.full((6, 9, 3), 1e-4)
    assert "3x3 blocks" in blocked_z_test(odd, vodd, odd, vodd)[1]
    assert not blocked_z_test(odd * 1.1, vodd, odd, vodd)[0]
