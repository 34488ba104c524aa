"""The motion layer and the motion's HTML export in a real browser: the example's motion is played back from the saved
trajectory; the object's pixels follow the holding hand from a Carry sample to a Place sample; Play advances the timeline
(the joint sliders stay); the exported HTML page animates offline."""
from __future__ import annotations

import csv
import dataclasses
import html
import json
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from playwright.sync_api import Browser, Page
from test_workbench_browser import (
    CHANGED,
    EXAMPLE,
    VIEWPORT,
    _changed,
    _free_port,
    _object_pixels,
    _project,
    _settled,
    _tab,
    _until_changed,
    _view,
    _wait_for,
)

from planner.core.session import Session
from planner.motion.result import PHASE_SECONDS, PHASES, Motion
from workbench.app import Workbench
from workbench.export import EXPORT_FPS, MAX_FRAMES, frame_samples
from workbench.layers import LAYERS
from workbench.layers.motion import MotionLayer, route_segments, table_one
from workbench.layers.phases import PHASE_COLORS
from workbench.layers.stages import FAILURE_COLOR
from workbench.playback import sample_at

pytestmark = [pytest.mark.browser, pytest.mark.slow]
CARRY, PLACE = PHASES.index("Carry"), PHASES.index("Place")
NEAR = 30.0  # px: the object's pixels must be centred this close to where its saved pose projects


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A copy of the example session with its motion step (run here, resuming the copy, when the example has none)."""
    folder = tmp_path_factory.mktemp("sessions") / "example"
    shutil.copytree(EXAMPLE, folder)
    if "motion" not in Session.open(folder).finished():
        run = subprocess.run([sys.executable, "-m", "workbench.cli", "plan", "default", "--out", str(folder), "--resume"],
                             check=False, capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr[-2000:]
    return folder


@pytest.fixture(scope="module")
def workbench(folder: Path) -> Iterator[Workbench]:
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=folder.parent)
    for name, layer in wb.session_layers.layers.items():
        layer.visible = name == "motion"  # the roadmap's thousands of edges take software WebGL seconds a frame
    yield wb
    wb.close()


@pytest.fixture(scope="module")
def layer(workbench: Workbench) -> MotionLayer:
    assert workbench.session_layers is not None and not workbench.session_layers.errors, workbench.session_layers.errors
    layer = workbench.session_layers.layers["motion"]
    assert isinstance(layer, MotionLayer) and layer.result is not None
    assert not layer.result.failure and len(layer.result.t) > 2, layer.result.failure
    return layer


def _middle_held(result: Motion, phase: int) -> int:
    """The middle sample of `phase` among those where a hand holds the object."""
    samples = np.flatnonzero((result.phase == phase) & (result.holder >= 0))
    assert len(samples), f"no sample of {PHASES[phase]} has the object held"
    return int(samples[len(samples) // 2])


def _apart_held(workbench: Workbench, layer: MotionLayer, phases: tuple[int, int]) -> tuple[int, int]:
    """A sample of each phase, among the middle half of those where a hand holds the object, the two where the object
    projects farthest apart (the test needs it to move visibly, whichever path the planner found)."""
    r = layer.result
    middles, projected = [], []
    for phase in phases:
        samples = np.flatnonzero((r.phase == phase) & (r.holder >= 0))
        assert len(samples), f"no sample of {PHASES[phase]} has the object held"
        middles.append(samples[len(samples) // 4: max(3 * len(samples) // 4, len(samples) // 4 + 1)])
        projected.append(np.array([_project(workbench, _object_centre(layer, int(i))) for i in middles[-1]]))
    apart = np.linalg.norm(projected[0][:, None] - projected[1][None], axis=2)
    a, b = np.unravel_index(int(np.argmax(apart)), apart.shape)
    return int(middles[0][a]), int(middles[1][b])


def _object_on_screen(workbench: Workbench, page: Page) -> np.ndarray:
    """The centre (x, y px) of the pixels the workbench's object covers (the motion layer moves it)."""
    rows, cols = np.nonzero(_object_pixels(workbench, page))
    return np.array([cols.mean(), rows.mean()])


