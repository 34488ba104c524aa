"""The `motion` step drawn (paper V-B): the whole task played back from the saved trajectory, nothing recomputed.

The timeline (workbench/playback.py, in the Playback tab) poses the robot and draws the object at a
sample's `object_pose` (it moves with the holding hand). Each wrist's route and the object's trail are
drawn as line segments coloured by phase, the grasp, exchange and place keyframes are named where the
object is then, and the Steps tab's folder shows Table I of the session (counts from the result, seconds
from the step's session record).
"""
from __future__ import annotations

import contextlib
import threading

import numpy as np
import viser

from planner.core.plain_text import plain
from planner.core.session import Session
from planner.model.task import Scene
from planner.motion.result import PHASE_SECONDS, Motion
from planner.motion.trajectory_file import trajectory_of, trajectory_text

from ..meshes import matrix_wxyz
from ..notify import error_text
from ..playback import KEYFRAMES, MARKED, Playback, object_centres
from ..scene_layer import OBJECT_COLOR
from .base import Host, StepLayer
from .phases import PHASE_COLOR_NAMES, phase_segments
from .stages import FAILURE_COLOR

TIMELINE = "motion: the timeline's sample"  # what "Robot at" says when the timeline posed the robot
ROUTE_THICKNESS = 0.004  # m: each wrist's route
TRAIL_THICKNESS = 0.008  # m: the object's trail
STRATEGY_TITLES = {"table": "Table handover", "regrasp": "Same-hand regrasp"}  # the strategies through an intermediate placement
TRAJECTORY_FORMATS = ("JSON", "CSV")  # the trajectory downloads (planner/motion/trajectory_file.py), by the button's label


