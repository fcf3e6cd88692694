"""References at a second resolution (reference_scenes/registry.py
`more_refs`): the 128 x 128 references the main job compares with exist
for every scene that declares one, agree with the scene's 64 x 64
reference (which the scene tests keep using), and a resolution with no
reference is refused by name.

The consistency check is cheap (two committed EXRs, no render) and able to
fail: the same comparison with the 128 x 128 image scaled by 1.05 must be
rejected.

- Box-filtered scenes: a sample lands in exactly one pixel, so a 64 x 64
  pixel is the mean of the 2 x 2 pixels of the 128 x 128 film it covers,
  in expectation; Mitsuba's box-filtered pixels are independent, so that
  mean's variance is the sum of the four over 16. The 2 x 2 means are
  then z-tested against the 64 x 64 reference with the blocked z-test of
  the scene tests (analysis/blocks.py, 4 x 4 blocks), both variances
  counted.
- Gaussian-filtered scenes (cornell_box): each film blurs by its own pixel
  width (Mitsuba's gaussian, stddev 0.5 px), so near an edge a 2 x 2 mean
  of the finer film is not the coarser film's pixel. Measured on
  cornell_box: blocks of 2, 4 or 8 pixels (of 64) reject at min p 0 with
  no scaling, along the box edges. A region mean moves only by what the
  blur carries across the region's border, so the comparison is of
  regions of a quarter image side (16 x 16 at 64: 16 regions), where that
  is below the noise (p_min 0.40 measured), and both sides' region
  variances are the Cauchy-Schwarz bound (Mitsuba's splats correlate its
  pixels).
"""
import numpy as np
import pytest

import radiometer as rm
from radiometer.analysis.blocks import block_mean, block_var_bound, block_var_independent, blocked_z_test
from radiometer.benchmarks import effect_refs
from radiometer.reference_scenes import references, registry

DECLARED = [(s.name, r) for s in registry.SCENES.values() for r in sorted(s.more_refs)]
GAUSSIAN_REGION = 16  # region side at the coarse resolution (see above)


def _read(spec, res):
    path = spec.reference_file(res)
    assert path.exists(), f"{spec.name}: {path.name} missing (radiometer refs {spec.name} --res {res})"
    return rm.read_exr(path)


def _against_coarse(spec, fine, coarse, scale=1.0):
    """(passed, message): the fine reference, scaled by `scale`, against
    the coarse one by the comparison its filter allows (module doc)."""
    f = int(fine.image.shape[0]) // int(coarse.image.shape[0])
    img, var = np.asarray(fine.image, np.float64) * scale, np.asarray(fine.variance, np.float64) * scale ** 2
    splatted = rm.load_file(spec.xml, **registry.scene_params(spec, {})).desc.sensor.rfilter != "box"
    if splatted:
        return blocked_z_test(block_mean(img, f), block_var_bound(var, f), coarse.image, coarse.variance,
                              a_correlated=True, b_splatted=True, k=GAUSSIAN_REGION, label=f"{spec.name}: ")
    # Mitsuba's light tracer (ajar_door) splats each light path into every
    # pixel it sees, so one render's blocks share their errors: the blocks'
    # mean z then takes its Cauchy-Schwarz bound (common_mode), as for
    # Metropolis. Measured: without it the two independent references'
    # mean z is +3.9 (p 1e-4) for image means 0.02 % apart.
    light_traced = (spec.mitsuba_integrator or {}).get("type") == "ptracer"
    return blocked_z_test(block_mean(img, f), block_var_independent(var, f), coarse.image, coarse.variance,
                          a_common_mode=light_traced, label=f"{spec.name}: ")


def test_some_scene_declares_a_second_resolution():
    assert DECLARED, "no scene in the registry declares a reference at a second resolution"


@pytest.mark.parametrize("name,res", DECLARED)
def test_reference_exists_with_its_budget(name, res):
    spec = registry.get(name)
    ref = _read(spec, res)
    runs, spp, _ = spec.budget(res)
    assert ref.image.shape == (res, res, 3) and ref.variance.shape == (res, res, 3)
    assert res <= 256  # committed references stay small (registry.py)
    assert int(ref.metadata["total_spp"]) == runs * spp and int(ref.metadata.get("runs", runs)) == runs
    if spec.kind == "mitsuba":  # made from the seeds the registry names (first_seed)
        first = spec.first_seed(res)
        assert ref.metadata["seeds"] == f"{first}..{first + runs - 1}"
    assert np.all(np.isfinite(ref.image)) and np.all(ref.variance >= 0)
    # The runs differed (a pixel wholly on an emitter may not: veach_mis's
    # lights, 2.0 to 50.0 exactly in every run, at 64 x 64 too).
    assert np.count_nonzero(ref.variance) > ref.variance.size // 2, "the runs did not differ"


