"""`radiometer report RUN`: a static HTML report of one benchmark run.

One folder, index.html, viewer.html (analysis/viewer.py) plus PNGs and the
viewer's data, no scripts from elsewhere:
  * machine, commit, matrix and job counts;
  * the scene x effect matrix of winners by efficiency at the compared
    budget, each cell linking to its evidence (analysis/verdict.py);
  * each configuration's verdict against the target relMSE, with its error
    terms, and each effect's noise and bias over seeds;
  * the per-effect error table (scene x estimator x effect, relMSE, mean
    over seeds) and a table of every metric;
  * per scene: a log-log plot of relMSE against time from the renders'
    checkpoints, the geometric mean over seeds with its 95 % band, each
    estimator's fitted slope in the legend where its curves have enough
    checkpoints (-1 is the Monte Carlo rate of an unbiased estimator); the
    history of error and time across the store's runs of the matrix;
    an equal-budget image comparison (reference and each estimator's seed-0
    image, tone-mapped with the reference's exposure; a 4x crop around the
    region where the estimators err most; the per-pixel relative squared
    error as a heat map on one log scale per scene); a pyvista off-screen
    3D view of the scene (VTK through EGL: VTK_DEFAULT_OPENGL_WINDOW =
    vtkEGLRenderWindow), with the camera and its view frustum; for each
    estimator whose jobs kept a cache's records (irrcache, radcache), a 3D
    view of its lowest seed's records on the scene, from the camera and
    from over its shoulder, each a point with a circle of its radius,
    coloured by its irradiance, and a map of its bias (the seeds' mean
    against the reference, per pixel and in 4 x 4 blocks). Where a view
    cannot be made, the report says why in its place.
A small inline script checks on load that every image decoded and writes
the count into the page (body[data-images-ok]), for people and for the
headless-browser test.
"""
from __future__ import annotations

import datetime as _dt
import html
import math
import os
from pathlib import Path

import numpy as np

from . import tables as T

esc = html.escape

CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1400px; color: #222; }
h1 { font-size: 1.5em; } h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0; }
th, td { border: 1px solid #ddd; padding: 2px 6px; text-align: right; white-space: nowrap; }
td.why { white-space: normal; text-align: left; }
th { background: #f3f3f3; } td:nth-child(-n+3) { text-align: left; }
.status { font-weight: bold; } .failed { color: #b00; } .unsupported { color: #886; }
.why { color: #666; font-size: 0.9em; text-align: left; }
.note { color: #555; font-size: 0.9em; }
.figs { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
.figs img { border: 1px solid #ddd; }
#selfcheck { font-size: 0.8em; color: #666; }
table.winners td { text-align: left; } table.winners a { color: #123; font-weight: 600; text-decoration: none; }
table.winners .ratio { color: #345; font-size: 0.9em; }
.usable { color: #060; font-weight: bold; } .unusable { color: #b00; font-weight: bold; } .cannot { color: #886; }
table.evidence td.why { max-width: 60em; }
"""

SELF_CHECK = """
window.addEventListener('load', function () {
  var imgs = document.querySelectorAll('img'), ok = 0, bad = [];
  imgs.forEach(function (im) {
    if (im.complete && im.naturalWidth > 0) { ok++; } else { bad.push(im.getAttribute('src')); }
  });
  document.body.setAttribute('data-images-ok', String(ok));
  document.body.setAttribute('data-images-total', String(imgs.length));
  document.getElementById('selfcheck').textContent =
    ok + ' of ' + imgs.length + ' images shown' + (bad.length ? '; missing: ' + bad.join(', ') : '');
});
"""


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _load_exr(root: Path, rec):
    from radiometer import read_exr

    if not rec.get("exr"):
        return None
    p = root / rec["exr"]
    return read_exr(p) if p.exists() else None


def _band(values):
    """(geometric mean, lo, hi, n) over seeds: the 95 % Student-t interval of
    the mean log (benchmarks/compare.log_ci, the interval compare judges)."""
    from radiometer.benchmarks.compare import log_ci

    return log_ci(values)


def convergence_plot(scene, recs, out: Path) -> bool:
    """relMSE against time per estimator: at each checkpoint (spp) the
    geometric mean over seeds at the seeds' median time, a band of its 95 %
    interval over seeds, and the log-log slope where the curves have enough
    checkpoints (metrics.curves_slope), "too few checkpoints" else."""
    from .metrics import SLOPE_MIN_CHECKPOINTS, curves_slope, slope_fits

    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.6, 3.9), dpi=100)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    by_est = {}
    for r in recs:
        if r["status"] == "ok" and r.get("curve"):
            by_est.setdefault(r["estimator"], []).append(r)
    if not by_est:
        plt.close(fig)
        return False
    for i, (est, rs) in enumerate(sorted(by_est.items())):
        c = colours[i % len(colours)]
        levels = {}
        for r in rs:
            for spp, t, e in r["curve"]:
                levels.setdefault(spp, []).append((t, e))
        xs, ms, los, his = [], [], [], []
        for spp in sorted(levels):
            pts = levels[spp]
            b = _band([e for _, e in pts])
            if b is None:
                continue
            xs.append(float(np.median([t for t, _ in pts])))
            ms.append(b[0])
            los.append(b[1])
            his.append(b[2])
        curves = [r["curve"] for r in rs]
        s = curves_slope(curves)
        label = f"{est}: slope {s:.2f}" if s is not None else f"{est}: too few checkpoints"
        ax.plot(xs, ms, "-o", color=c, lw=1.4, ms=2.5, label=label)
        if len(rs) > 1:
            ax.fill_between(xs, los, his, color=c, alpha=0.2, lw=0)
        if s is not None:
            keep = [p for cv in curves if slope_fits([q[1] for q in cv], [q[2] for q in cv]) for p in cv
                    if p[1] > 0 and p[2] > 0]
            lt, le = np.log([p[1] for p in keep]), np.log([p[2] for p in keep])
            b0 = float(np.mean(le - s * lt))
            tx = np.array([min(p[1] for p in keep), max(p[1] for p in keep)])
            ax.plot(tx, np.exp(b0) * tx ** s, "--", color=c, lw=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds")
    ax.set_ylabel("relMSE")
    n = max(len(rs) for rs in by_est.values())
    ax.set_title(f"{scene}: error against time ({n} seeds, 95 % band)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, title=f"slope: >= {SLOPE_MIN_CHECKPOINTS} checkpoints over >= 4x time",
              title_fontsize=6)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return True


def history_plot(scene, hist, budget, out: Path):
    """Error and time of each estimator of `scene` at `budget` across the
    runs of the store (oldest first, each labelled by its commit): the
    geometric mean over seeds and its 95 % band, the way asv draws its
    graphs. Returns None, or why there is no plot (fewer than two runs).
    A matplotlib PNG rather than inline SVG: it looks like the page's other
    plots, the page's load check counts it as it counts them, and its size
    does not grow with the number of runs in the store (an SVG of every run
    and seed would, inside index.html)."""
    rows = [h for h in hist if h["scene"] == scene and h["budget"] == budget and h["status"] == "ok"]
    runs = []
    for h in rows:
        if h["run_id"] not in [r[0] for r in runs]:
            runs.append((h["run_id"], h["commit_id"] or "?", h["started"] or ""))
    if len(runs) < 2:
        return f"{len(runs)} run of this matrix with this scene in the store: no history yet"
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.4), dpi=100)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    x_of = {rid: i for i, (rid, _, _) in enumerate(runs)}
    for i, est in enumerate(sorted({h["estimator"] for h in rows})):
        c = colours[i % len(colours)]
        for ax, q in zip(axes, ("relmse", "seconds")):
            xs, ms, los, his = [], [], [], []
            for rid, _, _ in runs:
                b = _band([h[q] for h in rows if h["run_id"] == rid and h["estimator"] == est])
                if b is None:
                    continue
                xs.append(x_of[rid])
                ms.append(b[0])
                los.append(b[1])
                his.append(b[2])
            ax.plot(xs, ms, "-o", color=c, ms=3, lw=1.2, label=est if q == "relmse" else None)
            ax.fill_between(xs, los, his, color=c, alpha=0.2, lw=0)
    labels = [f"{cid[:12]}\n{started[5:16]}" for _, cid, started in runs]
    for ax, q in zip(axes, ("relMSE", "seconds per job")):
        ax.set_yscale("log")
        ax.set_ylabel(q)
        ax.set_xticks(range(len(runs)))
        ax.set_xticklabels(labels, fontsize=6, rotation=30, ha="right")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{scene}: history over {len(runs)} runs ({T.budget_label(budget)}; 95 % band over seeds)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return None


def _ratio_colour(ratio, resolved) -> str:
    """Background of a winner cell: white at a tie, deeper green up to a
    ratio of 100; grey where the seeds do not resolve the ratio."""
    if ratio is None:
        return "#f3f3f3"
    if resolved != "yes":
        return "#e8e8e8"
    t = min(1.0, math.log10(max(ratio, 1.0)) / 2.0)
    g = (int(255 - 155 * t), int(255 - 60 * t), int(255 - 155 * t))
    return "#%02x%02x%02x" % g


def _ratio_text(ratio, resolved=None) -> str:
    if resolved == "exact":
        return "exact"
    if ratio is None:
        return "alone"
    return "x" + (T.fmt(ratio, 2) if ratio < 1e6 else "&gt;1e6")


def winner_matrix_html(wins) -> str:
    """The scene x effect matrix of winners: each cell the winner, its
    efficiency ratio over the runner-up, coloured by it, linking to the
    scene's evidence table row."""
    if not wins:
        return "<p class='note'>no finished job to compare</p>"
    effs = ["total"] + T.effect_columns([{"effects": {w["effect"]: 1 for w in wins if w["effect"] != "total"}}])
    scenes = sorted({w["scene"] for w in wins})
    cell = {(w["scene"], w["effect"]): w for w in wins}
    out = ["<table class='winners'><thead><tr><th>scene</th><th>budget</th>" +
           "".join(f"<th>{esc(e)}</th>" for e in effs) + "</tr></thead><tbody>"]
    for sc in scenes:
        ws = [w for w in wins if w["scene"] == sc]
        kind = "equal time" if ws[0]["equal_time"] else "equal spp"
        row = [f"<td><a href='#{esc(sc)}'>{esc(sc)}</a></td><td>{esc(ws[0]['budget'])} ({kind})</td>"]
        for e in effs:
            w = cell.get((sc, e))
            if w is None:
                row.append("<td></td>")
                continue
            tie = {"yes": "", "no": " ~", "n<2": " (n&lt;2)", "exact": ""}[w["resolved"]]
            title = (f"{w['winner']} over {w['runner_up']}: efficiency ratio {w['ratio']:.3g}" if w["ratio"]
                     else f"{w['winner']} and {w['runner_up']}: both exact to rounding" if w["resolved"] == "exact"
                     else f"{w['winner']}: the only estimator measured")
            row.append(f"<td style='background:{_ratio_colour(w['ratio'], w['resolved'])}' title='{esc(title)}'>"
                       f"<a href='#ev-{esc(sc)}-{esc(e)}'>{esc(w['winner'])}</a> "
                       f"<span class='ratio'>{_ratio_text(w['ratio'], w['resolved'])}{tie}</span></td>")
        out.append("<tr>" + "".join(row) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def evidence_html(scene, wins) -> str:
    """Per effect of `scene`: every estimator's efficiency (geometric mean
    over seeds, 95 % interval) and mean relMSE, best first; each row is the
    target of a winner-matrix cell and links to the viewer."""
    ws = [w for w in wins if w["scene"] == scene]
    if not ws:
        return ""
    out = ["<table class='evidence'><thead><tr><th>effect</th><th>winner</th><th>ratio</th><th>resolved</th>"
           "<th>estimators: efficiency 1/(relMSE s) [95 % over seeds], relMSE</th><th></th></tr></thead><tbody>"]
    for w in ws:
        cands = "; ".join(f"{esc(c[0])} {T.fmt(c[1])} [{T.fmt(c[2])}, {T.fmt(c[3])}] n={c[4]}, {T.fmt(c[5])}"
                          for c in w["candidates"])
        link = f"viewer.html#scene={esc(scene)}&amp;layer={esc(w['effect'])}&amp;src={esc(w['winner'])}"
        out.append(f"<tr id='ev-{esc(scene)}-{esc(w['effect'])}'><td>{esc(w['effect'])}</td><td>{esc(w['winner'])}"
                   f"</td><td>{_ratio_text(w['ratio'], w['resolved'])}</td><td>{esc(w['resolved'])}</td>"
                   f"<td class='why'>{cands}</td><td><a href='{link}'>view</a></td></tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def verdict_table_html(rows) -> str:
    """Per configuration: its verdict against the target and its error terms."""
    from .verdict import BIAS_PARTS, TERMS, verdict_word

    head = ["scene", "estimator", "budget", "seeds", "relMSE", "own error", "target", "verdict", "dominant",
            "noise", "bias (remainder)", "reference noise", "of the bias: truncation", "discretisation", "model"]
    out = ["<table class='verdicts'><thead><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr></thead><tbody>"]
    for r in rows:
        v = r.get("verdict")
        if r["status"] != "ok" or not v:
            continue
        cls = {True: "usable", False: "unusable", None: "cannot"}[v["usable"]]
        cells = [esc(r["scene"]), esc(r["estimator"]), esc(r["budget"]), v["n"], T.fmt(r["total"]),
                 T.fmt(v["own_error"]), T.fmt(v["target"]), f"<span class='{cls}'>{verdict_word(v['usable'])}</span>",
                 esc(v["dominant"])] + [T.fmt(v["terms"].get(k)) for k in TERMS + BIAS_PARTS]
        out.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _crop_box(err_maps, shape, frac=0.25):
    """The square window (a quarter of the image side) where the summed error
    of all estimators is largest."""
    h, w = shape[:2]
    k = max(1, int(round(min(h, w) * frac)))
    total = np.zeros((h, w))
    for m in err_maps:
        total += np.nan_to_num(m)
    c = np.cumsum(np.cumsum(np.pad(total, ((1, 0), (1, 0))), 0), 1)
    win = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
    y, x = np.unravel_index(int(np.argmax(win)), win.shape)
    return int(y), int(x), k


def image_comparison(scene, recs, ref_image, root: Path, out: Path, title: str) -> bool:
    from .metrics import display_exposure, pixel_error_map, tonemapped

    plt = _plt()
    shown = []
    for est in sorted({r["estimator"] for r in recs}):
        ok = sorted((r for r in recs if r["estimator"] == est and r["status"] == "ok"), key=lambda r: r["seed"])
        if ok:
            img = _load_exr(root, ok[0])
            if img is not None and img.image.shape == ref_image.shape:
                shown.append((f"{est} ({ok[0]['spp']} spp)", img.image, ok[0]))
    if not shown:
        return False
    e = display_exposure(ref_image)
    errs = [pixel_error_map(im, ref_image) for _, im, _ in shown]
    y, x, k = _crop_box(errs, ref_image.shape)
    pos = [m[m > 0] for m in errs if np.any(m > 0)]
    vmax = max(float(np.percentile(np.concatenate(pos), 99.5)), 1e-12) if pos else 1.0
    vmin = vmax * 1e-4
    rows = [("reference", ref_image, None)] + [(lab, im, err) for (lab, im, _), err in zip(shown, errs)]
    # A panel is about 1.6 in square: at 90 dpi a 64 x 64 image gets ~2
    # screen pixels per pixel, a 128 x 128 one would get ~1 (smaller than
    # the film); the dpi grows so that every image keeps at least 2.
    dpi = max(90, int(np.ceil(2 * max(ref_image.shape[:2]) / 1.6)))
    fig, axes = plt.subplots(len(rows), 3, figsize=(7.5, 2.5 * len(rows)), dpi=dpi, squeeze=False)
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    im_h = None
    for i, (lab, im, err) in enumerate(rows):
        tm = tonemapped(im, e)
        axes[i, 0].imshow(tm, interpolation="nearest")
        axes[i, 0].add_patch(Rectangle((x - 0.5, y - 0.5), k, k, fill=False, ec="#0f0", lw=1))
        axes[i, 0].set_ylabel(lab, fontsize=8)
        axes[i, 1].imshow(tm[y:y + k, x:x + k], interpolation="nearest")
        if err is not None:
            im_h = axes[i, 2].imshow(np.maximum(err, vmin), cmap="inferno", norm=LogNorm(vmin=vmin, vmax=vmax),
                                     interpolation="nearest")
            axes[i, 2].set_title(f"relMSE {float(err.mean()):.3g}", fontsize=8)
        else:
            axes[i, 2].axis("off")
        for a in axes[i]:
            a.set_xticks([])
            a.set_yticks([])
    axes[0, 0].set_title("image", fontsize=9)
    axes[0, 1].set_title(f"crop {k}x{k} at ({x}, {y})", fontsize=9)
    if im_h is not None:
        fig.colorbar(im_h, ax=axes[:, 2].tolist(), shrink=0.6, label="relative squared error")
    fig.suptitle(f"{scene}: {title}", fontsize=10)
    fig.savefig(out)
    plt.close(fig)
    return True


# -- pyvista 3D views -----------------------------------------------------------


def _bsdf_colour(b):
    if b is None:
        return (0.5, 0.5, 0.5), 1.0
    t = b.type
    if t == "twosided" and b.nested:
        return _bsdf_colour(b.nested[0])
    if t in ("dielectric", "roughdielectric", "thindielectric"):
        return (0.55, 0.75, 1.0), 0.45
    if t in ("conductor", "roughconductor"):
        return (0.8, 0.8, 0.85), 1.0
    r = b.reflectance if t == "diffuse" else b.diffuse_reflectance
    try:
        c = tuple(float(min(1.0, max(0.0, v))) for v in r)
    except TypeError:
        c = (0.5, 0.5, 0.5)
    return c, 1.0


def scene_photons(scene, max_points: int = 20000, seed: int = 1):
    """Photons to draw into a scene's 3D view, where they explain something:
    the caustic photons (light paths L S+ D) of a scene with specular
    surfaces, else the photons of the first bounces (where direct and
    indirect light land). Returns (label, (N, 3) positions) or None (scenes
    with media: photon tracing does not follow media yet)."""
    feats = scene.core().features
    if feats.get("has_media") or not (feats.get("has_area_emitters") or feats.get("has_delta_emitters")
                                       or feats.get("has_environment")):
        return None
    core = scene.core()
    caustic = bool(feats.get("has_delta_bsdf"))
    r = core.trace_photons(200000 if caustic else 20000, caustic_only=caustic, seed=seed, max_depth=4)
    p = np.asarray(r["p"])
    if len(p) == 0:
        return None
    keep = max_points if caustic else max_points // 8  # a sprinkle: where first-bounce light lands
    if len(p) > keep:
        p = p[np.random.default_rng(seed).choice(len(p), keep, replace=False)]
    label = (f"{len(p)} caustic photons (L S+ D) in orange" if caustic
             else f"{len(p)} photons of the first bounces in orange")
    return label, p


def _add_scene_meshes(p, desc, pv, opacity=1.0, culling="back") -> int:
    """Adds the scene's shapes to the plotter `p`, coloured by their BSDF
    (emitters yellow, glass translucent blue, metal grey), each opacity
    times `opacity`. Returns how many shapes it drew."""
    n = 0
    for s in desc.shapes:
        col, op = _bsdf_colour(s.bsdf)
        if s.emitter is not None:
            col, op = (1.0, 0.85, 0.1), 1.0
        if s.type == "mesh" and s.positions is not None and s.indices is not None and len(s.indices):
            faces = np.hstack([np.full((len(s.indices), 1), 3), np.asarray(s.indices, np.int64)]).ravel()
            mesh = pv.PolyData(np.asarray(s.positions, np.float64), faces)
        elif s.type == "sphere":
            inside = np.linalg.norm(np.asarray(desc.sensor.to_world, np.float64)[:3, 3] -
                                    np.asarray(s.center, np.float64)) < float(s.radius)
            if inside:  # the camera is inside (a furnace): see through it
                op = min(op, 0.35)
            mesh = pv.Sphere(radius=float(s.radius), center=tuple(float(c) for c in s.center),
                             theta_resolution=32, phi_resolution=32)
        elif s.type == "disk":
            mesh = pv.Disc(center=(0, 0, 0), inner=0, outer=1, normal=(0, 0, 1), c_res=32)
            mesh = mesh.transform(np.asarray(s.to_world, np.float64), inplace=False)
        else:
            continue
        # Back faces culled: walls seen from outside vanish, so a closed room
        # shows its inside (a cut-away) and the camera in it.
        p.add_mesh(mesh, color=col, opacity=op * opacity, smooth_shading=s.type == "sphere", culling=culling)
        n += 1
    return n


def scene_view(desc, out: Path, size=(420, 320), photons=None):
    """Renders the scene's geometry off screen with pyvista: shapes coloured
    by their BSDF (emitters yellow, glass translucent blue, metal grey), the
    camera as a frustum, and `photons` ((N, 3) positions, from
    scene_photons) as orange points. Returns None, or the reason there is no
    view."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista as pv
    except Exception as e:  # pragma: no cover - a missing install
        return f"pyvista is not available ({type(e).__name__}: {e})"
    try:
        pv.OFF_SCREEN = True
        p = pv.Plotter(off_screen=True, window_size=list(size))
        p.set_background("white")
        n = _add_scene_meshes(p, desc, pv)
        if n == 0:
            p.close()
            return "the scene has no surfaces to draw"
        if photons is not None and len(photons):
            p.add_mesh(pv.PolyData(np.asarray(photons, np.float64)), color=(1.0, 0.45, 0.0), point_size=3,
                       render_points_as_spheres=True, opacity=0.8)
        # The camera: its position and a frustum (Mitsuba: +z forward, +y up).
        m = np.asarray(desc.sensor.to_world, np.float64)
        o, fwd, up, left = m[:3, 3], m[:3, 2], m[:3, 1], m[:3, 0]
        bounds = np.array(p.bounds, np.float64).reshape(3, 2)
        d = 0.15 * float(np.linalg.norm(bounds[:, 1] - bounds[:, 0]))
        if desc.sensor.type == "perspective":
            t = math.tan(math.radians(desc.sensor.fov_x) / 2)
            a = desc.sensor.height / max(1, desc.sensor.width)
            corners = [o + d * (fwd + sx * t * left + sy * t * a * up) for sx in (-1, 1) for sy in (-1, 1)]
            for c in corners:
                p.add_mesh(pv.Line(o, c), color="red", line_width=2)
            quad = [corners[0], corners[1], corners[3], corners[2], corners[0]]
            for a_, b_ in zip(quad[:-1], quad[1:]):
                p.add_mesh(pv.Line(a_, b_), color="red", line_width=2)
        p.add_mesh(pv.Sphere(radius=0.02 * max(d, 1e-6) / 0.15, center=o), color="red")
        # View over the scene camera's shoulder: behind it, above and to the
        # side, looking at the middle of the scene, the scene camera's up up.
        centre = bounds.mean(axis=1)
        radius = 0.5 * float(np.linalg.norm(bounds[:, 1] - bounds[:, 0]))
        view = -fwd + 0.7 * up + 0.6 * left
        view /= np.linalg.norm(view)
        p.camera_position = [tuple(centre + 2.4 * radius * view), tuple(centre), tuple(up)]
        p.reset_camera_clipping_range()
        p.screenshot(str(out))
        p.close()
        return None
    except Exception as e:
        return f"pyvista off-screen rendering failed ({type(e).__name__}: {e})"


def _record_frames(normals):
    """Two unit tangents (t, b) per unit normal (Duff et al. 2017's
    branchless orthonormal basis)."""
    n = np.asarray(normals, np.float64)
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def record_values(records, columns):
    """What a record view colours by: (values, label). The luminance of the
    record's irradiance (Rec. 709 weights) where the records carry one
    (irrcache: E_r, E_g, E_b), else the radius (radcache)."""
    a = np.asarray(records, np.float64)
    cols = list(columns or [])
    if all(c in cols for c in ("E_r", "E_g", "E_b")):
        e = a[:, [cols.index("E_r"), cols.index("E_g"), cols.index("E_b")]]
        return e @ np.array([0.2126, 0.7152, 0.0722]), "irradiance (luminance)"
    return a[:, cols.index("radius") if "radius" in cols else 6], "record radius"


def record_discs(records, columns, pv, segments: int = 24, lift: float = 4e-3, outline: bool = False):
    """The cache records as a pyvista PolyData: per record a disc (or, with
    `outline`, a circle) of the record's radius in its tangent plane, wound
    counter-clockwise about its normal (back faces can be culled), with the
    record's value (record_values) on each cell. Each disc is lifted along
    its normal by up to `lift` x the largest radius, the smaller the disc
    the higher, so that small records (corners, edges) lie on top of the
    large ones they overlap and nothing fights the surface for depth."""
    a = np.asarray(records, np.float64)
    cols = list(columns or [])

    def col(name, k):
        return cols.index(name) if name in cols else k

    pos = a[:, [col("x", 0), col("y", 1), col("z", 2)]]
    nrm = a[:, [col("nx", 3), col("ny", 4), col("nz", 5)]]
    nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    rad = a[:, col("radius", 6)]
    val, _ = record_values(a, cols)
    t, b = _record_frames(nrm)
    phi = 2 * math.pi * np.arange(segments) / segments
    ring = (np.cos(phi)[None, :, None] * t[:, None, :] + np.sin(phi)[None, :, None] * b[:, None, :])
    rmax = float(rad.max()) if len(rad) else 1.0
    rank = np.argsort(np.argsort(-rad, kind="stable"), kind="stable") / max(1, len(rad) - 1)
    h = lift * rmax * (0.25 + 0.75 * rank)
    pts = pos[:, None, :] + rad[:, None, None] * ring + (h[:, None] * nrm)[:, None, :]
    idx = np.arange(len(a) * segments).reshape(len(a), segments)
    if outline:
        cells = np.hstack([np.full((len(a), 1), segments + 1), idx, idx[:, :1]]).ravel()
        mesh = pv.PolyData(pts.reshape(-1, 3), lines=cells)
    else:
        cells = np.hstack([np.full((len(a), 1), segments), idx]).ravel()
        mesh = pv.PolyData(pts.reshape(-1, 3), faces=cells)
    mesh.cell_data["value"] = val
    return mesh


def records_view(desc, records, columns, out: Path, size=(900, 400), title=None):
    """A 3D view of a cache's records on the scene (pyvista, off screen):
    on the left seen from the scene's camera, on the right from over its
    shoulder as in scene_view; each record a translucent disc of its radius
    with its outline, and its centre as a point, all coloured by the
    record's irradiance (log scale; record_values). Returns None, or the
    reason there is no view."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista as pv
    except Exception as e:  # pragma: no cover - a missing install
        return f"pyvista is not available ({type(e).__name__}: {e})"
    a = np.asarray(records, np.float64)
    if a.ndim != 2 or len(a) == 0:
        return "the cache holds no records"
    try:
        val, label = record_values(a, columns)
        pos_v = val[val > 0]
        lo = float(np.percentile(pos_v, 1)) if pos_v.size else 1e-6
        hi = float(pos_v.max()) if pos_v.size else 1.0
        lo = min(lo, hi / 10)
        clim = [math.log10(lo), math.log10(hi)]
        cols = list(columns or [])
        m = np.asarray(desc.sensor.to_world, np.float64)
        o, fwd, up, left = m[:3, 3], m[:3, 2], m[:3, 1], m[:3, 0]
        pv.OFF_SCREEN = True
        p = pv.Plotter(off_screen=True, window_size=list(size), shape=(1, 2), border=False)
        for k in range(2):
            p.subplot(0, k)
            p.set_background("white")
            _add_scene_meshes(p, desc, pv, opacity=0.3)
            box = np.array(p.bounds, np.float64).reshape(3, 2)  # the scene's, and every record's centre in it
            box = np.stack([np.minimum(box[:, 0], a[:, :3].min(axis=0)),
                            np.maximum(box[:, 1], a[:, :3].max(axis=0))], axis=1)
            pad = 0.01 * float(np.linalg.norm(box[:, 1] - box[:, 0]))  # the discs' lift
            box = (box + np.array([-pad, pad])).ravel()
            rims = record_discs(a, cols, pv, outline=True)
            rims.cell_data["log10 " + label] = np.log10(np.maximum(rims.cell_data["value"], lo))
            rims = rims.clip_box(box, invert=False)  # what spills past the scene's walls
            if rims.n_cells:
                p.add_mesh(rims, scalars="log10 " + label, cmap="viridis", clim=clim, opacity=0.45, line_width=1,
                           show_scalar_bar=False)
            centres = pv.PolyData(a[:, :3].copy())
            centres.point_data["log10 " + label] = np.log10(np.maximum(val, lo))
            p.add_mesh(centres, scalars="log10 " + label, cmap="viridis", clim=clim, point_size=5,
                       render_points_as_spheres=True, show_scalar_bar=False)
            bounds = box.reshape(3, 2)
            centre = bounds.mean(axis=1)
            radius = 0.5 * float(np.linalg.norm(bounds[:, 1] - bounds[:, 0]))
            if k == 0 and desc.sensor.type == "perspective":
                p.camera_position = [tuple(o), tuple(o + fwd), tuple(up)]
                w, h = max(1, desc.sensor.width), max(1, desc.sensor.height)
                fy = 2 * math.degrees(math.atan(math.tan(math.radians(desc.sensor.fov_x) / 2) * h / w))
                p.camera.view_angle = fy * 1.05
            else:
                view = -fwd + 0.7 * up + 0.6 * left
                view /= np.linalg.norm(view)
                p.camera_position = [tuple(centre + 3.2 * radius * view), tuple(centre), tuple(up)]
                p.add_scalar_bar(title="log10 E" if label.startswith("irradiance") else "log10 R", n_labels=4,
                                 color="black", vertical=True,
                                 position_x=0.88, position_y=0.1, width=0.06, height=0.7, title_font_size=9,
                                 label_font_size=9)
            p.reset_camera_clipping_range()
            p.add_text(("from the camera" if k == 0 else "from over its shoulder") +
                       (f": {title}" if title and k == 0 else ""), font_size=7, color="black")
        p.screenshot(str(out))
        p.close()
        return None
    except Exception as e:
        return f"pyvista off-screen rendering failed ({type(e).__name__}: {e})"


def records_figures(scene, recs, desc, root: Path, out: Path) -> list:
    """The page's parts for the cache records of `recs` (jobs whose record
    names arrays kept beside the EXR: benchmarks/runner.RECORD_ARRAYS): per
    estimator, the records view (records_view) of its lowest seed, or why
    there is none."""
    first = {}
    for r in sorted(recs, key=lambda r: r["seed"]):
        if r["status"] == "ok" and r.get("arrays"):
            first.setdefault(r["estimator"], r)
    parts = []
    for est, r in sorted(first.items()):
        for _name, a in sorted(r["arrays"].items()):
            npy = Path(a.get("npy") or "")
            png = f"{scene}-{est}-records.png"
            if desc is None:
                why = "the scene does not load here"
            elif npy.is_absolute() or ".." in npy.parts or not (root / npy).is_file():
                why = f"{npy} is not under the results folder"
            else:
                why = records_view(desc, np.load(root / npy), a.get("columns"), out / png,
                                   title=f"{est}, {a.get('rows')} records")
            if why is None:
                values = "irradiance" if "E_r" in (a.get("columns") or []) else "radius"
                parts.append(f"<figure><img src='{png}' alt='{esc(scene)} {esc(est)} cache records'><figcaption>"
                             f"{esc(est)} (seed {r['seed']}): {a.get('rows')} cache records, each a point with a "
                             f"circle of its radius, coloured by its {values} (log scale)</figcaption></figure>")
            else:
                parts.append(f"<p class='note'>no view of {esc(est)}'s cache records: {esc(why)}</p>")
    return parts


BIAS_BLOCK = 4


def bias_maps(images, ref, block: int = BIAS_BLOCK, eps: float = 1e-2):
    """The bias of a biased estimator, seen over seeds: per pixel the
    luminance of (mean over `images` - `ref`) / (ref + eps) (eps as relMSE's,
    metrics.RELMSE_EPS), and the same of the block x block means of both
    images (most of the noise of the seed mean averages out there, the
    interpolation's blotches do not). Returns (pixel map, block map)."""
    w = np.array([0.2126, 0.7152, 0.0722])
    lum_mean = np.mean([np.asarray(im, np.float64) for im in images], axis=0) @ w
    lum_ref = np.asarray(ref, np.float64) @ w
    pix = (lum_mean - lum_ref) / (lum_ref + eps)
    h, wd = (lum_ref.shape[0] // block) * block, (lum_ref.shape[1] // block) * block

    def blocks(a):
        return a[:h, :wd].reshape(h // block, block, wd // block, block).mean(axis=(1, 3))

    return pix, (blocks(lum_mean) - blocks(lum_ref)) / (blocks(lum_ref) + eps)


def bias_map_panels(axes, pix, blk, v, prefix="", sep=" ", block=BIAS_BLOCK):
    """Draws bias_maps' pixel and block maps into the two axes `axes` on the
    symmetric scale [-v, v], each titled with its RMS and mean (`prefix`
    before the title, `sep` before its figures); returns the last image
    for a colour bar."""
    for ax, m, name in ((axes[0], pix, "per pixel"), (axes[1], blk, f"{block} x {block} blocks")):
        h = ax.imshow(m, cmap="RdBu_r", vmin=-v, vmax=v, interpolation="nearest")
        ax.set_title(f"{prefix}{name}:{sep}RMS {float(np.sqrt(np.mean(m ** 2))):.3g}, mean {float(m.mean()):+.3g}",
                     fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    return h


def cache_bias_figures(scene, recs, ref_image, root: Path, out: Path) -> list:
    """The page's parts for the bias of each estimator whose jobs kept cache
    records: its seeds' mean against the reference (bias_maps), signed, on
    one symmetric scale; or why there is none (fewer than two seeds)."""
    ests = sorted({r["estimator"] for r in recs if r["status"] == "ok" and r.get("arrays")})
    parts = []
    for est in ests:
        ims = [im.image for im in (_load_exr(root, r) for r in recs if r["estimator"] == est and r["status"] == "ok")
               if im is not None and im.image.shape == ref_image.shape]
        if len(ims) < 2:
            parts.append(f"<p class='note'>no bias map of {esc(est)}: {len(ims)} seed with its image here "
                         f"(the mean over seeds needs two)</p>")
            continue
        pix, blk = bias_maps(ims, ref_image)
        plt = _plt()
        fig, axes = plt.subplots(1, 2, figsize=(7.2, 3.3), dpi=90)
        h = bias_map_panels(axes, pix, blk, max(float(np.percentile(np.abs(pix), 99)), 1e-6))
        fig.colorbar(h, ax=axes.tolist(), shrink=0.8, label="(mean - ref) / (ref + 0.01), luminance")
        fig.suptitle(f"{scene}: {est}, mean of {len(ims)} seeds against the reference", fontsize=9)
        png = f"{scene}-{est}-bias.png"
        fig.savefig(out / png)
        plt.close(fig)
        parts.append(f"<figure><img src='{png}' alt='{esc(scene)} {esc(est)} bias map'><figcaption>{esc(est)}: "
                     f"signed relative error of the mean of {len(ims)} seeds (red: too bright); the block means "
                     f"keep the interpolation's blotches and lose most of the noise</figcaption></figure>")
    return parts


# -- the page -------------------------------------------------------------------


def metropolis_chains_html(recs) -> str:
    """The chains of a scene's Metropolis jobs (pssmlt, mmlt: the records
    whose stats carry mlt_chains), one row per job: acceptance, the longest
    run of consecutive rejections, and the chains whose run exceeded the
    job's `stuck_rejections` (res.stats mlt_stuck_chains). A stuck chain
    splats one sample hundreds of times, a bright blotch its image keeps:
    nothing is clamped or dropped, so the images above show it as rendered,
    and this table says where to look. "" when the scene has none."""
    rows = sorted((r for r in recs if r.get("status") == "ok" and "mlt_chains" in (r.get("stats") or {})),
                  key=lambda r: (r["estimator"], str(r["budget"]), r["seed"]))
    if not rows:
        return ""

    def num(st, k, fmt):
        v = st.get(k)
        return "?" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)

    out = ["<table class='chains'><thead><tr><th>estimator</th><th>budget</th><th>seed</th><th>spp</th>"
           "<th>acceptance</th><th>longest rejection run</th><th>stuck chains</th></tr></thead><tbody>"]
    stuck_jobs = 0
    for r in rows:
        st = r["stats"]
        n_stuck = int(st.get("mlt_stuck_chains") or 0)
        stuck_jobs += n_stuck > 0
        cls = " class='failed'" if n_stuck else ""
        out.append(f"<tr><td>{esc(r['estimator'])}</td><td>{esc(T.budget_label(r['budget']))}</td>"
                   f"<td>{r['seed']}</td><td>{r.get('spp', '?')}</td><td>{num(st, 'mlt_acceptance', '.3f')}</td>"
                   f"<td>{num(st, 'mlt_longest_rejection_run', '.0f')}</td>"
                   f"<td{cls}>{n_stuck} of {num(st, 'mlt_chains', '.0f')} (over "
                   f"{num(st, 'mlt_stuck_rejections', '.0f')})</td></tr>")
    out.append("</tbody></table>")
    head = (f"<p class='note'>Metropolis chains: {stuck_jobs} of {len(rows)} jobs have a stuck chain (one that "
            "rejected more consecutive proposals than its <code>stuck_rejections</code>). A stuck chain splats the "
            "same sample again and again: a bright blotch that its image keeps, as rendered (nothing is clamped), "
            "while the other seeds miss it; the estimator stays unbiased over seeds, but such a render may be far "
            "from the mean.</p>")
    return head + "".join(out)


def time_to_error_html(results_json: Path, out: Path) -> str:
    """The side-by-side measurement against Mitsuba 3
    (benchmarks/studies/time_to_error.py's results file): per scene the
    target error, the time each contender takes to reach it, the ratio of
    our best to Mitsuba's best, samples per second and thread scaling,
    with the commit and machine it was measured on; its plot copied beside
    the page. A note when the study has not been run."""
    import json
    import shutil

    results_json = Path(results_json)
    head = "<h2>Against Mitsuba 3: time to error</h2>"
    if not results_json.exists():
        return (head + "<p class='note'>Not measured yet: run <code>python -m "
                "radiometer.benchmarks.studies.time_to_error</code>.</p>")
    d = json.loads(results_json.read_text())
    m = d.get("machine") or {}
    # The ceiling beside it (benchmarks/studies/embree_limit.py --groups):
    # each scene's ratio if we cost nothing but Embree's fastest grouping.
    from radiometer.benchmarks.studies.embree_limit import zero_shading_ratio

    limit_json = results_json.with_name("embree_limit.json")
    limits = {}
    if limit_json.exists():
        limits = {r["scene"]: r for r in json.loads(limit_json.read_text()).get("rows", [])
                  if r.get("estimator") == "path" and r.get("groups")}
    def floor_cell(scene, r):
        f = zero_shading_ratio(r, limits[scene]) if scene in limits else None
        return "not measured" if f is None else f"{f:.2f}"

    rows = []
    for scene, r in d.get("scenes", {}).items():
        best = {c["renderer"]: c for c in sorted(r["contenders"], key=lambda c: c["time_to_target_s"], reverse=True)}
        threads = "; ".join(f"{t} thr.: ours {v['ours_msamples_per_s']:.2f}, Mitsuba "
                            f"{v['mitsuba_llvm_msamples_per_s']:.2f}" for t, v in r.get("thread_scaling", {}).items())
        rows.append(f"<tr><td>{esc(scene)}</td><td>{r['target_relmse']:.3g}</td>"
                    f"<td>{esc(r['best_ours'])}: {best['radiometer']['time_to_target_s']:.3g} s</td>"
                    f"<td>{esc(r['best_mitsuba'])}: {best['mitsuba']['time_to_target_s']:.3g} s</td>"
                    f"<td style='background:{_ratio_colour(1 / r['ratio'], 'yes')}'>{r['ratio']:.2f}</td>"
                    f"<td>{floor_cell(scene, r)}</td><td>{esc(threads)}</td></tr>")
    png = results_json.with_suffix(".png")
    img = ""
    if png.exists():
        shutil.copy(png, Path(out) / "time_to_error.png")
        img = "<p><img src='time_to_error.png' alt='error against time, ours and Mitsuba 3' width='100%'></p>"
    return (head + "<p class='note'>Time to the scene's target relMSE on each renderer's own error-against-time "
            "curve (box filter on both sides, the same max_depth; Msamples/s at the ladder's middle spp), our best "
            "sampler against Mitsuba 3's best variant and sampler; the goal is a ratio of at most 0.5. Measured at "
            f"commit {esc(str(d.get('commit')))} on {esc(str(m.get('cpu', '?')))}, {esc(str(m.get('cores', '?')))} "
            f"cores, {esc(str(d.get('date')))}. "
            "The ratio at zero shading cost is what it would be if our renderer cost nothing but bare Embree's "
            "fastest grouping of the same rays (packets or streams, queued as a wavefront renderer would; "
            "<code>embree_limit --groups</code>, robust mode on), with our samples as they are: above 0.5, "
            "faster rays alone cannot reach the goal on this machine.</p>"
            "<table><tr><th>scene</th><th>target relMSE</th><th>ours, best</th><th>Mitsuba, best</th>"
            "<th>ratio</th><th>ratio at zero shading cost</th><th>Msamples/s by threads</th></tr>" + "".join(rows) +
            "</table>" + img)


def write_page(run: dict, recs: list, root: Path, out: Path, source, log=print, history=None) -> Path:
    """Writes the report of one run (its store row `run` and job records
    `recs`, renders under `root`) into the folder `out`; `source` names
    where they came from; `history`: the store's jobs of every run of this
    matrix (Store.history), for the history view. Returns index.html's
    path. The harness reads the store and calls this
    (radiometer.benchmarks.report)."""
    from radiometer.reference_scenes import references as R
    from radiometer.reference_scenes import registry as S

    from . import viewer as V
    from .verdict import TERM_HOW, winners

    root, out = Path(root), Path(out)
    rid = run["run_id"]
    out.mkdir(parents=True, exist_ok=True)
    rows = T.aggregate(recs)
    wins = winners(recs)
    target = next((r["verdict"]["target"] for r in rows if r.get("verdict")), None)
    n = {s: sum(1 for r in recs if r["status"] == s) for s in ("ok", "unsupported", "failed")}
    m = run.get("machine") or {}
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>radiometer bench {esc(rid)}</title>",
             f"<style>{CSS}</style></head><body>",
             f"<h1>radiometer benchmark: {esc(run['matrix'])}</h1>",
             "<table class='meta'>",
             f"<tr><th>run</th><td>{esc(rid)}</td></tr>",
             f"<tr><th>commit</th><td>{esc(str(run.get('commit_id')))}</td></tr>",
             f"<tr><th>machine</th><td>{esc(m.get('host', '?'))}: {esc(m.get('cpu', '?'))}, "
             f"{esc(str(m.get('cores', '?')))} cores, "
             f"{esc(m.get('system', ''))} {esc(m.get('release', ''))}, Python {esc(m.get('python', ''))}</td></tr>",
             f"<tr><th>matrix</th><td>{esc(str(run.get('matrix_path')))}</td></tr>",
             f"<tr><th>started / finished</th><td>{esc(str(run.get('started')))} / "
             f"{esc(str(run.get('finished')))}</td></tr>",
             f"<tr><th>jobs</th><td>{len(recs)}: {n['ok']} ok, {n['unsupported']} unsupported, "
             f"{n['failed']} failed</td></tr>",
             "</table>",
             "<p id='selfcheck'>(image check runs on load)</p>",
             "<p><a href='viewer.html'>image viewer</a>: flip between the reference, the estimators and the effects, "
             "zoom, exposure, relative and FLIP error maps.</p>",
             "<h2>Which estimator wins</h2>",
             "<p class='note'>Per scene and effect, the estimator with the highest efficiency 1 / (relMSE x seconds) "
             "at the compared budget (equal time where the run has a seconds budget), a geometric mean over seeds; "
             "the cell shows its ratio over the runner-up and is greener the larger it is (white: a tie, full green: "
             "100x). Grey with ~: the 95 % intervals over seeds overlap, so the seeds do not tell the two apart. Each "
             "cell links to its evidence (every estimator's efficiency and interval) in the scene's section.</p>",
             winner_matrix_html(wins),
             "<h2>Is each result usable?</h2>",
             "<p class='note'>" + (f"Target relMSE {target:g} (the matrix's <code>target_relmse</code>). " if target
                                   else "") +
             "A configuration is usable when every seed's own error (relMSE less the reference's own noise) is at "
             "most the target; 'cannot tell' when the reference's noise alone reaches it. The dominant term is the "
             "largest of: " + "; ".join(f"<b>{esc(k)}</b>: {esc(v)}" for k, v in TERM_HOW.items()) +
             ". Means over seeds.</p>",
             verdict_table_html(rows),
             time_to_error_html(Path(__file__).resolve().parents[1] / "benchmarks" / "results" /
                                "time_to_error.json", out),
             "<h2>Per-effect error</h2>",
             "<p class='note'>relMSE (eps 1e-2) of each effect class against its per-effect reference, mean over "
             "seeds; total: the whole image against the scene's reference (analytic, or Mitsuba 3's). Per-effect "
             "references: exact for analytic scenes; for the others a long run of our unbiased path tracer whose "
             "total passed the z-test against Mitsuba (listed below the table). Bold: the lowest total error of the "
             "scene.</p>",
             T.effect_table_html(rows),
             "<h2>All metrics (total image)</h2>", _metrics_table(rows),
             "<h2>Bias and variance over seeds</h2>",
             "<p class='note'>From the renders of each configuration with independent seeds (analysis/stats.py "
             "bias_variance): the bias of the image mean relative to the reference's mean, its z (the bias over its "
             "standard error, with the reference's variance; |z| &gt; 3 is a bias the seeds resolve), and the "
             "relative variance of one render, mean(var / (ref<sup>2</sup> + 0.01)), which is what relMSE would be "
             "without bias. Read z with care: with a few seeds at a small budget a heavy-tailed estimator misses its "
             "rare paths in every seed and underestimates its variance there (tests/test_canonical_mitsuba.py measures "
             "this), so a moderate |z| is a hint; a large one with a large bias is a finding (direct lighting's "
             "truncation, light tracing's missing L...S E paths). A zero-variance render's z measures float32 "
             "rounding.</p>", _bias_table(recs, root),
             "<h2>Error budget per effect over seeds</h2>",
             "<p class='note'>For each effect class against its per-effect reference, from the seeds of each "
             "configuration (renders keep one variance, of the whole image, so a per-effect noise comes from the "
             "spread over seeds): noise = mean(s<sup>2</sup> / (ref<sup>2</sup> + 0.01)), s<sup>2</sup> the "
             "per-pixel variance across seeds, the expected relMSE of one render from noise; bias = "
             "mean(((mean - ref)<sup>2</sup> - s<sup>2</sup> / k) / (ref<sup>2</sup> + 0.01)), clamped at 0, the "
             "squared bias less the seed mean's own variance. The larger is bold. With few seeds both are rough "
             "(the variance over k seeds has k - 1 degrees of freedom). In brackets: the noise from each render's own "
             "per-effect variance (res.effect_variance: the films of camera estimators keep it), mean over seeds; "
             "the two noise estimates should agree within the seeds' spread.</p>", _effect_budget_table(recs, root)]
    scenes = sorted({r["scene"] for r in recs})
    views_note = None
    viewer_scenes = []
    from .verdict import comparison_budget

    for scene in scenes:
        srecs = [r for r in recs if r["scene"] == scene]
        parts.append(f"<h2 id='{esc(scene)}'>{esc(scene)}</h2>")
        parts.append(evidence_html(scene, wins))
        parts.append("<div class='figs'>")
        spec = S.ALL_SCENES.get(scene)
        params = srecs[0]["scene_params"]
        # Convergence plot.
        png = f"{scene}-convergence.png"
        if convergence_plot(scene, srecs, out / png):
            parts.append(f"<figure><img src='{png}' alt='{esc(scene)} error against time'><figcaption>relMSE "
                         f"against time: geometric mean over seeds at each checkpoint, 95 % band, fitted slopes"
                         f"</figcaption></figure>")
        else:
            parts.append("<p class='note'>no convergence curve: no job of this scene finished</p>")
        # The compared budget (as the winners'): equal time where there is a seconds budget.
        b, _ = comparison_budget(srecs)
        brecs = [r for r in srecs if r["budget"] == b]
        png = f"{scene}-history.png"
        why_hist = history_plot(scene, history or [], b, out / png)
        if why_hist is None:
            parts.append(f"<figure><img src='{png}' alt='{esc(scene)} history'><figcaption>error and time per "
                         f"estimator across the store's runs of this matrix</figcaption></figure>")
        else:
            parts.append(f"<p class='note'>no history view: {esc(why_hist)}</p>")
        ref = None
        try:
            eff_ref = next((r.get("effect_ref") for r in brecs if r.get("effect_ref")), None)
            ref = R.reference(scene, params, eff_ref) if spec else None
        except Exception as e:
            parts.append(f"<p class='note'>no reference image: {esc(str(e))}</p>")
        png = f"{scene}-images.png"
        label = ("equal time, " if "seconds" in b else "equal samples, ") + T.budget_label(b)
        if ref is not None:
            shown = []
            for est in sorted({r["estimator"] for r in brecs}):
                ok = sorted((r for r in brecs if r["estimator"] == est and r["status"] == "ok"),
                            key=lambda r: r["seed"])
                if ok:
                    shown.append((est, f"{est} ({ok[0]['spp']} spp, seed {ok[0]['seed']})", _load_exr(root, ok[0])))
            if V.scene_data(scene, ref, shown, out) is not None:
                viewer_scenes.append(scene)
        if ref is not None and image_comparison(scene, brecs, ref.image, root, out / png, label):
            parts.append(f"<figure><img src='{png}' alt='{esc(scene)} equal-budget images'><figcaption>{esc(label)}: "
                         f"image, crop, per-pixel relative squared error</figcaption></figure>")
        else:
            parts.append("<p class='note'>no image comparison: no render of this scene is available "
                         "(jobs unsupported or failed, or their EXRs are on another machine)</p>")
        # 3D view.
        png = f"{scene}-view.png"
        why = None
        loaded = None
        try:
            import radiometer as rm

            loaded = rm.load_file(spec.xml, **params)
            ph = scene_photons(loaded)
            why = scene_view(loaded.desc, out / png, photons=None if ph is None else ph[1])
        except Exception as e:
            ph = None
            why = f"the scene does not load here ({type(e).__name__}: {e})"
        if why is None:
            extra = "" if ph is None else f"; {esc(ph[0])}"
            parts.append(f"<figure><img src='{png}' alt='{esc(scene)} 3D view'><figcaption>3D view (pyvista, off "
                         f"screen): camera and frustum in red, emitters yellow{extra}</figcaption></figure>")
        else:
            if "pyvista" in why:
                views_note = why
            parts.append(f"<p class='note'>no 3D view: {esc(why)}</p>")
        parts += records_figures(scene, brecs, None if loaded is None else loaded.desc, root, out)
        if ref is not None:
            parts += cache_bias_figures(scene, brecs, ref.image, root, out)
        parts.append("</div>")
        parts.append(metropolis_chains_html(srecs))
        # Errors of failed jobs.
        bad = [r for r in srecs if r["status"] != "ok"]
        if bad:
            msgs = sorted({(r["estimator"], r["status"], (r.get("error") or "").strip()) for r in bad})
            parts.append("<details><summary>jobs not run or failed</summary><ul>")
            parts += [f"<li>{esc(e)}: <span class='status {esc(s)}'>{esc(s)}</span> <pre>{esc(msg)}</pre></li>"
                      for e, s, msg in msgs]
            parts.append("</ul></details>")
    if views_note:
        log(f"report: 3D views unavailable: {views_note}")
    parts.append(f"<p class='note'>written {_dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')} "
                 f"from {esc(str(source))}</p>")
    parts.append(f"<script>{SELF_CHECK}</script></body></html>")
    V.write_viewer(out, viewer_scenes, f"radiometer bench {rid}", CSS)
    index = out / "index.html"
    index.write_text("\n".join(parts))
    return index


def _bias_table(recs, root: Path) -> str:
    from radiometer.reference_scenes import references as R

    from .metrics import RELMSE_EPS
    from .stats import bias_variance

    groups = {}
    for r in recs:
        if r["status"] == "ok":
            groups.setdefault((r["scene"], r["estimator"], T.budget_label(r["budget"])), []).append(r)
    head = ["scene", "estimator", "budget", "seeds", "relative bias", "bias z", "relative variance", "relMSE"]
    out = ["<table><thead><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr></thead><tbody>"]
    n = 0
    for (scene, est, bl), rs in sorted(groups.items()):
        imgs = [im.image for im in (_load_exr(root, r) for r in rs) if im is not None]
        if len(imgs) < 2:
            continue
        try:
            ref = R.reference(scene, rs[0]["scene_params"], rs[0].get("effect_ref"))
            bv = bias_variance(imgs, ref.image, ref.variance)
        except Exception:
            continue
        k = len(imgs)
        se = math.sqrt(float(np.sum(bv["bias_se"] ** 2))) / bv["bias"].size
        z = bv["mean_bias"] / se if se > 0 else (0.0 if bv["mean_bias"] == 0 else math.inf)
        relvar = float(np.mean(bv["variance"] / (ref.image ** 2 + RELMSE_EPS)))
        relmse = float(np.mean([r["metrics"]["relmse"] for r in rs]))
        zs = T.fmt(z, 2)
        if math.isfinite(z) and abs(z) > 3:
            zs = f"<b>{zs}</b>"
        out.append("<tr>" + "".join(f"<td>{c}</td>" for c in (
            esc(scene), esc(est), esc(bl), k, f"{100 * bv['rel_bias']:+.3g} %", zs, T.fmt(relvar),
            T.fmt(relmse))) + "</tr>")
        n += 1
    out.append("</tbody></table>")
    if n == 0:
        return "<p class='note'>no configuration has two finished seeds with their images here</p>"
    return "\n".join(out)


def _effect_budget_table(recs, root: Path) -> str:
    """Per configuration with two seeds or more and its EXRs here: each
    effect's noise and bias over seeds (verdict.effect_budget_over_seeds),
    the larger one in bold."""
    from radiometer.reference_scenes import references as R

    from .verdict import effect_budget_over_seeds

    groups = {}
    for r in recs:
        if r["status"] == "ok":
            groups.setdefault((r["scene"], r["estimator"], T.budget_label(r["budget"])), []).append(r)
    lines, effs_all = [], set()
    for (scene, est, bl), rs in sorted(groups.items()):
        ims = [im for im in (_load_exr(root, r) for r in rs) if im is not None]
        if len(ims) < 2:
            continue
        try:
            ref = R.reference(scene, rs[0]["scene_params"], rs[0].get("effect_ref"))
        except Exception:
            continue
        if ref.effects is None:
            continue
        cells = {}
        for eff, theirs in ref.effects.items():
            theirs = np.asarray(theirs, np.float64)
            mine = [np.asarray(im.effects.get(eff, np.zeros_like(theirs)), np.float64) for im in ims]
            if not (np.any(theirs != 0) or any(np.any(m != 0) for m in mine)):
                continue
            cells[eff] = effect_budget_over_seeds(mine, theirs)
            own = [((r.get("effect_metrics") or {}).get(eff) or {}).get("noise") for r in rs]
            own = [x for x in own if x is not None]
            cells[eff]["render_noise"] = float(np.mean(own)) if own else None
            effs_all.add(eff)
        if cells:
            lines.append((scene, est, bl, len(ims), cells))
    if not lines:
        return "<p class='note'>no configuration has two finished seeds, its images and a per-effect reference here</p>"
    effs = T.effect_columns([{"effects": {e: 1 for e in effs_all}}])
    out = ["<table><thead><tr><th>scene</th><th>estimator</th><th>budget</th><th>seeds</th>" +
           "".join(f"<th>{esc(e)}: noise / bias</th>" for e in effs) + "</tr></thead><tbody>"]
    for scene, est, bl, k, cells in lines:
        row = [esc(scene), esc(est), esc(bl), str(k)]
        for e in effs:
            c = cells.get(e)
            if c is None:
                row.append("")
                continue
            n, b = T.fmt(c["noise"]), T.fmt(c["bias"])
            txt = f"<b>{n}</b> / {b}" if c["noise"] >= c["bias"] else f"{n} / <b>{b}</b>"
            if c["render_noise"] is not None:
                txt += f" <span class='note'>(render: {T.fmt(c['render_noise'])})</span>"
            row.append(txt)
        out.append("<tr>" + "".join(f"<td>{x}</td>" for x in row) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _metrics_table(rows) -> str:
    head = ["scene", "estimator", "budget", "spp", "seconds", "relMSE", "MSE", "SMAPE", "FLIP", "CIEDE2000",
            "relMSE floor", "slope", "time to target", "efficiency"]
    out = ["<table><thead><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr></thead><tbody>"]
    for r in rows:
        if r["status"] != "ok":
            continue
        mm = r["metrics"]
        cells = [esc(r["scene"]), esc(r["estimator"]), esc(r["budget"]), f"{r['spp']:.0f}", T.fmt(r["seconds"])]
        cells += [T.fmt(mm.get(k)) for k in ("relmse", "mse", "smape", "flip", "ciede2000", "relmse_floor")]
        cells += [T.fmt(mm.get("slope"), 2), T.fmt(mm.get("time_to_target")), T.fmt(mm.get("efficiency"))]
        out.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)
