"""A suite's folder as untrusted input: `--resume` reads each finished task's record in results/ and refuses one of the
wrong shape or types with one line naming the file and the field; links among the suite's folders are refused (as a
session's files are), so neither `--resume` nor `--force` writes where a link points."""
from __future__ import annotations

import contextlib
import io
import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from sandbox import one_error_line, regrasp, snapshot
from test_suite import REGIONS

from workbench.cli import main

SUITE = f"""
name = "one"
task = "default"
tasks = 1
seed = 1
plan_seed = 3
attempts = 20

[[objects]]
name = "statuette"
mesh = "statuette"

{REGIONS}"""
TASK = "0001-statuette"


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A one-task suite file and its folder, run through the arms step."""
    root = tmp_path_factory.mktemp("suite")
    (root / "one.toml").write_text(SUITE)
    run = regrasp("suite", str(root / "one.toml"), "--out", str(root / "out"), "--until", "arms")
    assert run.returncode == 0, run.stderr
    return root / "one.toml", root / "out"


@pytest.fixture
def suite(finished: tuple[Path, Path], tmp_path: Path) -> tuple[Path, Path, Path]:
    """The suite file, a copy of its finished folder, and an empty folder outside it that must stay empty."""
    spec, folder = finished
    (tmp_path / "outside").mkdir()
    return spec, Path(shutil.copytree(folder, tmp_path / "out", symlinks=True)), tmp_path / "outside"


def _run(spec: Path, folder: Path, *options: str) -> tuple[int, str]:
    """`regrasp suite` on the finished folder, in this process (the finished suite's run is the one subprocess: these
    refusals come before any task runs, and a fresh interpreter's imports were most of each test's time)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["suite", str(spec), "--out", str(folder), "--until", "arms", *options])
    return code, err.getvalue()


def _outcome(key: str, value: Any) -> Callable[[dict[str, Any]], None]:
    return lambda data: data["outcome"].__setitem__(key, value)


RECORD_CASES: dict[str, tuple[Callable[[dict[str, Any]], None], str, str]] = {
    "outcome a list": (lambda d: d.__setitem__("outcome", [1]), "outcome", "expected the task's outcome as an object"),
    "success a string": (_outcome("success", "yes"), "outcome.success", "expected bool"),
    "steps a number": (_outcome("steps", 3), "outcome.steps", "expected list"),
    "a step a number": (_outcome("steps", [3]), "outcome.steps[0]", "expected a step name"),
    "double_grasps a float": (_outcome("double_grasps", 2.5), "outcome.double_grasps", "expected int or null"),
    "another task's id": (_outcome("id", "0002-statuette"), "outcome.id", "expected '0001-statuette'"),
    "a field missing": (lambda d: d["outcome"].pop("message"), "outcome.message", "missing field"),
    "an unknown field": (_outcome("extra", 1), "outcome.extra", "unknown field"),
    "seconds a string": (lambda d: d.__setitem__("seconds", "ab"), "seconds", "expected each step's seconds"),
    "seconds negative": (lambda d: d["seconds"].__setitem__("arms", -1), "seconds.arms", ">= 0"),
}


@pytest.mark.parametrize("case", list(RECORD_CASES))
def test_a_bad_task_record_on_resume_is_one_line(suite: tuple[Path, Path, Path], case: str) -> None:
    spec, folder, _ = suite
    change, field, phrase = RECORD_CASES[case]
    path = folder / "results" / f"{TASK}.json"
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))
    (folder / "suite.json").unlink()
    code, stderr = _run(spec, folder, "--resume")
    assert code == 2, stderr
    line = one_error_line(stderr)
    assert str(path) in line and f"'{field}'" in line and phrase in line, line


def test_a_long_integer_in_a_task_record_is_one_line(suite: tuple[Path, Path, Path]) -> None:
    spec, folder, _ = suite
    path = folder / "results" / f"{TASK}.json"
    path.write_text(path.read_text().replace('"arms": ', f'"arms": {"9" * 5000}, "x": ', 1))
    code, stderr = _run(spec, folder, "--resume")
    assert code == 2, stderr
    line = one_error_line(stderr)
    assert str(path) in line and "'seconds.arms'" in line and "5,000 digits" in line, line


def test_resume_refuses_a_session_folder_that_is_a_link(suite: tuple[Path, Path, Path]) -> None:
    spec, folder, outside = suite
    (folder / "results" / f"{TASK}.json").unlink()  # the task runs again: its session would be written through the link
    shutil.rmtree(folder / "sessions" / TASK)
    (folder / "sessions" / TASK).symlink_to(outside, target_is_directory=True)
    before = snapshot(folder.parent)
    code, stderr = _run(spec, folder, "--resume")
    assert code == 2, stderr
    line = one_error_line(stderr)
    assert str(folder / "sessions" / TASK) in line and "symbolic link" in line, line
    assert snapshot(folder.parent) == before and not any(outside.iterdir())


@pytest.mark.parametrize("options", [("--force",), ("--resume",)])
def test_a_sessions_folder_that_is_a_link_is_refused(suite: tuple[Path, Path, Path], options: tuple[str, ...]) -> None:
    spec, folder, outside = suite
    shutil.rmtree(folder / "sessions")
    (folder / "sessions").symlink_to(outside, target_is_directory=True)
    (folder / "results" / f"{TASK}.json").unlink()
    before = snapshot(folder.parent)
    code, stderr = _run(spec, folder, *options)
    assert code == 2, stderr
    line = one_error_line(stderr)
    assert str(folder / "sessions") in line and "symbolic link" in line, line
    assert snapshot(folder.parent) == before and not any(outside.iterdir())
