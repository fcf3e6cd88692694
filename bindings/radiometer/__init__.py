"""radiometer: a physically based validation and benchmark suite around a
reference renderer. `load_file` / `load_dict` read Mitsuba 3 scenes, `render`
runs an estimator and returns the image with its variance and effect classes.
"""
from __future__ import annotations

__version__ = "0.1.0"

from .scene_desc import SceneError
from .loader import SceneWarning
from .registry import estimators
from .render import EFFECTS, RenderCancelled, RenderResult, refusal, render
from .scene import Scene


def load_file(path, **params) -> Scene:
    """Loads a Mitsuba 3 XML scene (the subset of DESIGN section 3); keyword
    arguments override its <default> parameters."""
    from .loader import load_file as _load_file

    return Scene(_load_file(path, **params))


def load_dict(d: dict) -> Scene:
    """Loads the dict that `mitsuba.load_dict` takes (`mitsuba.cornell_box()`
    loads unchanged)."""
    from .loader import load_dict as _load_dict

    return Scene(_load_dict(d))


def write_exr(path, result, **metadata):
    """Writes a RenderResult (image, variance and effects as layers) to EXR."""
    from .exr import write_exr as _write

    return _write(path, result, **metadata)


def read_exr(path):
    """Reads an EXR written by write_exr (or any RGB EXR) into an ExrImage."""
    from .exr import read_exr as _read

    return _read(path)


__all__ = ["load_file", "load_dict", "render", "estimators", "write_exr", "read_exr", "Scene", "SceneError",
           "SceneWarning", "RenderResult", "RenderCancelled", "refusal", "EFFECTS", "__version__"]
