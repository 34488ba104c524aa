"""A suite's report: one self-contained HTML page (inline SVG plots, no script) from suite.json's data and the base scene.

Plots: a top view of the desk with every sampled placement coloured by its task's outcome and success per placement
region, success per object, failures per step and stage, seconds per step (median and p95); then every task, each failed
one with the `regrasp replay` command of its session."""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np
from scipy.spatial import ConvexHull

from planner.core.plain_text import plain
from planner.core.results import atomic_write_text
from planner.model.environment import Environment
from planner.suite.spec import Region, SuiteSpec

OK, FAILED, INK, FAINT = "#2a9d4a", "#d1495b", "#222", "#888"
STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 24px auto; max-width: 1100px; color: #222; }
h1 { font-size: 22px; } h2 { font-size: 17px; margin-top: 28px; }
.plots { display: flex; flex-wrap: wrap; gap: 24px; } figure { margin: 0; } figcaption { color: #555; font-size: 13px; }
table { border-collapse: collapse; font-size: 12px; } td, th { border-bottom: 1px solid #ddd; padding: 3px 6px; text-align: left; }
tr.failed td { background: #fdf0f2; } code { font-size: 12px; } .figures span { margin-right: 18px; }
svg text { font: 11px system-ui, sans-serif; fill: #222; }
"""

STRATEGY_NAMES = {"handover": "handover in the air", "table": "table handover", "regrasp": "same-hand regrasp"}  # the motion's


def _margins(labels: Iterable[str], notes: Iterable[str]) -> tuple[int, int]:
    """(the width left of the bars, the width right of them) that fit the labels and the notes (6.5 px a character)."""
    return 12 + int(6.5 * max(map(len, labels), default=0)), 12 + int(6.5 * max(map(len, notes), default=0))


def _bars(title: str, rows: list[tuple[str, float, float, str]], unit: str = "", cls: str = "") -> str:
    """A horizontal bar chart: (label, value, a mark at this value or 0 for none, text after the bar) per row."""
    if not rows:
        return f'<figure class="plot {cls}"><figcaption>{plain(title)}: nothing to show</figcaption></figure>'
    (left, right), bar_w, row_h = _margins((r[0] for r in rows), (r[3] for r in rows)), 240, 20
    width = left + bar_w + right
    top = max(max(v, w) for _, v, w, _ in rows) or 1.0
    parts = []
    for i, (label, value, whisker, note) in enumerate(rows):
        y = 8 + i * row_h
        parts.append(f'<text x="{left - 6}" y="{y + 13}" text-anchor="end">{plain(label)}</text>')
        parts.append(f'<rect class="bar" x="{left}" y="{y + 3}" width="{max(value / top * bar_w, 1):.1f}" height="13" fill="#4a78b5"/>')
        if whisker:
            x = left + whisker / top * bar_w
            parts.append(f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{y + 1}" y2="{y + 18}" stroke="{INK}" stroke-width="2"/>')
        parts.append(f'<text x="{left + max(value, whisker) / top * bar_w + 6:.1f}" y="{y + 13}">{plain(note)}</text>')
    height = 16 + len(rows) * row_h
    return (f'<figure class="plot {cls}"><svg width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img">'
            f'<title>{plain(title)}</title>{"".join(parts)}</svg><figcaption>{plain(title)}{plain(unit)}</figcaption></figure>')


def _success_bars(title: str, rates: dict[str, dict[str, Any]], cls: str) -> str:
    """Per key, a bar split into succeeded (green) and failed (red) tasks, with 'k/n'."""
    (left, right), bar_w, row_h = _margins(rates, ["100/100 (100%)"]), 240, 20
    width = left + bar_w + right
    most = max((r["tasks"] for r in rates.values()), default=1)
    parts = []
    for i, (name, r) in enumerate(rates.items()):
        y, ok_w = 8 + i * row_h, r["succeeded"] / most * bar_w
        fail_w = (r["tasks"] - r["succeeded"]) / most * bar_w
        parts += [f'<text x="{left - 6}" y="{y + 13}" text-anchor="end">{plain(name)}</text>',
                  f'<rect class="ok" x="{left}" y="{y + 3}" width="{ok_w:.1f}" height="13" fill="{OK}"/>',
                  f'<rect class="failed" x="{left + ok_w:.1f}" y="{y + 3}" width="{fail_w:.1f}" height="13" fill="{FAILED}"/>',
                  f'<text x="{left + ok_w + fail_w + 6:.1f}" y="{y + 13}">{plain(r["succeeded"])}/{plain(r["tasks"])} '
                  f'({r["success_rate"]:.0%})</text>']
    height = 16 + len(rates) * row_h
    return (f'<figure class="plot {cls}"><svg width="{width}" height="{height}" viewBox="0 0 {width} {height}" role="img">'
            f'<title>{plain(title)}</title>{"".join(parts)}</svg><figcaption>{plain(title)}: succeeded (green) and failed (red) tasks'
            f'</figcaption></figure>')


def _footprints(environment: Environment) -> list[tuple[str, np.ndarray, tuple[int, int, int]]]:
    """Each obstacle's outline seen from above (the convex hull of its mesh's x, y), highest last so it is drawn on top."""
    out: list[tuple[str, np.ndarray, tuple[int, int, int], float]] = []
    for ob in environment:
        mesh = ob.to_trimesh()
        xy = np.asarray(mesh.vertices)[:, :2]
        out.append((ob.name, xy[ConvexHull(xy).vertices], ob.color, float(mesh.bounds[1][2])))
    return [(name, xy, color) for name, xy, color, _ in sorted(out, key=lambda o: o[3])]


def _top_view(environment: Environment, regions: Iterable[Region], results: list[dict[str, Any]], size: int = 760) -> str:
    """The desk from above (the robot at the bottom facing up, its right hand on the right): obstacles, regions, placements."""
    feet = _footprints(environment)
    placements = np.array([r[k][:2] for r in results for k in ("initial", "final")] or [[0.0, 0.0]])
    pts = np.vstack([*(xy for _, xy, _ in feet), placements, [[0.0, 0.0]]])
    lo, hi = pts.min(axis=0) - 0.05, pts.max(axis=0) + 0.05
    scale = (size - 20) / max(hi - lo)
    width, height = (hi[1] - lo[1]) * scale + 20, (hi[0] - lo[0]) * scale + 20

    def at(x: float, y: float) -> tuple[float, float]:  # screen right = the robot's right (-y), screen up = forward (+x)
        return 10 + (hi[1] - y) * scale, 10 + (hi[0] - x) * scale

    parts = []
    for name, xy, color in feet:
        points = " ".join("{:.1f},{:.1f}".format(*at(x, y)) for x, y in xy)
        parts.append(f'<polygon points="{points}" fill="rgb{plain(tuple(color))}" fill-opacity="0.55" stroke="#555" stroke-width="0.5">'
                     f'<title>{plain(name)}</title></polygon>')
    for region in regions:
        (sx0, sy0), (sx1, sy1) = at(region.x[1], region.y[1]), at(region.x[0], region.y[0])
        parts.append(f'<rect class="region" x="{sx0:.1f}" y="{sy0:.1f}" width="{sx1 - sx0:.1f}" height="{sy1 - sy0:.1f}" fill="none" '
                     f'stroke="{INK}" stroke-dasharray="4 3"/><text x="{sx0:.1f}" y="{sy0 - 3:.1f}">{plain(region.name)}</text>')
    rx, ry = at(0.0, 0.0)
    parts.append(f'<circle cx="{rx:.1f}" cy="{ry:.1f}" r="9" fill="#bbb" stroke="{INK}"/>'
                 f'<text x="{rx + 12:.1f}" y="{ry + 4:.1f}">robot</text>')
    for r in results:
        colour = OK if r["success"] else FAILED
        (ix, iy), (fx, fy) = at(*r["initial"][:2]), at(*r["final"][:2])
        tip = plain(f'{r["id"]}: ' + ("succeeded" if r["success"] else f'failed at {r["failed_step"]}'))
        parts.append(f'<line x1="{ix:.1f}" y1="{iy:.1f}" x2="{fx:.1f}" y2="{fy:.1f}" stroke="{colour}" stroke-opacity="0.15"/>')
        parts.append(f'<circle class="placement initial" cx="{ix:.1f}" cy="{iy:.1f}" r="4" fill="{colour}">'
                     f'<title>{tip} (start)</title></circle>')
        parts.append(f'<rect class="placement final" x="{fx - 3.5:.1f}" y="{fy - 3.5:.1f}" width="7" height="7" fill="{colour}">'
                     f'<title>{tip} (goal)</title></rect>')
    return (f'<figure class="plot top-view"><svg width="{width:.0f}" height="{height:.0f}" viewBox="0 0 {width:.0f} {height:.0f}" '
            f'role="img"><title>Top view of the desk</title>{"".join(parts)}</svg><figcaption>The desk from above, the robot at the '
            f'bottom: each task\'s start (dot) and goal (square), green when it succeeded, red when it failed; dashed: the '
            f'placement regions</figcaption></figure>')


def _task_rows(results: list[dict[str, Any]], folder: str) -> str:
    rows = []
    for r in results:
        replay = f"regrasp replay {folder}/{r['session']}"
        outcome = "ok" if r["success"] else f"failed at {r['failed_step']}" + (f" ({r['failed_stage']})" if r["failed_stage"] else "")
        href = plain(quote(str(r["session"])))  # a relative address: ':' quoted, so no scheme (javascript:) can start it
        link = f'<a class="replay" href="{href}/">session</a> <code>{plain(replay)}</code>' if not r["success"] else \
            f'<a href="{href}/">session</a>'
        figures = [r["double_grasps"], *(f"{r[k]:.1f}" if r[k] is not None else "" for k in ("motion_duration", "path_length"))]
        rows.append(f'<tr class="{"ok" if r["success"] else "failed"}"><td>{plain(r["id"])}</td><td>{plain(r["initial_region"])} → '
                    f'{plain(r["final_region"])}</td><td>{plain(outcome)}</td><td>{plain(r["message"])}</td>'
                    + "".join(f"<td>{plain('' if v is None else v)}</td>" for v in figures) + f"<td>{link}</td></tr>")
    head = "<tr><th>task</th><th>regions</th><th>outcome</th><th>message</th><th>double grasps</th><th>motion s</th>" \
           "<th>path rad</th><th>session</th></tr>"
    return f'<table id="tasks">{head}{"".join(rows)}</table>'


def report_html(data: dict[str, Any], spec: SuiteSpec, environment: Environment, folder: str) -> str:
    """The whole page."""
    results = data["results"]
    seconds = [(step, s["median"], s["p95"], f'{s["median"]:.2f} s (p95 {s["p95"]:.2f})') for step, s in data["seconds"].items()]
    failures = [(key, n, 0.0, str(n)) for key, n in data["by_stage"].items()]
    strategies = [(STRATEGY_NAMES.get(key, key), n, 0.0, str(n)) for key, n in data.get("by_strategy", {}).items()]
    regions = {**{f"from {k}": v for k, v in data["by_initial_region"].items()},
               **{f"to {k}": v for k, v in data["by_final_region"].items()}}
    figures = (f'<span>tasks <b>{plain(data["finished"])}</b> of {plain(data["tasks"])}</span>'
               f'<span>succeeded <b>{plain(data["succeeded"])}</b></span>'
               f'<span>success rate <b id="success-rate">{data["success_rate"]:.1%}</b></span>'
               f'<span>through step <b>{plain(data["until"])}</b></span><span>wall time <b>{data["wall_seconds"]:.0f} s</b></span>')
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Suite {plain(spec.name)}: report</title><style>{STYLE}</style></head>
<body><h1>Suite {plain(spec.name)}</h1><p>{plain(spec.source)} · base task {plain(spec.base_task.name)}
· seed {plain(spec.seed)} · plan seed {plain(spec.plan_seed)}</p><p class="figures">{figures}</p>
<h2>Where the objects were placed</h2><div class="plots">{_top_view(environment, (*spec.initial_regions, *spec.final_regions), results)}
{_success_bars("Success per placement region", regions, "regions")}</div>
<h2>Success per object</h2><div class="plots">{_success_bars("Success per object", data["by_object"], "objects")}</div>
<p>{"; ".join(f"<b>{plain(o.name)}</b>: {plain(o.description)}" for o in spec.objects)}</p>
<h2>How the tasks that succeeded moved the object</h2>
<div class="plots">{_bars("Successes per strategy", strategies, cls="strategies")}</div>
<h2>Failures and time</h2><div class="plots">{_bars("Failures per step and stage", failures, cls="failures")}
{_bars("Seconds per step: median (bar) and p95 (mark)", seconds, cls="seconds")}</div>
<h2>Tasks</h2><p>Each task's session is in <code>sessions/</code>; open one with the command beside it.</p>{_task_rows(results, folder)}
</body></html>
"""


def write_report(data: dict[str, Any], spec: SuiteSpec, environment: Environment, folder: Path) -> Path:
    """Write `folder/report.html`; returns its path."""
    path = folder / "report.html"
    atomic_write_text(path, report_html(data, spec, environment, str(folder)))
    return path
