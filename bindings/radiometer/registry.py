"""The estimators the renderer core registers, read from its declarations
(renderer/render/registry.h): each estimator's name, aliases, one-line
description, capabilities and parameters (type, default, range, description,
Mitsuba 0.6 names). Every list of estimators or parameters in Python (the
loader's plugin table, render()'s checks, the command line's help, the
tests' estimator lists) comes from here.
"""
from __future__ import annotations

import copy
import functools


@functools.lru_cache(maxsize=None)
def _schema() -> dict:
    from . import _core

    return {e["name"]: e for e in _core.estimators()}


def estimators() -> dict:
    """name -> {"name", "aliases", "doc", "capabilities": {"media", "dipole",
    "driver", "bias", "effects"}, "params": {name -> {"type", "default", "range", "min", "max",
    "min_open", "max_open", "choices", "special", "doc", "aliases",
    "ignored", "sets"}}}, by name; aliases (volpath) are not keys."""
    return copy.deepcopy(_schema())


def estimator_names() -> tuple:
    """Every name an integrator may have in a scene: the estimators and their aliases, sorted."""
    return tuple(sorted(n for e in _schema().values() for n in [e["name"], *e["aliases"]]))


def estimator(name: str) -> dict:
    """The declaration of the estimator `name` names (an alias gives its estimator's); KeyError otherwise."""
    for e in _schema().values():
        if name == e["name"] or name in e["aliases"]:
            return copy.deepcopy(e)
    raise KeyError(f"unknown estimator '{name}' (known: {', '.join(estimator_names())})")


@functools.lru_cache(maxsize=None)
def planned_estimators() -> tuple:
    """Names the scene format knows whose estimators have not arrived yet."""
    from . import _core

    return tuple(_core.planned_estimators())


def integrator_params() -> dict:
    """name (aliases too) -> {parameter -> (Python type, default or None)}:
    every parameter the estimator accepts under its own name (ignored and
    setting ones included, their default None), in declaration order."""
    types = {"int": int, "float": float, "bool": bool, "string": str}
    out = {}
    for e in _schema().values():
        params = {k: (types[p["type"]], p["default"]) for k, p in e["params"].items()}
        for n in [e["name"], *e["aliases"]]:
            out[n] = dict(params)
    return dict(sorted(out.items()))


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f"'{v}'"
    return repr(v)


def help_text(name: str) -> str:
    """The parameter table of estimator `name`, as `radiometer render --help-integrator NAME` prints it."""
    e = estimator(name)
    caps = e["capabilities"]
    renders = [w for w, k in (("participating media", "media"), ("the dipole BSSRDF", "dipole")) if caps[k]]
    driver = {"camera": "camera paths, one per sample (render.cpp)",
              "light": "light paths, splatted onto the film (light_render.cpp)",
              "own": "passes of its own (drive())"}[caps["driver"]]
    lines = [f"{e['name']}: {e['doc']}"]
    if e["aliases"]:
        lines.append(f"  also called: {', '.join(e['aliases'])}")
    lines.append(f"  renders media and dipoles: {', '.join(renders) if renders else 'neither (refuses such scenes)'}")
    lines.append(f"  driver: {driver}")
    lines.append(f"  bias: {caps['bias']}; renders completely: {', '.join(caps['effects'])}")
    used = {k: p for k, p in e["params"].items() if not p["ignored"] and not p["sets"]}
    other = {k: p for k, p in e["params"].items() if p["ignored"] or p["sets"]}
    rows = [("parameter", "type", "default", "allowed", "Mitsuba 0.6", "description")]
    for k, p in used.items():
        rows.append((k, p["type"], _fmt(p["default"]), p["range"] or "any", ", ".join(p["aliases"]) or "-", p["doc"]))
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    lines.append("")
    for r in rows:
        lines.append("  " + "  ".join(c.ljust(w) for c, w in zip(r[:5], widths)) + "  " + r[5])
    if other:
        lines.append("")
        lines.append("  accepted for Mitsuba's scenes:")
        for k, p in other.items():
            what = f"sets {' and '.join(p['sets'])}" if p["sets"] else "ignored"
            lines.append(f"    {k} ({p['type']}{', ' + p['range'] if p['range'] else ''}): {what}; {p['doc']}")
    return "\n".join(lines)


__all__ = ["estimators", "estimator", "estimator_names", "planned_estimators", "integrator_params", "help_text"]
