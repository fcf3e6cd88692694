"""The estimator matrix: every registered estimator (radiometer.estimators(),
the core's registry) against every canonical scene (reference_scenes/
registry.py) it supports, as one parametrised comparison. A new estimator
joins it by registering: which cells it gets and how each is judged come
from its declaration (its capabilities: media, dipole, driver, bias,
effects), never from a list here; only budgets measured for a particular
estimator on a particular scene are kept by name (MITSUBA's "per"), and
an estimator without one runs at the scene's budget.

The cell (estimator, scene):

- Skipped, naming the capability, when the scene needs one the estimator
  does not declare (`media` for a scene with participating media, `dipole`
  for one with a dipole BSSRDF), with the estimator's own refusal when its
  check of the scene refuses it (radiometer.refusal), and, naming the reason, when the scene's
  reference cannot judge what the estimator renders (a partial estimator on
  a Mitsuba scene, whose reference is only the total, unless the registry
  declares the pixels to leave out for it; a biased or consistent one on a
  Mitsuba scene, see below).
- Rendered with `effects` = the classes the estimator declares it renders
  completely, so that its image and its variance are the estimate of just
  those classes (whitted, direct: emission and direct; ptracer: all but
  specular).
- Every cell: no NaN or Inf sample; image, variance and effect images
  finite and non-negative. On the analytic scenes the effect images sum to
  the image, every class the exact solution leaves dark is empty, and on
  the mirror caustic each lit class holds its exact power to 3 %.
- Unbiased estimators: the blocked z-test (analysis/blocks.py: k x k block
  means, each channel at ALPHA / 3, so level ALPHA = 0.01 per comparison)
  against the reference of those classes: on the analytic scenes the exact
  per-effect images (furnace by bounce, area lights all direct, mirror
  caustic direct + caustic; var_b = 0), on the Mitsuba scenes the total
  with its variance, the reference variance floor (box-filtered scenes; why:
  tests/test_canonical_mitsuba.py) and the registry's known exclusions for
  the estimator (ptracer: the pixels seen only through smooth glass, and
  veach_mis's two sharpest plates). On the one-pixel irradiance meters
  (van de Hulst's slab) the block is the pixel. Power: the same test
  against the reference with the scene's `power` bias (1 % to 10 %, the
  reasons at MITSUBA; ajar_door's 5 % on its effect region) must reject.
- Biased and consistent estimators (photonmapper, sppm), on the analytic
  scenes: the image mean's relative error against the exact mean of the
  declared classes must stay within MEAN_BOUND[bias] (measured first, see
  there), and the exact mean scaled by MEAN_POWER = 1.02 must be outside it
  (power). On the Mitsuba scenes they are skipped (the reason: their spread
  at a test's budget, measured, is wider than the power check's bias).
- Each Mitsuba reference is also checked for form (test_mitsuba_reference_
  is_well_formed: the registry's runs and spp, a variance layer, finite).

Budgets, seeds and resolutions (one seed, SEED, for every cell): the
furnace and the mirror caustic at 32 x 32 and the area lights at their own
64 x 64, with the spp of tests/test_canonical_analytic.py (the furnace at
its Russian-roulette 256); the Mitsuba scenes at their references'
parameters (their resolution cannot change without a new reference) and
the budgets of MITSUBA (each from the per-estimator test it replaced);
biased and consistent estimators at BIASED_SPP and CONSISTENT_SPP.
The whole file: about 200 s on 2 shared cores (69 cells run; the slowest
bdpt on ajar_door, 21 s, and on the Cornell box, 18 s), the renders that
the per-estimator Mitsuba comparisons made before, in one place.
many_lights (2026-12-03) adds 5 cells and 14 skips, 60-95 s (bdpt 19-37 s).
keyhole (2026-12-03) adds 5 cells and 13 skips, about 45 s; corner_room 5 cells
and 14 skips, about 45 s.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.stats as st

import radiometer as rm
from radiometer.reference_scenes import references, registry

from refcompare import blocked_z_test, reference_variance_floor, region_mask, scale_region

ALPHA = 0.01
EST = rm.estimators()

# The scene features each capability is needed for (Scene.features).
NEEDS = {"has_media": "media", "has_dipole": "dipole"}

# Per canonical scene: the XML parameters (analytic scenes: any of their
# <default>s; Mitsuba scenes: their reference's, registry.fixed_params),
# spp, block size k and the bias the power check must see.
ANALYTIC = {
    # 32 x 32, max_depth 3 (emission, direct and indirect all present);
    # 256 spp, test_canonical_analytic.py's Russian-roulette budget: path
    # and direct are zero-variance here, the light tracers are not (at its
    # finite-depth 64 spp ptracer missed the 1 % power check).
    "furnace": {"params": {"res": 32, "max_depth": 3}, "spp": 256, "k": 4, "power": 1.01},
    # test_canonical_analytic.py: 256 spp at 64 x 64, 4 x 4 blocks (a light
    # tracer's sample count is spp x pixels: at 32 x 32 ptracer missed the
    # 1 % power check).
    "area_lights_disk": {"params": {"res": 64}, "spp": 256, "k": 4, "power": 1.01},
    "area_lights_rect": {"params": {"res": 64}, "spp": 256, "k": 4, "power": 1.01},
    # refcompare.check_mirror_caustic's 32 x 32, test_canonical_analytic.py's
    # 1024 spp, max_depth 3.
    # Each lit class (direct, caustic) to 3 % of its exact power, as
    # check_mirror_caustic held bdpt and ptracer.
    "mirror_caustic": {"params": {"res": 32}, "spp": 1024, "k": 4, "power": 1.01, "class_tol": 0.03},
}
# Analytic cells measured for particular estimators. Metropolis (pssmlt,
# mmlt) correlates neighbouring pixels, so its blocks get the
# Cauchy-Schwarz bound (correlated_pixels), under which a 1 % bias is
# within its noise at these budgets (measured 2026-12-02: the power check
# missed on furnace, area lights and mirror caustic); 5 % here, and its
# over-seed tests (tests/test_mlt.py) check bias to 3-5 % with power. mmlt's
# mirror caustic classes (one render, no variance): direct was 0.942 x exact;
# on the furnace (each sample one strategy) 5 % went undetected, so 10 %;
# on the mirror caustic 5 % went undetected under seed offset 5 (z -1.43).
_MLT_ANALYTIC = {n: {"power": 1.05} for n in ("furnace", "area_lights_disk", "area_lights_rect", "mirror_caustic")}
# ptracer on the furnace: at 256 spp the 1 % power check went undetected
# under seed offset 5 (its splats' noise on the furnace's uniform image).
ANALYTIC_PER = {"ptracer": {"furnace": {"spp": 1024}},
                "pssmlt": _MLT_ANALYTIC,
                "mmlt": {**_MLT_ANALYTIC, "furnace": {"power": 1.10},
                         "mirror_caustic": {"power": 1.10, "class_tol": 0.1}}}
# Per Mitsuba scene: spp, block size k, optionally "integrator" (estimator
# parameters every cell of the scene adds: many_lights' light tree) and the
# power check's bias (a float:
# the whole reference scaled by it; a (region, boxes, s) triple: the pixels
# outside `boxes` scaled by s, the region the scene is about). "per": the
# budgets measured for particular estimators where the scene's own does not
# suit them (each from the per-estimator test it replaced, measured there);
# an estimator without an entry runs at the scene's (a new one starts
# there, and gets an entry only from a measurement). A cell may name a
# "seed" in place of SEED; none does (a seed kept because it passes hides
# a budget at its edge).
AJAR_DOORWAY = (28, 15, 40, 41)  # ajar_door's card.md: the view through the doorway into the lit room
AJAR_BEAM = (54, 18, 64, 40)  # the lamp's strip through the gap on the near room's right wall
KEYHOLE_OPENING = (25, 24, 35, 32)  # keyhole's card.md: the far room seen through the opening
KEYHOLE_PATCH = (20, 40, 60, 62)  # the panel's light through the opening on the near room's floor
MITSUBA = {
    # test_cornell_reference.py's budgets: path 512, ptracer 256 (bdpt had
    # 128 there; the matrix holds it to 512).
    "cornell_box": {"spp": 512, "k": 4, "power": 1.01, "per": {"ptracer": {"spp": 256}}},
    # test_canonical_mitsuba.py's surface budgets: path and bdpt at the
    # scene's, ptracer at 1024 (light tracing spends its samples on the
    # whole scene, not on the pixels). mmlt: a bootstrap of 2^23, as its
    # depth 5's b_5 rests on a spike that 2^21 points find in 9 of 16
    # renders (UNDER_INVESTIGATION's comment; 2.3 x the time of 2^21).
    "glass_sphere_caustic": {"spp": 1024, "k": 4, "power": 1.01,
                             "per": {"mmlt": {"integrator": {"bootstrap_samples": 1 << 23}},
                                     "pssmlt": {"integrator": {"bootstrap_samples": 1 << 20}}}},
    "veach_mis": {"spp": 512, "k": 4, "power": 1.01,
                  "per": {"ptracer": {"spp": 1024}, "pssmlt": {"integrator": {"bootstrap_samples": 1 << 20}},
                          "mmlt": {"integrator": {"bootstrap_samples": 1 << 20}}}},
    # At 512 spp a 1 % overall bias is near the mean z's noise here
    # (measured for path: rejected for 1 of seeds 1-3), so the power check
    # scales the region the scene is about, the near room lit only through
    # the gap (every pixel outside the doorway and the lamp's strip), by 5 %.
    "ajar_door": {"spp": 512, "k": 4, "power": ("near room, indirect only", [AJAR_DOORWAY, AJAR_BEAM], 1.05),
                  "per": {"ptracer": {"spp": 1024}}},
    # All diffuse, the light easy to reach: 256 spp (path's image mean has
    # a standard error of about 0.04 % there, so a 1 % bias is plain).
    "corner_room": {"spp": 256, "k": 4, "power": 1.01},
    # keyhole (card.md): as ajar_door, the power check scales the near room
    # lit only indirectly through the opening (every pixel outside the
    # opening and the floor's directly lit patch) by 5 %. Budgets (2 loaded
    # cores, 2026-12-03): path 256 spp (5 s), bdpt 64 (7 s), ptracer 512
    # (12 s), pssmlt 64 (12 s), mmlt 256 (7 s); all pass under seed offsets
    # 0-5 (path, bdpt, ptracer 0-7) but ptracer under offset 1 (one block's
    # blue channel at p 2.6e-6 against 4.3e-6; image mean 1.004).
    "keyhole": {"spp": 256, "k": 4, "power": ("near room, indirect only", [KEYHOLE_OPENING, KEYHOLE_PATCH], 1.05),
                "per": {"bdpt": {"spp": 64}, "ptracer": {"spp": 512}, "pssmlt": {"spp": 64}}},
    # Media and subsurface scenes: path's (volpath's) budgets at the
    # scene's, measured per scene in its card.md (the block test's mean z
    # is biased negative for a heavy-tailed estimator, so each scene gets
    # the budget at which independent seeds pass). volumetric_caustic's
    # L S S V E paths are found only by phase sampling through the glass
    # sphere onto a small light: at 1024 spp 2 of 3 seeds failed with 4 x 4
    # blocks (mean z -3.7, -4.8) while 4 pooled renders matched (image mean
    # ratio 1.0035 +- 0.0043: skew, not bias); 16 x 16 blocks pass 3 of 3
    # and see a 2 % bias (the reference's own noise, 10 % per pixel, limits
    # what any budget can see).
    # bdpt (no pixel left out: its camera subpaths see through smooth
    # glass): at half its budgets the power checks failed (mean z -2.4 to
    # -2.9). volumetric_caustic: 10 % (5 % gave mean z -1.7 at 256 spp,
    # where 1.0 gave +0.25). translucent_slab: walks of hundreds of events
    # behind a smooth boundary make the blocks skewed (over seeds 1-7 at
    # 64 spp their mean z ran from -0.3 to -3.5), 8 x 8 blocks passing 6 of
    # 7 seeds (4 x 4: 5 of 7), while the image means pooled over 8 seeds x
    # 1024 spp are 0.994 / 0.997 / 0.997 of the reference (standard error
    # 0.4 %): a heavy tail, no bias measured. fog_room: 7 % (seeds 1-4 at
    # 64 spp: mean z -2.95 to -3.33 against the reference x 1.05, where the
    # channel's mean-z level is |z| > 3.26). translucent_object: 3 % (2 %
    # was rejected on each of seeds 1-4 by one channel only).
    # bdpt on translucent_slab at 256 spp: at 64 spp and SEED its image mean
    # was 0.974 of the reference (0.984 at 128; the heavy tail above), so it
    # had kept its old test's seed; at 256 spp it passes at SEED and under
    # seed offsets 1-3, its 5 % power check included. path on
    # volumetric_caustic likewise passes at SEED with its 10 % power check.
    # Power checks sized under fresh noise (seed offsets, docs/false_alarms.md):
    # path on translucent_slab 2 % (1 % was missed under offset 2 and both
    # its reruns: the strongest channel's mean z -2.98 against 3.26; 2 %
    # reaches -5.8 to -8.6); bdpt on translucent_slab 5 % (2 % was missed
    # under 9 of offsets 0-15; each 1 % moves mean z by about -0.9);
    # path on volumetric_caustic 10 % (mean z at 1.0 from -1.94 to +0.51
    # under offsets 0-2, -0.67 per 1 %: 2 % was missed under 2 of 3).
    # ptracer (the registry's exclusions: the torus of translucent_object
    # and the glass sphere of volumetric_caustic, each seen only through a
    # smooth boundary): volumetric_caustic's reference noise allows 5 % at
    # this budget (2 % gives mean z -2.4); translucent_slab is seen only
    # through glass (test_ptracer_media.py: light tracing renders it black),
    # so the registry declares no exclusion and the cell is skipped.
    "homogeneous_slab": {"spp": 512, "k": 4, "power": 1.01},
    "fog_room": {"spp": 1024, "k": 4, "power": 1.01,
                 "per": {"bdpt": {"spp": 64, "power": 1.07}, "ptracer": {"spp": 512, "power": 1.02}}},
    "translucent_slab": {"spp": 512, "k": 4, "power": 1.02,
                         "per": {"bdpt": {"spp": 256, "k": 8, "power": 1.05}}},
    "translucent_object": {"spp": 512, "k": 4, "power": 1.01,
                           "per": {"bdpt": {"spp": 64, "power": 1.03}, "ptracer": {"spp": 1024, "power": 1.02}}},
    "volumetric_caustic": {"spp": 1024, "k": 16, "power": 1.10,
                           "per": {"bdpt": {"spp": 256, "k": 8, "power": 1.10},
                                   "ptracer": {"spp": 1024, "k": 8, "power": 1.05}}},
    # many_lights (10 000 emitters of powers over five decades, card.md):
    # every cell selects emitters with the light tree ("integrator": the
    # scene's estimator parameters, added to each cell's), the selection
    # the scene is about; under every estimator's default, uniform, the
    # samples are heavy-tailed (a rare bright light at 0.25 m carries a
    # pixel), so the blocks' mean z runs negative: path at 512 spp, SEED,
    # 0.9935 of the reference with mean z -5.6 (4 x 4 blocks), -3.4 (8 x 8),
    # while power (1.0004, mean z -0.4) and tree (1.0013, +0.2) passed.
    # Per-sample relative variance (pixel variance / image mean^2, SEED):
    # path uniform 32, power 12, tree 5.
    # pssmlt at 64 spp (256 took 53 s on the loaded machine).
    "many_lights": {"spp": 256, "k": 4, "power": 1.02, "integrator": {"light_sampler": "tree"},
                    "per": {"pssmlt": {"spp": 64}}},
    # One pixel (an irradiance meter): a plain z-test, 2^18 samples (at that
    # budget bdpt's standard error is 0.5 % of T_d and 0.7 % of R, measured
    # in tests/test_irradiancemeter.py, hence 2 % and 3 %).
    "vandehulst_slab": {"spp": 1 << 18, "k": 1, "power": 1.02},
    "vandehulst_slab_reflectance": {"spp": 1 << 18, "k": 1, "power": 1.03},
}

# Biased and consistent estimators: the bound on |mean(image) / mean(ref) - 1|
# per declared bias, on the analytic scenes at BIASED_SPP / CONSISTENT_SPP.
# Measured first (2026-12-01, seeds 0..3 of every analytic cell): the
# largest |relative error of the mean| was 0.263 % for photonmapper
# (area_lights_rect, seed 2) and 0.346 % for sppm (mirror_caustic, seed 2);
# the bound is that times MEAN_BOUND_FACTOR = 2. Power: the reference mean
# scaled by MEAN_POWER must fall outside the bound.
MEAN_BOUND_FACTOR = 2.0
MEAN_BOUND = {"biased": MEAN_BOUND_FACTOR * 0.00263, "consistent": MEAN_BOUND_FACTOR * 0.00346}
MEAN_POWER = 1.02
# Cells whose spread over seeds was measured wider than that (2026-12-03,
# seeds 1000..1007 of render_cell, relative error of the image mean in %):
# bpm and ppm on the mirror caustic carry their radius bias, -0.54 on
# average (-0.34 .. -0.81; -0.735 and -0.773 under seed offsets 4 and 1);
# vpl and rowcolumn on the rectangle light are noise around 0 (-0.51 ..
# +0.46, sd 0.40; +0.625 under offset 1). Bound: twice the largest seen;
# power: a bias that lands about 2.5 bounds' widths away, 3 % for the
# noisy ones. (bound, power) per (estimator, scene).
MEAN_PER = {("bpm", "mirror_caustic"): (0.0161, 1.02), ("ppm", "mirror_caustic"): (0.0161, 1.02),
            ("vpl", "area_lights_rect"): (0.0125, 1.03), ("rowcolumn", "area_lights_rect"): (0.0125, 1.03)}

# Biased estimators whose bias is confined to the indirect class, every
# other class being path's own (irrcache, radcache: indirect light from their
# cache, the rest path traced on path's streams), and the analytic scenes on
# which that class is exact for them: nothing to cache (area lights, mirror
# caustic) or, for irrcache, constant (furnace: exact to 1e-4 there,
# tests/test_irrcache.py; radcache's harmonics projection is not). There they
# take the unbiased estimators' z-test at the scene's budget: at BIASED_SPP
# the path-traced caustic of mirror_caustic alone put irrcache's image mean
# 4.5 % off (measured 2026-12-02).
_NO_INDIRECT = ("area_lights_disk", "area_lights_rect", "mirror_caustic")
BIAS_CONFINED = {"irrcache": _NO_INDIRECT + ("furnace",), "radcache": _NO_INDIRECT}

SEED = 7
# Biased and consistent estimators render with their declared defaults
# (photonmapper: 250 000 photons per map, 32 final-gathering rays and 16
# shadow rays per camera sample; sppm: 250 000 photons per pass) at these
# spp instead of the scene's (at the scene's spp photonmapper alone took
# over 10 minutes). A consistent estimator's error shrinks with its passes
# (one per spp), so it gets more of them.
BIASED_SPP = 4
CONSISTENT_SPP = 32
# Consistent estimators that declare `light_paths` (vcm, bpm, ppm: default
# the pixel count, 1024 here) trace this many per pass: at 1024 their image
# mean spread over -1.9 % .. +0.9 % across seeds 0..3 (measured
# 2026-12-02, bpm on mirror_caustic and furnace), wider than the bound.
CONSISTENT_LIGHT_PATHS = 1 << 15


def _cells():
    out = []
    for est in sorted(EST):
        for name in sorted(registry.SCENES):
            marks = ()
            if registry.get(name).kind == "ours":
                # caustic_in_mirror: its reference is ours (bdpt on the unfolded
                # twin); the unbiased estimators' single renders there carry the
                # caustic by rare paths (path, bdpt: L S S D S E only by hitting
                # the light through the sphere), so its test is over seeds,
                # tests/test_caustic_in_mirror.py.
                marks = (pytest.mark.skip(reason=f"{name}: reference and its test in tests/test_caustic_in_mirror.py"),)
            out.append(pytest.param(est, name, id=f"{est}-{name}", marks=marks))
    return out


def _config(est, name):
    """(spec, cfg): the scene's budget, with the estimator's measured one
    where MITSUBA has it."""
    spec = registry.get(name)
    if spec.kind == "analytic":
        cfg = dict(ANALYTIC[name])
        cfg.update(ANALYTIC_PER.get(est, {}).get(name, {}))
        cfg["params"] = registry.scene_params(spec, cfg["params"])
    else:
        cfg = dict(MITSUBA[name])
        cfg.update(cfg.pop("per", {}).get(est, {}))
        cfg["params"] = dict(spec.fixed_params)
    return spec, cfg


def _box_filtered(spec):
    """Mitsuba references of box-filtered scenes have independent pixels
    (the variance floor applies); the Cornell box's gaussian splats."""
    from radiometer.reference_scenes.registry import xml_defaults

    return xml_defaults(spec).get("rfilter", "box") == "box"


