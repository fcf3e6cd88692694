"""The estimator registry (renderer/render/registry.h): every estimator's
declaration read from the core, the parameters checked once in C++ against
it, and the views built from it (radiometer.registry, INTEGRATOR_PARAMS, the
loader's plugin table, `radiometer render --help-integrator`).

The checks run over every registered estimator and every declared
parameter, so an estimator added later is covered by registering."""
import math

import numpy as np
import pytest

import radiometer as rm
from radiometer import _core, registry
from radiometer.cli import main
from radiometer.render import _integrator_desc

EST = rm.estimators()
PARAMS = [(n, k) for n, e in EST.items() for k in e["params"]]
USED = [(n, k) for n, e in EST.items() for k, p in e["params"].items() if not p["ignored"] and not p["sets"]]


def _resolve(itype, **params):
    return _core.resolve_integrator(_core.IntegratorDesc(itype, params))


# --- the schema -------------------------------------------------------------------


def test_schema_is_complete():
    assert EST, "no estimator registered (the core must be linked as an object library)"
    for name, e in EST.items():
        assert e["name"] == name and e["doc"], name
        caps = e["capabilities"]
        assert set(caps) == {"media", "dipole", "driver", "bias", "effects", "correlated_pixels"}, name
        assert caps["driver"] in ("camera", "light", "own"), name
        assert caps["bias"] in ("unbiased", "consistent", "biased"), name
        assert caps["effects"] and set(caps["effects"]) <= set(rm.EFFECTS), name
        for k, p in e["params"].items():
            assert p["type"] in ("int", "float", "bool", "string") and p["doc"], (name, k)
            assert (p["default"] is None) == (p["ignored"] or bool(p["sets"])), (name, k)


@pytest.mark.parametrize("name", sorted(EST))
def test_defaults_round_trip(name):
    """With no parameters an estimator is built (its factory reads every
    declared parameter) and runs with its declared defaults; resolving the
    resolved set again changes nothing."""
    e = EST[name]
    want = {k: p["default"] for k, p in e["params"].items() if p["default"] is not None}
    got = _resolve(name)
    assert got == want and list(got) == list(want)
    for k, v in got.items():
        assert type(v) is {"int": int, "float": float, "bool": bool, "string": str}[e["params"][k]["type"]], k
    assert _resolve(name, **got) == got
    spec = _integrator_desc({"type": name, **got}, None)
    assert spec == {"type": name, **got}


def test_views_match_the_schema():
    from radiometer.loader import PLUGINS
    from radiometer.render import INTEGRATOR_PARAMS, PLANNED_INTEGRATORS

    names = registry.estimator_names()
    assert set(names) == set(EST) | {a for e in EST.values() for a in e["aliases"]}
    # The loader's table: the estimators, and Mitsuba's `moment` wrapper around one.
    assert tuple(PLUGINS["integrator"]) == names + ("moment",)
    assert set(INTEGRATOR_PARAMS) == set(names)
    for n in names:
        e = registry.estimator(n)
        assert list(INTEGRATOR_PARAMS[n]) == list(e["params"])
    # Planned names are those the design lists and nobody registered (none
    # since the second half's estimators landed): never a registered one.
    assert not set(PLANNED_INTEGRATORS) & set(names)


# --- errors, each naming the estimator and the parameter ---------------------------


def _raises(spec, *words):
    scene = rm.load_dict({"type": "scene", "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4,
                                                                                      "height": 4}}})
    with pytest.raises(rm.SceneError) as e:
        rm.render(scene, integrator=spec, spp=1)
    for w in words:
        assert w in str(e.value), str(e.value)
    return e.value


@pytest.mark.parametrize("name", sorted(EST))
def test_unknown_parameter(name):
    e = _raises({"type": name, "bogus_param": 1}, f"integrator '{name}'", "unknown parameter 'bogus_param'",
                "known: ")
    assert e.estimator == name and e.parameter == "bogus_param"
    for k in EST[name]["params"]:
        assert k in str(e)


