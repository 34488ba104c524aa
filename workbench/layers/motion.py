"""The `motion` step drawn (paper V-B): the whole task played back from the saved trajectory, nothing recomputed.

A timeline over the trajectory's samples poses the robot and draws the object at the sample's
`object_pose` (it moves with the holding hand); play / pause runs the timeline in a background
thread at a chosen speed. Each wrist's route is drawn as line segments coloured by phase, and the
GUI folder shows the current phase and Table I of the session (counts from the result, seconds
from the step's session record).
"""
from __future__ import annotations

import contextlib
import threading
import time

import numpy as np
import viser

from planner.core.plain_text import plain
from planner.core.session import Session
from planner.model.task import Scene
from planner.motion.result import PHASE_SECONDS, Motion
from planner.motion.trajectory_file import trajectory_of, trajectory_text

from ..meshes import matrix_wxyz
from ..notify import error_text
from ..scene_layer import OBJECT_COLOR
from .base import Host, StepLayer
from .stages import FAILURE_COLOR

TIMELINE = "motion: the timeline's sample"  # what "Robot at" says when the timeline posed the robot

# Grasp, Carry, Place, Rest, then a table handover's Set down and Regrasp (planner/motion/phase.py)
PHASE_COLORS = ((0, 170, 170), (90, 60, 220), (200, 50, 200), (110, 110, 110), (230, 140, 20), (40, 160, 60))
PHASE_COLOR_NAMES = ("teal", "violet", "magenta", "grey", "orange", "green")
STRATEGY_TITLES = {"table": "Table handover", "regrasp": "Same-hand regrasp"}  # the strategies through an intermediate placement
ROUTE_THICKNESS = 0.004  # m
FPS = 30.0  # frames a second at most while playing (samples are skipped when the trajectory's rate or the speed is higher)
SPEEDS = (0.1, 4.0)  # playback speed range (1 = real time)
TRAJECTORY_FORMATS = ("JSON", "CSV")  # the trajectory downloads (planner/motion/trajectory_file.py), by the button's label
KEYFRAMES = ("initial", "q_grasp", "q_exch", "q_place", "final")  # `Motion.keyframes` (not "exchange": the Double grasps folder has it)