def _object_centre(layer: MotionLayer, i: int) -> np.ndarray:
    """The object's centre of mass at sample i, in the world, as the result saved it."""
    assert layer.result is not None
    T = layer.result.object_pose[i]
    return T[:3, :3] @ np.asarray(layer.scene.object_mesh.center_mass) + T[:3, 3]


def test_layer_helpers(layer: MotionLayer) -> None:
    """Route segments join consecutive wrist positions, coloured by phase; the export's frames stay within the rate and
    count limits and keep both ends; Table I carries the record's seconds."""
    r = layer.result
    points, colors = route_segments(r)
    n, wrists = len(r.t), r.wrists.shape[1]
    assert points.shape == colors.shape == ((n - 1) * wrists, 2, 3)
    assert np.allclose(points[0], r.wrists[:2, 0], atol=1e-6) and np.allclose(points[1], r.wrists[:2, 1], atol=1e-6)
    k = _middle_held(r, CARRY)
    assert tuple(colors[(k - 1) * wrists][0]) == PHASE_COLORS[CARRY]
    for t in (r.t, np.arange(5000) / 30.0, np.arange(3) / 30.0):
        s = frame_samples(t)
        assert s[0] == 0 and s[-1] == len(t) - 1 and len(s) <= MAX_FRAMES and np.all(np.diff(s) > 0)
        assert len(s) - 1 <= (t[-1] - t[0]) * EXPORT_FPS + 1
    seconds = layer.session.record_of("motion")["stage_seconds"]
    table = table_one(r, seconds)
    # per phase its stages, then the timing, the regrasp graph's search and the sequences planned
    assert len(seconds) == len(PHASE_SECONDS) * len(PHASES) + 3 and all(p in table for p in PHASES)
    assert f"{seconds[len(PHASE_SECONDS) + 1]:.3f}" in table  # the Carry phase's validation
    assert FAILURE_COLOR not in layer.summary(r)
    failed = layer.summary(dataclasses.replace(r, failure="Carry phase, transit: no path"))
    assert FAILURE_COLOR in failed and "Carry phase, transit: no path" in html.unescape(failed)


def test_motion_layer_is_drawn(workbench: Workbench, page: Page, layer: MotionLayer) -> None:
    """The layer is registered and drawn: Table I in the Steps tab, the timeline in the Playback tab saying that the robot
    is not at its sample (the replay shows it at the task's initial configuration)."""
    assert LAYERS["motion"] is MotionLayer
    _tab(page, "Steps")
    page.get_by_text("nodes validating").first.wait_for(timeout=10_000)
    _tab(page, "Playback")
    page.get_by_text("move the timeline or press Play", exact=False).first.wait_for(timeout=10_000)
    shown = _settled(page)
    layer.visible = False
    try:
        assert _until_changed(page, shown) > CHANGED, "hiding the motion layer (routes, object) changed nothing on screen"
    finally:
        layer.visible = True
    _settled(page)


def test_object_moves_with_the_hand(workbench: Workbench, page: Page, layer: MotionLayer) -> None:
    """At a Carry sample, then a Place sample, the robot is at the sample's configuration and the object's pixels sit where
    the saved object pose projects: they moved on screen with the holding hand."""
    r = layer.result
    samples = dict(zip((CARRY, PLACE), _apart_held(workbench, layer, (CARRY, PLACE))))
    centres = []
    try:
        for phase, i in samples.items():
            layer.playback.timeline.value = float(r.t[i])
            assert _wait_for(lambda i=i: np.allclose(workbench.q, r.q[i])), "the timeline did not pose the robot"
            assert PHASES[phase] in layer.playback.now.content and PHASES[phase] in layer.playback.label.text
            seen, expected = _object_on_screen(workbench, page), _project(workbench, _object_centre(layer, i))
            assert np.linalg.norm(seen - expected) < NEAR, f"{PHASES[phase]}: object seen at {seen}, its pose projects to {expected}"
            centres.append(seen)
        moved = np.linalg.norm(centres[1] - centres[0])
        expected = np.linalg.norm(_project(workbench, _object_centre(layer, samples[PLACE]))
                                  - _project(workbench, _object_centre(layer, samples[CARRY])))
        assert moved > 2 * NEAR and abs(moved - expected) < NEAR, f"the object moved {moved:.0f} px on screen, its poses {expected:.0f} px"
    finally:
        layer.playback.seek(0)


