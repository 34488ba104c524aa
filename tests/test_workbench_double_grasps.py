"""The online steps' layers in a real browser: the filtered grasp lists, the exchange grid and the double grasps of the
example are drawn; "exchange" in the Double grasps folder puts the robot at q_exch; a double_grasps step run from the
GUI ("Run up to this step") gets its layer, whose pair the robot is then shown holding at the exchange."""
from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from playwright.sync_api import Browser, Page
from test_workbench_browser import (
    CHANGED,
    EXAMPLE,
    _example_before,
    _free_port,
    _open,
    _run_up_to_from_the_gui,
    _settled,
    _tab,
    _until_changed,
    _wait_for,
)

from workbench.app import Workbench
from workbench.layers import LAYERS
from workbench.layers.double_grasps import DoubleGraspsLayer, pair_labels
from workbench.layers.exchange import ExchangeLayer, cost_colors, palm_routes
from workbench.layers.grasp_configs import KEPT_COLOR, REMOVED_COLOR, GraspConfigsLayer, grasp_colors

ONLINE = ("grasp_configs", "exchange", "double_grasps")
pytestmark = pytest.mark.browser


def _focus(wb: Workbench, page: Page, step: str) -> None:
    """Put `step` in focus in the Steps tab (its controls under the table), the online layers shown again after."""
    _tab(page, "Steps")
    wb.session_panel.step.value = step
    for name in ONLINE if wb.layer_toggles is not None else ():
        if name in wb.layer_toggles.boxes:
            wb.layer_toggles.boxes[name].value = True


def _robot_to_exchange(wb: Workbench, page: Page, layer: DoubleGraspsLayer) -> None:
    """From the initial configuration, click "exchange" in the Double grasps folder: the robot must go to the pair's q_exch."""
    wb.reset()
    _focus(wb, page, "double_grasps")
    before = _settled(page)
    page.get_by_role("button", name="exchange", exact=True).click()
    assert layer.result is not None
    assert _wait_for(lambda: np.allclose(wb.q, layer.result.q_exch[layer.index]), 10), "the click did not pose the robot"
    assert _until_changed(page, before) > CHANGED, "the robot at q_exch looks as at the initial configuration"


@pytest.fixture(scope="module")
def workbench(tmp_path_factory) -> Iterator[Workbench]:
    folder = tmp_path_factory.mktemp("sessions") / "example"
    shutil.copytree(EXAMPLE, folder)
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=folder.parent)
    wb.session_layers.layers["roadmap"].visible = False  # thousands of edges: software WebGL takes seconds a frame
    for name in ONLINE:  # only the last step's layer (motion) is shown at first: these tests look at the online steps
        wb.layer_toggles.boxes[name].value = True
    yield wb
    wb.close()


def test_layer_helpers() -> None:
    """Palm colours by how far a grasp got; cost colours cheap to expensive; each palm's route passes the exchange."""
    colors = grasp_colors(np.array([True, True, False]), np.array([1]))
    assert tuple(colors[1]) == KEPT_COLOR and tuple(colors[2]) == REMOVED_COLOR and tuple(colors[0]) != KEPT_COLOR
    ramp = cost_colors(np.array([1.0, 2.0, 3.0])).astype(int)
    assert ramp[0].sum() > ramp[1].sum() > ramp[2].sum(), "cheap nodes should be bright, expensive ones dark"
    w, x = np.arange(18.0).reshape(6, 3), np.array([9.0, 9.0, 9.0])
    picking, placing = palm_routes(w, x)
    assert np.allclose(picking[1, 1], x) and np.allclose(placing[0, 1], x)
    assert np.allclose(picking[0, 0], w[0]) and np.allclose(picking[-1, 1], w[2])
    assert np.allclose(placing[0, 0], w[3]) and np.allclose(placing[-1, 1], w[5])


def test_online_layers_are_drawn(workbench: Workbench, page: Page) -> None:
    """The example's three online steps have layers; the exchange grid is on screen (hiding it, or showing all its free
    nodes, changes the view)."""
    assert set(ONLINE) <= set(LAYERS)
    layers = workbench.session_layers.layers
    assert not workbench.session_layers.errors, workbench.session_layers.errors
    assert isinstance(layers["grasp_configs"], GraspConfigsLayer) and isinstance(layers["exchange"], ExchangeLayer)
    assert isinstance(layers["double_grasps"], DoubleGraspsLayer)
    _focus(workbench, page, "double_grasps")
    page.get_by_text("Pair 1", exact=False).first.wait_for(timeout=10_000)
    _focus(workbench, page, "exchange")
    page.get_by_text("Exchange position").first.wait_for(timeout=10_000)
    shown = _settled(page)
    layers["exchange"].visible = False
    try:
        assert _until_changed(page, shown) > CHANGED, "hiding the exchange grid changed nothing on screen"
    finally:
        layers["exchange"].visible = True
    shown = _settled(page)
    layers["exchange"].shown.value = 100  # the whole free grid, not only its cheapest nodes
    try:
        assert _until_changed(page, shown) > CHANGED, "showing every free node changed nothing on screen"
    finally:
        layers["exchange"].shown.value = 10
    _settled(page)


def test_best_configurations_are_offered(workbench: Workbench) -> None:
    """The session panel's "Robot at" lists the best grasp / place configurations and pair 1's three configurations."""
    result = workbench.session.result("grasp_configs")
    options = workbench.pose_choice.dropdown.options
    best = int(np.argmax(result.pick_score))
    label = f"grasp configs: best pick (rank {result.pick_rank[best] + 1})"
    assert label in options and any(o.startswith("grasp configs: best place") for o in options)
    assert sum(o.startswith("double grasps: pair 1") for o in options) == 3
    workbench.pose_choice.dropdown.value = label
    try:
        assert np.allclose(workbench.q, result.pick_q[best])
    finally:
        workbench.reset()


def test_exchange_button_poses_the_robot_at_q_exch(workbench: Workbench, page: Page) -> None:
    layer = workbench.session_layers.layers["double_grasps"]
    assert layer.index == 0
    try:
        _robot_to_exchange(workbench, page, layer)
        assert np.allclose(workbench.q, workbench.session.result("double_grasps").q_exch[0])
        layer.pair.value = pair_labels(layer.result)[2]  # another pair: the robot follows, still at the exchange
        assert layer.index == 2 and np.allclose(workbench.q, layer.result.q_exch[2])
        layer.show_phase("place")
        assert np.allclose(workbench.q, layer.result.q_place[2])
    finally:
        layer.select(0)
        workbench.reset()


def test_double_grasps_run_from_the_gui_then_shown_at_the_exchange(browser: Browser, tmp_path: Path) -> None:
    """A session finished up to `exchange`: "Run up to this step" on double_grasps draws its layer; "exchange" poses the robot."""
    with _example_before(tmp_path, "double_grasps") as wb:
        folder = wb.session.folder
        assert "double_grasps" not in wb.session_layers.layers and "exchange" in wb.session_layers.layers
        page = _open(wb, browser)
        try:
            _run_up_to_from_the_gui(wb, page, "double_grasps")
            assert wb.session_panel.job is not None
            wb.session_panel.job.join(60)
            assert wb.session.finished()[-1] == "double_grasps" and wb.session.folder != folder
            layer = wb.session_layers.layers["double_grasps"]
            result = wb.session.result("double_grasps")
            assert layer.result is result and len(result) > 0, result.failure
            page.get_by_text("Pair 1", exact=False).first.wait_for(timeout=10_000)
            _robot_to_exchange(wb, page, layer)
            assert np.allclose(wb.q, result.q_exch[0])
        finally:
            page.close()
