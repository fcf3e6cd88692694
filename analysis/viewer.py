"""The report's image viewer (viewer.html): its data files and its page.

Per scene, data/SCENE.js holds the reference and each estimator's seed-0
image at the compared budget, for the total and every effect layer, as
Radiance RGBE bytes (4 bytes a pixel, 1/256 relative precision: enough to
look at, a quarter of float32's size) in base64, loaded by a <script> tag
so the page works from file:// (a fetch of a local file is refused there,
and a canvas that drew a local image could not be read back). Error maps
are PNGs written here: the per-pixel relative squared error on one log
scale per scene and layer (shared by its estimators), and the FLIP error
map (flip-evaluator, LDR at the reference's display exposure, magma). The
script itself is report_assets/viewer.js, copied beside the page.
"""
from __future__ import annotations

import base64
import html
import json
import shutil
from pathlib import Path

import numpy as np

ASSETS = Path(__file__).resolve().parent / "report_assets"
esc = html.escape


def rgbe_bytes(img) -> bytes:
    """(H, W, 3) linear RGB -> Radiance RGBE, row-major, 4 bytes a pixel
    (negative and non-finite values become 0)."""
    a = np.nan_to_num(np.asarray(img, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    a = np.maximum(a, 0.0).reshape(-1, 3)
    m = a.max(axis=1)
    out = np.zeros((a.shape[0], 4), np.uint8)
    ok = m > 1e-32
    mant, e = np.frexp(m[ok])
    scale = mant * 256.0 / m[ok]
    out[ok, :3] = np.clip(np.floor(a[ok] * scale[:, None]), 0, 255).astype(np.uint8)
    out[ok, 3] = np.clip(e + 128, 0, 255).astype(np.uint8)
    return out.tobytes()


def rgbe_decode(b: bytes, shape) -> np.ndarray:
    """The inverse of rgbe_bytes (what viewer.js does), for the tests."""
    a = np.frombuffer(b, np.uint8).reshape(-1, 4).astype(np.float64)
    f = np.where(a[:, 3] > 0, np.ldexp(1.0, a[:, 3].astype(int) - 136), 0.0)
    return ((a[:, :3] + 0.5) * f[:, None] * (a[:, 3:] > 0)).reshape(shape)


def _layers(img_obj, image):
    """{layer: image} of a render or reference: total plus nonzero effects."""
    out = {"total": np.asarray(image, np.float64)}
    for k, v in (getattr(img_obj, "effects", None) or {}).items():
        if v is not None and np.any(np.asarray(v) != 0):
            out[k] = np.asarray(v, np.float64)
    return out


def scene_data(scene: str, ref, shown, out: Path) -> dict | None:
    """Writes data/SCENE.js and the scene's error-map PNGs under `out`.
    `ref`: the reference (.image, .effects); `shown`: [(estimator, label,
    ExrImage)] of the renders to show. Returns the data written (without
    the images), or None when there is nothing to show."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .metrics import display_exposure, pixel_error_map, relmse, tonemapped
    from .tables import EFFECT_ORDER

    h, w = ref.image.shape[:2]
    shown = [s for s in shown if s[2] is not None and s[2].image.shape == ref.image.shape]
    if not shown:
        return None
    exposure = display_exposure(ref.image)
    srcs = {"reference": _layers(ref, ref.image)}
    for est, _, im in shown:
        srcs[est] = _layers(im, im.image)
    present = {k for v in srcs.values() for k in v}
    layers = ["total"] + [e for e in EFFECT_ORDER if e in present] + sorted(present - set(EFFECT_ORDER) - {"total"})
    images, relerr, flip, stats, scale = {}, {}, {}, {}, {}
    edir = out / "maps" / scene
    edir.mkdir(parents=True, exist_ok=True)
    for layer in layers:
        r = srcs["reference"].get(layer)
        maps = {}
        for src, ls in srcs.items():
            if layer in ls:
                images[f"{src}/{layer}"] = base64.b64encode(rgbe_bytes(ls[layer])).decode("ascii")
            if src != "reference" and r is not None:
                mine = ls.get(layer, np.zeros_like(r))
                maps[src] = (mine, pixel_error_map(mine, r))
        if not maps:
            continue
        pos = np.concatenate([m[m > 0] for _, m in maps.values()] + [np.zeros(0)])
        vmax = max(float(np.percentile(pos, 99.5)), 1e-12) if pos.size else 1.0
        vmin = vmax * 1e-4
        scale[layer] = f"{vmin:.1e} .. {vmax:.1e} (inferno)"
        for src, (mine, m) in maps.items():
            name = f"{src}-{layer}"
            plt.imsave(edir / f"{name}-rel.png", np.log10(np.maximum(m, vmin)), cmap="inferno",
                       vmin=np.log10(vmin), vmax=np.log10(vmax))
            relerr[f"{src}/{layer}"] = f"maps/{scene}/{name}-rel.png"
            st = {"relmse": relmse(mine, r), "flip": None}
            try:
                import flip_evaluator

                fm, mean_err, _ = flip_evaluator.evaluate(tonemapped(r, exposure), tonemapped(mine, exposure), "LDR",
                                                          inputsRGB=True, applyMagma=False, computeMeanError=True)
                fm = np.asarray(fm, np.float64)
                if fm.ndim == 3:
                    fm = fm[..., 0]
                plt.imsave(edir / f"{name}-flip.png", np.clip(fm, 0, 1), cmap="magma", vmin=0.0, vmax=1.0)
                flip[f"{src}/{layer}"] = f"maps/{scene}/{name}-flip.png"
                st["flip"] = float(mean_err)
            except Exception:  # FLIP refuses images smaller than its filters: no map, the relative one stays
                pass
            stats[f"{src}/{layer}"] = st
    for layer in layers:
        scale.setdefault(layer, "(no reference for this layer)")
    labels = {"reference": f"reference ({ref.kind})" if getattr(ref, "kind", None) else "reference"}
    labels.update({est: lab for est, lab, _ in shown})
    d = {"scene": scene, "w": int(w), "h": int(h), "exposure": float(exposure), "layers": layers,
         "sources": ["reference"] + [est for est, _, _ in shown], "labels": labels, "relerr": relerr, "flip": flip,
         "stats": stats, "relerr_scale": scale}
    (out / "data").mkdir(parents=True, exist_ok=True)
    (out / "data" / f"{scene}.js").write_text("RM.scene(" + json.dumps(dict(d, images=images)) + ");\n")
    return d


VIEWER_CSS = """
#vcontrols { display: flex; flex-wrap: wrap; gap: 0.6em 1.2em; align-items: center; margin: 0.5em 0; }
#vcontrols button { font: inherit; font-size: 0.85em; margin: 1px; padding: 1px 6px; border: 1px solid #bbb;
  background: #f6f6f6; border-radius: 3px; cursor: pointer; }
#vcontrols button.on { background: #246; color: #fff; border-color: #246; }
.vpanes { display: flex; flex-wrap: wrap; gap: 1em; } .vpanes figure { margin: 0; }
.vpane { width: 384px; height: 384px; overflow: hidden; position: relative; background: #111; cursor: grab; }
.vpane .content { position: absolute; left: 0; top: 0; transform-origin: 0 0; }
.vpane canvas, .vpane img { width: 100%; height: 100%; display: block; image-rendering: pixelated; }
#vstatus { font-family: ui-monospace, monospace; font-size: 0.9em; }
kbd { border: 1px solid #aaa; border-radius: 3px; padding: 0 3px; font-size: 0.85em; background: #fafafa; }
"""


def write_viewer(out: Path, scenes: list, title: str, css: str) -> Path:
    """Writes viewer.html, data/index.js and viewer.js into `out` for the
    scenes whose data/SCENE.js exists. Returns viewer.html's path."""
    out = Path(out)
    (out / "data").mkdir(parents=True, exist_ok=True)
    (out / "data" / "index.js").write_text("RM.index(" + json.dumps({"scenes": list(scenes)}) + ");\n")
    shutil.copyfile(ASSETS / "viewer.js", out / "viewer.js")
    page = f"""<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{esc(title)}: images</title>
<style>{css}{VIEWER_CSS}</style></head><body>
<h1>{esc(title)}: image viewer</h1>
<p class='note'><a href='index.html'>back to the report</a>. Keys: <kbd>&larr;</kbd> <kbd>&rarr;</kbd> flip between
the reference and the estimators (seed 0 of the compared budget), <kbd>&uarr;</kbd> <kbd>&darr;</kbd> between the
total and the effects, <kbd>1</kbd>-<kbd>9</kbd> pick a source, <kbd>e</kbd> relative error / FLIP,
<kbd>+</kbd> <kbd>-</kbd> zoom, <kbd>0</kbd> reset, <kbd>[</kbd> <kbd>]</kbd> exposure. Wheel zooms, drag pans; the
panes follow each other. Exposure is in stops over the reference's display exposure (its 99th percentile of
luminance at 1).</p>
<div id='vcontrols'>
<label>scene <select id='vscene'></select></label>
<span>source <span id='vsources'></span></span>
<span>layer <span id='vlayers'></span></span>
<label>exposure <input type='range' id='vev' min='-10' max='10' step='0.1' value='0'> <output id='vev-out'>+0.0</output>
</label>
<label>error map <select id='verrmode'><option value='rel'>relative</option><option value='flip'>FLIP</option></select>
</label>
</div>
<div class='vpanes'>
<figure><div class='vpane'><div class='content'><canvas id='vmain'></canvas></div></div>
<figcaption id='vmain-cap'></figcaption></figure>
<figure><div class='vpane'><div class='content'><canvas id='vref'></canvas></div></div>
<figcaption id='vref-cap'></figcaption></figure>
<figure><div class='vpane'><div class='content'><img id='verr' alt='error map'></div></div>
<figcaption id='verr-cap'></figcaption></figure>
</div>
<p id='vstatus'>(loading)</p>
<script src='viewer.js'></script>
<script src='data/index.js'></script>
<script>RM.init();</script>
</body></html>
"""
    p = out / "viewer.html"
    p.write_text(page)
    return p