def route_segments(result: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Each wrist's route as ((n-1)*wrists, 2, 3) float32 segments between consecutive samples, and their colours by the
    phase of each segment's end sample (same shape, uint8)."""
    return phase_segments(np.asarray(result.wrists, float), result.phase)


def table_one(result: Motion, seconds: list[float] | None) -> str:
    """Table I of the session as markdown, one column per phase: nodes added planning / validating, the seconds of
    planning, validating, reconnecting, shortcutting and contact motions (from the session record; '–' when absent),
    edges invalidated, query ends no graph edge joined, RRT calls, transit and smoothing collision checks, path length,
    straight distance between the phase's ends and duration."""
    phases, per = result.phases, len(PHASE_SECONDS)
    secs = seconds if seconds and len(seconds) >= per * len(phases) else None
    rows = [("nodes planning", [plain(p["nodes_planning"]) for p in phases]),
            ("nodes validating", [plain(p["nodes_validating"]) for p in phases])]
    rows += [(f"s {stage}", [f"{secs[per * k + j]:.3f}" if secs else "–" for k in range(len(phases))])
             for j, stage in enumerate(PHASE_SECONDS)]
    rows += [("edges invalidated", [plain(p["edges_invalidated"]) for p in phases]),
             ("ends alone", [plain(p.get("ends_alone", "–")) for p in phases]),  # query ends no graph edge joined
             ("RRT calls", [plain(p["rrt_calls"]) for p in phases]),
             ("transit checks", [plain(p.get("transit_checks", "–")) for p in phases]),  # sessions before they were counted: '–'
             ("smoothing checks", [plain(p.get("smoothing_checks", "–")) for p in phases]),
             ("length (rad)", [f"{p['path_length']:.2f}" for p in phases]),
             ("straight (rad)", [f"{p['straight_distance']:.2f}" if "straight_distance" in p else "–" for p in phases]),
             ("duration (s)", [f"{p['duration']:.2f}" for p in phases])]
    head = "| | " + " | ".join(plain(p["phase"]) for p in phases) + " |\n|---|" + "---:|" * len(phases)
    return "\n".join([head, *(f"| {name} | " + " | ".join(cells) + " |" for name, cells in rows)])


class MotionLayer(StepLayer):
    """The trajectory on a timeline (`playback`): the robot posed and the object drawn at the current sample; routes and
    the object's trail coloured by phase, the keyframes named, Table I, and the downloads."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Host | None = None,
                 session: Session | None = None):
        super().__init__(server, scene, root, workbench, session)
        self.result: Motion | None = None
        self.playback: Playback | None = None
        self.object: viser.FrameHandle | None = None
        self.trails: viser.FrameHandle | None = None  # the routes, the object's trail and the keyframes' names
        self.controls: viser.GuiFolderHandle | None = None  # the Playback tab's folder of a live workbench
        self.export_button: viser.GuiButtonHandle | None = None
        self.trajectory_buttons: viser.GuiButtonGroupHandle | None = None

    # -- drawing ---------------------------------------------------------------------------------

    def update(self, result: Motion) -> None:
        self.remove_folder()
        self._remove_drawing()
        self.result, self.poses = result, {}
        n = len(result.t)
        centres = object_centres(result, self.scene.object_mesh.center_mass) if n else np.zeros((0, 3))
        if n:
            self._draw_trails(result, centres)
        if n and self.workbench is None:  # in an HTML export; the live workbench's object is moved instead
            node = f"{self.name}/object"
            self.object = self.server.scene.add_frame(node, show_axes=False)
            mesh = self.scene.object_mesh
            self.server.scene.add_mesh_simple(f"{node}/mesh", mesh.vertices, mesh.faces, color=OBJECT_COLOR,
                                              cast_shadow=False, receive_shadow=False)
        with self.server.gui.add_folder("Motion") as self.folder:
            self.server.gui.add_markdown(self.summary(result))
        wb = self.workbench
        with wb.tabs.playback if wb is not None else contextlib.nullcontext():
            self.controls = self.server.gui.add_folder("Motion") if wb is not None else None
            with self.controls if self.controls is not None else contextlib.nullcontext():
                if n:
                    self.playback = Playback(self.server, result, self.name, centres, self._pose, controls=wb is not None)
                if wb is not None:
                    self._build_controls(n)
        if self.playback is not None:
            self.playback.draw(0)  # the robot stays where it is until the timeline moves
            if wb is not None:
                wb.pose_choice.watch(self._robot_shown)
        if wb is not None:
            wb.tabs.playback_empty.visible = False

    def _draw_trails(self, result: Motion, centres: np.ndarray) -> None:
        """The wrists' routes, the object's trail (both coloured by phase) and the keyframes named where the object is."""
        scene = self.server.scene
        self.trails = scene.add_frame(f"{self.name}/trails", show_axes=False)
        for node, points, thickness in (("routes", np.asarray(result.wrists, float), ROUTE_THICKNESS),
                                        ("trail", centres[:, None, :], TRAIL_THICKNESS)):
            segments, colors = phase_segments(points, result.phase)
            if len(segments):
                scene.add_line_segments(f"{self.name}/trails/{node}", segments, colors, thickness=thickness)
        for key, mark in MARKED.items():
            i = int(result.keyframes[KEYFRAMES.index(key)])
            if 0 <= i < len(centres):
                scene.add_label(f"{self.name}/trails/{key}", mark, position=tuple(centres[i]), anchor="top-center",
                                font_screen_scale=0.8)

    def _build_controls(self, n: int) -> None:
        """The Playback tab's controls beyond the timeline: the trails' checkbox and the downloads."""
        gui = self.server.gui
        if not n:
            gui.add_markdown("*The motion step found no motion (see the Steps tab).*")
            return
        trails = gui.add_checkbox("Trails", True, hint="The wrists' routes and the object's trail, coloured by phase")
        trails.on_update(lambda e: setattr(self.trails, "visible", e.target.value) if self.trails is not None else None)
        if self.session is not None:
            self.export_button = gui.add_button("Export animation", hint="Download the whole motion as one HTML file "
                                                "that plays offline, looping, at a speed you choose (10 frames a second at most)")
            self.trajectory_buttons = gui.add_button_group("Trajectory", TRAJECTORY_FORMATS, hint=(
                "Download the motion as a trajectory file (joint names, time, positions, velocities, phase, holder, "
                "object pose): JSON shaped as a ROS JointTrajectory, or CSV (docs/sessions.md)"))
            self.export_button.on_click(lambda e: self.export(e.client))
            self.trajectory_buttons.on_click(lambda e: self.download_trajectory(e.client, e.target.value))

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
                f"Routes (wrists thin, the object thick): " + ", ".join(
                    f"{plain(str(p))} {PHASE_COLOR_NAMES[k % len(PHASE_COLOR_NAMES)]}" for k, p in enumerate(result.phase_names)) + ".\n\n")
        if result.phases:
            text += table_one(result, self._seconds())
        if failed and not result.failure:
            text += "\n\nFailed before: " + "; ".join(failed)
        if result.failure:
            text += f"\n\n<span style='color:{FAILURE_COLOR}'>**Failed:** {plain(result.failure)}</span>"
        return text

    # -- the current sample ----------------------------------------------------------------------

    def _pose(self, i: int, playing: bool) -> None:
        """Put sample i in place: the exported object, or the workbench's robot and object (only the meshes while playing;
        the sliders follow, and collisions are checked, otherwise)."""
        r = self.result
        assert r is not None
        if self.object is not None:
            self.object.wxyz, self.object.position = matrix_wxyz(r.object_pose[i])
        wb = self.workbench
        if wb is None:
            return
        if playing:
            wb.robot_layer.update(r.q[i])
            wb.scene_layer.place_object(r.object_pose[i])
            wb.pose_choice.showing(TIMELINE)
        else:
            wb.pose_robot(r.q[i], r.object_pose[i], TIMELINE)

    def _robot_shown(self, label: str) -> None:
        """"Robot at" changed: the caption says so when the robot left the timeline's sample."""
        if label != TIMELINE and self.playback is not None:
            self.playback.off_timeline(label)

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

    def _remove_drawing(self) -> None:
        """Stop playing and take the drawn nodes and the Playback tab's controls out."""
        if self.playback is not None:
            self.playback.remove()
            self.playback = None
        for handle in (self.object, self.trails, self.controls):
            if handle is not None:
                handle.remove()
        self.object = self.trails = self.controls = self.export_button = self.trajectory_buttons = None
        if self.workbench is not None:
            self.workbench.pose_choice.watch(None)
            self.workbench.tabs.playback_empty.visible = True

    def remove(self) -> None:
        self._remove_drawing()
        super().remove()
