"""`radiometer report RUN`: a static HTML report of one benchmark run.

One folder, index.html plus PNGs, no scripts from elsewhere:
  * machine, commit, matrix and job counts;
  * the per-effect error table (scene x estimator x effect, relMSE, mean
    over seeds) and a table of every metric;
  * per scene: a log-log plot of relMSE against time from each render's
    checkpoints, every seed drawn, each estimator's fitted slope in the
    legend (-1 is the Monte Carlo rate of an unbiased estimator);
    an equal-budget image comparison (reference and each estimator's seed-0
    image, tone-mapped with the reference's exposure; a 4x crop around the
    region where the estimators err most; the per-pixel relative squared
    error as a heat map on one log scale per scene); a pyvista off-screen
    3D view of the scene (VTK through EGL: VTK_DEFAULT_OPENGL_WINDOW =
    vtkEGLRenderWindow), with the camera and its view frustum. Where a view
    cannot be made, the report says why in its place.
A small inline script checks on load that every image decoded and writes
the count into the page (body[data-images-ok]), for people and for the
headless-browser test.
"""
from __future__ import annotations

import datetime as _dt
import html
import json
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


def convergence_plot(scene, recs, out: Path) -> bool:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.2, 3.8), dpi=100)
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
        ts, es = [], []
        for r in rs:
            t = [p[1] for p in r["curve"]]
            e = [p[2] for p in r["curve"]]
            ax.plot(t, e, "-", color=c, alpha=0.35, lw=1)
            ts += t
            es += e
        from .metrics import loglog_slope

        s = loglog_slope(ts, es)
        ok = [(t, e) for t, e in zip(ts, es) if t > 0 and e > 0]
        if s is not None and ok:
            lt, le = np.log([p[0] for p in ok]), np.log([p[1] for p in ok])
            b = float(np.mean(le - s * lt))
            xs = np.array([min(p[0] for p in ok), max(p[0] for p in ok)])
            ax.plot(xs, np.exp(b) * xs ** s, "--", color=c, lw=1.5, label=f"{est}: slope {s:.2f}")
        else:
            ax.plot([], [], color=c, label=f"{est}: slope n/a")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds")
    ax.set_ylabel("relMSE")
    ax.set_title(f"{scene}: error against time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return True


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
    fig, axes = plt.subplots(len(rows), 3, figsize=(7.5, 2.5 * len(rows)), dpi=90, squeeze=False)
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
            p.add_mesh(mesh, color=col, opacity=op, smooth_shading=s.type == "sphere", culling="back")
            n += 1
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


# -- the page -------------------------------------------------------------------


def write_page(run: dict, recs: list, root: Path, out: Path, source, log=print) -> Path:
    """Writes the report of one run (its store row `run` and job records
    `recs`, renders under `root`) into the folder `out`; `source` names
    where they came from. Returns index.html's path. The harness reads
    the store and calls this (radiometer.benchmarks.report)."""
    from radiometer.reference_scenes import references as R
    from radiometer.reference_scenes import registry as S

    root, out = Path(root), Path(out)
    rid = run["run_id"]
    out.mkdir(parents=True, exist_ok=True)
    rows = T.aggregate(recs)
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
             "rounding.</p>", _bias_table(recs, root)]
    scenes = sorted({r["scene"] for r in recs})
    views_note = None
    for scene in scenes:
        srecs = [r for r in recs if r["scene"] == scene]
        parts.append(f"<h2 id='{esc(scene)}'>{esc(scene)}</h2><div class='figs'>")
        spec = S.SCENES.get(scene)
        params = srecs[0]["scene_params"]
        # Convergence plot.
        png = f"{scene}-convergence.png"
        if convergence_plot(scene, srecs, out / png):
            parts.append(f"<figure><img src='{png}' alt='{esc(scene)} error against time'><figcaption>relMSE "
                         f"against time (checkpoints of each render, every seed), fitted slopes</figcaption></figure>")
        else:
            parts.append("<p class='note'>no convergence curve: no job of this scene finished</p>")
        # Equal-budget images (the largest budget).
        budgets = sorted({json.dumps(r["budget"], sort_keys=True) for r in srecs})
        big = max(budgets, key=lambda b: list(json.loads(b).values())[0])
        b = json.loads(big)
        brecs = [r for r in srecs if json.dumps(r["budget"], sort_keys=True) == big]
        ref = None
        try:
            eff_ref = next((r.get("effect_ref") for r in brecs if r.get("effect_ref")), None)
            ref = R.reference(scene, params, eff_ref) if spec else None
        except Exception as e:
            parts.append(f"<p class='note'>no reference image: {esc(str(e))}</p>")
        png = f"{scene}-images.png"
        label = ("equal time, " if "seconds" in b else "equal samples, ") + T.budget_label(b)
        if ref is not None and image_comparison(scene, brecs, ref.image, root, out / png, label):
            parts.append(f"<figure><img src='{png}' alt='{esc(scene)} equal-budget images'><figcaption>{esc(label)}: "
                         f"image, crop, per-pixel relative squared error</figcaption></figure>")
        else:
            parts.append("<p class='note'>no image comparison: no render of this scene is available "
                         "(jobs unsupported or failed, or their EXRs are on another machine)</p>")
        # 3D view.
        png = f"{scene}-view.png"
        why = None
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
        parts.append("</div>")
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
