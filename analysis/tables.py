"""Per-effect error tables (scene x estimator x effect) from benchmark job
records (benchmarks/runner.py), for the terminal and the HTML report.

Each cell is the mean over seeds of a metric (relMSE by default) of one
effect class's image against its per-effect reference; "total" is the whole
image against the scene's reference. A configuration whose jobs were all
unsupported or failed shows that status instead of numbers.
"""
from __future__ import annotations

import html
import math

import numpy as np

EFFECT_ORDER = ("emission", "direct", "indirect", "caustic", "specular", "volume", "subsurface")


def budget_label(b: dict) -> str:
    return f"{b['spp']} spp" if "spp" in b else f"{b['seconds']:g} s"


def aggregate(records, metric: str = "relmse") -> list:
    """One row per (scene, estimator, budget): mean and spread over seeds."""
    groups = {}
    for r in records:
        k = (r["scene"], r["estimator"], budget_label(r["budget"]))
        groups.setdefault(k, []).append(r)
    rows = []
    for (scene, est, bl), rs in sorted(groups.items()):
        ok = [r for r in rs if r["status"] == "ok"]
        row = {"scene": scene, "estimator": est, "budget": bl, "n": len(rs), "n_ok": len(ok),
               "status": "ok" if ok else rs[0]["status"], "error": None if ok else (rs[0].get("error") or ""),
               "total": None, "total_sd": None, "effects": {}, "spp": None, "seconds": None, "slope": None,
               "efficiency": None, "metrics": {}, "effects_kind": None, "verdict": None}
        if ok:
            vals = [r["metrics"].get(metric) for r in ok if r["metrics"].get(metric) is not None]
            if vals:
                row["total"] = float(np.mean(vals))
                row["total_sd"] = float(np.std(vals, ddof=1)) if len(vals) > 1 else None
            for m in ("relmse", "mse", "smape", "flip", "ciede2000", "relmse_floor", "slope", "time_to_target",
                      "efficiency"):
                v = [r["metrics"].get(m) for r in ok if r["metrics"].get(m) is not None]
                row["metrics"][m] = float(np.mean(v)) if v else None
            row["spp"] = float(np.mean([r["spp"] for r in ok]))
            row["seconds"] = float(np.mean([r["seconds"] for r in ok]))
            # One fit over the seeds' checkpoints (the report's plot draws the same line).
            from .metrics import curves_slope

            row["slope"] = curves_slope([r.get("curve") or [] for r in ok])
            from .verdict import config_verdict

            target = next((r["target_relmse"] for r in ok if r.get("target_relmse")), None)
            if target is None:
                from radiometer.benchmarks.matrix import DEFAULT_TARGET_RELMSE as target
            row["verdict"] = config_verdict(ok, target)
            row["efficiency"] = row["metrics"]["efficiency"]
            effs = {}
            for r in ok:
                for e, d in (r.get("effect_metrics") or {}).items():
                    if d.get(metric) is not None:
                        effs.setdefault(e, []).append(d[metric])
            row["effects"] = {e: float(np.mean(v)) for e, v in effs.items()}
            row["effects_kind"] = (ok[0].get("reference") or {}).get("effects")
        rows.append(row)
    return rows


def short_reason(error: str, width: int = 0) -> str:
    """The last line of an error, with file paths cut to their names (the
    row names the scene), shortened from the left to `width`."""
    import re

    lines = (error or "").strip().splitlines()
    why = re.sub(r"[^\s:]*/([^/\s:]+)", r"\1", lines[-1] if lines else "")
    if width and len(why) > width:
        why = "..." + why[-(width - 3):]
    return why


def collapse_unsupported(rows) -> list:
    """Rows of a scene whose every estimator was refused for the same reason
    become one row (estimator "all"), so a scene the loader refuses does not
    fill the table."""
    out, by_scene = [], {}
    for r in rows:
        by_scene.setdefault(r["scene"], []).append(r)
    for rs in by_scene.values():
        reasons = {short_reason(r["error"]) for r in rs}
        if len(rs) > 1 and all(r["status"] == "unsupported" for r in rs) and len(reasons) == 1:
            budgets = sorted({r["budget"] for r in rs})
            out.append(dict(rs[0], estimator="all", budget=", ".join(budgets), n=sum(r["n"] for r in rs)))
        else:
            out.extend(rs)
    return out


