"""A motion played back: a timeline in seconds (keyframes marked, the phases as coloured bands under it), play / pause,
loop, speed, jumps to the keyframes and an optional camera that follows the object; the current phase is named in the
3-D view by a label above the object.

It owns the timeline's state and its controls; what a sample shows (the workbench's robot, the exported object) is
the motion layer's `pose` callback, so the same class drives the live Playback tab and an HTML export (no controls).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import viser

from planner.core.plain_text import plain
from planner.motion.result import Motion

from .layers.phases import phase_bands
from .view import follow_cameras

FPS = 30.0  # frames a second at most while playing (samples are skipped when the trajectory's rate or the speed is higher)
SPEEDS = (0.1, 4.0)  # playback speed range (1 = real time)
KEYFRAMES = ("initial", "q_grasp", "q_exch", "q_place", "final")  # `Motion.keyframes` (not "exchange": the Double grasps folder has it)
MARKED = {"q_grasp": "grasp", "q_exch": "exch", "q_place": "place"}  # the keyframes marked on the timeline, by their mark
LABEL_HEIGHT = 0.18  # m above the object's centre: the phase label
TIME_STEP = 0.01  # s: the timeline's resolution


def object_centres(result: Motion, centre_of_mass: np.ndarray) -> np.ndarray:
    """(n, 3): where the object's centre of mass is at each sample."""
    P = np.asarray(result.object_pose, float)
    return np.einsum("nij,j->ni", P[:, :3, :3], np.asarray(centre_of_mass, float)) + P[:, :3, 3]


def timeline_marks(result: Motion) -> tuple[tuple[float, str], ...]:
    """The timeline's marks: its ends in seconds and the grasp, exchange and place keyframes by name."""
    t = result.t
    marks = [(0.0, "0 s"), (round(result.duration, 2), f"{result.duration:.1f} s")]
    marks += [(round(float(t[int(result.keyframes[KEYFRAMES.index(key)])]), 2), mark) for key, mark in MARKED.items()
              if 0 <= int(result.keyframes[KEYFRAMES.index(key)]) < len(t)]
    return tuple(sorted(marks))


def sample_at(t: np.ndarray, seconds: float) -> int:
    """The sample nearest to time `seconds` (clipped to the trajectory)."""
    i = int(np.clip(np.searchsorted(t, seconds), 1, len(t) - 1)) if len(t) > 1 else 0
    return i - 1 if len(t) > 1 and seconds - t[i - 1] <= t[i] - seconds else i