@pytest.mark.parametrize("name,res", DECLARED)
def test_agrees_with_the_coarse_reference(name, res):
    spec = registry.get(name)
    fine, coarse = _read(spec, res), _read(spec, None)
    assert res % coarse.image.shape[0] == 0
    ok, msg = _against_coarse(spec, fine, coarse)
    assert ok, msg
    # Power: a 5 % error in the fine reference is caught.
    ok, msg = _against_coarse(spec, fine, coarse, scale=1.05)
    assert not ok, f"a 5 % scaling of {name}'s {res} x {res} reference was not caught:\n{msg}"


def test_unknown_resolution_is_refused_by_name():
    spec = registry.get("cornell_box")
    for call in (lambda: spec.reference_file(96), lambda: spec.budget(96),
                 lambda: registry.scene_params(spec, {"res": 96}),
                 lambda: references.reference("cornell_box", {"res": 96, "max_depth": 8})):
        with pytest.raises(ValueError) as e:
            call()
        assert all(w in str(e.value) for w in ("cornell_box", "res = 96", "64 x 64", "128 x 128")), str(e.value)
    # A scene with no second reference names the one it has.
    with pytest.raises(ValueError, match=r"fog_room: no Mitsuba reference at res = 128 \(references exist at: "
                                         r"64 x 64\)"):
        registry.scene_params(registry.get("fog_room"), {"res": 128})
    # A film without a res parameter has none to choose.
    with pytest.raises(ValueError, match="vandehulst_slab"):
        registry.scene_params(registry.get("vandehulst_slab"), {"res": 128})
    # Only res may change: the other parameters stay the reference's.
    with pytest.raises(ValueError, match="max_depth"):
        registry.scene_params(spec, {"res": 128, "max_depth": 4})


def test_a_job_at_a_declared_resolution_gets_its_reference():
    spec = registry.get("cornell_box")
    p = registry.scene_params(spec, {"res": 128})
    assert p == {**spec.fixed_params, "res": 128}
    assert registry.scene_params(spec, {"res": 64}) == spec.fixed_params
    ref = references.reference("cornell_box", p)
    assert ref.image.shape == (128, 128, 3) and ref.spp == spec.budget(128)[0] * spec.budget(128)[1]


def test_effect_reference_cache_separates_resolutions(tmp_path):
    """The per-effect reference's cache key covers the resolution, and a job
    at 128 gets the budget the registry gives that resolution."""
    spec = registry.get("cornell_box")
    p64, p128 = registry.scene_params(spec, {}), registry.scene_params(spec, {"res": 128})
    spp = spec.budget(128)[2]
    assert effect_refs.ref_path(tmp_path, "cornell_box", p64, spp) != effect_refs.ref_path(tmp_path, "cornell_box",
                                                                                          p128, spp)
    assert spp > 0 and spp != spec.effect_ref_spp

    class Job:  # what ensure() reads of a job
        scene, scene_params, effect_ref, effect_note = "cornell_box", p128, None, None

    # A cached file at the budget's path is what ensure() looks for: one
    # that does not read back is remade, so plant an accepted one.
    out = effect_refs.ref_path(tmp_path, "cornell_box", p128, spp)
    out.parent.mkdir(parents=True)
    rm.write_exr(out, None, image=np.zeros((128, 128, 3), np.float32), accepted=1, effects_kind="planted")
    j = Job()
    notes = effect_refs.ensure(tmp_path, [j], log=lambda *a: None)
    assert j.effect_ref == str(out) and notes["cornell_box"] == "planted"


def test_main_job_renders_where_a_reference_exists():
    """Every job of the main matrix renders at a resolution whose committed
    reference file is there (scene_params refuses an undeclared one; this
    catches a declared one not yet made), and the surface scenes that have
    a second reference use it."""
    from radiometer.benchmarks import matrix as MX

    jobs = MX.load("default").jobs
    for j in jobs:
        spec = registry.get(j.scene)
        if spec.kind != "analytic":
            assert spec.reference_file(j.scene_params.get("res")).exists(), (j.scene, j.scene_params)
    at = {j.scene: j.scene_params.get("res") for j in jobs}
    for name, res in DECLARED:
        assert at[name] == res, f"{name} has a {res} x {res} reference but the main job renders it at {at[name]}"
