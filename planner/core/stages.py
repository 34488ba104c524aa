"""Stages inside a step: what each one kept and how long it took, and the stage-named failure when one empties.

The online steps (grasp configurations, exchange, double grasps) funnel candidates through
stages; their results carry the stage list (for the stage table of `regrasp plan`) and, when a
stage kept nothing, a `failure` message naming it with the numbers at every stage before. Stage
times are measurements, not results: they go to the step's session record (`stage_seconds`), so
a result stays byte-identical run to run.
"""
from __future__ import annotations

import time


class StageLog:
    """Times consecutive stages: `done(name, count, note)` closes the stage that started at the previous call."""

    def __init__(self) -> None:
        self.stages: list[dict] = []
        self.seconds: list[float] = []
        self._start = time.perf_counter()

    def done(self, name: str, count: int, note: str = "") -> int:
        now = time.perf_counter()
        self.stages.append({"stage": name, "count": int(count), "note": note})
        self.seconds.append(now - self._start)
        self._start = now
        return count

    def failure(self, what: str) -> str:
        """'<what>' followed by the count at every stage so far."""
        counts = "; ".join(f"{s['stage']}: {s['count']}" for s in self.stages)
        return f"{what} ({counts})"


def stage_table(step_stages: list[tuple[str, list[dict], list[float]]]) -> str:
    """A plain-text table of (step name, stages, stage seconds) rows."""
    lines = [f"{'step':<16}{'stage':<38}{'count':>7}{'seconds':>9}  note"]
    for step, stages, seconds in step_stages:
        for s, t in zip(stages, seconds):
            lines.append(f"{step:<16}{s['stage']:<38}{s['count']:>7}{t:>9.3f}  {s['note']}".rstrip())
    return "\n".join(lines)
