"""The Playback tab in a real browser: the timeline runs in seconds with the keyframes marked and the phases as named
bands under it, the current phase is named above the object in the 3-D view, and Loop starts the motion again."""
from __future__ import annotations

import html
import shutil
from collections.abc import Iterator

import numpy as np
import pytest
from playwright.sync_api import Browser, Page
from test_workbench_browser import CHANGED, EXAMPLE, _free_port, _open, _settled, _tab, _until_changed, _wait_for

from workbench.app import Workbench
from workbench.layers.motion import MotionLayer
from workbench.layers.phases import phase_spans
from workbench.playback import sample_at, timeline_marks

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def workbench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workbench]:
    folder = tmp_path_factory.mktemp("sessions") / "example"
    shutil.copytree(EXAMPLE, folder)
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=folder.parent)
    for name, layer in wb.session_layers.layers.items():
        layer.visible = name == "motion"  # the roadmap's thousands of edges take software WebGL seconds a frame
    yield wb
    wb.close()


@pytest.fixture(scope="module")
def page(workbench: Workbench, browser: Browser) -> Iterator[Page]:
    page = _open(workbench, browser)
    _tab(page, "Playback")
    yield page
    page.close()


@pytest.fixture(scope="module")
def layer(workbench: Workbench) -> MotionLayer:
    layer = workbench.session_layers.layers["motion"]
    assert isinstance(layer, MotionLayer) and layer.playback is not None
    return layer


def test_timeline_shows_seconds_and_phases(workbench: Workbench, page: Page, layer: MotionLayer) -> None:
    """The timeline is labelled in seconds and ends at the motion's duration; the keyframes are marked; every phase the
    motion stores is named in the bands, in time order; End on the slider shows the last sample, named in the caption."""
    r = layer.result
    page.get_by_text("Time (s)", exact=True).wait_for(timeout=10_000)
    page.get_by_text(f"{r.duration:.1f} s", exact=True).first.wait_for(timeout=10_000)
    for mark in ("grasp", "exch", "place"):
        assert page.get_by_text(mark, exact=True).count() > 0, f"the keyframe mark {mark} is not on the timeline"
    names = [r.phase_name(k) for k, _, _ in phase_spans(r)]
    assert set(names) == set(r.phase_names[: int(r.phase.max()) + 1]) and len(names) >= 4
    bands = page.locator("span[title]").all_inner_texts()
    assert [b for b in bands if b in names] == names, f"the bands read {bands}, the phases are {names}"
    assert layer.playback.timeline.max == pytest.approx(round(r.duration, 2))
    page.get_by_role("slider", name="Time (s)").or_(page.get_by_role("slider")).first.focus()
    page.keyboard.press("End")
    assert _wait_for(lambda: layer.playback.index == len(r.t) - 1), "End did not move the timeline to the last sample"
    assert _wait_for(lambda: np.allclose(workbench.q, r.q[-1])), "the robot is not at the last sample"
    last = r.phase_name(int(r.phase[-1]))
    page.get_by_text(f"t = {r.t[-1]:.2f} s of {r.duration:.2f} s", exact=False).first.wait_for(timeout=10_000)
    assert html.unescape(layer.playback.now.content).startswith(f"**{last}**")
    assert layer.playback.label.text == f"{last} · {r.t[-1]:.1f} s"


def test_timeline_helpers(layer: MotionLayer) -> None:
    """The nearest sample to a time, and the marks' places, checked against the stored samples."""
    r = layer.result
    for i in (0, 1, len(r.t) // 2, len(r.t) - 1):
        assert sample_at(r.t, float(r.t[i])) == i
        assert sample_at(r.t, float(r.t[i]) + 1e-4) == i
    assert sample_at(r.t, -5.0) == 0 and sample_at(r.t, r.duration + 5.0) == len(r.t) - 1
    marks = dict((label, value) for value, label in timeline_marks(r))
    assert marks["exch"] == pytest.approx(r.t[r.keyframes[2]], abs=0.006) and marks["0 s"] == 0.0


def test_phase_label_moves_with_the_object_and_loop_restarts(workbench: Workbench, page: Page, layer: MotionLayer) -> None:
    """The phase label sits above the object's sample position and changes on screen with the phase; with Loop the
    playback goes past the end and on from the start."""
    playback, r = layer.playback, layer.result
    carry = int(np.flatnonzero(r.phase == list(r.phase_names).index("Carry"))[0])
    playback.seek(0)
    before = _settled(page)
    playback.seek(carry)
    assert playback.label.text.startswith("Carry")
    assert np.allclose(playback.label.position, playback.centres[carry] + (0, 0, 0.18), atol=1e-6)
    assert _until_changed(page, before) > CHANGED
    playback.seek(len(r.t) - 20)
    playback.loop.value = True
    playback.speed.value = 4.0
    try:
        page.get_by_role("button", name="Play", exact=True).click()
        assert _wait_for(lambda: playback.playing and playback.index < len(r.t) // 2, 30), "Loop did not start again"
        assert playback.playing, "the playback stopped at the end while looping"
    finally:
        playback.pause()
        playback.loop.value = False
        playback.speed.value = 1.0
        playback.seek(0)


def test_camera_follows_the_object(workbench: Workbench, page: Page, layer: MotionLayer) -> None:
    """With "Camera follows", moving the timeline moves the camera and the point it looks at by the object's move."""
    playback, r = layer.playback, layer.result
    carry = np.flatnonzero(r.phase == list(r.phase_names).index("Carry"))
    a, b = int(carry[0]), int(carry[len(carry) // 2])
    playback.seek(a)
    camera = next(iter(workbench.server.get_clients().values())).camera
    playback.follow.value = True
    try:
        look_at, position = np.array(camera.look_at), np.array(camera.position)
        playback.seek(b)
        shift = playback.centres[b] - playback.centres[a]
        assert np.linalg.norm(shift) > 0.05, "the object hardly moves in Carry"
        assert _wait_for(lambda: np.allclose(camera.look_at, look_at + shift, atol=2e-3)), "the camera did not follow"
        assert np.allclose(camera.position, position + shift, atol=2e-3)
    finally:
        playback.follow.value = False
        playback.seek(0)
