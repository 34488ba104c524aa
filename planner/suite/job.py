"""One suite task run through the pipeline in whatever process runs it (a local worker, a Ray worker on another machine).

A job carries its task's files (task file, robot spec, meshes) and comes back with the outcome, the seconds of each step
and the session's files: nothing is shared but the user cache, where the grasp lists and the roadmap are computed once.
"""
from __future__ import annotations

import contextlib
import signal
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from planner.core.errors import RegraspError
from planner.core.forked import cpu_budget
from planner.core.paths import file_in
from planner.core.results import atomic_write_bytes, writing
from planner.core.runner import run_pipeline
from planner.core.session import MANIFEST, Session, cached_spec_file
from planner.core.steps import StepFailed
from planner.core.tomlread import load_toml
from planner.model.task import scene_from_dict
from planner.pipeline import PIPELINE, step_named, steps_until

CHECK = "check"  # the failing "step" of a task rejected before any step runs
ERROR = "error"  # the failing "step" of a task on which the planner raised an unexpected exception
TIMEOUT = "timeout"  # the failing stage of a task that ran past its suite's task_timeout


class TaskTimeout(BaseException):
    """A task ran past its limit (a BaseException: no `except Exception` of the planner's swallows it)."""


@contextlib.contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Inside: `TaskTimeout` is raised in this (main) thread after `seconds` (SIGALRM; forked workers inherit no timer)."""
    if threading.current_thread() is not threading.main_thread():
        raise RegraspError("a suite task runs in the main thread of its worker (its time limit is a SIGALRM)")

    def expired(signum: int, frame: object) -> None:
        raise TaskTimeout()
    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@dataclass(frozen=True)
class TaskJob:
    """What a worker needs to run one task: its files by name (the task file first), the session seed, the last step,
    the CPUs it may use and its time limit."""

    id: str
    files: dict[str, bytes] = field(repr=False)
    robot_spec: str  # the name of the robot spec among `files`
    seed: int
    until: str | None
    cpus: int = 1
    timeout: float = 1200.0  # s
    params: dict[str, dict[str, Any]] = field(default_factory=dict)  # step name -> parameter values


@dataclass(frozen=True)
class TaskOutcome:
    """A task's result (deterministic: the same task and seed give the same outcome), apart from its measured times."""

    id: str
    success: bool
    failed_step: str  # empty on success
    failed_stage: str  # the stage that kept nothing, when the failing step has stages
    message: str
    steps: tuple[str, ...]  # the steps finished
    double_grasps: int | None
    motion_duration: float | None  # s, the timed trajectory
    path_length: float | None  # rad, summed over the joints
    strategy: str = ""  # the motion's ('handover', 'table', 'regrasp'); empty when it did not move (suites written before it too)

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "success": self.success, "failed_step": self.failed_step, "failed_stage": self.failed_stage,
                "message": self.message, "steps": list(self.steps), "double_grasps": self.double_grasps,
                "motion_duration": self.motion_duration, "path_length": self.path_length, "strategy": self.strategy}


@dataclass(frozen=True)
class JobResult:
    """What comes back from a worker: the outcome, each step's seconds and the session's files by name."""

    outcome: TaskOutcome
    seconds: dict[str, float]
    session: dict[str, bytes] = field(repr=False)


def _failed_stage(session: Session, step: str) -> str:
    """The first stage of a failed step's result that kept nothing; for the motion, where its first sequence tried failed
    (e.g. 'Place phase, set-down' of 'double grasp 1 (36.5 s estimated): Place phase, set-down: collides ...'); ''
    when the step tells neither."""
    result = session.result(step)
    emptied = next((s["stage"] for s in getattr(result, "stages", None) or [] if s["count"] == 0), "")
    said = (getattr(result, "tried", None) or [""])[0].split(": ")
    return emptied or said[min(1, len(said) - 1)]


def _running(session: Session | None) -> str:
    """The step a task was running (the first it had not finished), or "check" before its session existed."""
    done = {r["name"] for r in session.records} if session else set()
    return next((s.name for s in PIPELINE if s.name not in done), ERROR) if session else CHECK


def _outcome(job: TaskJob, session: Session | None, failure: tuple[str, str] | None) -> TaskOutcome:
    records = {r["name"]: r["stats"] for r in session.records} if session else {}
    step, message = failure or ("", "")
    timed_out = failure is not None and message.startswith("ran past the suite's task_timeout")
    stage = TIMEOUT if timed_out else _failed_stage(session, step) if session and step in records else ""
    motion = records.get("motion", {}) if step != "motion" else {}  # a failed motion has no duration nor length
    return TaskOutcome(job.id, failure is None, step, stage, message, tuple(records),
                       records.get("double_grasps", {}).get("double_grasps"), motion.get("duration"), motion.get("path_length"),
                       str(motion.get("strategy", "")))


def run_job(job: TaskJob) -> JobResult:
    """Run a task's pipeline in a scratch folder laid out like a suite's (tasks/, sessions/) and return what it produced."""
    with tempfile.TemporaryDirectory(prefix="regrasp-suite-") as tmp:
        tasks, folder = Path(tmp) / "tasks", Path(tmp) / "sessions" / job.id
        tasks.mkdir()
        for name, data in job.files.items():
            file_in(tasks, name, job.id, "files").write_bytes(data)
        task = tasks / next(iter(job.files))
        spec = cached_spec_file(job.files[job.robot_spec].decode(), job.robot_spec, task)
        session, failure = None, None
        try:
            with time_limit(job.timeout), cpu_budget(job.cpus):
                scene = scene_from_dict(load_toml(task), task, robot_path=spec)
                session = Session.create(folder, scene, job.seed)
                run_pipeline(session, job.until, job.params, warn=lambda message: None)
        except TaskTimeout:
            failure = (_running(session), f"ran past the suite's task_timeout of {job.timeout:g} s")
        except StepFailed as exc:
            failure = (exc.step, exc.failure)
        except RegraspError as exc:
            failure = (CHECK if session is None or not session.records else ERROR, str(exc).replace(tmp, "."))
        except Exception as exc:  # a fault of the planner on this task: recorded as its failure, the suite goes on
            failure = (ERROR, f"{type(exc).__name__}: {exc}".replace(tmp, "."))
        seconds = {r["name"]: r["seconds"] for r in session.records} if session else {}
        files = {p.name: p.read_bytes() for p in sorted(folder.iterdir())} if session else {}
        return JobResult(_outcome(job, session, failure), seconds, files)


def write_session(folder: Path, files: dict[str, bytes]) -> None:
    """Write a session's files into its folder in the suite, the manifest last (so a half-written one is never read as done)."""
    with writing(folder):
        folder.mkdir(parents=True, exist_ok=True)
    for name in sorted(files, key=lambda n: n == MANIFEST):
        atomic_write_bytes(file_in(folder, name, folder / MANIFEST, "files"), files[name])


def check_until(until: str | None) -> str | None:
    """The canonical name of the last step to run (None: every step); a RegraspError for an unknown one."""
    steps_until(until)
    return step_named(until).name if until else None

