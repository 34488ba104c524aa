"""A suite's totals: success rate, failures by step and stage, successes by the motion's strategy, per-step seconds, per
object and region; JSON and CSV.

`results` (per task, in task order) depend only on the suite and its seeds; measured times are kept apart
(`timings`, `seconds`, and `wall_seconds`: the last run's, from its start to its end, a resumed suite's from its resume)."""
from __future__ import annotations

import csv
import io
import json
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from planner.pipeline import PIPELINE
from planner.suite.generate import GeneratedTask
from planner.suite.job import TaskOutcome


@dataclass(frozen=True)
class TaskRecord:
    """A finished task: what it was, its outcome, and the seconds of its steps."""

    task: GeneratedTask
    outcome: TaskOutcome
    seconds: dict[str, float]

    def result(self) -> dict[str, Any]:
        """The task and its outcome (no times), as suite.json lists it."""
        task = self.task.to_json()
        del task["files"]
        return {**task, **self.outcome.to_json(), "session": f"sessions/{self.task.id}"}


def failure_key(outcome: TaskOutcome) -> str:
    """'double_grasps: exchange configurations', or the step alone when it has no stage."""
    return f"{outcome.failed_step}: {outcome.failed_stage}" if outcome.failed_stage else outcome.failed_step


def _rates(records: list[TaskRecord], key: str) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for r in records:
        entry = out.setdefault(getattr(r.task, key), {"tasks": 0, "succeeded": 0})
        entry["tasks"] += 1
        entry["succeeded"] += r.outcome.success
    for entry in out.values():
        entry["success_rate"] = round(entry["succeeded"] / entry["tasks"], 4)
    return out


def step_seconds(records: list[TaskRecord]) -> dict[str, dict[str, float]]:
    """Per step (in pipeline order) and in total: the median and 95th percentile of the tasks' seconds."""
    columns = {s.name: [r.seconds[s.name] for r in records if s.name in r.seconds] for s in PIPELINE}
    columns["total"] = [sum(r.seconds.values()) for r in records]
    return {name: {"median": round(float(np.median(v)), 3), "p95": round(float(np.percentile(v, 95)), 3), "tasks": len(v)}
            for name, v in columns.items() if v}


def summary(name: str, until: str | None, total: int, records: list[TaskRecord], wall_seconds: float) -> dict[str, Any]:
    """suite.json: totals over the finished tasks, then per-task results and, apart, the times."""
    succeeded = sum(r.outcome.success for r in records)
    failures = Counter(failure_key(r.outcome) for r in records if not r.outcome.success)
    return {
        "suite": name,
        "until": until or PIPELINE[-1].name,
        "tasks": total,
        "finished": len(records),
        "succeeded": succeeded,
        "success_rate": round(succeeded / len(records), 4) if records else 0.0,
        "by_stage": dict(sorted(failures.items(), key=lambda kv: (-kv[1], kv[0]))),
        "by_strategy": dict(sorted(Counter(r.outcome.strategy for r in records if r.outcome.success and r.outcome.strategy).items())),
        "by_object": _rates(records, "object"),
        "by_initial_region": _rates(records, "initial_region"),
        "by_final_region": _rates(records, "final_region"),
        "results": [r.result() for r in records],
        "seconds": step_seconds(records),
        "wall_seconds": round(wall_seconds, 1),
        "timings": {r.task.id: r.seconds for r in records},
    }


CSV_COLUMNS = ("id", "object", "initial_region", "final_region", "initial", "final", "success", "failed_step", "failed_stage",
               "message", "double_grasps", "motion_duration", "path_length", "session")


def csv_text(records: list[TaskRecord]) -> str:
    """suite.csv: one row per finished task (placements as 'x y z yaw'), then each step's seconds."""
    steps = [s.name for s in PIPELINE]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([*CSV_COLUMNS, *(f"seconds_{s}" for s in steps)])
    for r in records:
        row = r.result()
        row["initial"], row["final"] = (" ".join(f"{v:g}" for v in row[k]) for k in ("initial", "final"))
        writer.writerow([("" if row[c] is None else row[c]) for c in CSV_COLUMNS] + [r.seconds.get(s, "") for s in steps])
    return buf.getvalue()


def json_text(data: dict[str, Any]) -> str:
    return json.dumps(data, indent=1)
