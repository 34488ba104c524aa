"""The workbench's WebSocket trusts no client (crafted messages sent over a raw WebSocket, as a hostile page or script
would), one run at a time however many clicks arrive together, and no scratch session left in the temp folder."""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgspec
import pytest
import viser
from test_workbench_browser import EXAMPLE, _free_port, _wait_for
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from planner.core.paths import DEFAULT_TASK
from planner.core.session import Session
from workbench import session_panel
from workbench.app import Workbench
from workbench.client_guard import origin_allowed

CAMERA = {"wxyz": [1.0, 0.0, 0.0, 0.0], "position": [2.0, 0.0, 1.5], "fov": 1.0, "near": 0.01, "far": 100.0,
          "image_height": 480, "image_width": 640, "look_at": [0.0, 0.0, 0.8], "up_direction": [0.0, 0.0, 1.0]}


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """tmp/sessions/good (a saved session: the example's first step) and tmp/outside, a session outside sessions/."""
    root = tmp_path_factory.mktemp("client")
    for folder in (root / "sessions" / "good", root / "outside"):
        Session.open(EXAMPLE).branch(folder, before="pick_grasps")
    (root / "secret.toml").write_text('name = "x"\napi_token_name_leaks = "s3cret"\n')
    return root


@pytest.fixture(scope="module")
def bench(folders: Path) -> Iterator[Workbench]:
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=folders / "sessions")
    yield wb
    wb.close()


def _connect(wb: Workbench, origin: str | None = None) -> ClientConnection:
    """A raw WebSocket client speaking viser's protocol, registered like a page (it sent its camera)."""
    port = wb.server.get_port()
    ws = connect(f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"], max_size=None,
                 additional_headers={"Origin": origin} if origin else None)
    _send(ws, "ViewerCameraMessage", **CAMERA)
    return ws


def _send(ws: ClientConnection, kind: str, **fields: Any) -> None:
    ws.send(msgspec.msgpack.encode({"type": kind, **fields}))


def _change(ws: ClientConnection, handle: Any, **updates: Any) -> None:
    _send(ws, "GuiUpdateMessage", uuid=handle._impl.uuid, updates=updates)


def _processed(ws: ClientConnection, wb: Workbench, marker: float) -> None:
    """Send an innocent change (the seed) after the crafted ones and wait until it is applied: the ones before it were
    handled by then (one connection's messages are handled in order)."""
    _change(ws, wb.session_panel.seed, value=marker)
    assert _wait_for(lambda: wb.session_panel.seed.value == marker), "the marker change never arrived"


def _refusals(caplog: pytest.LogCaptureFixture) -> list[str]:
    lines = [r.getMessage() for r in caplog.records if r.name == "regrasp.workbench"]
    assert all("\n" not in line for line in lines) and not any(r.exc_info for r in caplog.records)
    return lines


@pytest.mark.slow
def test_dropdown_values_outside_their_options_are_refused(bench: Workbench, folders: Path,
                                                           caplog: pytest.LogCaptureFixture) -> None:
    panel = bench.session_panel
    assert panel.saved.options == ("good",) and panel.saved.value == "good"
    with _connect(bench) as ws, caplog.at_level(logging.WARNING):
        _change(ws, panel.saved, value="../outside")
        _change(ws, panel.saved, options=["../outside"], value="../outside")  # a client must not rewrite the options
        _change(ws, bench.task_tab.choice, value="no such task")
        _processed(ws, bench, 11)
        assert panel.saved.value == "good" and panel.saved.options == ("good",)
        _change(ws, panel.load_button, value=True)  # Load: what is chosen, never the crafted value
        assert _wait_for(lambda: bench.session is not None, 60)
    assert bench.session.folder == folders / "sessions" / "good"
    lines = _refusals(caplog)
    assert len(lines) == 3 and all("ignored a change of" in line for line in lines), lines


@pytest.mark.slow
def test_disabled_controls_are_not_acted_on(bench: Workbench, caplog: pytest.LogCaptureFixture) -> None:
    panel = bench.session_panel
    bench._load(DEFAULT_TASK, None)
    assert bench.session is None
    panel.load_button.disabled = True
    try:
        with _connect(bench) as ws, caplog.at_level(logging.WARNING):
            _change(ws, panel.load_button, value=True)
            _change(ws, panel.load_button, disabled=False, value=True)  # nor enable it first
            _processed(ws, bench, 12)
            time.sleep(0.5)
        assert bench.session is None, "a click on a disabled button loaded a session"
        lines = _refusals(caplog)
        assert len(lines) == 2 and "the control is disabled" in lines[0] and "only a control's value may change" in lines[1], lines
    finally:
        panel.load_button.disabled = False


