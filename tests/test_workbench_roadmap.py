"""The roadmap layer in a real browser: the Super Graph is drawn, a picked node poses the robot, a query animates its path."""
from __future__ import annotations

import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from playwright.sync_api import Page
from test_workbench_browser import CHANGED, EXAMPLE, _changed, _free_port, _settled, _tab, _until_changed, _view, _wait_for

from planner.core.session import Session
from planner.roadmap.build import wrist_positions
from planner.roadmap.result import Roadmap
from workbench.app import Workbench
from workbench.layers.roadmap import JOINT_STEP, MOVE_BUDGET, SHOWN, RoadmapLayer, edge_colors, wrist_segments

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def workbench(tmp_path_factory) -> Iterator[Workbench]:
    folder = tmp_path_factory.mktemp("sessions") / "example"
    shutil.copytree(EXAMPLE, folder)
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=folder.parent)
    wb.focus_step("roadmap")  # hidden at first (only the last step, motion, is shown)
    yield wb
    wb.close()


@pytest.fixture(scope="module")
def layer(workbench: Workbench) -> RoadmapLayer:
    assert workbench.session_layers is not None and not workbench.session_layers.errors
    layer = workbench.session_layers.layers["roadmap"]
    assert isinstance(layer, RoadmapLayer)
    return layer


def _node_in_largest(layer: RoadmapLayer) -> int:
    """The node of the largest component whose wrists are farthest from the initial configuration's, among those with
    both wrists in front of the robot and below its head (in the camera's view): clearly visible."""
    roadmap = layer.roadmap
    comp = roadmap.node_component
    nodes = np.flatnonzero(comp == np.argmax(np.bincount(comp)))
    wrists = roadmap.wrists[nodes]
    nodes = nodes[np.all((wrists[..., 0] > 0.1) & (wrists[..., 2] < 1.4), axis=1)]
    initial = wrist_positions(layer.scene.robot, layer.scene.q_initial[None])[0]
    return int(nodes[np.argmax(np.linalg.norm(roadmap.wrists[nodes] - initial, axis=2).sum(axis=1))])


@contextmanager
def _super_graph_hidden(page: Page, layer: RoadmapLayer) -> Iterator[float]:
    """The layer hidden while a test looks at the robot alone (software WebGL takes seconds per frame of the Super
    Graph's thousands of lines, and the robot's pixels are what these tests compare); yields the fraction of the view
    that hiding it changed."""
    shown = _view(page)
    layer.visible = False
    try:
        yield _until_changed(page, shown)
    finally:
        layer.visible = True


def test_each_wrist_move_is_drawn_once_in_its_most_prominent_colour() -> None:
    """The example's segments are exactly the distinct moves of a wrist along an edge (either direction, zero-length
    ones left out), each once, coloured as the valid edge of the largest component that makes it (a plain loop)."""
    roadmap = Session.open(EXAMPLE).result("roadmap")
    assert isinstance(roadmap, Roadmap)
    colors = edge_colors(roadmap)
    sizes = {c: int(n) for c, n in enumerate(np.bincount(roadmap.node_component))}
    best: dict[frozenset, tuple] = {}
    for e, (i, j) in enumerate(roadmap.edges.tolist()):
        for w in range(roadmap.wrists.shape[1]):
            a, b = tuple(roadmap.wrists[i, w]), tuple(roadmap.wrists[j, w])
            if a == b:
                continue
            size = sizes[int(roadmap.node_component[i])]
            key = (not roadmap.edge_valid[e], -size, sum(sizes[c] == size for c in range(int(roadmap.node_component[i]))))
            old = best.get(frozenset((a, b)))
            if old is None or key < old[0]:
                best[frozenset((a, b))] = (key, tuple(colors[e, w]))
    points, drawn, edge = wrist_segments(roadmap)
    for p, (i, j) in zip(points, roadmap.edges[edge]):  # each move is one of its edge's wrist moves
        ends = frozenset(map(tuple, p))
        assert any(frozenset((tuple(roadmap.wrists[i, w]), tuple(roadmap.wrists[j, w]))) == ends
                   for w in range(roadmap.wrists.shape[1])), "a move's edge does not make it"
    segments = [frozenset((tuple(p[0]), tuple(p[1]))) for p in points]
    assert len(set(segments)) == len(segments), "a move is drawn twice"
    assert set(segments) == set(best)
    assert len(segments) < 0.7 * len(roadmap.edges) * roadmap.wrists.shape[1]
    for seg, color in zip(segments, drawn):
        assert tuple(color) == best[seg][1]


def test_super_graph_is_drawn(workbench: Workbench, page: Page, layer: RoadmapLayer) -> None:
    _tab(page, "Steps")
    page.get_by_text("Super Graph:").wait_for(timeout=10_000)
    _settled(page)
    with _super_graph_hidden(page, layer) as changed:
        assert changed > CHANGED, "hiding the Super Graph changed nothing on screen"