def _skip_reason(est, spec, scene):
    caps = EST[est]["capabilities"]
    for feature, cap in NEEDS.items():
        if scene.features.get(feature) and not caps[cap]:
            return f"{est} does not declare capability '{cap}' ({spec.name} has {feature[4:]})"
    # The estimator's own refusal, by name (prt: lights not at infinity,
    # non-diffuse BSDFs; radiosity: non-diffuse BSDFs, non-area emitters),
    # the message render() would raise.
    why = rm.refusal(scene, {"type": est})
    if why:
        return f"{est} refuses {spec.name}: {why}"
    return None


def render_cell(est, name, seed=SEED):
    """(spec, cfg, result, reference) for one cell; skips with the reason."""
    spec, cfg = _config(est, name)
    scene = rm.load_file(spec.xml, **cfg["params"])
    why = _skip_reason(est, spec, scene)
    if why:
        pytest.skip(why)
    caps = EST[est]["capabilities"]
    complete = list(caps["effects"])
    partial = len(complete) < len(rm.EFFECTS)
    if spec.kind == "mitsuba" and caps["bias"] != "unbiased":
        pytest.skip(f"{est} is {caps['bias']}: on the Mitsuba scenes at the matrix's budget its image mean "
                    "spreads wider than a 2 % bias (measured: photonmapper on cornell_box -2.4 % .. +2.5 % over "
                    "seeds 0..3 at 4 spp; sppm 21 s per cornell_box render at 32 spp), so no power")
    if spec.kind == "mitsuba" and partial and est not in spec.exclusions:
        pytest.skip(f"{est} renders only {complete}; {name}'s Mitsuba reference is the total, and the "
                    f"registry declares no exclusions for {est} there")
    ref = references.reference(name, cfg["params"])
    integ = {"type": est, **cfg.get("integrator", {})}
    md = registry.max_depth(spec, cfg["params"])
    if md is not None and "max_depth" in EST[est]["params"]:
        integ["max_depth"] = md
    if caps["bias"] == "consistent" and "light_paths" in EST[est]["params"]:
        integ["light_paths"] = CONSISTENT_LIGHT_PATHS
    spp = {"biased": BIASED_SPP, "consistent": CONSISTENT_SPP}.get(_bias(est, spec), cfg["spp"])
    res = rm.render(scene, integrator=integ, spp=spp, seed=cfg.get("seed", seed), effects=complete if partial else None)
    return spec, cfg, res, ref, complete


