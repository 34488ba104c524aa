"""The workbench in a real browser: headless Debian chromium (software WebGL) draws the robot and obeys the GUI."""
from __future__ import annotations

import io
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import Browser, Page
from scipy.spatial.transform import Rotation

from planner.core.paths import DEFAULT_TASK, PROJECT_ROOT
from planner.core.session import Session
from workbench.app import Workbench
from workbench.screenshot import free_port as _free_port

pytestmark = pytest.mark.browser

VIEWPORT = {"width": 1024, "height": 720}
SCENE_WIDTH = 640  # px: the left part of the page, where the 3-D view is not covered by the GUI panel
EXAMPLE = PROJECT_ROOT / "sessions" / "default-example"  # the example session the tests replay (copied, never written)
CHANGED = 0.003  # fraction of the view's pixels that must change for a change to count
OBJECT_PIXELS = 40  # the fewest pixels the object covers when it is on screen


def _view(page: Page) -> np.ndarray:
    """The 3-D view as an int array (rows, cols, rgb)."""
    image = Image.open(io.BytesIO(page.screenshot())).convert("RGB")
    return np.asarray(image, dtype=np.int16)[:, :SCENE_WIDTH]


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels whose colour differs noticeably."""
    return float((np.abs(a - b).max(axis=2) > 24).mean())


def _settled(page: Page, timeout: float = 20.0) -> np.ndarray:
    """The view once two shots in a row agree (meshes arrived and drawn)."""
    last, end = _view(page), time.monotonic() + timeout
    while time.monotonic() < end:
        time.sleep(0.4)
        shot = _view(page)
        if _changed(shot, last) < 1e-4:
            return shot
        last = shot
    raise AssertionError("the 3-D view never settled")


def _until_changed(page: Page, before: np.ndarray, timeout: float = 15.0) -> float:
    """Wait for the view to change from `before`, then settle; returns the changed fraction."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and _changed(_view(page), before) < CHANGED:
        time.sleep(0.3)
    return _changed(_settled(page), before)


@contextmanager
def _example_before(tmp_path: Path, step: str) -> Iterator[Workbench]:
    """A workbench on a copy of the example session holding only the steps before `step` (closed afterwards)."""
    folder = tmp_path / f"before-{step}"
    Session.open(EXAMPLE).branch(folder, before=step)
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=tmp_path)
    try:
        yield wb
    finally:
        wb.close()


def _open(wb: Workbench, browser: Browser) -> Page:
    """A new page on the workbench, once its GUI is up."""
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(wb.url)
    page.get_by_text("Collisions:").wait_for(timeout=60_000)
    return page


def _tab(page: Page, name: str) -> None:
    """Open one of the panel's tabs (Task, Steps, Playback, Joints, View)."""
    page.get_by_role("tab", name=name).click()


def _project(workbench: Workbench, point: np.ndarray) -> np.ndarray:
    """Where a world point appears in a screenshot (x, y px), through the browser's camera (OpenCV convention)."""
    camera = next(iter(workbench.server.get_clients().values())).camera
    R = Rotation.from_quat(np.roll(camera.wxyz, -1)).as_matrix()  # camera to world
    x, y, z = R.T @ (point - camera.position)
    assert z > 0, "the point is behind the camera"
    f = camera.image_height / 2 / np.tan(camera.fov / 2)
    u, v = camera.image_width / 2 + f * x / z, camera.image_height / 2 + f * y / z
    return np.array([u * VIEWPORT["width"] / camera.image_width, v * VIEWPORT["height"] / camera.image_height])


def _object_pixels(wb: Workbench, page: Page) -> np.ndarray:
    """(rows, cols) bool: the pixels the workbench's object covers, the view with it shown against the view without
    (taken again until the view with it is the same before and after, so nothing else changed meanwhile)."""
    shown_object = wb.scene_layer.object
    for _ in range(3):
        shown = _settled(page)
        shown_object.visible = False
        try:
            hidden = _settled(page)
        finally:
            shown_object.visible = True
        if _changed(_settled(page), shown) < 1e-4:
            break
    else:
        raise AssertionError("the view kept changing while the object was hidden and shown again")
    mask = np.abs(shown - hidden).max(axis=2) > 24
    assert mask.sum() >= OBJECT_PIXELS, f"the object covers {mask.sum()} pixels: not on screen"
    return mask