def test_values_of_the_wrong_type_are_one_line_not_a_traceback(bench: Workbench, caplog: pytest.LogCaptureFixture,
                                                                capfd: pytest.CaptureFixture[str]) -> None:
    panel = bench.session_panel
    with _connect(bench) as ws, caplog.at_level(logging.WARNING):
        _change(ws, panel.seed, value="not a number")
        _change(ws, bench.show_robot, value="yes")
        _change(ws, bench.task_tab.path, value="x" * 100_000)
        _send(ws, "ShareUrlRequest")  # would publish the workbench through viser's share server
        _processed(ws, bench, 13)
    assert len(_refusals(caplog)) == 4
    assert "Traceback" not in capfd.readouterr().err
    assert bench.show_robot.value is True and bench.server._share_tunnel is None


def test_task_file_reads_only_task_folders(bench: Workbench, folders: Path) -> None:
    scene = bench.scene
    with _connect(bench) as ws:
        _change(ws, bench.task_tab.path, value=str(folders / "secret.toml"))
        _change(ws, bench.task_tab.load_button, value=True)
        assert _wait_for(lambda: bench.task_tab.error.visible)
    assert bench.scene is scene and "expected a .toml file in" in bench.task_tab.error.content.replace("&#46;", ".")
    assert "api" not in bench.task_tab.error.content
    bench.task_tab.error.visible = False


def test_foreign_origins_are_refused(bench: Workbench, caplog: pytest.LogCaptureFixture) -> None:
    port = bench.server.get_port()
    with _connect(bench, f"http://127.0.0.1:{port}") as ws:  # the workbench's own page
        _processed(ws, bench, 14)
    with caplog.at_level(logging.WARNING), pytest.raises(ConnectionClosed) as closed:
        with _connect(bench, "http://evil.example") as ws:
            _change(ws, bench.session_panel.seed, value=15)
            while True:
                ws.recv(timeout=10)
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
    time.sleep(0.5)
    assert bench.session_panel.seed.value == 14
    assert [line for line in _refusals(caplog) if "evil.example" in line]


@pytest.mark.parametrize(("origin", "host", "bound", "allowed"), [
    (None, "127.0.0.1:8080", "127.0.0.1", True),  # not a browser
    ("http://127.0.0.1:8080", "127.0.0.1:8080", "127.0.0.1", True),
    ("http://localhost:8080", "localhost:8080", "127.0.0.1", True),
    ("http://evil.example", "127.0.0.1:8080", "127.0.0.1", False),
    ("http://evil.example:8080", "evil.example:8080", "127.0.0.1", False),  # DNS rebinding: a foreign name for this machine
    ("http://localhost:9999", "localhost:8080", "127.0.0.1", False),  # another local page
    ("null", "127.0.0.1:8080", "127.0.0.1", False),  # a sandboxed frame or a file
    ("http://10.1.2.3:8080", "10.1.2.3:8080", "0.0.0.0", True),  # served on every interface, opened by address
])
def test_origin_rule(origin: str | None, host: str, bound: str, allowed: bool) -> None:
    assert origin_allowed(origin, host, bound) is allowed


@pytest.fixture
def counted_runs(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[list[int], threading.Event]]:
    """Runs started from the panel count themselves and wait on the event instead of planning."""
    runs: list[int] = []
    gate = threading.Event()

    def counting(session: Session, until: str, params: Any, progress: Any) -> list:  # stands in for run_pipeline
        runs.append(1)
        assert gate.wait(120), "the test never let the run finish"
        return []
    monkeypatch.setattr(session_panel, "run_pipeline", counting)
    yield runs, gate
    gate.set()


def _together(n: int, call: Callable[[], Any]) -> None:
    barrier = threading.Barrier(n)
    threads = [threading.Thread(target=lambda: (barrier.wait(), call())) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)


def test_eight_clicks_at_once_start_one_run(folders: Path, counted_runs: tuple[list[int], threading.Event]) -> None:
    runs, gate = counted_runs
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=folders / "sessions")
    try:
        _together(8, wb.session_panel.run_next)  # what 8 "Run the next step" callbacks do at once
        gate.set()
        job = wb.session_panel.job
        assert job is not None
        job.join(60)
        assert len(runs) == 1
    finally:
        wb.close()


def test_scratch_sessions_are_deleted(folders: Path, counted_runs: tuple[list[int], threading.Event]) -> None:
    _, gate = counted_runs
    gate.set()
    wb = Workbench(DEFAULT_TASK, "127.0.0.1", _free_port(), sessions_dir=folders / "sessions")
    try:
        panel = wb.session_panel
        panel.run_until("arms").join(60)
        first = panel.scratch
        assert first is not None and first.is_dir()
        assert panel.load(folders / "sessions" / "good")
        assert not first.parent.exists(), "the scratch session replaced by a loaded one was kept"
        panel.run_until("pick_grasps").join(60)  # a new scratch: a copy of the loaded session
        second = panel.scratch
        assert second is not None and second.is_dir() and second != first
    finally:
        wb.close()
    assert not second.parent.exists(), "closing the workbench left its scratch session"