def _bias(est, spec):
    """The declared bias, or "unbiased" on the scenes BIAS_CONFINED lists
    for the estimator."""
    bias = EST[est]["capabilities"]["bias"]
    return "unbiased" if spec.name in BIAS_CONFINED.get(est, ()) else bias


def _scaled(spec, cfg, image, variance):
    """The reference with the bias the power check must see: (image,
    variance, what)."""
    p = cfg["power"]
    if isinstance(p, tuple):
        region, boxes, s = p
        mask = ~region_mask(image.shape, boxes)
        img, var = scale_region(image, np.zeros_like(image) if variance is None else variance, mask, s)
        return img, None if variance is None else var, f"{(s - 1) * 100:.0f} % on the {region} region"
    return image * p, None if variance is None else variance * p * p, f"{(p - 1) * 100:.0f} %"


def _check_classes(spec, cfg, res, ref, complete, where):
    """Analytic scenes: the effect images sum to the image, every class the
    exact solution leaves dark is empty, and (cfg["class_tol"]) each lit
    class the estimator renders holds its exact power to that tolerance
    (the classes' own variances are not reported; the total's z-test above
    is the strict one)."""
    np.testing.assert_allclose(sum(res.effects.values()), res.image, rtol=1e-5, atol=1e-7, err_msg=where)
    for k, v in res.effects.items():
        lit = k in ref.effects and np.any(ref.effects[k])
        if not lit:
            assert not np.any(v), f"{where}: effect '{k}' must be empty here, has sum {float(v.sum()):g}"
        elif "class_tol" in cfg and k in complete:
            ratio = float(v.sum()) / float(ref.effects[k].sum())
            assert abs(ratio - 1) <= cfg["class_tol"], f"{where}: effect '{k}' at {ratio:.4f} x exact"


