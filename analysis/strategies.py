"""Per-strategy images of the bidirectional estimators as one figure: the
pyramid of Veach's thesis (1997, fig. 10.3) and pbrt-v4's
visualize_strategies, one row per path depth d = s + t - 1, strategy s = 0
(the camera path finds the light) on the left to s = d (light tracing,
t = 1) on the right.

Each panel is a strategy's image; `weighted=False` shows the unweighted
contributions (each alone an estimate of its depth's light: where it is
noisy, that strategy is bad there), `weighted=True` what MIS kept of each
(they sum to the render). Images share one exposure per row so the panels
compare."""
from __future__ import annotations

import numpy as np


def strategy_pyramid(result, path, weighted: bool = False, exposure: float = 0.0, title: str | None = None):
    """Writes the pyramid of `result` (a RenderResult rendered with the
    integrator's strategy_images > 0) to `path` (PNG); returns the path."""
    from ..tonemap import to_srgb

    images = result.strategies if weighted else result.strategies_unweighted
    # the connections (s, t); vcm's merges, keyed ("merge", i, t), are not in the pyramid
    images = {k: v for k, v in images.items() if len(k) == 2}
    if not images:
        raise ValueError("strategy_pyramid: the result has no per-strategy images; render with the integrator "
                         "parameter strategy_images = D (bdpt or ptracer)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    depths = sorted({s + t - 1 for s, t in images})
    cols = max(depths) + 1
    fig, axes = plt.subplots(len(depths), cols, figsize=(1.8 * cols, 1.9 * len(depths)), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for row, d in enumerate(depths):
        # one exposure per depth: the 99th percentile of the row maps to 0.8
        row_imgs = [np.asarray(images[(s, d + 1 - s)]) for s in range(d + 1) if (s, d + 1 - s) in images]
        peak = float(np.percentile(np.concatenate([i.ravel() for i in row_imgs]), 99)) if row_imgs else 0.0
        scale = 0.8 / peak if peak > 0 else 1.0
        for s in range(d + 1):
            key = (s, d + 1 - s)
            if key not in images:
                continue
            ax = axes[row, s]
            ax.imshow(to_srgb(np.asarray(images[key]) * scale, exposure), interpolation="nearest")
            ax.set_title(f"s={key[0]}, t={key[1]}", fontsize=8)
    kind = "MIS-weighted" if weighted else "unweighted"
    fig.suptitle(title or f"{result.integrator.get('type', '')}: {kind} strategies, rows = path depth", fontsize=10)
    fig.tight_layout()
    fig.savefig(str(path), dpi=110)
    plt.close(fig)
    return path
