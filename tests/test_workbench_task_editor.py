"""Task editing in a real browser (headless chromium): the goal moved in the Task tab changes the task, the live check
shows the new placement, "Save task as" writes a file `regrasp check` accepts; the goal's handle dragged in the 3-D view
moves the goal too; an uploaded mesh becomes the object, and the steps plan it through double_grasps."""
from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import trimesh
from playwright.sync_api import Browser, Page
from test_workbench_browser import _free_port, _open, _project, _run_up_to_from_the_gui, _settled, _tab, _wait_for

from planner.core.paths import DEFAULT_TASK, PROJECT_ROOT
from planner.core.runner import run_pipeline
from planner.core.session import Session
from planner.model.task import load_task
from workbench import session_panel
from workbench.app import Workbench
from workbench.task_handles import PLACEMENT_SCALE

pytestmark = pytest.mark.browser
CHECK_SECONDS = 120  # the live check on a loaded two-core machine (it takes a few seconds alone)
# grasp lists of 50 x 50 frames instead of 80 x 80: a new mesh has no cached lists, and a box needs no more
SMALL = {**{step: {"positions": 50, "orientations": 50} for step in ("pick_grasps", "place_grasps")},
         "grasp_configs": {"wide_attempts": 0}}  # the near-rest IK starts only


@pytest.fixture(scope="module")
def workbench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workbench]:
    """On the default task; tasks are saved and meshes uploaded into folders of its own, never the project's."""
    folder = tmp_path_factory.mktemp("editor")
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=folder / "sessions")
    wb.task_editor.tasks_dir, wb.task_editor.uploads_dir = folder / "tasks", folder / "uploads"
    yield wb
    wb.close()


@pytest.fixture(scope="module")
def page(workbench: Workbench, browser: Browser) -> Iterator[Page]:
    page = _open(workbench, browser)
    _tab(page, "Task")
    page.get_by_text("Edit the task", exact=True).click()
    yield page
    page.close()


def _checked(workbench: Workbench, count: int) -> bool:
    """Whether the live check has shown `count` checks and has nothing waiting."""
    return _wait_for(lambda: workbench.task_editor.live.checked >= count and workbench.task_editor.live.idle.is_set(),
                     CHECK_SECONDS)


def _regrasp(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, timeout=300,
                          cwd=PROJECT_ROOT, env={"PYTHONPATH": str(PROJECT_ROOT), "PATH": "/usr/bin:/bin"})


def test_the_goal_typed_changes_the_task_the_check_follows_and_save_writes_a_checked_file(workbench: Workbench,
                                                                                          page: Page) -> None:
    editor = workbench.task_editor
    assert _checked(workbench, 1), "the task shown was never checked"
    page.get_by_text("(0.500, 0.850, 0.720) m", exact=False).first.wait_for(timeout=30_000)
    checked = editor.live.checked
    row = page.locator(".mantine-Flex-root", has=page.get_by_text("Goal x, y, °", exact=True)).last
    y = row.locator("input").nth(1)
    y.fill("0.88")
    y.press("Tab")
    assert _wait_for(lambda: abs(workbench.scene.object_final[1, 3] - 0.88) < 1e-9, 30), "the typed goal did not change the task"
    assert workbench.scene.object_final[2, 3] == pytest.approx(0.72)  # still on the desk
    assert _checked(workbench, checked + 1), "the edit was not checked"
    page.get_by_text("(0.500, 0.880, 0.720) m", exact=False).first.wait_for(timeout=30_000)
    assert "OK: a valid two-hand regrasping task" in editor.check.content
    assert page.get_by_text("Edited, not saved", exact=False).count() > 0

    name = page.locator(".mantine-Flex-root", has=page.get_by_text("Save as", exact=True)).last.locator("input")
    name.fill("goal-moved")
    name.press("Tab")
    page.get_by_role("button", name="Save task as").click()
    saved = editor.tasks_dir / "goal-moved.toml"
    assert _wait_for(saved.exists, 30), editor.status.content
    assert load_task(saved).object_final[:3, 3] == pytest.approx([0.5, 0.88, 0.72])
    check = _regrasp("check", str(saved))
    assert check.returncode == 0 and "OK: a valid two-hand regrasping task" in check.stdout, check.stdout + check.stderr
    assert _wait_for(lambda: workbench.scene.source == saved.resolve(), 30), "the saved task is not the one shown"

    page.get_by_role("button", name="Save task as").click()  # the name is taken now: asked, and kept until confirmed
    page.get_by_text("already exists. Replace it", exact=False).wait_for(timeout=30_000)
    page.get_by_role("button", name="Cancel").click()
    assert saved.read_text() == (editor.tasks_dir / "goal-moved.toml").read_text()


