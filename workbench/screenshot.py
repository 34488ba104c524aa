"""A picture of the workbench replaying a session, taken with headless Debian chromium (the README's image): the
Playback tab open and the robot mid-motion, at the handover (or, for a session without a motion, posed at its exchange)."""
from __future__ import annotations

import io
import socket
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image

from planner.core.errors import RegraspError

from .view import close_up, move_cameras

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page

    from .app import Workbench

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
    "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
]
VIEWPORT = {"width": 1600, "height": 1000}
COLORS = 160  # the PNG's palette: keeps the picture under MAX_BYTES
MAX_BYTES = 300_000
SETTLE_SECONDS = 60.0
POSE = "double grasps: pair 1 at exchange (q_exch)"  # without a motion: the robot handing the object over, if the session has it
MID_MOTION = "q_exch"  # the motion's keyframe shown: the robot handing the object over
DISTANCE = 1.7  # m from the exchange: the robot, the desk and both placements in view


def free_port() -> int:
    """A TCP port free on this machine right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _settled_png(page: Page, timeout: float = SETTLE_SECONDS) -> bytes:
    """A screenshot once two in a row agree (every mesh arrived and drawn)."""
    last, end = page.screenshot(), time.monotonic() + timeout
    while time.monotonic() < end:
        time.sleep(0.5)
        shot = page.screenshot()
        a, b = (np.asarray(Image.open(io.BytesIO(x)).convert("RGB"), dtype=np.int16) for x in (last, shot))
        if (np.abs(a - b).max(axis=2) > 24).mean() < 1e-4:
            return shot
        last = shot
    raise RegraspError(f"the workbench never finished drawing within {timeout:.0f} s")


def _mid_motion(wb: Workbench, page: Page) -> None:
    """Open the Playback tab with the motion at its handover keyframe, the other step layers hidden; a session without
    a motion shows the robot at its exchange instead."""
    from .layers.motion import MotionLayer
    from .playback import KEYFRAMES

    motion = wb.session_layers.layers.get("motion") if wb.session_layers is not None else None
    if isinstance(motion, MotionLayer) and motion.playback is not None:
        wb.session_panel.step.value = "motion"  # its layer alone in view
        page.get_by_role("tab", name="Playback").click()
        motion.playback.seek(int(motion.result.keyframes[KEYFRAMES.index(MID_MOTION)]))
    elif POSE in wb.pose_choice.dropdown.options:
        wb.pose_choice.dropdown.value = POSE


def screenshot(session: Path, out: Path, browser: Browser | None = None) -> int:
    """Replay `session` in a workbench, the robot at the exchange, photograph it in chromium into `out` (PNG); returns its
    bytes. Without `browser`, headless Debian chromium is started for it."""
    from playwright.sync_api import sync_playwright

    from .app import Workbench

    if browser is None:
        if not CHROMIUM.exists():
            raise RegraspError(f"chromium is not installed at {CHROMIUM} (apt-get install chromium)")
        with sync_playwright() as p:
            started = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            try:
                return screenshot(session, out, started)
            finally:
                started.close()
    wb = Workbench(None, "127.0.0.1", free_port(), session=session)
    try:
        page = browser.new_page(viewport=VIEWPORT)
        try:
            page.goto(wb.url)
            page.get_by_text("Collisions:").wait_for(timeout=60_000)
            wb.collision_ready.wait(60)
            for close in page.locator(".mantine-Notification-closeButton").all():  # e.g. "software WebGL": not the workbench's
                close.click()
            _mid_motion(wb, page)
            point = wb.exchange_point()
            if point is not None:
                for job in move_cameras(wb.server, *close_up(point, DISTANCE), seconds=0.1):
                    job.join()
            png = _settled_png(page)
        finally:
            page.close()
    finally:
        wb.close()
    buffer = io.BytesIO()
    Image.open(io.BytesIO(png)).convert("RGB").quantize(COLORS).save(buffer, format="PNG", optimize=True)
    if buffer.tell() > MAX_BYTES:
        raise RegraspError(f"the picture takes {buffer.tell() // 1024} kB, more than {MAX_BYTES // 1000} kB: lower COLORS")
    out.write_bytes(buffer.getvalue())
    return buffer.tell()
