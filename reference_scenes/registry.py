"""The canonical scenes, in one place: for each its XML, where its
reference comes from and how it was made. The Mitsuba references
(make_reference.py, `radiometer refs`), the benchmark harness (its matrices,
jobs and per-effect references) and the scene tests all read this table.

- "analytic": the scene's analytic.py (reference_scenes/<folder>), exact,
  with an exact split into effect classes where the physics gives one
  (furnace: emission / direct / indirect by bounce count; area lights: all
  direct; mirror caustic: direct + caustic). Any XML parameter may be
  overridden (the solution takes them), so a smoke matrix can run them at
  8 x 8 pixels.
- "mitsuba": reference_scenes/<folder>/reference.exr, the mean of `runs`
  Mitsuba 3 renders of `spp` each with the variance of that mean, made with
  `fixed_params` and `mitsuba_integrator` (make_reference.py); whatever is
  compared with it must use those parameters unchanged (a benchmark matrix
  that overrides them is refused). Their per-effect references are long
  runs of our own unbiased `effect_ref_estimator` at `effect_ref_spp`,
  accepted only when their total passes the blocked z-test against
  Mitsuba's (benchmarks/effect_refs.py).
- "ours": reference_scenes/<folder>/reference.exr made by our own unbiased
  renderer (`ours_estimator`) on a scene of the same expectation where that
  estimator samples the light well (`ours_scene`, in the folder), by the
  folder's make_reference.py: for scenes Mitsuba's estimators cannot render
  to a useful precision (caustic_in_mirror: a caustic seen only in a
  mirror, L S S D S E, which no connection reaches; its unfolded twin by
  the method of images shows the caustic directly). Otherwise as a
  Mitsuba reference: mean and variance of the mean, `fixed_params`
  unchanged; no per-effect reference.

A scene may carry committed references at further resolutions
(`more_refs`, reference_<res>.exr, each with its own budget): the main job
renders at 128 x 128 where one exists, the tests compare at the
registry's own resolution (reference.exr). A job at a resolution with no
reference is refused, naming those that exist.

Committed references stay small: at most 256 px a side (64 x 64 keeps the
EXR ~100 KB, 128 x 128 ~390 KB). Budgets and times of the Mitsuba references: llvm_ad_rgb on
2 shared cores. Most scenes are box-filtered, so a sample lands in one
pixel and Mitsuba's pixels are independent (its box filter splats nowhere
else); card.md in each folder says what the scene isolates.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class SceneSpec:
    name: str
    xml: Path
    kind: str  # "analytic", "mitsuba" or "ours"
    folder: str
    fixed_params: dict = field(default_factory=dict)  # mitsuba: the reference's XML parameters
    # The Mitsuba reference: `runs` independent renders (seeds 0 .. runs-1)
    # of `spp` samples per pixel each, with `mitsuba_integrator` (a Mitsuba
    # plugin dict) in place of the scene's own integrator when given.
    runs: int = 0
    spp: int = 0
    mitsuba_integrator: Optional[dict] = None
    # Budget and estimator of the per-effect reference (ours, unbiased, all
    # cores), mitsuba scenes.
    effect_ref_spp: int = 0
    effect_ref_estimator: str = "path"
    # Known exclusions: estimator -> pixel boxes (x0, y0, x1, y1), half-open,
    # at the reference's resolution, that the estimator cannot estimate and
    # that a comparison with the reference leaves out (why: the comments
    # below and the scene's card.md).
    exclusions: dict = field(default_factory=dict)
    # "ours" references: the estimator and the scene (a file in the
    # folder) of make_reference.py.
    ours_estimator: str = ""
    ours_scene: str = ""
    # A model variant (MODEL_VARIANTS): the scene whose physics this one
    # approximates with another model; its reference is that scene's, so
    # what a render of this one misses against it is the model's error.
    model_of: Optional[str] = None
    # mitsuba: "module:function" in the scene's folder that writes, at the
    # path it is given, the XML Mitsuba's reference renders in place of
    # `xml`: the same scene with the same expectation, differing only in
    # how Mitsuba samples it (many_lights: every emitter's sampling_weight
    # set to its power, a parameter our loader does not take).
    mitsuba_writer: str = ""
    # mitsuba: parameters of the per-effect reference's estimator beyond
    # max_depth (many_lights: the light tree; under the default uniform
    # selection its samples are heavy-tailed and the total's z-test
    # rejects it, card.md).
    effect_ref_params: dict = field(default_factory=dict)
    # mitsuba and ours: committed references at further resolutions, res ->
    # (runs, spp, effect_ref_spp[, first_seed]), each in reference_<res>.exr beside
    # reference.exr (which is at fixed_params["res"] and stays what the
    # tests compare with). A job may set `res` to any resolution listed
    # here, nothing else of fixed_params. Keyed by resolution, not a second
    # scene, so that a matrix names the scene once and its records stay one
    # scene in the store and the report.
    more_refs: dict = field(default_factory=dict)

    @property
    def reference_exr(self) -> Path:
        """The committed reference at the registry's own resolution
        (mitsuba and ours scenes)."""
        return self.xml.parent / "reference.exr"

    @property
    def resolutions(self) -> tuple:
        """The resolutions a committed reference exists for, ascending
        (empty for analytic scenes, which render at any)."""
        base = self.fixed_params.get("res")
        return tuple(sorted(([int(base)] if base is not None else []) + [int(r) for r in self.more_refs]))

    def _check_res(self, res) -> Optional[int]:
        base = self.fixed_params.get("res")
        if res is None or (base is not None and res == base):
            return None
        if res not in self.more_refs:
            have = ", ".join(f"{r} x {r}" for r in self.resolutions) or "none: its film is fixed"
            whose = "Mitsuba reference" if self.kind == "mitsuba" else "reference of ours"
            raise ValueError(f"{self.name}: no {whose} at res = {res!r} (references exist at: {have}); "
                             f"another resolution needs a new reference (registry.py more_refs)")
        return int(res)

    def reference_file(self, res=None) -> Path:
        """The committed reference at resolution `res` (None: the registry's
        own); ValueError naming the scene and the resolutions that exist
        when there is none at `res`."""
        r = self._check_res(res)
        return self.reference_exr if r is None else self.xml.parent / f"reference_{r}.exr"

    def budget(self, res=None) -> tuple:
        """(runs, spp, effect_ref_spp) of the reference at `res`."""
        r = self._check_res(res)
        return (self.runs, self.spp, self.effect_ref_spp) if r is None else tuple(self.more_refs[r][:3])

    def first_seed(self, res=None) -> int:
        """The first of the reference's `runs` consecutive seeds: 0, or a
        more_refs entry's fourth value. Why one may need another: Mitsuba's
        light tracer traces the same light paths for the same seed and
        sample count whatever the film, so a 128 x 128 reference at 1/4
        of the spp from seeds 0.. is the 64 x 64 one's samples binned
        finer (ajar_door's first one: its 2 x 2 means equalled the 64 x 64
        image to |z| < 6e-4) and the two cannot check each other."""
        r = self._check_res(res)
        return 0 if r is None or len(self.more_refs[r]) < 4 else int(self.more_refs[r][3])


def _analytic(name, xml, folder):
    return SceneSpec(name, HERE / folder / xml, "analytic", folder)


def _mitsuba(name, params, runs, spp, effect_ref_spp, effect_ref_estimator="path", integrator=None,
             exclusions=None, mitsuba_writer="", effect_ref_params=None, more_refs=None):
    return SceneSpec(name, HERE / name / "scene.xml", "mitsuba", name, dict(params), runs, spp, integrator,
                     effect_ref_spp, effect_ref_estimator, dict(exclusions or {}), mitsuba_writer=mitsuba_writer,
                     effect_ref_params=dict(effect_ref_params or {}), more_refs=dict(more_refs or {}))


# 128 x 128 references (more_refs, the main job's resolution): each in
# about the time of its 64 x 64 one, so 1/4 of the spp per pixel (the
# same runs); a 3 s job at 128 reaches about 1/4 of its spp at 64 too
# (cornell_box path: 90 against 366 spp, glass_sphere_caustic 239 against
# 956, veach_mis 112 against 499; one thread, 2 loaded cores, 2026-12-03),
# so the reference keeps its ratio to a job's noise: 180 x (cornell_box),
# 550 x (glass_sphere_caustic), 590 x (veach_mis) less variance. Their
# per-effect references likewise at 1/4 of the spp. Times measured
# 2026-12-03 with llvm_ad_rgb sharing 2 cores with a test suite (about
# one core left to it), beside the 64 x 64 ones' own times.
# Per-effect reference budgets (surface scenes): about 15-60 s each with
# `path` on 2 cores (measured 2026-11: cornell ~250 spp/s, glass ~650, veach
# ~550 at 64 x 64), 10-30 x what a 4 s benchmark job reaches. Media scenes:
# `path` (volpath) passes its z-tests against these references at 512-1024
# spp (tests/test_canonical_mitsuba.py); 1024 keeps the main job's first run
# near 10 minutes (translucent_slab ~36 s).
_SCENES = [
    _analytic("furnace", "scene.xml", "furnace"),
    _analytic("area_lights_disk", "disk_light.xml", "area_lights"),
    _analytic("area_lights_rect", "rect_light.xml", "area_lights"),
    _analytic("mirror_caustic", "scene.xml", "mirror_caustic"),
    # 32 x 2048 = 65536 spp in total: the reference's variance is 1/256 of a
    # 256 spp test render's, so it barely widens the z-test. About 3-4
    # minutes. Gaussian-filtered (Mitsuba's splats correlate its pixels:
    # tests/test_cornell_reference.py). ptracer: nothing left out (every
    # surface is diffuse: there is no specular class to miss). 128 x 128:
    # 32 x 512 spp in 162 s (the 64 x 64: 117 s).
    _mitsuba("cornell_box", {"res": 64, "max_depth": 8}, 32, 2048, 8192, exclusions={"ptracer": []},
             more_refs={128: (32, 512, 2048)}),
    # 524288 spp in all, ~2.5 min. ptracer: the sphere itself is seen
    # through a delta BSDF (L ... S E), which a light path can never
    # connect to a pinhole camera through, so light tracing renders it 0.
    # 128 x 128: 32 x 4096 spp in 324 s (64 x 64: 225 s).
    _mitsuba("glass_sphere_caustic", {"res": 64, "max_depth": 12}, 32, 16384, 16384,
             exclusions={"ptracer": [(16, 14, 41, 39)]}, more_refs={128: (32, 4096, 4096)}),
    # 262144 spp, ~3 min. ptracer: the plates of alpha 0.005 and 0.02
    # reflect the indirectly lit room into the camera through lobes so
    # narrow that light tracing's estimate is carried by rare huge samples
    # (a heavy tail, not a bias; measured in card.md). 128 x 128: 32 x
    # 2048 spp in 348 s (64 x 64: 200 s).
    _mitsuba("veach_mis", {"res": 64, "max_depth": 8}, 32, 8192, 16384,
             exclusions={"ptracer": [(0, 28, 64, 34), (0, 34, 64, 39)]}, more_refs={128: (32, 2048, 4096)}),
    # Mitsuba's light tracer, not its path tracer: the near room is lit only
    # by a narrow strip the lamp throws through the door's gap, which a
    # camera path finds by BSDF sampling less than 1 time in 100 per
    # bounce, while every light path that leaves the far room lands on it
    # first. All surfaces are diffuse, so light tracing sees every path
    # (card.md: its cross-check against Mitsuba's path). The per-effect
    # reference is `bdpt`'s (unbiased, every strategy filed under its effect
    # class): it reaches there in 1024 spp what path would in ~20 000 (21 x
    # less error per sample, card.md), in about 20 s on 2 cores. ptracer:
    # nothing left out (every surface is diffuse, so light tracing renders
    # every path class there is; tests/test_canonical_mitsuba.py).
    # 128 x 128: 32 x 1024 spp from seeds 1000.. (first_seed: its light
    # paths would otherwise be the 64 x 64 one's) in 1281 s (beside a test
    # run; from seeds 0..: 725 s; 64 x 64: 875 s); per-effect reference
    # bdpt at 256 spp.
    _mitsuba("ajar_door", {"res": 64, "max_depth": 10}, 32, 4096, 1024, "bdpt",
             integrator={"type": "ptracer", "max_depth": 10}, exclusions={"ptracer": []},
             more_refs={128: (32, 1024, 256, 1000)}),
    # Many concave corners, all diffuse (card.md): what irradiance caching
    # interpolates worst. Mitsuba's path tracer (the scene's integrator):
    # the light under the ceiling faces the open room, so NEE finds it from
    # every surface. Per-effect reference: path, 1024 spp. ptracer: nothing
    # left out (all diffuse, the camera sees no light).
    _mitsuba("corner_room", {"res": 64, "max_depth": 8}, 32, 4096, 1024, exclusions={"ptracer": []}),
    # keyhole: a room lit only through a 0.5 x 0.5 opening by a diffuse
    # panel behind it (card.md). Mitsuba's light tracer, as for ajar_door:
    # every surface is diffuse and no light is seen, so light tracing
    # renders every path; a few per cent of its light paths cross the
    # opening (3.1 % directly), so 64 x 1024 spp (ajar_door, where a
    # fifth does, had 32 x 4096) took 509 s on 2 shared cores, median
    # per-pixel standard error 1.38 % (1.41 % in the near room lit
    # indirectly). Per-effect reference: bdpt at 256 spp (about 30 s).
    _mitsuba("keyhole", {"res": 64, "max_depth": 10}, 64, 1024, 256, "bdpt",
             integrator={"type": "ptracer", "max_depth": 10}, exclusions={"ptracer": []}),
    # Media and subsurface scenes: Mitsuba's volpath (the scene's integrator).
    # ptracer: nothing left out of these two (no surface seen only through
    # glass; tests/test_ptracer_media.py measured them whole).
    _mitsuba("homogeneous_slab", {"res": 64, "max_depth": 8}, 32, 4096, 1024, exclusions={"ptracer": []}),
    _mitsuba("fog_room", {"res": 64, "max_depth": 16}, 32, 1024, 1024, exclusions={"ptracer": []}),
    _mitsuba("vandehulst_slab", {"max_depth": 256}, 32, 524288, 1024),  # a 1 x 1 irradiancemeter film
    _mitsuba("vandehulst_slab_reflectance", {"max_depth": 256}, 32, 524288, 1024),  # a 1 x 1 irradiancemeter film
    _mitsuba("translucent_slab", {"res": 64, "max_depth": 1024}, 32, 256, 1024),
    # ptracer: the torus is seen through its smooth dielectric boundary
    # only (L ... S E); what stays is the floor, lit directly and through it.
    _mitsuba("translucent_object", {"res": 64, "max_depth": 512}, 32, 1024, 1024,
             exclusions={"ptracer": [(12, 6, 53, 48)]}),
    # ptracer: the glass sphere, seen through itself.
    _mitsuba("volumetric_caustic", {"res": 64, "max_depth": 12}, 32, 2048, 1024,
             exclusions={"ptracer": [(23, 24, 41, 41)]}),
    # 10 000 emitters (points, small squares, two meshed tubes) of powers
    # over five decades, 60 % behind a partition (card.md). Mitsuba renders
    # the copy generate.write_weighted makes, each emitter's sampling_weight
    # its power (Mitsuba picks emitter i with probability w_i / sum w; the
    # expectation is unchanged); 806 s on 2 loaded cores. Per-effect
    # reference: path with the light tree, 1024 spp. ptracer: nothing left
    # out (all diffuse).
    _mitsuba("many_lights", {"res": 64, "max_depth": 4}, 32, 2048, 1024, exclusions={"ptracer": []},
             mitsuba_writer="generate:write_weighted", effect_ref_params={"light_sampler": "tree"}),
]
# Ours, not Mitsuba's: the caustic is seen only in the mirror (L S S D S E),
# so Mitsuba's path tracer (NEE blocked by the glass, the small light found
# by chance through the sphere) would need hours for a 64 x 64 reference.
# bdpt on the unfolded scene (method of images; card.md) at 16 x 1024 spp,
# about 3 minutes on 2 shared cores. 128 x 128: 16 x 256 spp in 104 s
# (ours, threads 0: both cores; the 64 x 64 took 129 s).
_SCENES.append(SceneSpec("caustic_in_mirror", HERE / "caustic_in_mirror" / "scene.xml", "ours", "caustic_in_mirror",
                         {"res": 64, "max_depth": 16}, 16, 1024, ours_estimator="bdpt", ours_scene="unfolded.xml",
                         more_refs={128: (16, 256, 0)}))
SCENES = {s.name: s for s in _SCENES}


def _variant(name, of, xml):
    base = SCENES[of]
    return SceneSpec(name, base.xml.parent / xml, base.kind, base.folder, dict(base.fixed_params), base.runs,
                     base.spp, base.mitsuba_integrator, 0, base.effect_ref_estimator, {}, model_of=of)


# Scenes with one known alternative model (the model term of the error
# budget): the same geometry and optical properties with another
# physical model, measured against the original scene's reference. Kept out
# of SCENES (whose every scene is compared with its reference as an
# estimator test: a model variant differs from it by design); the bench
# matrices may name them, and their jobs record the model term. No
# per-effect reference (effect_ref_spp 0): the totals are what the model
# term compares.
#   *_dipole: the dipole BSSRDF (Jensen et al. 2001; dipole.xml next to the
#   scene, rendered by `path`) in place of the random-walk medium, against
#   Mitsuba's random walk (benchmarks/studies/dipole_vs_randomwalk.py
#   measured the gap first).
MODEL_VARIANTS = {s.name: s for s in (
    _variant("translucent_slab_dipole", "translucent_slab", "dipole.xml"),
    _variant("translucent_object_dipole", "translucent_object", "dipole.xml"),
)}
# Every scene a matrix may name.
ALL_SCENES = {**SCENES, **MODEL_VARIANTS}


def get(name: str) -> SceneSpec:
    try:
        return ALL_SCENES[name]
    except KeyError:
        raise KeyError(f"unknown scene '{name}' (known: {', '.join(sorted(ALL_SCENES))})") from None


def mitsuba_scenes() -> dict:
    """The scenes whose reference is Mitsuba's, by name."""
    return {n: s for n, s in SCENES.items() if s.kind == "mitsuba"}


