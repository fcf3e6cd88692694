"""vcm, bpm and ppm against the Mitsuba references of the Cornell box and
glass_sphere_caustic (reference_scenes/registry.py) at a budget CI can
afford: the blocked z-test of tests/test_estimator_matrix.py (4 x 4 block
means, each channel at ALPHA / 3, ALPHA = 0.01, the reference's variance
floor on box-filtered scenes), and its power check: the reference scaled by
`power` must be rejected. vcm at its defaults; bpm and ppm, whose merges
alone carry the light, with 65536 light paths per iteration (and on the
Cornell box radius 0.02: at the default 0.01 their variance at this budget
is too wide to see a 2 % error, measured). Their bias at these budgets is
below what the test resolves; that it shrinks: tests/test_vcm.py."""
from __future__ import annotations

import pytest

import radiometer as rm
from radiometer.reference_scenes import references, registry

from refcompare import blocked_z_test, reference_variance_floor
from test_estimator_matrix import _box_filtered

ALPHA = 0.01
CELLS = {
    # (estimator, scene): (spp, extra parameters, power); measured seconds on 2 shared cores
    ("vcm", "cornell_box"): (256, {}, 1.01),  # 8.4 s
    # 256 spp missed the 1 % power check under seed offset 5
    ("vcm", "glass_sphere_caustic"): (1024, {}, 1.01),
    # 64 spp missed the 2 % power check under seed offset 1
    ("bpm", "glass_sphere_caustic"): (128, {"light_paths": 65536}, 1.02),
    ("ppm", "glass_sphere_caustic"): (128, {"light_paths": 65536}, 1.02),
    # 1 % went undetected under seed offset 5: 2 % as for bpm (ppm's bias
    # and noise at this budget are what tests/test_vcm.py measures)
    ("ppm", "cornell_box"): (64, {"light_paths": 65536, "radius": 0.02}, 1.02),  # 12.3 s
    ("bpm", "cornell_box"): (64, {"light_paths": 65536, "radius": 0.02}, 1.02),
}


@pytest.mark.parametrize("est,name", list(CELLS), ids=lambda v: str(v))
def test_converges_to_mitsuba_reference(est, name):
    spp, extra, power = CELLS[est, name]
    spec = registry.get(name)
    params = dict(spec.fixed_params)  # the reference's
    scene = rm.load_file(spec.xml, **params)
    ref = references.reference(name, params)
    integ = {"type": est, **extra}
    md = registry.max_depth(spec, params)
    if md is not None:
        integ["max_depth"] = md
    res = rm.render(scene, integrator=integ, spp=spp, seed=7)
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0
    box = _box_filtered(spec)
    floor = reference_variance_floor(ref.variance, ref.spp, res.spp) if box else None

    def z(scale):
        return blocked_z_test(res.image, res.variance, ref.image * scale, ref.variance * scale * scale,
                              b_splatted=not box, a_correlated=not box, alpha=ALPHA, k=4, var_a_floor=floor,
                              exclude=spec.exclusions.get(est, ()))

    passed, msg = z(1.0)
    assert passed, f"{est} on {name}: mean / reference = {res.image.mean() / ref.image.mean():.5f}\n{msg}"
    passed, msg = z(power)
    assert not passed, f"{est} on {name}: a {(power - 1) * 100:.0f} % error went undetected\n{msg}"
