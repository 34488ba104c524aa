"""Sessions in the workbench: replay in a real browser, bad sessions, save without overwriting, re-run, HTML export."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from playwright.sync_api import Browser, Page
from test_workbench_browser import CHANGED, EXAMPLE, VIEWPORT, _free_port, _settled, _tab, _until_changed, _view, _wait_for

from planner.core.errors import RegraspError
from planner.core.paths import DEFAULT_TASK
from planner.core.session import MANIFEST, Session
from planner.pipeline import PIPELINE
from workbench.app import Workbench
from workbench.export import export_html
from workbench.layers import LAYERS

MAX_HTML_BYTES = 30_000_000


def _coloured(view: np.ndarray) -> float:
    """Fraction of clearly coloured (not grey) pixels: the empty viewer and its grid are grey, the desk and layers are not."""
    return float((view.max(axis=2) - view.min(axis=2) > 60).mean())


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def example() -> Session:
    """The repo's example session (regenerate it with the command in README.md if this fails)."""
    return Session.open(EXAMPLE)


@pytest.fixture(scope="module")
def sessions_dir(tmp_path_factory) -> Path:
    """A private sessions folder: a copy of the example, its first step alone (quick to re-run), a broken copy."""
    folder = tmp_path_factory.mktemp("sessions")
    shutil.copytree(EXAMPLE, folder / "example")
    Session.open(EXAMPLE).branch(folder / "first", before=PIPELINE[1].name)
    shutil.copytree(EXAMPLE, folder / "broken")
    npz = folder / "broken" / f"{PIPELINE[0].name}.npz"
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    return folder


@pytest.fixture(scope="module")
def workbench(sessions_dir: Path, example: Session) -> Iterator[Workbench]:
    wb = Workbench(None, "127.0.0.1", _free_port(), session=sessions_dir / "example", sessions_dir=sessions_dir)
    yield wb
    wb.close()