def _run_up_to_from_the_gui(wb: Workbench, page: Page, step: str, timeout: float = 240) -> None:
    """Choose `step` in the session panel, click "Run up to this step" and wait until the step's layer is drawn."""
    panel = wb.session_panel
    panel.until.value = step
    _tab(page, "Steps")
    page.get_by_role("button", name="Run up to this step").click()
    assert _wait_for(lambda: wb.session_layers is not None and step in wb.session_layers.layers, timeout), panel.message.content


def _wait_for(condition: Callable[[], bool], timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.1)
    return condition()


@pytest.fixture(scope="module")
def workbench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workbench]:
    """On the default task; the steps it runs are kept at close in a sessions folder of its own, never the project's."""
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=tmp_path_factory.mktemp("sessions"))
    yield wb
    wb.close()


@pytest.fixture(scope="module")
def page(workbench: Workbench, browser: Browser) -> Iterator[Page]:
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(workbench.url)
    assert workbench.collision_ready.wait(60), "the collision model was never built"
    page.get_by_text("Collisions:").wait_for(timeout=30_000)
    yield page
    page.close()


def _assert_robot_visible(wb: Workbench, page: Page) -> None:
    """The view is not empty and hiding the robot changes more than 1 % of it (the robot is shown again after)."""
    with_robot = _settled(page)
    assert len(np.unique(with_robot.reshape(-1, 3), axis=0)) > 100, "the 3-D view looks empty"
    wb.show_robot.value = False
    try:
        assert _until_changed(page, with_robot) > 0.01, "hiding the robot changed almost nothing on screen"
    finally:
        wb.show_robot.value = True


def test_robot_is_drawn(workbench: Workbench, page: Page) -> None:
    _assert_robot_visible(workbench, page)


def test_collision_checkbox_shows_collision_geometry(workbench: Workbench, page: Page) -> None:
    before = _settled(page)
    layer = workbench.collision_layer
    assert layer is not None and not any(h.visible for h in layer.handles.values())
    _tab(page, "View")
    page.get_by_label("Show collision geometry").click()
    try:
        assert _wait_for(lambda: all(h.visible for h in layer.handles.values())), "the click did not reach the server"
        assert _until_changed(page, before) > CHANGED, "showing the collision geometry changed nothing on screen"
    finally:
        page.get_by_label("Show collision geometry").click()
        assert _wait_for(lambda: not any(h.visible for h in layer.handles.values()))


def test_joint_slider_swings_the_arm(workbench: Workbench, page: Page) -> None:
    workbench.part.value = "right"
    robot = workbench.scene.robot
    shoulder = int(robot.part_idx("right")[0])
    before = _settled(page)
    _tab(page, "Joints")
    page.get_by_role("slider").first.focus()  # the arm's first joint: the shoulder
    page.keyboard.press("Home")
    try:
        assert _wait_for(lambda: abs(workbench.q[shoulder] - robot.lower[shoulder]) < 0.02), "the slider did not move the joint"
        assert _until_changed(page, before) > 0.005, "swinging the arm changed little on screen"
    finally:
        workbench.reset()


def test_bad_task_file_shows_its_error(workbench: Workbench, page: Page, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\nrobot = "no_such_robot.toml"\n')
    scene = workbench.scene
    _tab(page, "Task")
    row = page.locator(".mantine-Flex-root", has=page.get_by_text("Task file", exact=True)).last
    row.locator("input").fill(str(bad))
    page.get_by_role("button", name="Load file").click()
    page.get_by_text("expected a .toml file in").first.wait_for(timeout=10_000)  # not a folder tasks are read from
    monkeypatch.setattr(workbench.task_tab, "roots", (*workbench.task_tab.roots, tmp_path))  # as if the workbench started there
    page.get_by_role("button", name="Load file").click()
    page.get_by_text("no_such_robot.toml", exact=False).first.wait_for(timeout=10_000)
    assert page.get_by_text("Could not load the task").count() > 0
    assert workbench.scene is scene, "a bad task file replaced the loaded task"
