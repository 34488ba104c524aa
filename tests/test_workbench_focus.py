"""The workbench as a person uses it, in a real browser (issue 14): one layer in focus, a chosen grasp framed with the rest
dimmed, whole poses (the object between the hands at the exchange), camera views, and the README's picture."""
from __future__ import annotations

import html
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import viser
from PIL import Image
from playwright.sync_api import Browser, Page
from test_workbench_browser import (
    CHANGED,
    EXAMPLE,
    _assert_robot_visible,
    _free_port,
    _object_pixels,
    _project,
    _settled,
    _tab,
    _until_changed,
    _view,
    _wait_for,
)
from test_workbench_grasps import _choose_rank

from workbench.app import GRASP_CLOSE_UP, VIEWS, Workbench
from workbench.layers.double_grasps import DoubleGraspsLayer
from workbench.layers.roadmap import BACKGROUND, faint
from workbench.scene_layer import DIM_OPACITY
from workbench.screenshot import MAX_BYTES, VIEWPORT, screenshot
from workbench.view import CAMERA_POSITION, close_up

pytestmark = pytest.mark.browser
BOX_MARGIN = 0.05  # m around the object's bounding box: the chosen hand touches the object
INSIDE = 0.8  # of the pixels a new grasp changes, at least this many fall in the object's screen box
NEAR_HAND = 90  # px: object pixels this close to each hand's frame, seen from the handover view (about 10 cm there)


@pytest.fixture(scope="module")
def workbench(tmp_path_factory) -> Iterator[Workbench]:
    folder = tmp_path_factory.mktemp("sessions") / "example"
    shutil.copytree(EXAMPLE, folder)
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=folder.parent)
    yield wb
    wb.close()


def _client(wb: Workbench) -> viser.ClientHandle:
    assert _wait_for(lambda: len(wb.server.get_clients()) > 0)
    return next(iter(wb.server.get_clients().values()))


def _camera_at(wb: Workbench, position: np.ndarray) -> bool:
    """Wait until the browser's camera has glided to `position`."""
    return _wait_for(lambda: np.allclose(_client(wb).camera.position, position, atol=0.02), 10)


def _screen_box(wb: Workbench, T: np.ndarray, margin: float) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) px: the object's bounding box at pose T, grown by `margin`, as the browser's camera sees it."""
    vertices = wb.scene.object_mesh.vertices @ T[:3, :3].T + T[:3, 3]
    lo, hi = vertices.min(axis=0) - margin, vertices.max(axis=0) + margin
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    uv = np.array([_project(wb, c) for c in corners])
    (x0, y0), (x1, y1) = np.floor(uv.min(axis=0)).astype(int), np.ceil(uv.max(axis=0)).astype(int)
    return max(x0, 0), max(y0, 0), x1, y1


def test_only_the_last_step_is_in_focus(workbench: Workbench) -> None:
    """By default the last step's layer alone is shown (the Super Graph hidden); the step table keeps two or three
    figures a step and the Step details show the rest."""
    layers = workbench.session_layers.layers
    assert workbench.layer_toggles.shown() == ["motion"]
    assert [n for n, layer in layers.items() if layer.visible] == ["motion"] and not layers["roadmap"].visible
    panel = workbench.session_panel
    assert panel.step.value == "motion" and "| path_length |" in html.unescape(panel.details.content)
    rows = [row for row in panel.table.content.splitlines()[2:]]
    assert all(1 <= row.split("|")[4].count("=") <= 3 for row in rows), panel.table.content
    assert "collision_checks" not in panel.table.content  # the roadmap's many figures: in its details only
    assert workbench.task_tab.path.value == "default" and workbench.task_tab.choice.value == "session example"  # not …/session.json
    panel.step.value = "roadmap"
    try:
        assert workbench.layer_toggles.shown() == ["roadmap"] and "| collision_checks |" in html.unescape(panel.details.content)
    finally:
        panel.step.value = "motion"


def test_super_graph_is_drawn_faint() -> None:
    """Its edge colours are faded most of the way to the background, so it never hides the robot when shown."""
    colors = np.array([[0, 0, 0], [40, 110, 240], [BACKGROUND] * 3], dtype=np.uint8)
    faded = faint(colors).astype(int)
    assert np.all(np.abs(BACKGROUND - faded) <= np.ceil(0.4 * np.abs(BACKGROUND - colors.astype(int))))
    assert np.array_equal(faded[2], [BACKGROUND] * 3)


def test_robot_pixels_are_visible(workbench: Workbench, page: Page) -> None:
    """With the example loaded (its last step in focus), the robot is seen: a render without it differs."""
    _assert_robot_visible(workbench, page)
    _settled(page)


def test_toggling_one_layer_changes_the_picture_and_leaves_the_others(workbench: Workbench, page: Page) -> None:
    layers = workbench.session_layers.layers
    others = {name: layer.visible for name, layer in layers.items() if name != "exchange"}
    assert not layers["exchange"].visible
    _tab(page, "View")  # the Layers folder
    before = _settled(page)
    page.get_by_label("exchange", exact=True).click()
    try:
        assert _wait_for(lambda: layers["exchange"].visible), "the checkbox did not reach the layer"
        assert _until_changed(page, before) > CHANGED, "showing the exchange layer changed nothing on screen"
        assert {name: layer.visible for name, layer in layers.items() if name != "exchange"} == others
    finally:
        page.get_by_label("exchange", exact=True).click()
        assert _wait_for(lambda: not layers["exchange"].visible)
    _settled(page)


def test_choosing_a_grasp_rank_frames_it_and_dims_the_rest(workbench: Workbench, page: Page) -> None:
    """A rank chosen in the browser: its layer alone, robot and obstacles dimmed, the camera on the object; another rank
    then changes pixels mostly within the object's screen box."""
    layer = workbench.session_layers.layers["pick_grasps"]
    try:
        _choose_rank(page, layer, 1)
        assert _wait_for(lambda: layer.shown_rank == 1), "choosing a rank in the browser did not reach the layer"
        assert workbench.layer_toggles.shown() == ["pick_grasps"]
        assert all(h.opacity == DIM_OPACITY for h in workbench.robot_layer.handles)
        assert all(h.opacity == DIM_OPACITY for h in workbench.scene_layer.obstacles)
        assert _camera_at(workbench, close_up(workbench.scene_layer.centre(layer.object_pose), GRASP_CLOSE_UP)[0])
        before = _settled(page)
        _choose_rank(page, layer, 4)
        assert _wait_for(lambda: layer.shown_rank == 4)
        assert _until_changed(page, before) > CHANGED, "another grasp changed nothing on screen"
        changed = np.abs(_settled(page) - before).max(axis=2) > 24
        x0, y0, x1, y1 = _screen_box(workbench, layer.object_pose, BOX_MARGIN)
        box = np.zeros_like(changed)
        box[y0:y1, x0:x1] = True
        assert box.mean() < 0.5, "the object's box covers most of the view: the test would prove nothing"
        inside = (changed & box).sum() / changed.sum()
        assert inside >= INSIDE, f"only {inside:.0%} of the changed pixels are within the object's screen box"
    finally:
        workbench.focus_step("motion")
        workbench.show_view("overview")
    assert all(h.opacity is None for h in workbench.robot_layer.handles), "focusing another step did not undim the robot"
    _settled(page)


