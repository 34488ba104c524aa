"""The session's step table as markdown (status, seconds, two or three key figures a step) and one step's details."""
from __future__ import annotations

import json
from typing import Any

from planner.core.plain_text import plain
from planner.core.session import Session
from planner.pipeline import PIPELINE

from .layers import LAYERS

MAX_FIGURES = 3  # per row when a step names no key figures: the panel is narrow; the details view shows them all
MAX_TEXT = 16  # characters of a text figure in the table
CACHED = "(cached)"  # after the seconds of a step whose result came from the user cache: they are not what it costs
KEY_FIGURES = {  # the figures a person looks at first, per step (the rest: in the step's details)
    "arms": ("picking_arm", "placing_arm"),
    "pick_grasps": ("kept", "best_quality"),
    "place_grasps": ("kept", "best_quality"),
    "grasp_configs": ("pick_configs", "place_configs"),
    "exchange": ("free", "best_cost"),
    "double_grasps": ("compatible", "double_grasps"),
    "roadmap": ("nodes", "edges", "components"),
    "motion": ("duration", "path_length"),
}


def _figure(value: Any, limit: int | None = MAX_TEXT) -> str:
    """A key figure, short and shown as plain text: floats to 3 significant digits, long texts cut."""
    text = f"{value:.3g}" if isinstance(value, float) else str(value)
    if limit is not None and len(text) > limit:
        text = text[: limit - 1] + "…"
    return plain(text)


def key_figures(name: str, stats: dict[str, Any]) -> list[tuple[str, Any]]:
    """The two or three figures of a step's row: its KEY_FIGURES, else its first scalar figures."""
    scalars = [(k, v) for k, v in stats.items() if isinstance(v, (int, float, str, bool)) and k != "failure"]
    chosen = [(k, stats[k]) for k in KEY_FIGURES.get(name, ()) if k in stats]
    return chosen or scalars[:MAX_FIGURES]


def step_table(session: Session | None) -> str:
    """One row per pipeline step: done (drawn, or listed when no layer draws it), failed or pending, seconds (marked
    when the result came from the user cache), key figures."""
    records = {r["name"]: r for r in session.records} if session is not None else {}
    rows = ["| step | status | s | key figures |", "| --- | --- | ---: | --- |"]
    for step in PIPELINE:
        record = records.get(step.name)
        if record is None:
            rows.append(f"| {step.name} | pending | | |")
            continue
        status = "failed" if record["stats"].get("failure") else "done" if step.name in LAYERS else "done (not drawn)"
        figures = ", ".join(f"{plain(k)}={_figure(v)}" for k, v in key_figures(step.name, record["stats"]))
        seconds = f"{record['seconds']:.1f}" + (f" {CACHED}" if record.get("cached") else "")
        rows.append(f"| {step.name} | {status} | {seconds} | {figures} |")
    return "\n".join(rows)


def step_details(session: Session, name: str) -> str:
    """Everything the session records of one finished step: seconds, seed, every figure and parameter."""
    record = session.record_of(name)
    step = next(s for s in PIPELINE if s.name == name)
    cached = f" {CACHED}: loaded from the user cache, not computed" if record.get("cached") else ""
    lines = [f"**{name}** — {step.summary}", "", f"{record['seconds']:.2f} s{cached}, seed {plain(record['seed'])}", "",
             "| figure | value |", "| --- | --- |"]
    lines += [f"| {plain(k)} | {_figure(json.dumps(v) if isinstance(v, (dict, list)) else v, None)} |" for k, v in record["stats"].items()]
    if record.get("stage_seconds"):
        lines.append(f"| stage seconds | {', '.join(f'{t:.2f}' for t in record['stage_seconds'])} |")
    lines += ["", "| parameter | value |", "| --- | --- |"]
    lines += [f"| {plain(k)} | {_figure(v, None)} |" for k, v in record["params"].items()]
    return "\n".join(lines)
