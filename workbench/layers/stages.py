"""The stage table of an online step (grasp configurations, exchange, double grasps) as GUI markdown."""
from __future__ import annotations

from planner.core.plain_text import plain

FAILURE_COLOR = "#d22"


def stages_markdown(stages: list[dict], failure: str) -> str:
    """What each stage kept, and the step's failure (if any) in red: why the funnel emptied."""
    rows = "\n".join(f"| {plain(s['stage'])} | {plain(s['count'])} | {plain(s['note'])} |" for s in stages)
    text = f"| stage | kept | note |\n|---|---:|---|\n{rows}"
    return text + (f"\n\n<span style='color:{FAILURE_COLOR}'>**Failed:** {plain(failure)}</span>" if failure else "")
