"""The task check run live while a task is edited: `regrasp check`'s checks (reachability per arm, collisions) of the
latest edit, in one background thread, a short while after the edits stop (a drag sends many), shown as markdown.

Only the newest edit is checked: an edit made while a check runs replaces the one waiting, and a check finished after a
newer edit is not shown.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from planner.check import TaskReport, check_task
from planner.core.plain_text import plain
from planner.model.geometry import heading
from planner.model.task import Scene

from .notify import error_text

DEBOUNCE = 0.4  # s: how long edits must pause before the check runs
Work = Callable[[Scene], None]  # what runs on an edited scene before it is checked (the workbench shows it)
Show = Callable[[str], None]  # shows the check's markdown


def _placement(T: np.ndarray) -> str:
    x, y, z = T[:3, 3]
    return f"({x:.3f}, {y:.3f}, {z:.3f}) m, heading {np.degrees(heading(T)):.0f}°"


def report_markdown(scene: Scene, report: TaskReport) -> str:
    """The check of an edited task: its verdict, each placement's position and reach by each arm, problems, warnings."""
    verdict = ("OK: a valid two-hand regrasping task" if report.handover else "OK: a valid pick-and-place task for one arm") \
        if report.ok else "Not plannable"
    colour = "#2a6" if report.ok else "#d22"
    lines = [f"<span style='color:{colour}'>**Check: {verdict}**</span>", "", "| placement | where | " +
             " | ".join(plain(a) for a in scene.robot.spec.arm_names) + " |", "|---|---|" + "---|" * len(scene.robot.spec.arm_names)]
    for name, T in (("initial", scene.object_initial), ("final", scene.object_final)):
        hits = report.placement_collisions.get(name) or []
        where = _placement(T) + (f", in {', '.join(hits)}" if hits else "")
        cells = [plain(report.reach[name][arm].describe(report.tolerance)) for arm in scene.robot.spec.arm_names]
        lines.append(f"| {name} | {plain(where)} | " + " | ".join(cells) + " |")
    lines += ["", f"Arms: {plain(report.arms)}"]
    lines += [f"- **Problem:** {plain(p)}" for p in report.problems]
    lines += [f"- *Warning:* {plain(w)}" for w in report.warnings]
    return "\n".join(lines)


class LiveCheck:
    """One daemon thread: `request(scene)` schedules `work(scene)` then the check of `scene`, DEBOUNCE seconds after the
    last request; `show` gets the markdown of the newest one. `checked` counts the checks shown (tests wait on it)."""

    def __init__(self, work: Work, show: Show, delay: float = DEBOUNCE):
        self._work, self._show, self._delay = work, show, delay
        self._wake = threading.Condition()
        self._pending: Scene | None = None
        self._due = 0.0
        self._closed = False
        self.checked = 0
        self.idle = threading.Event()
        self.idle.set()
        threading.Thread(target=self._loop, daemon=True, name="live-check").start()

    def request(self, scene: Scene) -> None:
        """Check `scene` once no newer request came for DEBOUNCE seconds (an older waiting one is dropped)."""
        with self._wake:
            self._pending, self._due = scene, time.monotonic() + self._delay
            self.idle.clear()
            self._wake.notify()

    def close(self) -> None:
        """Stop the thread after the check it runs (a waiting one is dropped)."""
        with self._wake:
            self._closed, self._pending = True, None
            self._wake.notify()

    def _next(self) -> Scene | None:
        """The scene to check once it is due; None when closed."""
        with self._wake:
            while not self._closed:
                if self._pending is None:
                    self.idle.set()
                    self._wake.wait()
                elif (wait := self._due - time.monotonic()) > 0:
                    self._wake.wait(wait)
                else:
                    scene, self._pending = self._pending, None
                    return scene
            return None

    def _loop(self) -> None:
        while (scene := self._next()) is not None:
            try:
                self._work(scene)
                text = report_markdown(scene, check_task(scene))
            except Exception as exc:  # a check that fails is shown, never raised in the thread
                text = f"<span style='color:#d22'>**Check failed:**</span> {plain(error_text(exc))}"
            with self._wake:
                stale = self._pending is not None or self._closed  # a newer edit waits, or the workbench closed
            if not stale:
                self._show(text)
                self.checked += 1