def _target(spec, ref, complete):
    """The reference of the classes `complete`: (image, variance)."""
    if spec.kind == "analytic":
        img = sum((ref.effects[k] for k in complete if k in ref.effects), np.zeros_like(ref.image))
        return img, None
    return ref.image, ref.variance


def _z(spec, cfg, res, ref, est, image, variance):
    # Metropolis chains correlate neighbouring pixels (capability
    # correlated_pixels): its block variance is the Cauchy-Schwarz bound,
    # and so is its mean z, as a chain's normalisation b scales every pixel
    # it visits: the whole image moves at once (measured: pssmlt on
    # veach_mis, b over 12 seeds 0.90 to 4.98 x its median with 16384
    # bootstrap samples; under seed offset 5 the image mean was 2.51 x the
    # reference, mean z +6.1 with independent blocks, +0.38 bounded).
    chained = bool(EST[est]["capabilities"].get("correlated_pixels"))
    if spec.kind == "analytic":
        return blocked_z_test(res.image, res.variance, image, None, a_correlated=chained, a_common_mode=chained,
                              alpha=ALPHA, k=cfg["k"])
    box = _box_filtered(spec)
    floor = reference_variance_floor(ref.variance, ref.spp, res.spp) if box else None
    # A light tracer's splats spread over the filter's footprint, so with a
    # filter wider than a pixel its own pixels are correlated too.
    light = EST[est]["capabilities"]["driver"] == "light"
    return blocked_z_test(res.image, res.variance, image, variance, b_splatted=not box,
                          a_correlated=chained or (light and not box), a_common_mode=chained,
                          alpha=ALPHA, k=cfg["k"], var_a_floor=floor, exclude=spec.exclusions.get(est, ()))


