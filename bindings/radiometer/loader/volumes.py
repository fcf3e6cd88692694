"""Grid volumes in Mitsuba's binary .vol format: reading and writing."""
from __future__ import annotations

import struct

import numpy as np

from ..scene_desc import SceneError


def _read_vol(path, err, quote=True):
    """Mitsuba's binary grid format: 'VOL', version 3, int32 encoding (1 =
    float32), int32 xres, yres, zres, channels, 6 float32 bounding box
    (min, max), then xres*yres*zres*channels float32, x fastest. Returns
    ((z, y, x, channels) float32 array, (bbox_min, bbox_max)). quote=False:
    messages give no values read from the header (an untrusted scene's)."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        raise SceneError(f"{err}: '{path}': cannot read the volume file ({e.strerror})") from None
    if len(raw) < 48 or raw[:3] != b"VOL":
        raise SceneError(f"{err}: '{path}' is not a Mitsuba .vol file (no 'VOL' header)")
    version = raw[3]
    enc, nx, ny, nz, ch = struct.unpack("<5i", raw[4:24])
    if version != 3 or enc != 1:
        found = f" (version {version}, encoding {enc})" if quote else ""
        raise SceneError(f"{err}: '{path}': only version 3 float32 .vol files are supported{found}")
    if min(nx, ny, nz) < 1 or ch not in (1, 3):
        found = f" {nx}x{ny}x{nz} or channel count {ch}" if quote else " or channel count"
        raise SceneError(f"{err}: '{path}': bad resolution{found}")
    bbox = np.frombuffer(raw[24:48], "<f4").astype(np.float64)
    n = nx * ny * nz * ch
    if len(raw) != 48 + 4 * n:
        found = f": expected {n} values ({48 + 4 * n} bytes), file has {len(raw)} bytes" if quote else ""
        raise SceneError(f"{err}: '{path}': the file size does not match the header's resolution{found}")
    data = np.frombuffer(raw[48:], "<f4").astype(np.float32).reshape(nz, ny, nx, ch)
    if not np.all(np.isfinite(data)) or not np.all(np.isfinite(bbox)):
        raise SceneError(f"{err}: '{path}': non-finite values")
    return data, (bbox[:3], bbox[3:])


def write_vol(path, data, bbox=((0, 0, 0), (1, 1, 1))):
    """Writes `data` ((z, y, x) or (z, y, x, channels) floats) as a Mitsuba
    version 3 float32 .vol file."""
    a = np.asarray(data, np.float32)
    if a.ndim == 3:
        a = a[..., None]
    nz, ny, nx, ch = a.shape
    with open(path, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<5i", 1, nx, ny, nz, ch))
        f.write(np.asarray(bbox, "<f4").reshape(6).tobytes())
        f.write(np.ascontiguousarray(a, "<f4").tobytes())
