"""The stress scenes (reference_scenes/stress, tests/test_stress.py) with
every structured sampler: for each estimator that draws on the sampler, no
NaN, no Inf, nothing negative in the image, the variance or any effect
image, no NaN/Inf sample counted, and light where the scene must show light
(test_stress's regions and exceptions). test_stress.py runs the same checks
on the independent sampler; a structured sampler hands out other values at
the same dimensions (values at exactly 0 or next to 1 included), so each
is run here. No statistics: these are exact checks.
"""
from __future__ import annotations

import pytest
from test_samplers import STRUCTURED
from test_stress import CANNOT_LIGHT, MEDIA_CANNOT_LIGHT, MEDIA_SCENES, SCENES, SPP, STRESS, SUPPORTS_MEDIA, assert_sane

import radiometer as rm

# The estimators that draw on the sampler (docs/samplers.md): the camera
# driver's and the light driver's.
DRAWING = ("path", "direct", "whitted", "ptracer", "bdpt")


def _render(name, est, sampler):
    res = rm.render(rm.load_file(STRESS / f"{name}.xml"), integrator=est, spp=SPP, seed=0, sampler=sampler)
    assert res.stats["sampler"] == sampler, f"{name} / {est}: drew on {res.stats['sampler']}, not {sampler}"
    return res


def _lit(res, regions, where):
    for rows, cols, what in regions:
        m = float(res.image[rows, cols].mean())
        assert m > 0, f"{where}: {what} must be lit, mean {m:g}"


@pytest.mark.parametrize("sampler", STRUCTURED)
@pytest.mark.parametrize("est", DRAWING)
@pytest.mark.parametrize("name", sorted(SCENES))
def test_stress_scene_with_every_sampler(name, est, sampler):
    where = f"{name} / {est} / {sampler}"
    res = _render(name, est, sampler)
    assert_sane(res, where)
    exp = SCENES[name]
    if (est, name) in CANNOT_LIGHT:
        return
    if exp.get("zero"):
        assert not res.image.any(), f"{where}: must be exactly 0, max {res.image.max():g}"
    _lit(res, exp.get("lit", []), where)
    if "max_at_least" in exp:
        assert res.image.max() >= exp["max_at_least"], f"{where}: max {res.image.max():g}"


@pytest.mark.parametrize("sampler", STRUCTURED)
@pytest.mark.parametrize("est", [e for e in DRAWING if e in SUPPORTS_MEDIA])
@pytest.mark.parametrize("name", sorted(MEDIA_SCENES))
def test_media_stress_scene_with_every_sampler(name, est, sampler):
    where = f"{name} / {est} / {sampler}"
    res = _render(name, est, sampler)
    assert_sane(res, where)
    if (est, name) not in MEDIA_CANNOT_LIGHT:
        _lit(res, MEDIA_SCENES[name]["lit"], where)