@pytest.mark.parametrize("name", sorted(registry.mitsuba_scenes()))
def test_mitsuba_reference_is_well_formed(name):
    """The committed reference is what the registry says was made: its
    runs and total spp, a variance layer, the reference's resolution (a
    1 x 1 irradiance meter without `res`), finite, not black."""
    spec = registry.get(name)
    path = spec.reference_exr
    assert path.exists(), (f"{path} is missing: regenerate it with "
                           f"python -m radiometer.reference_scenes.make_reference {name}")
    ref = rm.read_exr(path)
    assert ref.variance is not None, f"{path} has no variance layer"
    res = spec.fixed_params.get("res", 1)
    assert ref.image.shape == (res, res, 3), ref.image.shape
    assert np.all(np.isfinite(ref.image)) and np.all(np.isfinite(ref.variance)) and np.all(ref.variance >= 0), path
    assert int(ref.metadata.get("runs", 0)) == spec.runs, ref.metadata
    assert int(ref.metadata.get("total_spp", 0)) == spec.runs * spec.spp, ref.metadata
    assert float(ref.image.max()) > 0, f"{name}: the reference is black"


def _mean_z(spec, res, image, variance):
    """Per channel: z of the render's image mean against the reference's,
    with the render's own variance of its image mean (Metropolis:
    "mlt_image_mean_variance", batch means over independent chains) and
    the reference's (its pixels independent, or their Cauchy-Schwarz bound
    where Mitsuba splats)."""
    m = res.image.reshape(-1, 3).astype(np.float64).mean(axis=0)
    r = np.asarray(image, np.float64).reshape(-1, 3).mean(axis=0)
    v = np.asarray(res.stats["mlt_image_mean_variance"], np.float64)
    if variance is not None:
        sd = np.sqrt(np.asarray(variance, np.float64)).reshape(-1, 3)
        v = v + ((sd ** 2).sum(axis=0) / sd.shape[0] ** 2 if _box_filtered(spec) else sd.mean(axis=0) ** 2)
    return (m - r) / np.sqrt(v)