def effect_columns(rows) -> list:
    present = {e for r in rows for e in r["effects"]}
    return [e for e in EFFECT_ORDER if e in present] + sorted(present - set(EFFECT_ORDER))


def fmt(v, digits=3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if v == 0:
        return "0"
    return f"{v:.{digits}g}" if 1e-3 <= abs(v) < 1e4 else f"{v:.{max(1, digits - 1)}e}"


TEXT_WIDTH = 100  # the terminal table stays one screen wide
EFFECT_SHORT = {"subsurface": "subsurf"}
TERM_SHORT = {"noise": "noise", "bias": "bias", "reference": "ref", "truncation": "trunc", "discretisation": "disc",
              "model": "model", "none": "-"}
USABLE_SHORT = {True: "yes", False: "NO", None: "?"}


def _clip(s: str, w: int) -> str:
    return s if len(s) <= w else s[:max(1, w - 1)] + "~"


def _grid(head, body, width):
    """Left-aligned columns two spaces apart, indented by two; each line
    cut at `width` (the callers choose columns that fit)."""
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body)]
    lines = ["  " + "  ".join(str(x).ljust(w) for x, w in zip(head, widths)).rstrip()]
    for b in body:
        lines.append("  " + "  ".join(str(x).ljust(w) for x, w in zip(b, widths)).rstrip())
    return [ln[:width] for ln in lines]


def effect_table_text(rows, metric: str = "relmse", winners=None, width: int = TEXT_WIDTH) -> str:
    """A plain-text table for the terminal, at most `width` columns: one
    block per scene, a row per estimator and budget (spp, total error, each
    effect's error, slope, verdict against the target, dominant error
    term), a star on each effect's winner, and a line naming the winners
    with their efficiency ratio over the runner-up (analysis/verdict.py).
    Effect columns that do not fit continue in a second part of the block."""
    import textwrap

    rows = collapse_unsupported(rows)
    win = {(w["scene"], w["effect"]): w for w in (winners or [])}
    target = next((r["verdict"]["target"] for r in rows if r.get("verdict")), None)
    out = []
    if target is not None:
        out += textwrap.wrap(f"{metric} per effect, mean over seeds; usable: every seed's own error (relMSE less "
                             f"the reference's noise) <= target {target:g} (? = the reference's noise alone "
                             f"exceeds it); dominant term: noise (the render's variance), bias (remainder), ref "
                             f"(the reference's noise), or the part of the bias that explains most of it: trunc "
                             f"(max_depth), disc (photon radius, cache, clamping), model (dipole vs random walk); "
                             f"* = the effect's winner by efficiency", width)
    by_scene = {}
    for r in rows:
        by_scene.setdefault(r["scene"], []).append(r)
    for scene, rs in by_scene.items():
        effs = effect_columns(rs)
        wl = [w for (sc, _), w in win.items() if sc == scene]
        budgets = ", ".join(sorted({r["budget"] for r in rs}))
        out.append("")
        out.append(_clip(f"{scene}  ({budgets})", width))

        def cell(r, eff):
            v = r["total"] if eff == "total" else r["effects"].get(eff)
            w = win.get((scene, eff))
            star = "*" if w and w["winner"] == r["estimator"] and w["budget"] == r["budget"] else ""
            return fmt(v) + star

        fixed_head = ["estimator", "spp", "total"]
        tail_head = ["slope", "usable", "dominant"]

        def fixed(r):
            return [_clip(r["estimator"], 14), f"{r['spp']:.0f}", cell(r, "total")]

        def tail(r):
            v = r.get("verdict")
            return [fmt(r["slope"], 2), USABLE_SHORT[v["usable"]] if v else "-",
                    TERM_SHORT.get(v["dominant"], v["dominant"]) if v else "-"]

        ok = [r for r in rs if r["status"] == "ok"]
        bad = [r for r in rs if r["status"] != "ok"]
        # As many effect columns as fit beside the fixed ones; the rest continue below.
        groups, cur = [], []
        for e in effs:
            trial = cur + [e]
            head = fixed_head + [EFFECT_SHORT.get(x, x) for x in trial] + (tail_head if not groups else [])
            body = [fixed(r) + [cell(r, x) for x in trial] + (tail(r) if not groups else []) for r in ok]
            if cur and max(len(ln) for ln in _grid(head, body, 10 ** 6)) > width:
                groups.append(cur)
                cur = [e]
            else:
                cur = trial
        groups.append(cur)
        for i, g in enumerate(groups):
            if not ok:
                break
            head = (fixed_head if i == 0 else ["estimator"]) + [EFFECT_SHORT.get(x, x) for x in g]
            head += tail_head if i == 0 else []
            body = [(fixed(r) if i == 0 else fixed(r)[:1]) + [cell(r, x) for x in g] + (tail(r) if i == 0 else [])
                    for r in ok]
            out += _grid(head, body, width)
        for r in bad:
            out.append(_clip(f"  {_clip(r['estimator'], 14)}  {r['budget']}  {r['status']}: "
                             f"{short_reason(r['error'])}", width))
        if wl:
            words = []
            for w in wl:
                what = "total" if w["effect"] == "total" else EFFECT_SHORT.get(w["effect"], w["effect"])
                if w["resolved"] == "exact":
                    words.append(f"{what} {w['winner']} (exact, as {w['runner_up']})")
                elif w["ratio"] is None:
                    words.append(f"{what} {w['winner']} (alone)")
                else:
                    tie = "" if w["resolved"] == "yes" else " ~" if w["resolved"] == "no" else " n<2"
                    words.append(f"{what} {w['winner']} x{fmt(w['ratio'], 2)}{tie}")
            kind = "equal time" if wl[0]["equal_time"] else "equal samples"
            out += textwrap.wrap(f"winners ({kind}, {wl[0]['budget']}; efficiency over the runner-up, ~ = "
                                 f"within the seeds' noise): " + ", ".join(words), width,
                                 initial_indent="  ", subsequent_indent="    ")
    return "\n".join(out)