def xml_defaults(spec: SceneSpec) -> dict:
    from radiometer.reference_scenes.area_lights.analytic import xml_defaults as _d

    return _d(spec.xml)


def scene_params(spec: SceneSpec, overrides: Optional[dict] = None) -> dict:
    """The XML parameters a job renders with: the reference's, then the
    matrix's overrides (refused for Mitsuba-referenced scenes when they
    differ from the reference's)."""
    overrides = dict(overrides or {})
    if spec.kind in ("mitsuba", "ours"):
        out = dict(spec.fixed_params)
        if "res" in overrides and "res" in spec.fixed_params:
            spec.reference_file(overrides["res"])  # a resolution without a reference: the error names those with one
            out["res"] = overrides.pop("res")
        for k, v in overrides.items():
            if k not in spec.fixed_params or spec.fixed_params[k] != v:
                whose = "Mitsuba" if spec.kind == "mitsuba" else "our own"
                raise ValueError(f"parameter '{k}' = {v!r}: {spec.name}'s {whose} reference was made with "
                                 f"{spec.fixed_params}; these cannot change without a new reference")
        return out
    defaults = xml_defaults(spec)
    for k in overrides:
        if k not in defaults:
            raise ValueError(f"parameter '{k}': not a <default> of {spec.xml.name} "
                             f"(known: {', '.join(sorted(defaults))})")
    return overrides


def max_depth(spec: SceneSpec, params: Optional[dict] = None) -> Optional[int]:
    """The scene's max_depth (the job's parameter, else the reference's or
    the XML default)."""
    params = spec.fixed_params if params is None else params
    if "max_depth" in params:
        return int(params["max_depth"])
    d = xml_defaults(spec).get("max_depth")
    return None if d is None else int(float(d))