def test_dragging_the_goal_handle_moves_the_goal(workbench: Workbench, page: Page) -> None:
    """The goal handle's y arrow dragged with the mouse in the 3-D view (the camera at the goal, so that the arrow is
    large on screen): the goal follows along that arrow, stays on the desk, and is checked."""
    editor = workbench.task_editor
    assert _checked(workbench, 1)
    page.get_by_label("Handles in 3-D").check()
    assert _wait_for(lambda: editor.handles.visible, 10)
    for glide in workbench.show_view("goal"):
        glide.join()
    _settled(page, timeout=60)  # drawn where the glide ended: the camera the browser reports is the one it draws with
    checked, before = editor.live.checked, workbench.scene.object_final.copy()
    origin, y_axis = before[:3, 3], before[:3, 1]  # the handle turns with the goal's heading: its y arrow along the pose's y
    start = _project(workbench, origin + 0.8 * PLACEMENT_SCALE * y_axis)
    end = _project(workbench, origin + 1.2 * PLACEMENT_SCALE * y_axis)
    page.mouse.move(*start)
    page.mouse.down()
    for t in np.linspace(0, 1, 12)[1:]:
        page.mouse.move(*(start + t * (end - start)))
        time.sleep(0.05)
    page.mouse.up()
    assert _wait_for(lambda: not np.allclose(workbench.scene.object_final[:3, 3], origin, atol=0.01), 30), \
        "the drag did not move the goal"
    after = workbench.scene.object_final
    assert after[2, 3] == pytest.approx(0.72) and np.dot(after[:3, 3] - origin, y_axis) > 0.03
    assert np.linalg.norm(np.cross(after[:3, 3] - origin, y_axis)) < 0.01  # along the arrow only
    assert _checked(workbench, checked + 1)
    page.get_by_text(f"({after[0, 3]:.3f}, {after[1, 3]:.3f}, 0.720) m", exact=False).first.wait_for(timeout=30_000)


def test_an_edit_asks_before_the_steps_run_go(workbench: Workbench, page: Page) -> None:
    """With a step run and not saved, an edit asks first: Cancel keeps the task and the step; Keep keeps the step as
    sessions/<task>-unsaved-1 and makes the edit."""
    editor = workbench.task_editor
    editor.final.value = (0.5, 0.88, 150.0)  # a goal the arms step accepts (the drag may have left it in the lamp)
    assert editor.live.idle.wait(CHECK_SECONDS) and "Check: OK" in editor.check.content, editor.check.content
    job = workbench.session_panel.run_until("arms")
    assert job is not None
    job.join(120)
    assert workbench.session is not None and workbench.session.finished() == ["arms"], workbench.session_panel.message.content
    goal = workbench.scene.object_final.copy()
    _tab(page, "Task")
    row = page.locator(".mantine-Flex-root", has=page.get_by_text("Goal x, y, °", exact=True)).last
    y = row.locator("input").nth(1)
    y.fill("0.87")
    y.press("Tab")
    page.get_by_text("The steps run here are not saved", exact=False).wait_for(timeout=30_000)
    page.get_by_role("button", name="Cancel").click()
    assert _wait_for(lambda: editor.final.value[1] == pytest.approx(goal[1, 3]), 10), "the control did not go back"
    assert _wait_for(lambda: float(y.input_value()) == pytest.approx(goal[1, 3], abs=1e-3), 30), "the page's field did not"
    assert workbench.session.finished() == ["arms"] and (workbench.scene.object_final == goal).all()
    y.fill("0.87")
    y.press("Tab")
    keep = page.get_by_role("button", name="Keep as", exact=False)
    keep.wait_for(timeout=30_000)
    kept = keep.inner_text().removeprefix("Keep as ").strip()
    keep.click()
    assert _wait_for(lambda: workbench.scene.object_final[1, 3] == pytest.approx(0.87) and workbench.session is None, 30), \
        editor.status.content
    folder = workbench.session_panel.sessions_dir / kept
    assert _wait_for(lambda: Session.exists(folder), 30), f"the step was not kept in {folder}"
    assert Session.open(folder).finished() == ["arms"]


@pytest.mark.slow
def test_an_uploaded_mesh_plans_through_double_grasps(workbench: Workbench, page: Page, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    box = trimesh.creation.box(extents=(0.06, 0.06, 0.16))  # on a 12 cm box two hands fit one or two ways: too few to rely on
    box.apply_translation((0, 0, 0.08))
    upload = tmp_path / "small box.stl"
    box.export(upload)
    page.locator("input[type=file]").set_input_files(str(upload))
    editor = workbench.task_editor
    assert _wait_for(lambda: workbench.scene.object_name.endswith("small_box.stl"), 60), editor.status.content
    assert (editor.uploads_dir / "small_box.stl").read_bytes() == upload.read_bytes()
    assert workbench.scene.object_mesh.extents == pytest.approx([0.06, 0.06, 0.16])
    assert _checked(workbench, editor.live.checked)
    monkeypatch.setattr(session_panel, "run_pipeline", lambda s, until, params, progress: run_pipeline(
        s, until, params or SMALL, progress))
    _run_up_to_from_the_gui(workbench, page, "double_grasps", timeout=900)
    pairs = workbench.session.result("double_grasps")
    assert len(pairs) > 0 and workbench.session.scene.object_name.endswith("small_box.stl")
    replayed = Session.open(workbench.session.folder)  # the session embeds the uploaded mesh: a replay reads no upload
    assert np.array_equal(replayed.scene.object_mesh.vertices, workbench.scene.object_mesh.vertices)