class Playback:
    """The timeline over `result` (at least one sample): `show(i)` draws sample i, `play()` / `pause()` run it in a
    background thread. `pose(i, playing)` puts what the sample shows in place (only meshes while playing)."""

    def __init__(self, server: viser.ViserServer, result: Motion, root: str, centres: np.ndarray,
                 pose: Callable[[int, bool], None], controls: bool):
        self.server, self.result, self.centres, self._pose = server, result, centres, pose
        self.index = 0  # the sample shown
        self.playing = False
        self._generation = 0  # bumped to stop a running playback
        self._frame_lock = threading.Lock()  # a playback frame and pause / removal never interleave
        self._followed = 0  # the sample the cameras were last moved for (followed or not)
        self._follow_lock = threading.Lock()
        self.label = server.scene.add_label(f"{root}/phase", "", position=tuple(centres[0] + (0, 0, LABEL_HEIGHT)),
                                            anchor="bottom-center", font_screen_scale=1.2)
        self.now: viser.GuiMarkdownHandle | None = None
        self.timeline: viser.GuiSliderHandle | None = None
        self.play_button: viser.GuiButtonHandle | None = None
        self.loop: viser.GuiCheckboxHandle | None = None
        self.speed: viser.GuiSliderHandle | None = None
        self.follow: viser.GuiCheckboxHandle | None = None
        if controls:
            self._build_gui()

    def _build_gui(self) -> None:
        gui, r = self.server.gui, self.result
        self.now = gui.add_markdown("")
        self.timeline = gui.add_slider("Time (s)", min=0.0, max=max(round(r.duration, 2), TIME_STEP), step=TIME_STEP,
                                       initial_value=0.0, marks=timeline_marks(r),
                                       hint="The time shown, in seconds (robot and object); marks: the keyframes")
        gui.add_markdown(phase_bands(r))
        self.play_button = gui.add_button("Play", hint="Play / pause from the time shown")
        self.loop = gui.add_checkbox("Loop", False, hint="Start again at the end")
        self.speed = gui.add_slider("Speed", min=SPEEDS[0], max=SPEEDS[1], step=0.1, initial_value=1.0,
                                    hint="Playback speed (1 = real time)")
        self.follow = gui.add_checkbox("Camera follows", False, hint="The camera moves along with the object")
        jump = gui.add_button_group("Jump to", KEYFRAMES)
        self.timeline.on_update(lambda e: self.show(sample_at(self.result.t, float(e.target.value))))
        self.play_button.on_click(lambda _: self.pause() if self.playing else self.play())
        jump.on_click(lambda e: self.seek(int(self.result.keyframes[KEYFRAMES.index(e.target.value)])))

    # -- the current sample ----------------------------------------------------------------------

    def seek(self, i: int) -> None:
        """Move the timeline to sample i (it draws the sample); without controls, draw it."""
        i = int(np.clip(i, 0, len(self.result.t) - 1))
        if self.timeline is None:
            self.show(i)
        elif sample_at(self.result.t, float(self.timeline.value)) == i:
            self.show(i)  # the slider's value stays: no update would come
        else:
            self.timeline.value = float(self.result.t[i])

    def show(self, i: int) -> None:
        """Draw sample i (clipped), then put in place what it poses; the camera follows the object if asked."""
        i = self.draw(i)
        self._pose(i, self.playing)
        with self._follow_lock:  # two shows at once (viser runs callbacks in a thread pool) move the cameras once
            shift = self.centres[i] - self.centres[self._followed]
            self._followed = i
        if self.follow is not None and self.follow.value and np.any(shift):
            follow_cameras(self.server, shift)

    def draw(self, i: int) -> int:
        """Make sample i (clipped) the shown one: the phase label above the object and the caption; returns i."""
        r = self.result
        self.index = i = int(np.clip(i, 0, len(r.t) - 1))
        with self.server.atomic():
            self.label.text = f"{r.phase_name(int(r.phase[i]))} · {r.t[i]:.1f} s"
            self.label.position = tuple(self.centres[i] + (0.0, 0.0, LABEL_HEIGHT))
            if self.now is not None:
                holder = int(r.holder[i])
                held = f"held by the {plain(r.arms[holder])} hand" if 0 <= holder < len(r.arms) else "object static"
                self.now.content = (f"**{plain(r.phase_name(int(r.phase[i])))}** — t = {r.t[i]:.2f} s of {r.duration:.2f} s "
                                    f"(sample {i}); {held}")
        return i

    def off_timeline(self, label: str) -> None:
        """Say that the robot is not at the timeline's sample any more (it was posed at `label` by something else)."""
        if self.now is not None and not self.playing:
            self.now.content = (f"*The robot is shown at {plain(label)}, not at t = {self.result.t[self.index]:.2f} s: "
                                f"move the timeline or press Play.*")

    # -- playing ---------------------------------------------------------------------------------

    def play(self) -> threading.Thread | None:
        """Play from the sample shown (from the start when at the end) in a background thread."""
        r = self.result
        if len(r.t) < 2 or self.playing:
            return None
        if self.index >= len(r.t) - 1:
            self.seek(0)
        with self._frame_lock:
            self._generation += 1
            self.playing = True
        if self.play_button is not None:
            self.play_button.label = "Pause"
        job = threading.Thread(target=self._run, args=(self._generation,), daemon=True)
        job.start()
        return job

    def pause(self) -> None:
        """Stop playing; what the sample poses is then posed fully (sliders and collisions follow)."""
        if not self.playing:
            return
        self.stop()
        self._paused_button()
        self.show(self.index)

    def stop(self) -> None:
        """End a running playback at its next frame (nothing is redrawn)."""
        with self._frame_lock:
            self._generation += 1
            self.playing = False

    def _paused_button(self) -> None:
        if self.play_button is not None:
            self.play_button.label = "Play"

    def _speed(self) -> float:
        return float(self.speed.value) if self.speed is not None else 1.0

    def _run(self, generation: int) -> None:
        """Advance by the elapsed time times the speed, at most FPS frames a second, until the end (again from the start
        when looping) or a stop."""
        r = self.result
        pos, shown, last = float(r.t[self.index]), self.index, time.monotonic()
        try:
            while True:
                time.sleep(1.0 / FPS)
                with self._frame_lock:
                    if generation != self._generation:
                        return
                    if self.index != shown:  # the user moved the timeline meanwhile: go on from there
                        pos = float(r.t[self.index])
                    now = time.monotonic()
                    pos = min(pos + (now - last) * self._speed(), r.duration)
                    last = now
                    if pos >= r.duration and self.loop is not None and self.loop.value:
                        pos = 0.0
                    shown = sample_at(r.t, pos)
                    self.seek(shown)  # draws the sample (see show)
                    if pos < r.duration:  # on until the end's time, not the last sample's (the nearest within half a
                        continue  # sample of the end): a loop starts again at the end, never stops short of it
                    self.playing = False
                break
            if generation == self._generation:  # neither removed nor restarted since the last frame
                self._paused_button()
                self.show(self.index)  # at the end: fully posed
        except RuntimeError:  # a handle was removed under us (the layer or the robot was replaced): nothing left to draw
            return

    def remove(self) -> None:
        """Stop playing and take the label out of the scene (the controls go with their folder)."""
        self.stop()
        self.label.remove()
