"""Workbench guards: save names are checked with a message in the panel (never an exception in the callback), and a
task cannot be loaded while a run is going (it would be thrown away when the run ends)."""
from __future__ import annotations

import html
import threading
from collections.abc import Iterator

import pytest
from sandbox import snapshot
from test_workbench_browser import _free_port

from planner.core.errors import RegraspError
from planner.core.paths import ASSETS, DEFAULT_TASK
from workbench import session_panel
from workbench.app import Workbench
from workbench.session_store import MAX_SESSION_NAME, check_name

BAD_NAMES = {
    "nul": ("a\0b", "not a session name"),
    "newline": ("two\nlines", "not a session name"),
    "tilde": ("~home", "not a session name"),
    "leading dash": ("-rf", "not starting with -"),
    "separator": ("a/b", "not a session name"),
    "parent": ("..", "not a session name"),
    "hidden": (".x", "not a session name"),
    "255 characters": ("n" * 255, f"at most {MAX_SESSION_NAME} characters"),
    "empty": ("   ", "not a session name"),
}


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workbench]:
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=tmp_path_factory.mktemp("sessions"))
    yield wb
    wb.close()


@pytest.fixture
def blocked_run(bench: Workbench, monkeypatch: pytest.MonkeyPatch) -> Iterator[threading.Event]:
    """Runs started from the panel wait on the returned event (set it to let them finish) instead of planning."""
    gate = threading.Event()

    def waiting(session, until, params, progress):  # stands in for planner.core.runner.run_pipeline
        assert gate.wait(120), "the test never let the run finish"
        return []
    monkeypatch.setattr(session_panel, "run_pipeline", waiting)
    yield gate
    gate.set()
    job = bench.session_panel.job
    if job is not None:
        job.join(120)


@pytest.mark.parametrize("case", list(BAD_NAMES))
def test_bad_save_name_is_a_message_not_an_exception(bench: Workbench, case: str) -> None:
    name, phrase = BAD_NAMES[case]
    panel = bench.session_panel
    before = snapshot(panel.sessions_dir)
    panel.message.visible = False
    panel.name.value = name
    panel._save_clicked(None)  # the Save button's callback; a bad name never reaches the dialog that needs the tab
    assert panel.message.visible and "Not saved" in panel.message.content and phrase in html.unescape(panel.message.content)
    with pytest.raises(RegraspError, match=phrase):
        check_name(name)
    assert snapshot(panel.sessions_dir) == before


def test_good_names_are_kept() -> None:
    assert [check_name(n) for n in ["plain", "with-dash_and_underscore", "Übung2", " padded "]] == \
        ["plain", "with-dash_and_underscore", "Übung2", "padded"]


@pytest.mark.slow  # 4-6 s: kept out of the fast subset (CI runs it)
def test_task_loading_is_refused_while_a_run_goes(bench: Workbench, blocked_run: threading.Event) -> None:
    panel = bench.session_panel
    scene = bench.scene
    job = panel.run_until("arms")
    assert job is not None
    assert bench.task_tab.load_button.disabled and bench.task_tab.choice.disabled, "task loading stays enabled during a run"
    other = ASSETS / "tasks" / "baxter.toml"
    bench._load(other, None)  # what "Load file" (or the task choice) of another tab calls
    assert bench.scene is scene and bench.task_tab.error.visible and "a step is running" in bench.task_tab.error.content
    blocked_run.set()
    job.join(120)
    assert not job.is_alive() and bench.scene is scene
    assert not bench.task_tab.load_button.disabled and not bench.task_tab.choice.disabled
    bench._load(other, None)  # after the run, loading works again
    assert bench.scene.source == other.resolve()
    bench._load(DEFAULT_TASK, None)


def test_a_session_saves_under_a_good_name(bench: Workbench, blocked_run: threading.Event) -> None:
    panel = bench.session_panel
    blocked_run.set()
    job = panel.run_until("arms")  # leaves a scratch session (no step planned: the run is stood in for)
    assert job is not None
    job.join(120)
    assert bench.session is not None
    panel.name.value = "saved-1"
    panel._save_clicked(None)
    assert "Saved" in panel.message.content, panel.message.content
    assert (panel.sessions_dir / "saved-1" / "session.json").is_file()
    assert sorted(p.name for p in panel.sessions_dir.iterdir()) == ["saved-1"], "a staging folder was left"