def route_segments(result: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Each wrist's route as ((n-1)*wrists, 2, 3) float32 segments between consecutive samples, and their colours by the
    phase of each segment's end sample (same shape, uint8)."""
    w = result.wrists
    if len(w) < 2:
        return np.zeros((0, 2, 3), np.float32), np.zeros((0, 2, 3), np.uint8)
    points = np.stack([w[:-1], w[1:]], axis=2)  # (n-1, wrists, 2 ends, 3)
    colors = np.asarray(PHASE_COLORS, np.uint8)[np.clip(result.phase[1:].astype(int), 0, len(PHASE_COLORS) - 1)]  # (n-1, 3)
    colors = np.broadcast_to(colors[:, None, None, :], points.shape)
    return points.reshape(-1, 2, 3).astype(np.float32), np.ascontiguousarray(colors.reshape(-1, 2, 3))


def table_one(result: Motion, seconds: list[float] | None) -> str:
    """Table I of the session as markdown, one column per phase: nodes added planning / validating, the seconds of
    planning, validating, reconnecting, shortcutting and contact motions (from the session record; '–' when absent),
    edges invalidated, RRT calls, transit and smoothing collision checks, path length, straight distance between the
    phase's ends and duration."""
    phases, per = result.phases, len(PHASE_SECONDS)
    secs = seconds if seconds and len(seconds) >= per * len(phases) else None
    rows = [("nodes planning", [plain(p["nodes_planning"]) for p in phases]),
            ("nodes validating", [plain(p["nodes_validating"]) for p in phases])]
    rows += [(f"s {stage}", [f"{secs[per * k + j]:.3f}" if secs else "–" for k in range(len(phases))])
             for j, stage in enumerate(PHASE_SECONDS)]
    rows += [("edges invalidated", [plain(p["edges_invalidated"]) for p in phases]),
             ("RRT calls", [plain(p["rrt_calls"]) for p in phases]),
             ("transit checks", [plain(p.get("transit_checks", "–")) for p in phases]),  # sessions before they were counted: '–'
             ("smoothing checks", [plain(p.get("smoothing_checks", "–")) for p in phases]),
             ("length (rad)", [f"{p['path_length']:.2f}" for p in phases]),
             ("straight (rad)", [f"{p['straight_distance']:.2f}" if "straight_distance" in p else "–" for p in phases]),
             ("duration (s)", [f"{p['duration']:.2f}" for p in phases])]
    head = "| | " + " | ".join(plain(p["phase"]) for p in phases) + " |\n|---|" + "---:|" * len(phases)
    return "\n".join([head, *(f"| {name} | " + " | ".join(cells) + " |" for name, cells in rows)])


class MotionLayer(StepLayer):
    """The trajectory on a timeline: the robot posed and the object drawn at the current sample; play / pause, speed,
    jumps to the keyframes, each wrist's route coloured by phase and Table I."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Host | None = None,
                 session: Session | None = None):
        super().__init__(server, scene, root, workbench, session)
        self.result: Motion | None = None
        self.index = 0  # the sample shown
        self.playing = False
        self.object: viser.FrameHandle | None = None
        self.routes: viser.LineSegmentsHandle | None = None
        self.timeline: viser.GuiSliderHandle | None = None
        self.speed: viser.GuiSliderHandle | None = None
        self.play_button: viser.GuiButtonHandle | None = None
        self.jump: viser.GuiButtonGroupHandle | None = None
        self.now: viser.GuiMarkdownHandle | None = None
        self.export_button: viser.GuiButtonHandle | None = None
        self.trajectory_buttons: viser.GuiButtonGroupHandle | None = None
        self._generation = 0  # bumped to stop a running playback
        self._frame_lock = threading.Lock()  # a playback frame and pause / removal never interleave

    # -- drawing ---------------------------------------------------------------------------------

    def update(self, result: Motion) -> None:
        self.stop()
        self.remove_folder()
        for handle in (self.object, self.routes):
            if handle is not None:
                handle.remove()
        self.object = self.routes = None
        self.result, self.index, self.poses = result, 0, {}
        self.timeline = self.speed = self.play_button = self.jump = self.now = self.trajectory_buttons = None
        if len(result.t):
            self._draw_routes(result)
        if len(result.t) and self.workbench is None:  # in an HTML export; the live workbench's object is moved instead
            node = f"{self.name}/object"
            self.object = self.server.scene.add_frame(node, show_axes=False)
            mesh = self.scene.object_mesh
            self.server.scene.add_mesh_simple(f"{node}/mesh", mesh.vertices, mesh.faces, color=OBJECT_COLOR,
                                              cast_shadow=False, receive_shadow=False)
        self._build_gui(result)
        if len(result.t):
            self._draw_sample(0)  # the robot stays where it is until the timeline moves

    def _draw_routes(self, result: Motion) -> None:
        points, colors = route_segments(result)
        if len(points):
            self.routes = self.server.scene.add_line_segments(f"{self.name}/routes", points, colors, thickness=ROUTE_THICKNESS)

    def _seconds(self) -> list[float] | None:
        """The step's stage seconds from the session record (4 per phase), if the session is known."""
        if self.session is None or "motion" not in self.session.finished():
            return None
        return self.session.record_of("motion").get("stage_seconds")

    def summary(self, result: Motion) -> str:
        """Which double grasp moved, the routes' colours, Table I and the failure (red)."""
        if result.strategy in STRATEGY_TITLES and len(result.t):
            used = f"{STRATEGY_TITLES[result.strategy]}: sequence **{len(result.tried)}** tried, through an intermediate placement"
        else:
            used = (f"Double grasp **{result.double_grasp + 1}**, sequence {len(result.tried)} tried" if result.double_grasp >= 0
                    else f"Nothing moved ({len(result.tried)} sequences tried)")
        used += "".join(f"; not the {plain(str(a.get('strategy', '?')))} strategy: {plain(str(a.get('failure', '')))}"
                        for a in result.alternatives if isinstance(a, dict))
        steps = [f"{plain(str(t.get('kind', '?')))} {float(t.get('seconds', 0.0)):.1f} s" for t in result.sequence if isinstance(t, dict)
                 and isinstance(t.get("seconds", 0.0), (int, float))]
        used += f". Regrasp graph: {' → '.join(steps)} (estimated)" if steps else ""
        failed = [f"{k + 1}: {plain(why)}" for k, why in enumerate(result.tried) if why]
        text = (f"{used}; planner *{plain(result.planner)}*, {len(result.t)} samples, {result.duration:.2f} s.\n\n"
                f"Wrist routes: " + ", ".join(f"{plain(str(p))} {c}" for p, c in zip(result.phase_names, PHASE_COLOR_NAMES)) + ".\n\n")
        if result.phases:
            text += table_one(result, self._seconds())
        if failed and not result.failure:
            text += "\n\nFailed before: " + "; ".join(failed)
        if result.failure:
            text += f"\n\n<span style='color:{FAILURE_COLOR}'>**Failed:** {plain(result.failure)}</span>"
        return text

    def _build_gui(self, result: Motion) -> None:
        gui = self.server.gui
        n = len(result.t)
        with gui.add_folder("Motion") as self.folder:
            if n:
                self.now = gui.add_markdown("")
                self.timeline = gui.add_slider("Sample", min=0, max=max(n - 1, 1), step=1, initial_value=0,
                                               hint="The trajectory's sample shown (robot and object)")
                self.play_button = gui.add_button("Play", hint="Play / pause the motion from the current sample")
                self.speed = gui.add_slider("Speed", min=SPEEDS[0], max=SPEEDS[1], step=0.1, initial_value=1.0,
                                            hint="Playback speed (1 = real time)")
                self.jump = gui.add_button_group("Jump to", KEYFRAMES)
                if self.session is not None:
                    self.export_button = gui.add_button("Export animation", hint="Download the whole motion as one HTML "
                                                        "file that plays offline (10 frames a second at most)")
                    self.trajectory_buttons = gui.add_button_group("Trajectory", TRAJECTORY_FORMATS, hint=(
                        "Download the motion as a trajectory file (joint names, time, positions, velocities, phase, holder, "
                        "object pose): JSON shaped as a ROS JointTrajectory, or CSV (docs/sessions.md)"))
            gui.add_markdown(self.summary(result))
        if self.timeline is not None and self.play_button is not None and self.jump is not None:
            self.timeline.on_update(lambda e: self.show(int(e.target.value)))
            self.play_button.on_click(lambda _: self.pause() if self.playing else self.play())
            self.jump.on_click(lambda e: self.seek(int(self.result.keyframes[KEYFRAMES.index(e.target.value)])))
        if self.export_button is not None:
            self.export_button.on_click(lambda e: self.export(e.client))
        if self.trajectory_buttons is not None:
            self.trajectory_buttons.on_click(lambda e: self.download_trajectory(e.client, e.target.value))

    # -- the current sample ----------------------------------------------------------------------

    def seek(self, i: int) -> None:
        """Move the timeline to sample i (it draws the sample)."""
        if self.timeline is not None:
            self.timeline.value = i

    def show(self, i: int) -> None:
        """Draw sample i and put the workbench's robot and object there (only the meshes while playing; the sliders follow,
        and collisions are checked, otherwise)."""
        r = self.result
        if r is None or not len(r.t):
            return
        i = self._draw_sample(i)
        wb = self.workbench
        if wb is None:
            return
        if self.playing:
            wb.robot_layer.update(r.q[i])
            wb.scene_layer.place_object(r.object_pose[i])
            wb.session_panel.showing(TIMELINE)
        else:
            wb.pose_robot(r.q[i], r.object_pose[i], TIMELINE)

    def _draw_sample(self, i: int) -> int:
        """Make sample i (clipped to the trajectory) the shown one: the object at its pose and the caption; returns i."""
        r = self.result
        assert r is not None
        self.index = i = int(np.clip(i, 0, len(r.t) - 1))
        with self.server.atomic():
            if self.object is not None:
                self.object.wxyz, self.object.position = matrix_wxyz(r.object_pose[i])
            if self.now is not None:
                self.now.content = self.caption(i)
        return i

    def caption(self, i: int) -> str:
        """The phase and time of sample i, and who holds the object."""
        r = self.result
        assert r is not None
        holder = int(r.holder[i])
        held = f"held by the {plain(r.arms[holder])} hand" if holder >= 0 else "object static"
        return f"**{plain(r.phase_name(int(r.phase[i])))}** — t = {r.t[i]:.2f} s of {r.duration:.2f} s, sample {i}; {held}"

    # -- playback --------------------------------------------------------------------------------

    def play(self) -> threading.Thread | None:
        """Play from the current sample (from the start when at the end) in a background thread."""
        r = self.result
        if r is None or len(r.t) < 2 or self.playing:
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
        """Stop playing; the robot is then posed fully at the shown sample (sliders and collisions follow)."""
        if not self.playing:
            return
        self.stop()
        if self.play_button is not None:
            self.play_button.label = "Play"
        self.show(self.index)

    def stop(self) -> None:
        """End a running playback at its next frame (nothing is redrawn)."""
        with self._frame_lock:
            self._generation += 1
            self.playing = False

    def _run(self, generation: int) -> None:
        """Advance the timeline by the elapsed time times the speed, at most FPS frames a second, until the end or a stop."""
        r = self.result
        assert r is not None and self.timeline is not None and self.speed is not None
        rate = (len(r.t) - 1) / max(r.duration, 1e-9)  # samples a second
        pos, shown, last = float(self.index), self.index, time.monotonic()
        try:
            while True:
                time.sleep(1.0 / FPS)
                with self._frame_lock:
                    if generation != self._generation:
                        return
                    if self.index != shown:  # the user moved the timeline meanwhile: go on from there
                        pos = float(self.index)
                    now = time.monotonic()
                    pos = min(pos + (now - last) * float(self.speed.value) * rate, len(r.t) - 1)
                    last, shown = now, int(pos)
                    self.timeline.value = shown  # draws the sample (see show)
                    if shown < len(r.t) - 1:
                        continue
                    self.playing = False
                break
            if generation == self._generation:  # neither removed nor restarted since the last frame
                self.play_button.label = "Play"
                self.show(self.index)  # at the end: the robot fully posed
        except RuntimeError:  # a handle was removed under us (the layer or the robot was replaced): nothing left to draw
            return

    # -- export ----------------------------------------------------------------------------------

    def export(self, client: viser.ClientHandle | None) -> threading.Thread | None:
        """In the background: record the drawn session's motion as one HTML page and send it to `client` to download."""
        if self.session is None or client is None or self.export_button is None or self.export_button.disabled:
            return None
        self.export_button.disabled = True
        job = threading.Thread(target=self._export, args=(client, self.session, self.export_button), daemon=True)
        job.start()
        return job

    def download_trajectory(self, client: viser.ClientHandle | None, label: str) -> None:
        """Send the drawn session's motion to `client` as a trajectory file in the format `label` names (JSON or CSV)."""
        if self.session is None or client is None or label not in TRAJECTORY_FORMATS:
            return
        suffix = f".{label.lower()}"
        try:
            text = trajectory_text(trajectory_of(self.session), suffix)
        except Exception as exc:  # shown, never raised into viser's callback thread
            client.add_notification("Trajectory export failed", error_text(exc), color="red", auto_close_seconds=10.0)
            return
        client.send_file_download(f"{self.session.folder.name}-trajectory{suffix}", text.encode(), save_immediately=True)

    @staticmethod
    def _export(client: viser.ClientHandle, session: Session, button: viser.GuiButtonHandle) -> None:
        # imported here: the export draws a session through these layers (a cycle at import time)
        from ..export import session_html

        try:
            html = session_html(session.folder)
        except Exception as exc:  # shown, never raised into a thread nobody watches
            client.add_notification("Export failed", error_text(exc), color="red", auto_close_seconds=10.0)
            return
        finally:
            with contextlib.suppress(RuntimeError):  # the layer may have been removed meanwhile
                button.disabled = False
        client.send_file_download(f"{session.folder.name}-motion.html", html.encode(), save_immediately=True)

    # -- removal ---------------------------------------------------------------------------------

    def remove(self) -> None:
        self.stop()
        super().remove()
