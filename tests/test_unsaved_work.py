"""Work is never lost silently: a scratch session's steps not saved as they are go to `sessions/<task>-unsaved-N` (listed
with the saved sessions, said in the panel) when another task or session replaces it, or the workbench closes; a
saved session, or a loaded one nothing was run on, is not copied again."""
from __future__ import annotations

import html
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from sandbox import EXAMPLE
from test_workbench_browser import _free_port

from planner.core.paths import DEFAULT_TASK, TASKS_DIR
from planner.core.session import Session
from workbench import session_panel
from workbench.app import Workbench
from workbench.session_dialogs import CANCEL, DISCARD, SAVE


@pytest.fixture
def sessions(tmp_path: Path) -> Path:
    """A sessions folder holding `good`: the example's first step."""
    Session.open(EXAMPLE).branch(tmp_path / "sessions" / "good", before="pick_grasps")
    return tmp_path / "sessions"


@pytest.fixture
def bench(sessions: Path) -> Iterator[Workbench]:
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=sessions)
    yield wb
    wb.close()


def _run_arms(wb: Workbench) -> Path:
    job = wb.session_panel.run_until("arms")
    assert job is not None
    job.join(300)
    assert wb.session is not None and wb.session.finished() == ["arms"]
    return wb.session_panel.scratch


def _kept(sessions: Path) -> list[str]:
    return sorted(p.name for p in sessions.iterdir() if "-unsaved-" in p.name)


@pytest.mark.slow  # 4-6 s: kept out of the fast subset (CI runs it)
def test_switching_the_task_keeps_the_steps_run(bench: Workbench, sessions: Path) -> None:
    scratch = _run_arms(bench)
    bench._load(TASKS_DIR / "baxter.toml", None)
    assert _kept(sessions) == ["default-unsaved-1"]
    kept = Session.open(sessions / "default-unsaved-1")
    assert kept.finished() == ["arms"]
    assert not scratch.exists(), "the scratch session stayed after it was kept"
    panel = bench.session_panel
    message = html.unescape(panel.message.content)
    assert panel.message.visible and "Unsaved work kept" in message and "default-unsaved-1" in message, message
    assert "default-unsaved-1" in panel.saved.options


@pytest.mark.slow
def test_loading_a_session_or_closing_keeps_them_too(bench: Workbench, sessions: Path) -> None:
    _run_arms(bench)
    assert bench.session_panel.load(sessions / "good")
    assert _kept(sessions) == ["default-unsaved-1"]
    job = bench.session_panel.run_until("pick_grasps")  # into a copy of `good`
    assert job is not None
    job.join(300)
    bench.close()
    assert _kept(sessions) == ["default-unsaved-1", "default-unsaved-2"]
    assert Session.open(sessions / "default-unsaved-2").finished() == ["arms", "pick_grasps"]


@pytest.mark.slow  # 4-6 s: kept out of the fast subset (CI runs it)
def test_saved_work_and_an_untouched_copy_are_not_kept_again(bench: Workbench, sessions: Path) -> None:
    _run_arms(bench)
    bench.session_panel.save("mine")
    assert bench.session_panel.load(sessions / "good")
    bench.session_panel.run_until("arms")  # nothing to run: arms is finished in `good`
    bench.close()
    assert _kept(sessions) == [], "saved work, or a loaded session with nothing run on it, was copied as unsaved"


class _Client:
    """Stands in for the tab a dialog is asked in: the question's `answer` is kept to be given by the test."""

    def __init__(self) -> None:
        self.asked: list[tuple[list[str], str, str, str]] = []
        self.answer: Any = None


@pytest.mark.slow  # two runs of the arms step
def test_the_dialogs_answers_save_discard_or_cancel(bench: Workbench, sessions: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Cancel leaves all as it was; Discard loads the task and keeps nothing; Save writes sessions/<name> first."""
    client = _Client()

    def asked(_: Any, steps: list[str], what: str, name: str, kept_as: str, answer: Any) -> None:
        client.asked.append((steps, what, name, kept_as))
        client.answer = answer

    monkeypatch.setattr(session_panel, "ask_unsaved", asked)
    panel = bench.session_panel
    scratch = _run_arms(bench)
    bench._load(TASKS_DIR / "baxter.toml", client)
    assert client.asked == [(["arms"], "load the task baxter", "untitled", "default-unsaved-1")]
    client.answer(CANCEL)
    assert bench.scene.source.stem == "default" and bench.task_tab.choice.value == "default" and scratch.exists()
    bench._load(TASKS_DIR / "baxter.toml", client)
    client.answer(DISCARD)
    assert bench.scene.source.stem == "baxter" and not scratch.exists() and _kept(sessions) == []

    bench._load(DEFAULT_TASK, None)
    _run_arms(bench)
    panel.name.value = "mine"
    panel.ask_unsaved(client, "load the session good", lambda: panel.load(sessions / "good"))
    client.answer(SAVE)
    assert Session.open(sessions / "mine").finished() == ["arms"] and _kept(sessions) == []
    assert bench.session.folder == sessions / "good"