def test_robot_at_the_exchange_holds_the_object_between_the_hands(workbench: Workbench, page: Page) -> None:
    """"Robot at" pair 1's exchange: the robot at q_exch, and the object's pixels by both hands (not on the desk)."""
    layer: DoubleGraspsLayer = workbench.session_layers.layers["double_grasps"]
    r = layer.result
    workbench.show_view("handover")
    assert _camera_at(workbench, close_up(workbench.scene_layer.centre(r.object_exchange[0]))[0])
    label, sliders = DoubleGraspsLayer.label(0, "exchange"), dict(workbench._slider_of)
    workbench.pose_choice.dropdown.value = label
    try:
        assert np.allclose(workbench.q, r.q_exch[0]) and workbench.pose_choice.dropdown.value == label
        assert workbench._slider_of == sliders, "posing the robot rebuilt the joint sliders (they vanish and come back)"
        assert all(np.isclose(slider.value, r.q_exch[0][i]) for i, slider in sliders.items()), "the sliders did not follow"
        mask = _object_pixels(workbench, page)
        rows, cols = np.nonzero(mask)
        pixels = np.stack([cols, rows], axis=1)
        pick, place = workbench.session.result("pick_grasps"), workbench.session.result("place_grasps")
        for name, grasps, rank in (("picking", pick, r.pick_rank[0]), ("placing", place, r.place_rank[0])):
            hand = _project(workbench, (r.object_exchange[0] @ grasps.hand_pose[rank])[:3, 3])
            nearest = np.linalg.norm(pixels - hand, axis=1).min()
            assert nearest < NEAR_HAND, f"the object's pixels are {nearest:.0f} px from the {name} hand"
        desk = _project(workbench, workbench.scene_layer.centre(workbench.scene.object_initial))
        assert np.linalg.norm(pixels.mean(axis=0) - desk) > 2 * NEAR_HAND, "the object is still drawn on the desk"
    finally:
        workbench.reset()
        workbench.show_view("overview")
    assert workbench.pose_choice.dropdown.value == "task: initial configuration"
    _settled(page)


def test_each_view_button_moves_the_camera(workbench: Workbench, page: Page) -> None:
    centre = workbench.scene_layer.centre
    targets = {"start": centre(workbench.scene.object_initial), "handover": workbench.exchange_point(),
               "goal": centre(workbench.scene.object_final)}
    assert set(VIEWS) == {"overview", *targets}
    _tab(page, "View")  # the camera buttons
    for name in ("start", "handover", "goal", "overview"):
        before, position = _settled(page), _client(workbench).camera.position
        page.get_by_role("button", name=name, exact=True).click()
        target = np.array(CAMERA_POSITION) if name == "overview" else close_up(targets[name])[0]
        assert not np.allclose(position, target, atol=0.02), f"the camera was already at the {name} view"
        assert _camera_at(workbench, target), f"the {name} button did not move the camera there"
        assert _until_changed(page, before) > CHANGED, f"the {name} view looks as the one before"
    _view(page)


def test_readme_screenshot_command(browser: Browser, tmp_path: Path) -> None:
    """`regrasp screenshot` pictures the example session: the whole viewport, as a PNG small enough for the README."""
    out = tmp_path / "workbench.png"
    size = screenshot(EXAMPLE, out, browser)
    assert size == out.stat().st_size < MAX_BYTES
    with Image.open(out) as image:
        assert image.format == "PNG" and image.size == (VIEWPORT["width"], VIEWPORT["height"])