def test_play_advances_the_timeline(workbench: Workbench, page: Page, layer: MotionLayer) -> None:
    """Play moves the timeline on (robot meshes only: the joint sliders are not rebuilt); Pause stops it with the robot
    fully posed at the shown sample."""
    playback = layer.playback
    playback.seek(0)
    playback.speed.value = 4.0
    before = _settled(page)
    sliders = dict(workbench._slider_of)
    _tab(page, "Playback")
    page.get_by_role("button", name="Play", exact=True).click()
    try:
        assert _wait_for(lambda: playback.playing and playback.index > len(layer.result.t) // 4, 60), f"stuck at sample {playback.index}"
        assert sample_at(layer.result.t, playback.timeline.value) == playback.index and playback.play_button.label == "Pause"
        assert workbench._slider_of == sliders, "the joint sliders were rebuilt while playing"
        page.get_by_role("button", name="Pause", exact=True).click()
        assert _wait_for(lambda: not playback.playing, 10), "Pause did not stop the playback"
        shown = playback.index
        time.sleep(0.5)
        assert playback.index == shown, "the timeline moved after Pause"
        assert _wait_for(lambda: np.allclose(workbench.q, layer.result.q[shown])), "the robot is not at the shown sample"
        assert _changed(_settled(page), before) > CHANGED, "playing changed nothing on screen"
    finally:
        playback.pause()
        playback.speed.value = 1.0
        playback.seek(0)


def _scene(page: Page) -> np.ndarray:
    """The exported page's 3-D view without the notification at the top and the player bar at the bottom (its clock moves)."""
    return _view(page)[160:-60]


def test_exported_html_animates(page: Page, layer: MotionLayer, browser: Browser, tmp_path: Path) -> None:
    """"Export animation" downloads one HTML page that plays the motion offline: once drawn, its 3-D view keeps changing."""
    _tab(page, "Playback")
    with page.expect_download(timeout=180_000) as download:
        page.get_by_role("button", name="Export animation").click()
    out = tmp_path / "motion.html"
    download.value.save_as(out)
    html = out.read_text()
    assert "__VISER_EMBED_DATA__" in html and len(html) < 30_000_000
    exported = browser.new_page(viewport=VIEWPORT)
    try:
        exported.goto(out.as_uri())
        assert _wait_for(lambda: len(np.unique(_scene(exported).reshape(-1, 3), axis=0)) > 100, 60), "the exported page draws nothing"
        for _ in range(2):
            shot = _scene(exported)
            time.sleep(1.5)
            assert _wait_for(lambda shot=shot: _changed(_scene(exported), shot) > CHANGED, 20), "the exported page does not animate"
    finally:
        exported.close()


@pytest.mark.parametrize("label", ["JSON", "CSV"])
def test_trajectory_downloads_hold_the_saved_samples(page: Page, layer: MotionLayer, tmp_path: Path, label: str) -> None:
    """The Trajectory buttons download the motion: the JSON's positions, the CSV's position columns are motion.npz's q."""
    _tab(page, "Playback")
    with page.expect_download(timeout=60_000) as download:
        page.get_by_role("button", name=label, exact=True).click()
    out = tmp_path / download.value.suggested_filename
    download.value.save_as(out)
    assert out.suffix == f".{label.lower()}"
    if label == "JSON":
        q = [p["positions"] for p in json.loads(out.read_text())["points"]]
    else:
        header, *rows = list(csv.reader(out.open()))
        columns = [i for i, name in enumerate(header) if name.startswith("position:")]
        q = [[float(r[i]) for i in columns] for r in rows]
    assert np.array_equal(np.array(q), layer.result.q)


def test_playback_stops_when_the_layer_is_removed(workbench: Workbench, layer: MotionLayer) -> None:
    """Redrawing the session replaces the layer: its playback thread ends and leaves the robot alone."""
    playback = layer.playback
    job = playback.play()
    assert job is not None and _wait_for(lambda: playback.index > 0), "the playback did not start"
    workbench.show_session(workbench.session)
    job.join(10)
    assert not job.is_alive() and not playback.playing, "the playback outlived its layer"
    q = workbench.q.copy()
    time.sleep(0.5)
    assert np.array_equal(workbench.q, q) and workbench.session_layers.layers["motion"] is not layer
