"""Display helpers: linear RGB to sRGB, and PNG previews of renders."""
from __future__ import annotations

import numpy as np


def to_srgb(image, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB -> sRGB-encoded floats in [0, 1] (IEC 61966-2-1 curve),
    after scaling by 2^exposure. Values above 1 saturate for display only."""
    x = np.asarray(image, np.float64) * (2.0 ** exposure)
    x = np.clip(np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def save_png(path, image, exposure: float = 0.0):
    """Writes an sRGB PNG preview of a linear image (H, W, 3)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.imsave(str(path), to_srgb(image, exposure))