def test_a_decimated_view_first_and_more_on_request(workbench: Workbench, page: Page, layer: RoadmapLayer) -> None:
    """At first at most MOVE_BUDGET wrist moves are drawn, spread over every component; "Moves drawn" at its end (End
    pressed in the browser) draws them all; one component at a time draws only that component's moves."""
    roadmap, total = layer.roadmap, len(wrist_segments(layer.roadmap)[0])
    assert total > MOVE_BUDGET, "the example's Super Graph is small: nothing to decimate"
    first = layer.moves_drawn()
    assert len(first) == MOVE_BUDGET and len(np.unique(first)) == len(first)
    edge = wrist_segments(roadmap)[2]
    with_moves = np.unique(roadmap.node_component[roadmap.edges[edge, 0]])
    drawn = np.unique(roadmap.node_component[roadmap.edges[edge[first], 0]])
    largest_moves = np.argmax(np.bincount(roadmap.node_component[roadmap.edges[edge, 0]]))
    assert set(drawn) <= set(with_moves) and largest_moves in drawn, "the largest component's moves come first"
    _tab(page, "Steps")
    page.get_by_text(f"Drawn: {MOVE_BUDGET} of {total} wrist moves").wait_for(timeout=10_000)
    try:
        page.get_by_role("slider").nth(0).focus()  # the Roadmap folder's first slider: "Moves drawn"
        page.keyboard.press("End")
        assert _wait_for(lambda: len(layer.moves_drawn()) == total, 20), "End did not draw every move"
        page.get_by_text(f"Drawn: {total} of {total} wrist moves").wait_for(timeout=20_000)
        layer.shown_of.value = SHOWN[1]
        largest = np.argmax(np.bincount(roadmap.node_component))
        shown = layer.moves_drawn()
        assert set(roadmap.node_component[roadmap.edges[edge[shown], 0]]) == {largest}
        assert len(shown) == int(np.sum(roadmap.node_component[roadmap.edges[edge, 0]] == largest))
    finally:
        layer.shown_of.value = SHOWN[0]
        layer.budget.value = MOVE_BUDGET
    assert len(layer.moves_drawn()) == MOVE_BUDGET


def _answer_seconds(workbench: Workbench, page: Page, limit: float) -> float | None:
    """Seconds from a click on "Show robot" (View tab) until the workbench has it and a screenshot taken after it shows
    the robot gone (its completion: an upper bound of when the browser drew it); None: not within `limit`. The robot is
    shown again after."""
    try:
        before = _settled(page)
        start = time.monotonic()
        page.get_by_label("Show robot").click()
        while time.monotonic() - start < limit:
            if workbench.show_robot.value is False and _changed(_view(page), before) > CHANGED:
                return time.monotonic() - start
            time.sleep(0.05)
        return None
    finally:
        workbench.show_robot.value = True


def test_the_page_answers_within_2_s(workbench: Workbench, page: Page, layer: RoadmapLayer) -> None:
    """With the roadmap drawn as after its step (its first MOVE_BUDGET moves), a click on "Show robot" reaches the
    workbench and the browser draws the robot gone within 2 s (what a person waits for, measured as the browser sees
    it). Printed for docs/benchmarks.md: the same with the roadmap hidden."""
    assert layer.visible and len(layer.moves_drawn()) == MOVE_BUDGET
    _tab(page, "View")
    try:
        seconds = _answer_seconds(workbench, page, 2.0)
        assert seconds is not None and seconds <= 2.0, "the page did not answer the click within 2 s"
        layer.visible = False
        hidden = _answer_seconds(workbench, page, 60.0)
        print(f"answered in {seconds:.2f} s with {MOVE_BUDGET} moves drawn, in {hidden or float('nan'):.2f} s with the roadmap hidden")
    finally:
        layer.visible = True
        _tab(page, "Steps")


def test_picked_node_poses_the_robot(workbench: Workbench, page: Page, layer: RoadmapLayer) -> None:
    i = _node_in_largest(layer)
    with _super_graph_hidden(page, layer):
        before = _settled(page)
        layer.node.value = i
        try:
            assert _wait_for(lambda: np.allclose(workbench.q, layer.roadmap.node_q[i]))
            assert _until_changed(page, before) > CHANGED, "posing the robot at a node changed nothing on screen"
        finally:
            workbench.reset()


def test_query_animates_the_path_to_a_node(workbench: Workbench, page: Page, layer: RoadmapLayer,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    workbench.reset()
    i = _node_in_largest(layer)
    layer.node.value = i  # the robot goes to the node: bring it back, then plan there
    workbench.reset()
    with _super_graph_hidden(page, layer):
        _query_animates(workbench, page, layer, i, monkeypatch)


def _query_animates(workbench: Workbench, page: Page, layer: RoadmapLayer, i: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """'Plan to node' from the workbench's configuration to node i: the path is found, animated frame by frame without
    jumps, and ends at the node, on screen too."""
    before = _settled(page)
    posed: list[np.ndarray] = []
    pose = workbench.pose_robot
    monkeypatch.setattr(workbench, "pose_robot", lambda q, *where: (posed.append(np.array(q)), pose(q, *where)))
    _tab(page, "Steps")
    page.get_by_role("button", name="Plan to node").click()
    # "Path found" stays in the status while animating and after; the animation may finish between two polls
    assert _wait_for(lambda: "Path found" in layer.status.content or "No path" in layer.status.content, 120), layer.status.content
    assert "Path found" in layer.status.content, layer.status.content
    assert layer.last_query is not None and layer.last_query.found
    path = layer.last_query.path
    assert np.allclose(path[0], workbench.scene.q_initial) and np.allclose(path[-1], layer.roadmap.node_q[i])
    assert layer.job is not None
    layer.job.join(120)
    assert "Robot at node" in layer.status.content, layer.status.content
    assert np.allclose(workbench.q, layer.roadmap.node_q[i]), "the animation did not end at the node"
    assert len(posed) > len(path), "the path was not animated frame by frame"
    steps = np.abs(np.diff(np.array(posed), axis=0)).max(axis=1)
    assert steps.max() <= JOINT_STEP + 1e-9, "the animation jumps"
    assert _changed(_settled(page), before) > CHANGED, "the robot at the end of the path looks as at the start"