def _check_chained(spec, cfg, res, ref, est, image, variance, where):
    """Metropolis (correlated_pixels): a chain's normalisation b_c scales
    every pixel it visits, so one error is shared across the image. Blocks:
    the Cauchy-Schwarz bound on each block and on the mean z (the local
    test). The image's scale: its mean against the reference's with the
    batch-means variance of the mean (_mean_z), each channel at ALPHA / 3;
    power: the reference scaled by MLT_POWER (or the cell's own power on
    the analytic scenes) is rejected by that test."""
    passed, msg = _z(spec, cfg, res, ref, est, image, variance)
    ratio = res.image.mean() / max(image.mean(), 1e-30)
    assert passed, f"{where} ({res.spp} spp): mean / reference = {ratio:.5f}\n{msg}"
    crit = st.norm.isf(ALPHA / 6)
    z = _mean_z(spec, res, image, variance)
    assert np.all(np.abs(z) <= crit), (f"{where}: image mean / reference {ratio:.4f}, z {np.round(z, 2)} "
                                       f"(|z| <= {crit:.2f})")
    p = MLT_POWER.get((est, spec.name), cfg["power"])
    zs = _mean_z(spec, res, image * p, None if variance is None else variance * p * p)
    assert np.any(np.abs(zs) > crit), (f"{where}: a scale error of {(p - 1) * 100:.0f} % went undetected, "
                                       f"z {np.round(zs, 2)}")


