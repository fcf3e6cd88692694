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
    """Linear RGB of the image at `path` (.exr as stored; .png/.jpg/.jpeg/.bmp
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
    elif ext in (".png", ".jpg", ".jpeg", ".bmp"):
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
        raise SceneError(f"{where}: image format '{ext or '(none)'}' is not supported (.exr, .png, .jpg, .bmp)")
    img = np.ascontiguousarray(img, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3:
        raise SceneError(f"{where}: expected an RGB image, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise SceneError(f"{where}: the image holds non-finite values")
    if np.any(img < 0):
        raise SceneError(f"{where}: the image holds negative values (radiance must be non-negative)")
    return img


def read_texture(path, where, raw=False, quote=True):
    """The pixels of a `bitmap` texture, as Mitsuba 3's bitmap plugin stores
    them in its RGB variants (src/textures/bitmap.cpp): (rows, columns, 1 or
    3) float32, row 0 at the top; grey images keep one channel, alpha is
    dropped; 8- and 16-bit PNG/JPEG/BMP are decoded from sRGB to linear unless
    `raw` (float32, as Mitsuba 3.9.1's scalar_rgb stores them: its format
    'auto' keeps float32 there, measured); EXR as stored. An
    image narrower or shorter than 2 pixels is repeated to 2 (Mitsuba
    resamples it to 2 with a tent filter, which for one row or column
    repeats it)."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".exr":
        from ..exr import read_exr

        try:
            img = np.asarray(read_exr(path).image, dtype=np.float32)
        except (ValueError, OSError) as e:
            raise SceneError(f"{where}: cannot read the EXR image" + (f" ({e})" if quote else "")) from None
    elif ext in (".png", ".jpg", ".jpeg", ".bmp"):
        try:
            from PIL import Image

            with Image.open(path) as im:
                if im.mode in ("I;16", "I;16B", "I;16L", "I"):
                    a = np.asarray(im, dtype=np.float64)[..., None] / 65535.0
                elif im.mode in ("1", "L", "LA"):
                    a = np.asarray(im.convert("L"), dtype=np.float64)[..., None] / 255.0
                else:
                    a = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        except (OSError, ValueError, Image.DecompressionBombError) as e:
            raise SceneError(f"{where}: cannot read the image" + (f" ({e})" if quote else "")) from None
        if not raw:
            a = _srgb_to_linear(a)
        img = a.astype(np.float32)
    else:
        raise SceneError(f"{where}: image format '{ext or '(none)'}' is not supported (.exr, .png, .jpg, .bmp)")
    if img.ndim != 3 or img.shape[2] not in (1, 3) or img.shape[0] < 1 or img.shape[1] < 1:
        raise SceneError(f"{where}: expected an image of 1 or 3 channels, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise SceneError(f"{where}: the image holds non-finite values")
    if np.any(img < 0):
        raise SceneError(f"{where}: the image holds negative values")
    if img.shape[0] < 2:
        img = np.repeat(img, 2, axis=0)
    if img.shape[1] < 2:
        img = np.repeat(img, 2, axis=1)
    return np.ascontiguousarray(img, dtype=np.float32)
