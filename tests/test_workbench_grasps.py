"""The grasp-list layers in a real browser: the example's lists drawn, a rank chosen in the GUI redraws the hand
and shows its scores; a list computed from the GUI ("Run up to this step") gets its layer too."""
from __future__ import annotations

import shutil
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

from planner.core.session import Session
from workbench.app import Workbench
from workbench.layers import LAYERS
from workbench.layers.grasps import CONE_STYLE, CONTACT_COLOR, NORMAL_COLOR, GraspsLayer, friction_cones, legend

pytestmark = pytest.mark.browser


def _look_at_object(wb: Workbench, layer: GraspsLayer) -> None:
    """Hide the robot and the other step layers, and bring every client's camera close to the object the layer draws on."""
    wb.show_robot.value = False
    for other in wb.session_layers.layers.values():
        other.visible = other is layer
    T = wb.scene.object_initial if layer.placement == "initial" else wb.scene.object_final
    centre = T[:3, :3] @ np.asarray(wb.scene.object_mesh.center_mass) + T[:3, 3]
    assert _wait_for(lambda: len(wb.server.get_clients()) > 0)
    for client in wb.server.get_clients().values():
        client.camera.position = tuple(centre + (0.25, -0.25, 0.2))
        client.camera.look_at = tuple(centre)
        client.camera.up_direction = (0.0, 0.0, 1.0)


def _choose_rank(page: Page, layer: GraspsLayer, rank: int) -> None:
    """Put the layer's step in focus (its folder under the step table), open the folder and pick a rank in its dropdown,
    as a user would."""
    assert layer.folder is not None and layer.rank is not None
    _tab(page, "Steps")
    if layer.workbench.session_panel.step.value != layer.step:
        layer.workbench.session_panel.step.value = layer.step
        for other in layer.workbench.session_layers.layers.values():
            other.visible = other is layer
    folder = page.get_by_text(layer.folder.label, exact=True)
    folder.wait_for(timeout=10_000)
    if not page.get_by_text("Finger sphere hierarchies").first.is_visible():
        folder.click()
    label = layer.rank_labels(layer.result)[rank]
    page.get_by_role("textbox", name="Rank").or_(page.get_by_label("Rank")).first.click()
    page.get_by_role("option", name=label, exact=True).click()


def test_legend_names_each_mark_in_its_colour() -> None:
    """The legend shows the contacts', normals' and cones' colours next to their names, the cone's half-angle from μ,
    and each finger's name (escaped)."""
    text = legend(0.5, ("thumb", "<b>index</b>"))
    for color, name in ((CONTACT_COLOR, "contact point"), (NORMAL_COLOR, "surface normal"), (CONE_STYLE[0], "friction cone")):
        swatch = f"rgb({color[0]},{color[1]},{color[2]})"
        assert swatch in text and text.index(swatch) < text.index(name), name
    assert "27°" in text  # atan 0.5
    assert "thumb" in text and "<b>" not in text


def test_friction_cone_geometry() -> None:
    """Apex at the contact, opening along the normal with half-angle atan(mu)."""
    point, normal = np.array([[0.1, 0.2, 0.3]]), np.array([[0.0, 1.0, 0.0]])
    cone = friction_cones(point, normal, mu=0.5, height=0.02)
    rel = cone.vertices - point[0]
    assert rel[:, 1].min() > -1e-9 and np.isclose(rel[:, 1].max(), 0.02)
    radial = np.linalg.norm(rel[:, [0, 2]], axis=1)
    assert np.all(radial <= 0.5 * rel[:, 1] + 1e-9)


def test_example_grasp_lists_are_drawn_and_a_rank_is_chosen_in_the_browser(browser: Browser, tmp_path: Path) -> None:
    folder = tmp_path / "example"
    shutil.copytree(EXAMPLE, folder)
    session = Session.open(folder)
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=tmp_path)
    try:
        assert {"pick_grasps", "place_grasps"} <= set(LAYERS)
        assert not wb.session_layers.errors, wb.session_layers.errors
        layers = wb.session_layers.layers
        assert isinstance(layers["pick_grasps"], GraspsLayer) and isinstance(layers["place_grasps"], GraspsLayer)
        pick = layers["pick_grasps"]
        result = session.result("pick_grasps")
        assert pick.shown_rank == 0 and len(result) > 4
        page = _open(wb, browser)
        try:
            _look_at_object(wb, pick)
            before = _settled(page)
            _choose_rank(page, pick, 4)
            assert _wait_for(lambda: pick.shown_rank == 4, 10), "choosing a rank in the browser did not reach the layer"
            assert _until_changed(page, before) > CHANGED, "choosing another grasp changed nothing on screen"
            eps = f"{result.epsilon[4]:.4f}"
            assert f"| epsilon | {eps} |" in pick.scores.content
            page.get_by_text("Rank 5", exact=False).first.wait_for(timeout=10_000)
            assert page.get_by_role("cell", name=eps, exact=True).count() > 0, "the scores table does not show rank 5's epsilon"
            # on request, what the search worked on: the object's point set, the finger sphere hierarchies in the hand frame
            without_points = _settled(page)
            page.get_by_label("Object point set").first.click()
            assert _until_changed(page, without_points) > CHANGED, "showing the object's point set changed nothing"
            with_spheres = _settled(page)
            page.get_by_label("Finger sphere hierarchies").first.click()
            assert _until_changed(page, with_spheres) > CHANGED, "showing the finger sphere hierarchies changed nothing"
        finally:
            page.close()
        # a redraw of the session replaces the layers' GUI instead of piling it up
        wb._draw_session(wb.session)
        assert pick.folder is None and wb.session_layers.layers["pick_grasps"].folder is not None
    finally:
        wb.close()


def test_grasp_list_computed_from_the_gui_then_a_grasp_selected(browser: Browser, tmp_path: Path) -> None:
    """A session with only `arms`: "Run up to this step" on pick_grasps (progress bar), then a rank chosen in the browser."""
    with _example_before(tmp_path, "pick_grasps") as wb:
        assert "pick_grasps" not in wb.session_layers.layers
        page = _open(wb, browser)
        try:
            _run_up_to_from_the_gui(wb, page, "pick_grasps")
            layer = wb.session_layers.layers["pick_grasps"]
            assert wb.session.finished() == ["arms", "pick_grasps"]
            _look_at_object(wb, layer)
            before = _settled(page)
            _choose_rank(page, layer, 2)
            assert _wait_for(lambda: layer.shown_rank == 2, 10)
            assert _until_changed(page, before) > CHANGED, "choosing another grasp changed nothing on screen"
            eps = f"{wb.session.result('pick_grasps').epsilon[2]:.4f}"
            assert page.get_by_role("cell", name=eps, exact=True).count() > 0
        finally:
            page.close()
