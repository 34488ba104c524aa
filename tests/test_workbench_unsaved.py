"""Unsaved work in a real browser: after a step run from the GUI, choosing another task asks first (Cancel keeps
everything as it was, Keep moves the steps to sessions/<task>-unsaved-N and loads the task), and the panel's message
matches the step table afterwards."""
from __future__ import annotations

import html
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Browser, Page
from test_workbench_browser import _free_port, _open, _run_up_to_from_the_gui, _tab, _wait_for

from planner.core.paths import DEFAULT_TASK
from planner.core.session import Session
from workbench.app import Workbench
from workbench.session_panel import NO_STEP

pytestmark = pytest.mark.browser


@pytest.fixture
def sessions(tmp_path: Path) -> Path:
    return tmp_path / "sessions"


@pytest.fixture
def bench(sessions: Path) -> Iterator[Workbench]:
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=sessions)
    yield wb
    wb.close()


@pytest.fixture
def page(bench: Workbench, browser: Browser) -> Iterator[Page]:
    page = _open(bench, browser)
    yield page
    page.close()


def _choose_task(page: Page, label: str) -> None:
    """Pick `label` in the Task tab's task dropdown, as a person does."""
    _tab(page, "Task")
    page.get_by_role("textbox", name="Task", exact=True).or_(page.get_by_label("Task", exact=True)).first.click()
    page.get_by_role("option", name=label, exact=True).click()


@pytest.mark.slow  # about a minute: the arms step runs, then the other task loads
def test_switching_the_task_after_running_a_step_asks_and_keeps_the_work(bench: Workbench, page: Page, sessions: Path) -> None:
    _run_up_to_from_the_gui(bench, page, "arms")
    scratch, scene = bench.session_panel.scratch, bench.scene
    assert scratch is not None and bench.session.finished() == ["arms"]
    _choose_task(page, "baxter")
    page.get_by_text("Unsaved steps", exact=True).wait_for(timeout=10_000)
    assert page.get_by_text("arms", exact=True).count() > 0
    page.get_by_role("button", name="Cancel", exact=True).click()
    assert _wait_for(lambda: bench.task_tab.choice.value == "default"), "Cancel left the dropdown on the other task"
    assert bench.scene is scene and bench.session.folder == scratch and scratch.exists()

    _choose_task(page, "baxter")
    keep = page.get_by_role("button", name="Keep as default-unsaved-1", exact=True)
    keep.wait_for(timeout=10_000)
    keep.click()
    assert _wait_for(lambda: bench.scene.source.stem == "baxter" and not scratch.exists(), 60), "Keep did not load the task"
    assert Session.open(sessions / "default-unsaved-1").finished() == ["arms"]
    assert bench.session is None
    panel = bench.session_panel
    assert panel.step.value == NO_STEP and "pending" in panel.table.content and "done" not in panel.table.content
    assert _wait_for(lambda: panel.message.visible, 10), "the kept steps were not said"  # said once the scratch is gone
    message = html.unescape(panel.message.content)
    assert panel.message.visible and "Unsaved work kept" in message and "Nothing to run" not in message, message
    _tab(page, "Steps")
    page.get_by_text("Unsaved work kept", exact=False).first.wait_for(timeout=10_000)


def test_nothing_asked_without_unsaved_steps(bench: Workbench, page: Page) -> None:
    """With no step run, another task loads at once; the panel then shows no message from before."""
    _choose_task(page, "baxter")
    assert _wait_for(lambda: bench.scene.source.stem == "baxter", 60), "the task was not loaded"
    assert page.get_by_text("Unsaved steps", exact=True).count() == 0
    assert not bench.session_panel.message.visible
