"""EXR files through the OpenEXR package's 3.x `OpenEXR.File` API.

A render is one file: the estimate as R, G, B; its variance as the layer
`variance.{R,G,B}`; each effect class as `effect.<name>.{R,G,B}`; render
metadata (spp, seconds, seed, integrator, versions) as header attributes
prefixed `radiometer_`.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

_META_PREFIX = "radiometer_"


@dataclass
class ExrImage:
    image: np.ndarray  # (H, W, 3) float32
    variance: Optional[np.ndarray] = None
    effects: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    layers: dict = field(default_factory=dict)  # any other RGB layers, by name


def _rgb(a, what):
    a = np.asarray(a, dtype=np.float32)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"write_exr: {what} must have shape (H, W, 3), got {a.shape}")
    return a


def _split(name, a):
    # OpenEXR writes a strided view's memory as if it were contiguous (seen
    # with OpenEXR 3.3): always hand it contiguous per-channel copies.
    return {f"{name}.{c}": np.ascontiguousarray(a[..., i]) for i, c in enumerate("RGB")}


def check_output(path, who: str = "output") -> Path:
    """The file an EXR written to `path` lands in, checked before any work
    is spent on it: its folder exists and is writable, and it is a regular
    file or not there yet. A symbolic link is written through (the file it
    points to is replaced, the link stays); a device, a FIFO, a socket or a
    folder is refused, since the atomic rename write_exr uses would replace
    the special file itself (`-o /dev/null` as root would replace /dev/null)."""
    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    if path.exists() and not path.is_file():
        kind = "a folder" if path.is_dir() else "not a regular file (a device, FIFO or socket)"
        raise ValueError(f"{who}: {path} is {kind}; give the path of an .exr file")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"{who}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(f"{who}: folder {folder} is not writable")
    if path.exists() and not os.access(path, os.W_OK):
        raise PermissionError(f"{who}: {path} is not writable")
    return path


def write_exr(path, result=None, *, image=None, variance=None, effects=None, layers=None, **metadata):
    """Writes `result` (a RenderResult) or explicit arrays to `path`.
    Keyword metadata values (str, int, float, or JSON-able) become header
    attributes. The file is written to a temporary name and renamed, so a
    crash never leaves a half-written EXR behind."""
    import OpenEXR

    if result is not None:
        image = result.image
        variance = result.variance
        effects = result.effects
        meta = {"spp": int(result.spp), "seconds": float(result.seconds), "seed": int(getattr(result, "seed", 0)),
                "integrator": json.dumps(getattr(result, "integrator", {}))}
        if getattr(result, "error_budget", None):
            meta["error_budget"] = json.dumps(result.error_budget)
        meta.update(metadata)
        metadata = meta
    if image is None:
        raise ValueError("write_exr: give a RenderResult or image=")
    image = _rgb(image, "image")
    channels = {"RGB": np.ascontiguousarray(image)}
    if variance is not None:
        v = _rgb(variance, "variance")
        if v.shape != image.shape:
            raise ValueError("write_exr: variance shape differs from the image")
        channels.update(_split("variance", v))
    for name, a in (effects or {}).items():
        channels.update(_split(f"effect.{name}", _rgb(a, f"effect '{name}'")))
    for name, a in (layers or {}).items():
        channels.update(_split(name, _rgb(a, f"layer '{name}'")))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    from . import __version__

    header[_META_PREFIX + "version"] = __version__
    for k, v in metadata.items():
        if isinstance(v, (bool, np.bool_)):
            v = int(v)
        if isinstance(v, (np.integer,)):
            v = int(v)
        if isinstance(v, (np.floating,)):
            v = float(v)
        if isinstance(v, float):
            # OpenEXR header floats are single precision: keep doubles exact as text.
            v = repr(v)
        if isinstance(v, int) and not -(1 << 31) <= v < 1 << 31:
            # OpenEXR header ints are 32-bit (a seed goes up to 2^64): keep wider ones exact as text.
            v = str(v)
        if not isinstance(v, (str, int)):
            v = json.dumps(v)
        header[_META_PREFIX + k] = v
    path = check_output(path, "write_exr")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.exr")
    try:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def read_exr(path) -> ExrImage:
    """Reads an EXR into an ExrImage (float32 arrays)."""
    import OpenEXR

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"read_exr: {path} does not exist")
    try:
        f = OpenEXR.File(str(path), separate_channels=True)
    except Exception as e:  # the package raises bare exceptions for bad files
        raise ValueError(f"read_exr: {path} is not a readable EXR file ({e})") from None
    with f:
        try:  # a truncated file opens, then fails on its pixels with the package's bare message
            chans = {k: np.asarray(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
            header = dict(f.header())
        except Exception as e:
            raise ValueError(f"read_exr: {path} is truncated or corrupt ({e})") from None
    groups: dict = {}
    for name, a in chans.items():
        base, _, c = name.rpartition(".")
        groups.setdefault(base, {})[c] = a
    def stack(g, name):
        if not all(c in g for c in "RGB"):
            raise ValueError(f"read_exr: {path}: layer '{name or 'main'}' lacks R, G or B")
        return np.stack([g["R"], g["G"], g["B"]], axis=-1)
    if "" not in groups:
        if "Y" in chans:
            y = chans["Y"]
            image = np.stack([y, y, y], axis=-1)
        else:
            raise ValueError(f"read_exr: {path} has no R, G, B channels")
    else:
        image = stack(groups.pop(""), "")
    out = ExrImage(image=image)
    for base, g in groups.items():
        if base == "variance":
            out.variance = stack(g, base)
        elif base.startswith("effect."):
            out.effects[base[len("effect."):]] = stack(g, base)
        elif all(c in g for c in "RGB"):
            out.layers[base] = stack(g, base)
    for k, v in header.items():
        if isinstance(k, str) and k.startswith(_META_PREFIX):
            key = k[len(_META_PREFIX):]
            if isinstance(v, str):
                # ints wider than 32 bits and floats were stored as text, to keep them exact
                for kind in (int, float):
                    try:
                        v = kind(v)
                        break
                    except ValueError:
                        pass
            out.metadata[key] = v
    return out