@pytest.mark.browser
def test_regrasp_replay_draws_the_saved_results(browser: Browser, example: Session) -> None:
    """`regrasp replay` on the example: the step table is in the page and hiding the step layers changes the view."""
    port = _free_port()
    server = subprocess.Popen([sys.executable, "-m", "workbench.cli", "replay", str(EXAMPLE), "--port", str(port)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    page = browser.new_page(viewport=VIEWPORT)
    try:
        end = time.monotonic() + 60
        while True:
            try:
                page.goto(f"http://127.0.0.1:{port}")
                break
            except Exception:
                assert server.poll() is None and time.monotonic() < end, "regrasp replay did not start"
                time.sleep(0.5)
        page.get_by_text("Collisions:").wait_for(timeout=60_000)
        picking = example.result("arms").picking_arm
        _tab(page, "Steps")
        page.get_by_text(f"picking_arm={picking}").wait_for(timeout=10_000)
        _tab(page, "View")
        with_layers = _settled(page)
        page.get_by_label("Show step results").click()
        assert _until_changed(page, with_layers) > CHANGED, "hiding the saved step results changed nothing on screen"
    finally:
        page.close()
        server.terminate()
        server.wait(timeout=20)


@pytest.mark.browser
def test_robot_goes_to_a_witness_configuration(workbench: Workbench, page: Page, example: Session) -> None:
    layers = workbench.session_layers.layers.values()
    for layer in layers:  # the robot alone in view: the step layers' drawings (the motion's routes) cover parts of it
        layer.visible = False
    before = _settled(page)
    label = next(o for o in workbench.pose_choice.dropdown.options if "q_pick" in o)
    workbench.pose_choice.dropdown.value = label
    try:
        assert _wait_for(lambda: np.allclose(workbench.q, example.result("arms").q_pick))
        assert _until_changed(page, before) > CHANGED, "posing the robot at q_pick changed nothing on screen"
    finally:
        workbench.reset()
        for layer in layers:
            layer.visible = True


@pytest.mark.browser
def test_export_button_downloads_what_is_shown(page: Page) -> None:
    _tab(page, "Task")
    with page.expect_download(timeout=120_000) as download:  # the example's motion is recorded frame by frame
        page.get_by_role("button", name="Export HTML").click(timeout=120_000)
    html = Path(download.value.path()).read_text()
    assert "__VISER_EMBED_DATA__" in html and len(html) < MAX_HTML_BYTES


@pytest.mark.browser
def test_bad_session_shows_its_error_and_the_workbench_stays_usable(workbench: Workbench, page: Page,
                                                                   sessions_dir: Path) -> None:
    panel = workbench.session_panel
    shown = workbench.session
    panel.saved.value = "broken"
    _tab(page, "Task")
    # the click is done when the button is pressed: waiting for "scheduled navigations" after it (there are none) stalled
    # 30 s in CI while software WebGL rendered the session; what the click does is waited for below. Pressing it can
    # itself wait over 30 s for the page's busy main thread on a loaded 2-core machine (seen with the full suite running)
    page.get_by_role("button", name="Load", exact=True).click(no_wait_after=True, timeout=120_000)
    page.get_by_text("Could not load the session").first.wait_for(timeout=60_000)
    assert page.get_by_text("truncated or corrupt").count() > 0
    assert workbench.session is shown, "a bad session replaced the shown one"
    panel.name.value = "before-the-load"  # the load sets the name last: once it reads "example", the load is over
    panel.saved.value = "example"
    page.get_by_role("button", name="Load", exact=True).click(no_wait_after=True, timeout=120_000)
    assert _wait_for(lambda: workbench.session is not shown and workbench.session.folder == sessions_dir / "example", 30)
    assert _wait_for(lambda: panel.name.value == "example", 30), "the panel did not follow the loaded session"


@pytest.mark.browser
def test_save_never_overwrites_without_confirmation(workbench: Workbench, page: Page, sessions_dir: Path) -> None:
    target = sessions_dir / "taken"
    target.mkdir()
    (target / "notes.txt").write_text("keep me")
    before = _files(target)
    panel = workbench.session_panel
    panel.name.value = "taken"  # no load is still going: the test before waits for its end
    dialog = page.get_by_text("Overwrite sessions/taken?")
    _tab(page, "Task")
    page.get_by_role("button", name="Save", exact=True).click()
    dialog.wait_for(timeout=60_000)  # software rendering under a loaded CI machine can be slow to draw the modal
    page.get_by_role("button", name="Cancel").click()
    time.sleep(0.5)
    assert _files(target) == before
    with pytest.raises(RegraspError, match="already exists"):
        workbench.session_panel.save("taken")
    with pytest.raises(RegraspError, match="holds no session"):
        workbench.session_panel.save("taken", overwrite=True)
    assert _files(target) == before
    saved = workbench.session_panel.save("fresh")
    assert _files(saved.folder) == _files(workbench.session.folder)


@pytest.mark.slow  # 4-6 s: kept out of the fast subset (CI runs it)
def test_rerun_from_here_makes_a_new_session_and_keeps_the_original(workbench: Workbench, sessions_dir: Path) -> None:
    panel = workbench.session_panel
    assert panel.load(sessions_dir / "first")
    original = workbench.session.folder
    before = _files(original)
    panel.rerun_step.value = "arms"
    assert panel._params is not None
    seeds = panel._params.values()["seeds"]
    panel._params.handles["seeds"].value = seeds + 8
    job = panel.rerun("arms", panel._params.values())
    assert job is not None
    job.join(300)
    new = workbench.session
    assert new.folder == sessions_dir / "first-rerun-1", panel.message.content
    assert new.record_of("arms")["params"]["seeds"] == seeds + 8
    assert Session.open(new.folder).finished() == ["arms"]
    assert _files(original) == before, "re-running changed the loaded session's files"


@pytest.mark.slow
def test_run_next_step_from_a_task(workbench: Workbench, monkeypatch: pytest.MonkeyPatch) -> None:
    """With no session, "run the next step" starts a scratch session, shows progress and draws the result."""
    panel = workbench.session_panel
    workbench._load(DEFAULT_TASK, None)
    assert workbench.session is None
    seen: list[float] = []

    class Bar:  # stands in for the progress bar, recording what the run shows on it
        visible = False

        @property
        def value(self) -> float:
            return seen[-1] if seen else 0.0

        @value.setter
        def value(self, v: float) -> None:
            seen.append(v)

    monkeypatch.setattr(panel, "progress", Bar())
    job = panel.run_next()
    assert job is not None
    job.join(300)
    first = PIPELINE[0].name
    assert workbench.session is not None and workbench.session.finished() == [first], panel.message.content
    assert workbench.session.folder.parent.parent != workbench.session_panel.sessions_dir
    assert seen and seen[-1] == 100 and len(seen) > 2, seen
    assert f"| {first} | done" in panel.table.content
    assert first in LAYERS and first in workbench.session_layers.layers


@pytest.mark.browser
def test_export_html_is_self_contained(example: Session, tmp_path: Path, browser: Browser) -> None:
    out = tmp_path / "example.html"
    export_html(EXAMPLE, out)
    html = out.read_text()
    assert 100_000 < len(html) < MAX_HTML_BYTES
    assert "__VISER_EMBED_DATA__" in html
    assert not re.search(r"""<(script|link)[^>]+(src|href)\s*=\s*["']?(https?:)?//""", html), "the HTML loads something from the network"
    page = browser.new_page(viewport=VIEWPORT)
    requests: list[str] = []
    page.route(re.compile(r"^(https?|wss?)://.*"), lambda route: (requests.append(route.request.url), route.abort()))
    try:
        page.goto(out.as_uri())
        assert _wait_for(lambda: _coloured(_view(page)) > 0.01, 30), "the exported page draws nothing offline"
    finally:
        page.close()
    assert not requests, f"the exported page asked the network for {requests}"


def test_replay_of_a_bad_session_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    shutil.copytree(EXAMPLE, bad)
    manifest = json.loads((bad / MANIFEST).read_text())
    manifest["format_version"] = 99
    (bad / MANIFEST).write_text(json.dumps(manifest))
    run = subprocess.run([sys.executable, "-m", "workbench.cli", "replay", str(bad), "--port", str(_free_port())],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "newer regrasp" in run.stderr and "Traceback" not in run.stderr