def effect_table_html(rows, metric: str = "relmse") -> str:
    """An HTML table; within each scene the best total is bold."""
    rows = collapse_unsupported(rows)
    effs = effect_columns(rows)
    esc = html.escape
    out = ['<table class="errors"><thead><tr><th>scene</th><th>estimator</th><th>budget</th><th>spp</th>',
           f"<th>total {esc(metric)}</th>"]
    out += [f"<th>{esc(e)}</th>" for e in effs]
    out.append("<th>log-log slope</th><th>efficiency</th></tr></thead><tbody>")
    best = {}
    for r in rows:
        if r["total"] is not None:
            best[r["scene"]] = min(best.get(r["scene"], math.inf), r["total"])
    for r in rows:
        cells = [esc(r["scene"]), esc(r["estimator"]), esc(r["budget"])]
        if r["status"] != "ok":
            cells += ["", f'<span class="status {esc(r["status"])}">{esc(r["status"])}</span>']
            cells += [f'<span class="why">{esc(short_reason(r["error"]))}</span>' if effs else ""]
            cells += [""] * (len(effs) + 1 - (1 if effs else 0))
        else:
            tot = fmt(r["total"])
            if r["total"] is not None and r["total"] == best.get(r["scene"]):
                tot = f"<b>{tot}</b>"
            cells += [f"{r['spp']:.0f}", tot] + [fmt(r["effects"].get(e)) for e in effs]
            cells += [fmt(r["slope"], 2), fmt(r["efficiency"])]
        if r["status"] != "ok" and effs:
            # The reason spans the effect columns.
            row = "".join(f"<td>{c}</td>" for c in cells[:5])
            row += f"<td colspan='{len(effs)}' class='why'>{cells[5]}</td><td></td><td></td>"
            out.append("<tr>" + row + "</tr>")
        else:
            out.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    out.append("</tbody></table>")
    # Where each scene's per-effect reference came from.
    kinds = {}
    for r in rows:
        if r["status"] == "ok":
            kinds.setdefault(r["scene"], r["effects_kind"] or "none")
    out.append("<p class='note'>Per-effect references: " + "; ".join(
        f"{esc(k)}: {esc(v)}" for k, v in sorted(kinds.items())) + ".</p>")
    return "\n".join(out)
