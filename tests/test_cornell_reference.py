"""The Cornell box: `direct` == `path` at max_depth 2. Every estimator
against the committed Mitsuba 3 reference (reference_scenes/cornell_box/
reference.exr: 64 x 64, max_depth 8, 32 runs x 2048 spp of llvm_ad_rgb,
mean and variance of the mean), with its power check, is a cell of
tests/test_estimator_matrix.py, which compares as described here.

How the images are compared, and why (measured on this scene, 64 x 64):

* Per channel, each at alpha / 3 (Bonferroni), so the whole test keeps
  alpha = 0.01. One path sample feeds R, G and B, so the three channels of a
  pixel are strongly correlated; `z_test`'s mean-z statistic treats its inputs
  as independent. Pooled over channels its spread across 32 seeds was 1.66
  instead of 1 (about 8 % false alarms at the alpha/3 level, not 0.33 %).
* In 4 x 4 pixel blocks (16 x 16 per channel), at 512 spp. Per-sample
  radiances here are heavy-tailed: median skewness 3.4, up to 50 at the image
  border and 26 two pixels above the light, where our filter importance
  sampling (each sample lands in one pixel) reaches the emitter (radiance 18)
  with probability ~1e-3 through the gaussian's tail, while Mitsuba's splat
  hands every neighbour a deterministic share. The z statistic with a pixel's
  own estimated variance then has a negative mean, about -skew / (2 sqrt(spp))
  (the estimate and its variance rise together), measured -0.16 per pixel at
  256 spp, i.e. mean z -10 per channel; and pixels that missed the rare
  event have a variance estimate far too small (|z| beyond 28). Per pixel the
  test rejected all 32 of 32 independent 256 spp renders. A block pools 16
  pixels x 512 spp = 8192 samples, enough for the normal approximation:
  bootstrapped from 4096 real samples per pixel, this test passed 1979 of
  2000 null replicas (1.05 % false alarms at alpha = 1 %) and rejected all
  1000 replicas scaled by 1.01 (and all scaled by 1.005); 30 of 30 real
  512 spp renders with independent seeds passed against Mitsuba.
  Ours is sampled pixel by pixel (FIS), so its block variance is the sum of
  its pixel variances. Mitsuba's splatting correlates neighbouring pixels of
  the reference, whose block variance is therefore bounded by the
  Cauchy-Schwarz bound (mean of the pixel standard deviations)^2, which is
  conservative and at most a few percent of ours.
"""

import radiometer as rm
from radiometer.reference_scenes import registry
from refcompare import blocked_z_test  # block means per channel; why: this module's docstring

SPEC = registry.get("cornell_box")
SCENE = SPEC.xml

RES = SPEC.fixed_params["res"]  # 64, as the reference was made
SPP = 512  # about 3 s on 2 cores
ALPHA = 0.01


def test_direct_equals_path_at_depth_2():
    """`direct` (emission + one bounce of direct light, MIS of an emitter and a
    BSDF sample) estimates the same image as `path` at max_depth 2; both ours,
    independent seeds."""
    scene = rm.load_file(SCENE, res=RES)
    d = rm.render(scene, integrator="direct", spp=SPP, seed=2)
    p = rm.render(scene, integrator={"type": "path", "max_depth": 2}, spp=SPP, seed=3)
    passed, msg = blocked_z_test(d.image, d.variance, p.image, p.variance, b_splatted=False)
    assert passed, f"direct != path at max_depth 2 ({SPP} spp each):\n{msg}"
    # And the test sees a 1 % bias between them.
    passed, msg = blocked_z_test(d.image * 1.01, d.variance * 1.01 ** 2, p.image, p.variance, b_splatted=False)
    assert not passed, f"a 1 % bias between direct and path went undetected:\n{msg}"