# The scale error each Metropolis cell on a Mitsuba scene must see (its
# image mean's relative standard deviation at the matrix's budget, from the
# batch means, measured 2026-12-03 at SEED: pssmlt cornell_box 4.6 %,
# glass_sphere_caustic 4.7 %, veach_mis 7.1 %): about 6 of those, so the
# test rejects it under fresh noise too. pssmlt's spread is b's: each
# chain's bootstrap estimate of the normalisation (res.stats mlt_b_variance
# gave the same relative error), and on veach_mis and glass_sphere_caustic
# it is heavy-tailed (docs/mlt.md). mmlt (a normalisation per depth since
# 2026-12-06, pssmlt.cpp's head), measured under seed offsets 1-5 (and
# 6-9 where noted): cornell_box 0.36-0.39 % (was 10-13 %), corner_room
# 0.34-0.43 % (1 % went undetected under offsets 0, 1, 4, 5 and 7),
# ajar_door 0.89-0.93 %, keyhole 1.5-1.7 %, many_lights 0.56-0.57 %,
# glass_sphere_caustic with its 2^23 bootstrap 0.40-1.38 % (offsets 0-15;
# 0.47-4.4 % at 2^21), veach_mis with its 2^20
# bootstrap 3.1-4.6 % (offsets 0-15; b_2's bootstrap, the plates'
# highlights; 4.9-15 % at the default 65536). pssmlt glass_sphere_caustic
# with its 2^20 bootstrap (2026-12-06): 0.47-0.73 % (offsets 0-15).
MLT_POWER = {("pssmlt", "cornell_box"): 1.3, ("pssmlt", "glass_sphere_caustic"): 1.05,
             ("pssmlt", "veach_mis"): 1.5, ("pssmlt", "ajar_door"): 1.1,
             ("mmlt", "cornell_box"): 1.03, ("mmlt", "glass_sphere_caustic"): 1.3,
             ("mmlt", "veach_mis"): 1.3, ("mmlt", "ajar_door"): 1.06, ("mmlt", "corner_room"): 1.03,
             # many_lights (light tree), pssmlt image mean / reference at seed
             # offsets 0, 1, 2: 64 spp 0.991 / 0.984 / 1.014 (relative sd of
             # the mean from the batch means 1.4-1.7 %; at 256 spp the same
             # 0.991: b's error, not the chains').
             ("pssmlt", "many_lights"): 1.10, ("mmlt", "many_lights"): 1.04,
             # keyhole (2026-12-03, seeds 7, 8, 9; the batch means' relative
             # sd of the image mean): pssmlt 64 spp 1.015 / 0.981 / 0.974 of
             # the reference (sd 2.3-2.6 %).
             ("pssmlt", "keyhole"): 1.15, ("mmlt", "keyhole"): 1.10}


