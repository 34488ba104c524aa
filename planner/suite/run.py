"""Running a suite into its folder: generate the tasks once, run the unfinished ones, record each as it finishes.

The folder holds `suite-run.json` (the suite's text, the last step, the generated tasks), `tasks/` (the task files and
what they name), `sessions/<id>/` (each task's session), `results/<id>.json` (its outcome and seconds, written once its
session is complete: a killed suite resumes from these) and, at the end, `suite.json` and `suite.csv`.

Test hook: with `REGRASP_SUITE_KILL_AFTER=<n>`, the suite kills itself (SIGKILL) right after recording its n-th task.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from planner.core.errors import InputError, RegraspError
from planner.core.results import atomic_write_text, not_a_link, read_json_object, writing
from planner.core.session import checked_seconds, typed
from planner.suite.generate import GeneratedTask, generate_tasks, load_generated
from planner.suite.job import JobResult, TaskJob, TaskOutcome, write_session
from planner.suite.spec import SuiteSpec
from planner.suite.summary import TaskRecord, csv_text, json_text, summary

MANIFEST = "suite-run.json"
FOLDERS = ("tasks", "sessions", "results")
OUTPUTS = ("suite.json", "suite.csv", "report.html")
KILL_AFTER = "REGRASP_SUITE_KILL_AFTER"  # test hook: the number of recorded tasks after which the suite kills itself


class Executor(Protocol):
    """Runs jobs somewhere (executors.py), handing back each result in this process as it arrives."""

    def run(self, jobs: Sequence[TaskJob], on_result: Callable[[JobResult], None], on_slots: Callable[[int], None]) -> None: ...


@dataclass(frozen=True)
class SuiteRun:
    """A suite's folder once every task is recorded: the summary (suite.json's data) and the records behind it."""

    folder: Path
    data: dict[str, Any]
    records: tuple[TaskRecord, ...]


def _prepare(folder: Path, spec: SuiteSpec, until: str | None, resume: bool, force: bool) -> dict[str, Any] | None:
    """The manifest of the suite to resume, or None for a fresh start (an existing suite removed only with `force`)."""
    manifest = folder / MANIFEST
    _refuse_links(folder)
    if manifest.exists():
        if resume:
            data = read_json_object(manifest)
            if data.get("suite") != spec.text or data.get("until") != until:
                raise RegraspError(f"{folder} holds another suite (or another --until); resume it with the same suite file and "
                                   "options, or use --force to replace it")
            return data
        if not force:
            raise RegraspError(f"{folder} already holds a suite; use --resume to continue it, or --force to replace it")
        with writing(folder):
            for name in FOLDERS:
                shutil.rmtree(folder / name, ignore_errors=True)
            for name in (MANIFEST, *OUTPUTS):
                (folder / name).unlink(missing_ok=True)
    elif resume and folder.is_dir() and {p.name for p in folder.iterdir()} <= {"tasks"}:
        with writing(folder):  # killed while drawing its tasks: they are drawn again
            shutil.rmtree(folder / "tasks", ignore_errors=True)
    elif folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise RegraspError(f"{folder} exists and is not an empty folder (and holds no suite): choose another folder")
    with writing(folder):
        folder.mkdir(parents=True, exist_ok=True)
    return None


NUMBER_OR_NONE = (int, float, type(None))
OUTCOME_TYPES = {"id": str, "success": bool, "failed_step": str, "failed_stage": str, "message": str, "steps": list,
                 "double_grasps": (int, type(None)), "motion_duration": NUMBER_OR_NONE, "path_length": NUMBER_OR_NONE,
                 "strategy": str}
OPTIONAL = {"strategy"}  # outcome fields added later: a record written before them has none


def _refuse_links(folder: Path) -> None:
    """The suite's own folders and what they hold must not be symbolic links (as a session's files must not): a resume
    or --force would read or write where they point."""
    for name in FOLDERS:
        sub = not_a_link(folder / name, "a suite's folders and their files must be plain ones inside it")
        for entry in sub.iterdir() if sub.is_dir() else ():
            not_a_link(entry, "a suite's folders and their files must be plain ones inside it")


def _finished(folder: Path, task: GeneratedTask) -> TaskRecord | None:
    """A task's record from results/, or None when it has not finished; a record of the wrong shape or types is an
    InputError naming the file and the field (delete it to run the task again)."""
    path = folder / "results" / f"{task.id}.json"
    if not path.is_file():
        return None
    data = read_json_object(path)
    outcome = typed(data.get("outcome"), dict, path, "outcome", "the task's outcome as an object")
    for key in sorted(set(outcome) | (set(OUTCOME_TYPES) - OPTIONAL)):
        if key not in OUTCOME_TYPES or key not in outcome:
            raise InputError(path, f"outcome.{key}", "missing field" if key in OUTCOME_TYPES else "unknown field")
        kinds = OUTCOME_TYPES[key] if isinstance(OUTCOME_TYPES[key], tuple) else (OUTCOME_TYPES[key],)
        typed(outcome[key], kinds, path, f"outcome.{key}", " or ".join("null" if k is type(None) else k.__name__ for k in kinds))
    if outcome["id"] != task.id:
        raise InputError(path, "outcome.id", f"expected {task.id!r}, the task the file is named after")
    for i, step in enumerate(outcome["steps"]):
        typed(step, str, path, f"outcome.steps[{i}]", "a step name")
    seconds = typed(data.get("seconds"), dict, path, "seconds", "each step's seconds as an object")
    for step, value in seconds.items():
        checked_seconds(value, path, f"seconds.{step}")
    return TaskRecord(task, TaskOutcome(**{**outcome, "steps": tuple(outcome["steps"])}), dict(seconds))


def _job(folder: Path, task: GeneratedTask, spec: SuiteSpec, until: str | None) -> TaskJob:
    files = {name: (folder / "tasks" / name).read_bytes() for name in task.files}
    return TaskJob(task.id, files, task.files[1], spec.plan_seed, until, spec.task_cpus, spec.task_timeout, spec.params)


def _eta(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.0f} min" if seconds < 5400 else f"{seconds / 3600:.1f} h"


def run_suite(spec: SuiteSpec, folder: Path, executor: Executor, until: str | None = None, resume: bool = False,
              force: bool = False, generate_workers: int = 1, say: Callable[[str], None] = print) -> SuiteRun:
    """Run every unfinished task of the suite into `folder` and write suite.json and suite.csv there."""
    start = time.perf_counter()
    resumed = _prepare(folder, spec, until, resume, force)
    if resumed is None:
        say(f"generating {spec.tasks} tasks of suite {spec.name} (each checked as `regrasp check` does) ...")
        tasks = generate_tasks(spec, folder / "tasks", generate_workers)
        atomic_write_text(folder / MANIFEST, json.dumps({"suite": spec.text, "source": str(spec.source), "until": until,
                                                         "tasks": [t.to_json() for t in tasks]}, indent=1))
    else:
        try:
            tasks = load_generated(folder / "tasks", spec, resumed["tasks"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(folder / MANIFEST, "tasks", f"expected the generated tasks ({type(exc).__name__}: {exc})") from exc
    records = {t.id: r for t in tasks if (r := _finished(folder, t))}
    todo = [t for t in tasks if t.id not in records]
    if resumed is not None:
        say(f"resuming {folder}: {len(records)} of {len(tasks)} tasks finished, {len(todo)} to run")
    by_id = {t.id: t for t in tasks}
    slots = [1]
    ran: list[float] = []
    kill_after = int(os.environ.get(KILL_AFTER, "0"))

    def recorded(result: JobResult) -> None:
        task = by_id[result.outcome.id]
        write_session(folder / "sessions" / task.id, result.session)
        with writing(folder / "results"):
            (folder / "results").mkdir(exist_ok=True)
        atomic_write_text(folder / "results" / f"{task.id}.json",
                          json.dumps({"outcome": result.outcome.to_json(), "seconds": result.seconds}, indent=1))
        records[task.id] = TaskRecord(task, result.outcome, result.seconds)
        ran.append(time.perf_counter())
        failed = sum(not r.outcome.success for r in records.values())
        left = len(tasks) - len(records)
        eta = (ran[-1] - run_start) / len(ran) * left
        verdict = "ok" if result.outcome.success else f"failed at {result.outcome.failed_step}"
        say(f"[{len(records)}/{len(tasks)}] {task.id}: {verdict} ({sum(result.seconds.values()):.1f} s)   done {len(records)}, "
            f"failed {failed}, running {min(slots[0], left)}" + (f", about {_eta(eta)} left" if left else ""))
        if kill_after and len(ran) == kill_after:
            os.kill(os.getpid(), signal.SIGKILL)

    run_start = time.perf_counter()
    executor.run([_job(folder, t, spec, until) for t in todo], recorded, lambda n: slots.__setitem__(0, n))
    ordered = tuple(records[t.id] for t in tasks)
    data = summary(spec.name, until, len(tasks), list(ordered), time.perf_counter() - start)
    atomic_write_text(folder / "suite.json", json_text(data))
    atomic_write_text(folder / "suite.csv", csv_text(list(ordered)))
    return SuiteRun(folder, data, ordered)
