"""The session's step table as markdown: every pipeline step, its status, time and key figures."""
from __future__ import annotations

from typing import Any

from planner.pipeline import PIPELINE
from planner.session import Session

from .layers import LAYERS

MAX_FIGURES = 4  # per row: the panel is narrow; session.json keeps them all


def _figure(value: Any) -> str:
    """A key figure, short: floats to 3 significant digits, pipes escaped for the table."""
    text = f"{value:.3g}" if isinstance(value, float) else str(value)
    return text.replace("|", "\\|")


def step_table(session: Session | None) -> str:
    """One row per pipeline step: done (drawn, or listed when no layer draws it yet) or pending; scalar figures only."""
    records = {r["name"]: r for r in session.records} if session is not None else {}
    rows = ["| step | status | s | key figures |", "| --- | --- | ---: | --- |"]
    for step in PIPELINE:
        record = records.get(step.name)
        if record is None:
            rows.append(f"| {step.name} | pending | | {step.summary} |")
            continue
        status = "done" if step.name in LAYERS else "done (not drawn)"
        scalars = [(k, v) for k, v in record["stats"].items() if isinstance(v, (int, float, str, bool))]
        figures = ", ".join(f"{k}={_figure(v)}" for k, v in scalars[:MAX_FIGURES])
        rows.append(f"| {step.name} | {status} | {record['seconds']:.2f} | {figures} |")
    return "\n".join(rows)