def test_unused_parameter_is_an_error():
    """A declared parameter the factory never reads (ParamReader's check,
    after pbrt-v4's ReportUnused) fails naming it; reading it passes."""
    with pytest.raises(rm.SceneError, match="integrator 'bdpt': parameter 'beta' is not used") as e:
        _core.param_reader_check("bdpt", {"beta": 3.0}, ["max_depth", "rr_depth", "hide_emitters", "mis",
                                                          "strategy_images"])
    assert e.value.parameter == "beta"
    got = _core.param_reader_check("bdpt", {"beta": 3.0}, ["max_depth", "rr_depth", "hide_emitters", "mis",
                                                            "strategy_images", "beta"])
    assert got["beta"] == 3.0


def _outside(p):
    """Values just outside a parameter's declared range (none when any value goes)."""
    if p["choices"]:
        return ["no_such_choice"]
    out = []
    step = 1 if p["type"] == "int" else 1e-3
    if p["min"] is not None:
        out.append(p["min"] if p["min_open"] else p["min"] - step)
    if p["max"] is not None:
        out.append(p["max"] if p["max_open"] else p["max"] + step)
    special = set(p["special"])
    return [v for v in out if v not in special]


@pytest.mark.parametrize("name,param", [(n, k) for n, k in USED if _outside(EST[n]["params"][k])])
def test_out_of_range(name, param):
    p = EST[name]["params"][param]
    with_ = COMPANIONS.get((name, param), {})
    for v in _outside(p):
        e = _raises({"type": name, param: v, **with_}, f"integrator '{name}'", f"parameter '{param}'", p["range"])
        assert e.parameter == param
    # The ends and special values themselves are accepted.
    ok = [p["min"]] if p["min"] is not None and not p["min_open"] else []
    ok += [p["max"]] if p["max"] is not None and not p["max_open"] else []
    ok += list(p["special"]) + (p["choices"] or [])
    for v in ok:
        if (name, param) == ("direct", "emitter_samples") or (name, param) == ("direct", "bsdf_samples"):
            continue  # 0 alone is fine, both 0 is not (test_direct_counts)
        assert _resolve(name, **{param: v}, **with_)[param] == v


# Parameters that apply only beside another (set without it they are
# refused by the estimator's factory, naming both): the companion setting
# under which their range is checked.
COMPANIONS = {("radiosity", "hr_epsilon"): {"hierarchical": True},
              ("radiosity", "min_area"): {"hierarchical": True}}


@pytest.mark.parametrize("name,param", PARAMS)
def test_wrong_type(name, param):
    p = EST[name]["params"][param]
    wrong = {"int": [2.5, "3", True], "float": ["0.5", False], "bool": [1, "true"], "string": [1, True]}[p["type"]]
    for v in wrong:
        e = _raises({"type": name, param: v}, f"integrator '{name}'", f"parameter '{param}'", "expects")
        assert e.parameter == param


def test_numbers_convert_as_declared():
    # An integer is a number; numpy scalars are plain values.
    assert _resolve("bdpt", beta=3)["beta"] == 3.0 and type(_resolve("bdpt", beta=3)["beta"]) is float
    assert _resolve("path", max_depth=np.int64(4), hide_emitters=np.bool_(True)) == {
        "max_depth": 4, "rr_depth": 5, "hide_emitters": True, "truncation_probe": 0.0625, "equiangular": False,
        "light_sampler": "uniform"}
    _raises({"type": "bdpt", "beta": math.nan}, "parameter 'beta'", "finite")
    _raises({"type": "sppm", "initial_radius": math.inf}, "parameter 'initial_radius'", "finite")
    _raises({"type": "path", "max_depth": 1 << 40}, "parameter 'max_depth'", "32-bit")
    _raises({"type": "path", "max_depth": [3]}, "parameter 'max_depth'", "must be an integer, float, boolean or string")
    # A float just below an open bound that single precision rounds onto it.
    _raises({"type": "sppm", "alpha": 1 - 1e-12}, "parameter 'alpha'", "(0, 1)")


def test_direct_counts():
    _raises({"type": "direct", "emitter_samples": 0, "bsdf_samples": 0}, "integrator 'direct'", "not both 0")
    assert _resolve("direct", emitter_samples=0)["bsdf_samples"] == 1
    # Mitsuba's shading_samples sets both counts; with one of them it is refused.
    assert _resolve("direct", shading_samples=3) == {"emitter_samples": 3, "bsdf_samples": 3, "hide_emitters": False,
                                                     "light_sampler": "uniform"}
    _raises({"type": "direct", "shading_samples": 3, "bsdf_samples": 2}, "parameter 'shading_samples'", "give either")
    _raises({"type": "direct", "shading_samples": -1}, "parameter 'shading_samples'", ">= 0")


