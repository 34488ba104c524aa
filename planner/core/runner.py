"""Running the pipeline into a session: the next step, or every step up to a named one.

Test hook: with the environment variable `REGRASP_KILL_AFTER=<step>`, the process kills itself
(SIGKILL, no clean-up) right after that step's files and manifest are saved: a deterministic crash
point for the resume test.
"""
from __future__ import annotations

import os
import signal
import sys
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from planner.check import require_valid
from planner.core.session import Session
from planner.core.steps import Progress, Step, StepContext, StepFailed, no_progress
from planner.pipeline import step_named, steps_until

ProgressFactory = Callable[[Step], Progress]
KILL_AFTER = "REGRASP_KILL_AFTER"  # test hook: the step after whose saving the process kills itself


def run_step(session: Session, step: Step, params: Mapping[str, Any] | None = None, progress: Progress = no_progress) -> Any:
    """Run one step on the session's scene and earlier results, and record it; StepFailed if its result reports a failure."""
    p = step.make_params(params)
    seed = step.seed(session.seed)
    inputs = {name: session.result(name) for name in step.needs}
    input_params = {name: step_named(name).recorded_params(session.record_of(name)["params"]) for name in step.needs}
    ctx = StepContext(session.scene, inputs, input_params, p, np.random.default_rng(seed), progress)
    start = time.perf_counter()
    output = step.run(ctx)
    result = output.result
    session.record(step, p, seed, time.perf_counter() - start, result, output.stage_seconds, output.cached)
    if os.environ.get(KILL_AFTER) == step.name:
        os.kill(os.getpid(), signal.SIGKILL)
    if getattr(result, "failure", ""):
        raise StepFailed(step.name, result.failure)
    return result


def warn_on_stderr(message: str) -> None:
    """Print a warning about the task for the person running the pipeline."""
    print(message, file=sys.stderr)


def run_pipeline(session: Session, until: str | None = None, params: Mapping[str, Mapping[str, Any]] | None = None,
                 progress: ProgressFactory | None = None, warn: Callable[[str], None] = warn_on_stderr) -> list[str]:
    """Run, in order, every step up to `until` that the session has not finished; returns their names. A recoverable
    step's failure stops the run only when it is the last step asked for.

    The task is validated first, as `regrasp check` does (InvalidTask, before any step)."""
    require_valid(session.scene, warn)
    params = params or {}
    done = {r["name"]: r for r in session.records}
    ran = []
    steps = steps_until(until)
    for step in steps:
        goes_on = step.recoverable and step is not steps[-1]  # a later step falls back (the double grasps: the table)
        if step.name in done:
            if done[step.name]["stats"].get("failure") and not goes_on:
                raise StepFailed(step.name, done[step.name]["stats"]["failure"])
            continue
        try:
            run_step(session, step, params.get(step.name), progress(step) if progress else no_progress)
        except StepFailed:
            if not goes_on:
                raise
        ran.append(step.name)
    return ran