# Cells that fail today and are being investigated, with what was measured
# (an expected failure, not a pass: each still runs, and reports XPASS once
# it passes). pssmlt on glass_sphere_caustic at the default 16384
# bootstrap passed at SEED and under seed offsets 1-4, but under offset 5
# its image mean was 0.926 of the reference (mean z -11.9 with a
# batch-means sd of 0.67 %: b's tail, as on veach_mis); with a 2^20
# bootstrap (2026-12-06, 12 s) it passes under offsets 0-15 (0.990-1.006),
# so it runs that and left this list. mmlt (history in
# docs/mlt.md): with one normalisation b for all depths its cells on
# veach_mis, the Cornell box and glass_sphere_caustic failed under some
# offsets, b's heavy tail (on veach_mis 36 % of b was depth 1, camera rays
# hitting the r = 0.01 and 0.03 lights, relative sd 37 % per 2^20
# points), no strategy biased. Since 2026-12-06 each depth has its own
# bootstrap, chains and b_d, depth 1 is a camera pass, and the variance
# adds each b_d's bootstrap error: the Cornell box passes under offsets
# 0-15 (image mean 0.990-1.004 of the reference), veach_mis with a 2^20
# bootstrap (as pssmlt's; 4 s) under 0-15 (0.943-1.087, |mean z| <= 1.84;
# at the default 65536 it failed under 3 of 16: 12, mean 0.851 at z -3.35;
# 15, the power check; 8, one dim block). glass_sphere_caustic (docs/mlt.md,
# "mmlt on glass_sphere_caustic"), with a 2^21 bootstrap, failed under
# offsets 0, 9 and 12 at block (4, 5), the sphere's highlights of the light
# (reference 1.45 at pixel (17, 20)), which most renders miss and a few
# chains keep for long: its variance was the reference floor summed as if
# mmlt's pixels were independent; blocked_z_test now takes the floor by
# the Cauchy-Schwarz bound for correlated pixels (over the 16 renders the
# smallest block z went from -4.95 to -2.28). Then offset 0 failed the
# image mean (0.9817, z -3.96): b_5 rests on a spike (strategy s = 0, the
# light's image after four specular events) that its bootstrap found in 9
# of 16 renders, the 7 others about 1.5 % low (mean z -2.1). With 2^23
# points (80 s against 35 s at 2^21 under offset 0, loaded cores) b_5 found it
# under 15 of 16 offsets and the cell passes under all 16 (image mean
# 0.993-1.010 of the reference, |mean z| <= 1.85; under 15, whose b_5
# missed it, 0.994 at z -1.28), so it left this list. mmlt's new
# per-pixel degrees of freedom (res.arrays["mlt_variance_dof"]) are not
# used here: t quantiles with them rescued no render and cost power
# (docs/mlt.md).
UNDER_INVESTIGATION = {}


@pytest.mark.parametrize("est,name", _cells())
def test_estimator_matrix(est, name, request):
    if (est, name) in UNDER_INVESTIGATION:
        request.applymarker(pytest.mark.xfail(reason=UNDER_INVESTIGATION[(est, name)], strict=False))
    spec, cfg, res, ref, complete = render_cell(est, name)
    where = f"{est} on {name}"
    assert res.stats["nan_samples"] == 0 and res.stats["inf_samples"] == 0, res.stats
    for what, a in [("image", res.image), ("variance", res.variance)] + list(res.effects.items()):
        assert np.all(np.isfinite(a)), f"{where}: {what} has non-finite pixels"
        assert not np.any(np.asarray(a) < 0), f"{where}: {what} has negative values"
    image, variance = _target(spec, ref, complete)
    bias = _bias(est, spec)
    if spec.kind == "analytic":
        _check_classes(spec, cfg if bias == "unbiased" else {}, res, ref, complete, where)
    if bias == "unbiased" and EST[est]["capabilities"].get("correlated_pixels"):
        _check_chained(spec, cfg, res, ref, est, image, variance, where)
        return
    if bias == "unbiased":
        passed, msg = _z(spec, cfg, res, ref, est, image, variance)
        ratio = res.image.mean() / max(image.mean(), 1e-30)
        assert passed, f"{where} ({res.spp} spp, {complete}): mean / reference = {ratio:.5f}\n{msg}"
        image_s, var_s, what = _scaled(spec, cfg, image, variance)
        passed, msg = _z(spec, cfg, res, ref, est, image_s, var_s)
        assert not passed, f"{where}: a bias of {what} went undetected\n{msg}"
        return
    bound, power = MEAN_PER.get((est, name), (MEAN_BOUND[bias], MEAN_POWER))
    err = res.image.mean() / image.mean() - 1
    assert abs(err) <= bound, (f"{est} ({bias}) on {name}: image mean off by {err * 100:+.3f} % "
                               f"(bound {bound * 100:.3f} %)")
    err_s = res.image.mean() / (image.mean() * power) - 1
    assert abs(err_s) > bound, f"{where}: a {(power - 1) * 100:.0f} % bias went undetected"