def test_ignored_parameters_are_checked_then_dropped():
    assert "samples_per_pass" not in _resolve("ptracer", samples_per_pass=64)
    assert "granularity" not in _resolve("sppm", granularity=1024)
    _raises({"type": "ptracer", "samples_per_pass": "many"}, "parameter 'samples_per_pass'", "expects an integer")


def test_estimators_unknown_and_planned():
    e = _raises("nosuch", "unknown estimator 'nosuch'", "known: ")
    assert e.estimator == "nosuch" and e.parameter is None
    for n in registry.estimator_names():
        assert n in str(e)
    for n in registry.planned_estimators():
        _raises(n, f"estimator '{n}' is not implemented yet")


# --- aliases ------------------------------------------------------------------------


@pytest.mark.parametrize("name,param", [(n, k) for n, k in PARAMS if EST[n]["params"][k]["aliases"]])
def test_parameter_aliases(name, param):
    p = EST[name]["params"][param]
    v = p["default"]
    if isinstance(v, bool):
        v = not v
    elif isinstance(v, (int, float)):
        v = v + 1 if p["min"] is None or v + 1 >= p["min"] else p["min"] + 1
        if p["max"] is not None and v >= p["max"]:
            v = p["min"]
    for alias in p["aliases"]:
        assert _resolve(name, **{alias: v}) == _resolve(name, **{param: v})
        assert _resolve(name, **{alias: v})[param] == v
        _raises({"type": name, alias: v, param: v}, f"parameter '{alias}'", f"alias '{param}'", "give one")


def test_estimator_alias_keeps_its_name():
    """volpath is path under another name: path's parameters, and messages
    and results name it as the scene did."""
    assert registry.estimator("volpath")["name"] == "path"
    assert _resolve("volpath", max_depth=3) == _resolve("path", max_depth=3)
    _raises({"type": "volpath", "bogus": 1}, "integrator 'volpath'", "unknown parameter 'bogus'")


# --- the core's own entry points -------------------------------------------------------


def test_core_render_checks_an_integrator_desc():
    """Attributes of _core.IntegratorDesc are parameters; _core.render checks
    them itself (no Python check in between) and raises SceneError."""
    scene = rm.load_dict({"type": "scene", "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4,
                                                                                      "height": 4}}})
    d = _core.IntegratorDesc()
    d.type = "sppm"
    d.alpha = 1.5
    assert d.alpha == 1.5 and d.params == {"alpha": 1.5}
    with pytest.raises(rm.SceneError, match="integrator 'sppm': parameter 'alpha' must lie in \\(0, 1\\), got 1.5"):
        _core.render(scene.core(), d, [True] * 7, 1, 0.0, 0, 1, [], None)
    with pytest.raises(AttributeError):
        _ = d.photon_count


# --- the command line -----------------------------------------------------------------


@pytest.mark.parametrize("name", registry.estimator_names())
def test_help_integrator_prints_the_table(name, capsys):
    with pytest.raises(SystemExit) as e:
        main(["render", "--help-integrator", name])
    assert e.value.code == 0
    out = capsys.readouterr().out
    est = registry.estimator(name)
    assert out.startswith(f"{est['name']}: {est['doc']}")
    for k, p in est["params"].items():
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(k + " ") or ln.strip().startswith(k))
        assert p["type"] in line and p["doc"] in line, line
        if p["range"]:
            assert p["range"] in line, line
        for a in p["aliases"]:
            assert a in line, line


def test_help_integrator_unknown(capsys):
    with pytest.raises(SystemExit) as e:
        main(["render", "--help-integrator", "nosuch"])
    assert e.value.code == 2
    assert "unknown estimator 'nosuch'" in capsys.readouterr().err


def test_render_help_lists_the_estimators(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    for n in registry.estimator_names():
        assert n in out
    assert "--help-integrator" in out
