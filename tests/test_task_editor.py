"""The task editor's controls driven from code (no browser): obstacles added, resized and removed reach the task shown,
a bad edit is refused with the loader's message and the controls go back, another robot spec is checked, an upload
that is no mesh is refused, an edit waits while a step runs, and only the newest of quick edits is checked."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import viser

from planner.core.paths import DEFAULT_TASK
from workbench.app import Workbench
from workbench.screenshot import free_port

CHECK_SECONDS = 120


@pytest.fixture(scope="module")
def workbench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workbench]:
    folder = tmp_path_factory.mktemp("editor")
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", free_port(), sessions_dir=folder / "sessions")
    wb.task_editor.tasks_dir, wb.task_editor.uploads_dir = folder / "tasks", folder / "uploads"
    yield wb
    wb.close()


def _settled(wb: Workbench) -> None:
    """Wait until the live check has nothing waiting (the edit is shown and checked)."""
    assert wb.task_editor.live.idle.wait(CHECK_SECONDS), "the live check never finished"


@pytest.mark.slow  # four edits, each shown and checked: 23 s
def test_an_added_box_is_resized_refused_when_absurd_and_removed(workbench: Workbench) -> None:
    editor = workbench.task_editor
    _settled(workbench)
    count = len(workbench.scene.environment)
    editor._add("box", None)
    _settled(workbench)
    assert [o.name for o in workbench.scene.environment][-1] == "box_1" and editor.obstacle.value == "box_1"
    box = workbench.scene.environment[-1]
    assert box.to_trimesh().bounds[0][2] == pytest.approx(0.72)  # standing on the desk, between the placements
    editor.box_size.value = (0.2, 0.1, 0.05)
    _settled(workbench)
    assert workbench.scene.environment[-1].size == (0.2, 0.1, 0.05)
    editor.box_size.value = (80.0, 0.1, 0.05)  # more than an obstacle may be: the loader's message, the size restored
    assert "expected positive dimensions up to 50 m" in editor.status.content
    assert editor.box_size.value == (0.2, 0.1, 0.05) and workbench.scene.environment[-1].size == (0.2, 0.1, 0.05)
    editor._edit(lambda d: d, None)  # the refusal does not stick: a later edit goes through
    editor.remove_obstacle.value = True  # the button's click, as the page sends it
    _settled(workbench)
    assert len(workbench.scene.environment) == count and "box_1" not in editor.obstacle.options
    assert "Check: OK" in editor.check.content


@pytest.mark.slow  # two robots built and checked: 22 s
def test_another_robot_spec_is_shown_and_checked(workbench: Workbench) -> None:
    editor = workbench.task_editor
    _settled(workbench)
    checked = editor.live.checked
    editor.robot_spec.value = "baxter_allegro.toml"
    _settled(workbench)
    assert workbench.scene.robot.spec.name == "baxter-allegro" and editor.live.checked > checked
    assert "LeftElbowPitch" in editor.status.content  # the joints Baxter has not, dropped and named
    assert "Check:" in editor.check.content and "running" not in editor.check.content
    editor.robot_spec.value = "alex_allegro.toml"
    _settled(workbench)
    assert workbench.scene.robot.spec.name == "alex-allegro"


def test_an_upload_that_is_no_mesh_is_refused_and_the_object_stays(workbench: Workbench) -> None:
    editor = workbench.task_editor
    before = workbench.scene.object_name
    editor._uploaded(viser.UploadedFile("../../notes.obj", b"v 0 0 0\nthis is no mesh\n"), None)
    assert "notes&#46;obj&#58; the object mesh could not be parsed" in editor.status.content  # named, and text only
    assert workbench.scene.object_name == before
    assert list(Path(editor.uploads_dir).iterdir()) == []  # nothing kept


def test_an_edit_waits_while_a_step_runs(workbench: Workbench, monkeypatch: pytest.MonkeyPatch) -> None:
    editor = workbench.task_editor
    _settled(workbench)
    goal = workbench.scene.object_final.copy()
    monkeypatch.setattr(workbench.session_panel, "busy", lambda: True)
    editor.final.value = (0.5, 0.9, 150.0)
    assert "a step is running" in editor.status.content
    assert editor.final.value[1] == pytest.approx(goal[1, 3])  # the control went back
    assert (workbench.scene.object_final == goal).all()


def test_only_the_newest_of_quick_edits_is_checked(workbench: Workbench) -> None:
    editor = workbench.task_editor
    _settled(workbench)
    checked = editor.live.checked
    for y in (0.86, 0.87, 0.88):
        editor.final.value = (0.5, y, 150.0)
    _settled(workbench)
    assert editor.live.checked == checked + 1
    assert workbench.scene.object_final[1, 3] == pytest.approx(0.88) and "0&#46;880" in editor.check.content
