"""Stages inside a step: what each one kept and how long it took, and the stage-named failure when one empties.

The online steps (grasp configurations, exchange, double grasps) funnel candidates through
stages; their results carry the stage list (for the stage table of `regrasp plan`) and, when a
stage kept nothing, a `failure` message naming it with the numbers at every stage before.
"""
from __future__ import annotations

import time


class StageLog:
    """Times consecutive stages: `done(name, count, note)` closes the stage that started at the previous call."""

    def __init__(self) -> None:
        self.stages: list[dict] = []
        self._start = time.perf_counter()

    def done(self, name: str, count: int, note: str = "") -> int:
        now = time.perf_counter()
        self.stages.append({"stage": name, "count": int(count), "seconds": round(now - self._start, 4), "note": note})
        self._start = now
        return count

    def failure(self, what: str) -> str:
        """'<what>' followed by the count at every stage so far."""
        counts = "; ".join(f"{s['stage']}: {s['count']}" for s in self.stages)
        return f"{what} ({counts})"


def stage_table(step_stages: list[tuple[str, list[dict]]]) -> str:
    """A plain-text table of (step name, stages) rows."""
    lines = [f"{'step':<16}{'stage':<34}{'count':>7}{'seconds':>9}  note"]
    for step, stages in step_stages:
        for s in stages:
            lines.append(f"{step:<16}{s['stage']:<34}{s['count']:>7}{s['seconds']:>9.3f}  {s['note']}".rstrip())
    return "\n".join(lines)
