"""Images that plugins read (envmap): OpenEXR through the OpenEXR package
(radiometer.exr), PNG and JPEG through Pillow, as linear RGB float32 arrays
of shape (rows, columns, 3), row 0 at the top."""
from __future__ import annotations

import os

import numpy as np

from ..scene_desc import SceneError


def _srgb_to_linear(v):
    """The sRGB transfer function inverted (IEC 61966-2-1), as Mitsuba's
    Bitmap converts 8-bit sRGB images to linear values."""
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def read_rgb(path, where, quote=True):
    """Linear RGB of the image at `path` (.exr as stored; .png/.jpg/.jpeg
    decoded from 8- or 16-bit sRGB); SceneError naming `where` otherwise.
    `quote`: False for an untrusted scene (the message says nothing the
    file's decoder said)."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".exr":
        from ..exr import read_exr

        try:
            img = read_exr(path).image
        except (ValueError, OSError) as e:
            raise SceneError(f"{where}: cannot read the EXR image" + (f" ({e})" if quote else "")) from None
    elif ext in (".png", ".jpg", ".jpeg"):
        try:
            from PIL import Image

            with Image.open(path) as im:
                if im.mode in ("I;16", "I;16B", "I"):
                    a = np.asarray(im, dtype=np.float64) / 65535.0
                    a = np.repeat(a[..., None], 3, axis=-1)
                else:
                    a = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        except (OSError, ValueError, Image.DecompressionBombError) as e:
            raise SceneError(f"{where}: cannot read the image" + (f" ({e})" if quote else "")) from None
        img = _srgb_to_linear(a).astype(np.float32)
    else:
        raise SceneError(f"{where}: image format '{ext or '(none)'}' is not supported (.exr, .png, .jpg)")
    img = np.ascontiguousarray(img, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3:
        raise SceneError(f"{where}: expected an RGB image, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise SceneError(f"{where}: the image holds non-finite values")
    if np.any(img < 0):
        raise SceneError(f"{where}: the image holds negative values (radiance must be non-negative)")
    return img
