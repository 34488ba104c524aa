"""The workbench app: a viser server that shows a task or a session, lets a person pose the robot and shows its collisions.

It holds no planning logic: it loads a task with `planner.model.task` or a session with `planner.core.session`,
builds the collision model with `planner.collision.checker` and draws what comes back through one layer per
concern (the session's steps through `session_layers`; the Session panel runs steps via `planner.core.runner`).
"""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import numpy as np
import viser

from planner.collision.checker import CollisionChecker, build_collision_model
from planner.core.errors import RegraspError
from planner.core.forked import sigterm_unwinds
from planner.core.paths import DEFAULT_TASK
from planner.core.plain_text import plain
from planner.core.session import Session
from planner.model.task import Scene, load_task

from .client_guard import ClientGuard
from .collision_layer import CollisionLayer
from .layer_toggles import LayerToggles
from .notify import error_text
from .pose_choice import INITIAL, MOVED, OTHER, PoseChoice
from .robot_layer import RobotLayer
from .scene_layer import SceneLayer
from .serving_port import start_server
from .session_layers import SessionLayers
from .session_panel import SessionPanel
from .session_store import SESSIONS_DIR
from .tabs import PanelTabs
from .task_editor import TaskEditor
from .task_tab import TaskTab
from .view import CAMERA_LOOK_AT, CAMERA_POSITION, close_up, move_cameras, setup_view

MAX_LISTED_PAIRS = 8
SIGNAL_POLL = 0.25  # s: the longest a SIGTERM or Ctrl-C waits before the server starts stopping
VIEWS = ("overview", "start", "handover", "goal")  # camera buttons: the scene, the object at its start, the exchange, its goal
GRASP_CLOSE_UP = 0.6  # m from the object when a grasp is chosen


class Workbench:
    """One viser server showing one task, or one session of a task, at a time; construct to start, `close()` to stop."""

    def __init__(self, task: str | Path | None = None, host: str = "127.0.0.1", port: int = 8080,
                 session: str | Path | None = None, sessions_dir: Path = SESSIONS_DIR):
        # a bad task or session named on the command line fails before serving
        opened = Session.open(session) if session is not None else None
        scene = opened.scene if opened is not None else load_task(task or DEFAULT_TASK)
        self.host = host
        self.server = start_server(host, port)
        self.guard = ClientGuard(self.server, host)
        self._lock = threading.RLock()
        self._generation = 0
        self.collision_ready = threading.Event()
        self.scene: Scene = scene
        self.q = scene.q_initial.copy()
        self.robot_layer: RobotLayer | None = None
        self.scene_layer: SceneLayer | None = None
        self.collision_layer: CollisionLayer | None = None
        self.session: Session | None = None
        self.session_layers: SessionLayers | None = None
        self._checker: CollisionChecker | None = None
        self._sliders: viser.GuiFolderHandle | None = None
        self.layer_toggles: LayerToggles | None = None
        self._dimmed = False
        self._grasp_focus: str | None = None  # the grasp list framed while dimmed
        self._slider_of: dict[int, viser.GuiSliderHandle] = {}
        self._posing = False  # True while pose_robot moves the sliders: their callbacks must not redraw joint by joint
        setup_view(self.server)
        self._build_gui(sessions_dir)
        self._show(scene, opened)

    @property
    def url(self) -> str:
        """Where a browser finds the workbench."""
        return f"http://{self.host}:{self.server.get_port()}"

    def close(self) -> str | None:
        """Stop the server and the workers of a run still going; a collision model still being built is dropped. Returns
        where unsaved steps were kept (sessions/<task>-unsaved-N), if there were any."""
        with self._lock:
            self._generation += 1
        kept = self.session_panel.close()
        self.task_editor.close()
        self.server.stop()
        return kept

    def _build_gui(self, sessions_dir: Path) -> None:
        """The panel: the tabs (task, steps, playback, joints, view), and the collision status below them."""
        gui = self.server.gui
        self.tabs = PanelTabs(gui)
        with self.tabs.task:
            self.task_tab = TaskTab(gui, self.scene)
        self.task_editor = TaskEditor(self, self.tabs.task)  # its folder comes after the task's controls
        with self.tabs.view:
            self.views = gui.add_button_group("Camera", VIEWS)
            self.show_robot = gui.add_checkbox("Show robot", True)
            self.show_collision = gui.add_checkbox("Show collision geometry", False)
            self.show_steps = gui.add_checkbox("Show step results", True, hint="Every step layer at once (see Layers)")
            self.layers_folder = gui.add_folder("Layers")
        with self.tabs.joints:
            self.pose_choice = PoseChoice(gui, self.pose_robot, order=0.5)
            parts = self.scene.robot.part_names()
            self.part = gui.add_dropdown("Part", tuple(parts), initial_value=next((p for p in parts if p != "torso"), parts[0]),
                                         order=1.0)
            self.reset_button = gui.add_button("Reset", order=3.0, hint="Back to the task's initial configuration")
        self.session_panel = SessionPanel(self, sessions_dir)
        self.collision_status = gui.add_markdown("")
        task = self.task_tab
        task.choice.on_update(lambda e: None if task.syncing else self._load(task.chosen(), e.client))
        task.load_button.on_click(lambda e: self._load(task.path.value, e.client))
        self.show_robot.on_update(lambda e: self._set_robot_visible(e.target.value))
        self.show_collision.on_update(lambda e: self._set_collision_shown(e.target.value))
        self.show_steps.on_update(lambda e: self._set_steps_visible(e.target.value))
        self.views.on_click(lambda e: self.show_view(e.target.value, e.client))
        self.part.on_update(lambda _: self._rebuild_sliders())
        self.reset_button.on_click(lambda _: self.reset())

    def _load(self, chosen: Path | str, client: viser.ClientHandle | None) -> None:
        """Load a task chosen in the GUI (a listed file, or the text typed in "Task file") once unsaved steps are dealt
        with (asked in `client`'s tab); a bad file shows its error and keeps the current task."""
        try:
            path = chosen if isinstance(chosen, Path) else self.task_tab.typed(chosen)
        except RegraspError as exc:
            self.task_tab.refuse("Could not load the task", str(exc), client)
            return
        if path.resolve() == self.scene.source:
            return
        if self.session_panel.busy():  # the run would throw the new task away when it ends
            self.task_tab.refuse("Not loaded", "a step is running: wait for it to finish, then load the task", client)
            self.task_tab.choose(self.scene)
            return
        self.task_tab.error.visible = False
        try:
            scene = load_task(path)
        except Exception as exc:  # a bad file must never take the workbench down
            self.task_tab.refuse("Could not load the task", error_text(exc), client)
            self.task_tab.choose(self.scene)
            return
        self.replace_task(scene, client)

    def replace_task(self, scene: Scene, client: viser.ClientHandle | None = None) -> None:
        """Show `scene` instead of the current task (and session): the unsaved steps of the current one are first saved,
        kept or discarded as the person answers in `client`'s tab (kept as sessions/<task>-unsaved-N without a client)."""

        def replace() -> None:
            self._show(scene)
            self.session_panel.scratch = None  # the last task's unsaved steps kept (and said) now, not at the next run

        self.session_panel.ask_unsaved(client, f"load the task {scene.name}", replace,
                                       cancelled=lambda: self.task_tab.choose(self.scene))

    def show_session(self, session: Session) -> None:
        """Draw a session: its step layers, and its scene too when it is not the one shown."""
        with self._lock:
            if session.scene is self.scene:
                self._draw_session(session)
            else:
                self._show(session.scene, session)

    def _draw_session(self, session: Session | None) -> None:
        """Replace the step layers with those of `session` (drawn from its saved results), the last one in focus, and
        refresh the panel."""
        if self.session_layers is not None:
            self.session_layers.remove()
        if self.layer_toggles is not None:
            self.layer_toggles.remove()
        self.session = session
        with self.session_panel.step_controls:  # each layer's folder sits under the step table, shown when in focus
            self.session_layers = SessionLayers(self.server, session, workbench=self) if session is not None else None
        self.layer_toggles = None
        if self.session_layers is not None:
            self.session_layers.visible = self.show_steps.value
            last = next(iter(reversed(self.session_layers.layers)), None)
            self.layer_toggles = LayerToggles(self.server.gui, self.layers_folder, self.session_layers, last)
        self.session_panel.shown(session, self.session_layers)

    def focus_step(self, step: str) -> None:
        """Show only the layer of `step` (the others hidden, nothing dimmed), and only its controls in the Steps tab."""
        with self._lock:
            self.dim(False)
            if self.layer_toggles is not None:
                self.layer_toggles.focus(step)
            for name, layer in self.session_layers.layers.items() if self.session_layers is not None else ():
                if layer.folder is not None:
                    layer.folder.visible = name == step

    def focus_grasp(self, step: str, object_pose: np.ndarray) -> None:
        """A grasp chosen in the layer of `step`: that layer alone, the robot and obstacles dimmed, the object framed (once:
        the camera stays put while more ranks of the same list are chosen)."""
        with self._lock:
            if self._dimmed and self._grasp_focus == step:
                return
            if self.layer_toggles is not None:
                self.layer_toggles.focus(step)
            self.dim(True)
            self._grasp_focus = step
            if self.scene_layer is not None:
                move_cameras(self.server, *close_up(self.scene_layer.centre(object_pose), GRASP_CLOSE_UP))

    def dim(self, dimmed: bool) -> None:
        """Draw the robot and the obstacles translucent (something else is in focus), or opaque again."""
        with self._lock:
            if dimmed == self._dimmed:
                return
            self._dimmed = dimmed
            for layer in (self.robot_layer, self.scene_layer):
                if layer is not None:
                    layer.dim(dimmed)

    def exchange_point(self) -> np.ndarray | None:
        """Where the object is handed over: the shown double grasp's exchange pose, else the exchange step's best position."""
        layers = self.session_layers.layers if self.session_layers is not None else {}
        pairs = layers.get("double_grasps")
        if pairs is not None and pairs.result is not None and len(pairs.result) and self.scene_layer is not None:
            return self.scene_layer.centre(pairs.result.object_exchange[pairs.index])
        if self.session is not None and "exchange" in self.session.finished():
            exchange = self.session.result("exchange")
            return np.asarray(exchange.position) if len(exchange.best) else None
        return None

    def show_view(self, name: str, client: viser.ClientHandle | None = None) -> list[threading.Thread]:
        """Glide every camera to a view (see VIEWS); one the session cannot give yet (no exchange) says so to `client`."""
        with self._lock:
            self.dim(False)
            if name == "overview":
                target: tuple[np.ndarray, np.ndarray] | None = (np.array(CAMERA_POSITION), np.array(CAMERA_LOOK_AT))
            else:
                assert self.scene_layer is not None
                point = {"start": lambda: self.scene_layer.centre(self.scene.object_initial), "handover": self.exchange_point,
                         "goal": lambda: self.scene_layer.centre(self.scene.object_final)}[name]()
                target = close_up(point) if point is not None else None
        if target is None:
            if client is not None:
                client.add_notification("No exchange yet", "run the exchange step first", color="yellow", auto_close_seconds=5.0)
            return []
        return move_cameras(self.server, *target)

    def _show(self, scene: Scene, session: Session | None = None) -> None:
        """Replace the drawn task (and session), reset the robot and start building the collision model."""
        with self._lock:
            self._generation += 1
            for layer in (self.robot_layer, self.scene_layer, self.collision_layer):
                if layer is not None:
                    layer.remove()
            self.collision_layer, self._checker = None, None
            self.collision_ready.clear()
            self.scene, self.q = scene, scene.q_initial.copy()
            self.scene_layer = SceneLayer(self.server, scene)
            self.robot_layer = RobotLayer(self.server, scene.robot, self.q)
            self.robot_layer.visible = self.show_robot.value
            self.task_tab.show(scene, session)
            self.part.options = tuple(scene.robot.part_names())
            self._rebuild_sliders()
            self.collision_status.content = "*Collisions: building the collision model…*"
            self._draw_session(session)
            self.task_editor.shown(scene)
            threading.Thread(target=self._build_collisions, args=(scene, self._generation), daemon=True).start()

    def _build_collisions(self, scene: Scene, generation: int) -> None:
        """Background: build the collision model, then draw it (unless another task was loaded meanwhile)."""
        try:
            cm = build_collision_model(scene.robot, scene.environment)
        except Exception as exc:  # shown in the GUI; the rest of the workbench stays usable
            with self._lock:
                if generation == self._generation:
                    self.collision_status.content = f"**Collision model failed:** {plain(error_text(exc))}"
            return
        with self._lock:
            if generation != self._generation:
                return
            self.collision_layer = CollisionLayer(self.server, cm)
            self.collision_layer.shown = self.show_collision.value
            self._checker = cm.checker()
            self._refresh()
            self.collision_ready.set()

    def _rebuild_sliders(self) -> None:
        """One slider per joint of the chosen part, within the joint limits, starting at the current q."""
        with self._lock:
            if self._sliders is not None:
                self._sliders.remove()
            robot, names = self.scene.robot, self.scene.robot.joint_names()
            with self.tabs.joints:
                self._sliders = self.server.gui.add_folder(None, order=2.0)
            with self._sliders:
                self._slider_of = {
                    int(i): self.server.gui.add_slider(names[i].rsplit("/", 1)[-1], min=float(robot.lower[i]), max=float(robot.upper[i]),
                                                       step=0.01, initial_value=float(self.q[i]))
                    for i in robot.part_idx(self.part.value)
                }
            for i, slider in self._slider_of.items():
                slider.on_update(lambda e, i=i: self.set_joint(i, e.target.value))

    def set_joint(self, index: int, value: float) -> None:
        """Move one joint (q index, clipped to its limits), keep its slider in step and redraw; "Robot at" says so."""
        with self._lock:
            if self._posing:
                return
            robot = self.scene.robot
            value = float(np.clip(value, robot.lower[index], robot.upper[index]))
            slider = self._slider_of.get(index)
            if slider is not None and slider.value != value:
                slider.value = value  # its callback comes back here with the same value
                return
            self.q[index] = value
            self.pose_choice.showing(MOVED)
            self._refresh()

    def reset(self) -> None:
        """Back to the task's initial configuration, the object on the desk at its initial placement."""
        self.pose_robot(self.scene.q_initial, self.scene.object_initial, INITIAL)

    def pose_robot(self, q: np.ndarray, object_pose: np.ndarray | None = None, label: str = OTHER) -> None:
        """Put the robot at configuration q and the object at `object_pose` (None: where it is); the joint sliders follow in
        place, "Robot at" shows `label`, collisions are checked."""
        with self._lock:
            self.dim(False)
            self.q = np.array(q, dtype=float)
            self._posing = True
            try:
                for i, slider in self._slider_of.items():
                    slider.value = float(self.q[i])
            finally:
                self._posing = False
            if object_pose is not None and self.scene_layer is not None:
                self.scene_layer.place_object(object_pose)
            self.pose_choice.showing(label)
            self._refresh()

    def _set_robot_visible(self, visible: bool) -> None:
        with self._lock:
            if self.robot_layer is not None:
                self.robot_layer.visible = visible

    def _set_steps_visible(self, visible: bool) -> None:
        with self._lock:
            if self.session_layers is not None:
                self.session_layers.visible = visible

    def _set_collision_shown(self, shown: bool) -> None:
        with self._lock:
            if self.collision_layer is not None:
                self.collision_layer.show(shown, self.q)

    def _refresh(self) -> None:
        """Redraw the robot at q, check it and paint the colliding geometries."""
        assert self.robot_layer is not None
        self.robot_layer.update(self.q)
        if self._checker is None or self.collision_layer is None:
            return
        pairs = self._checker.colliding_pairs(self.q)
        self.collision_layer.update(self.q, {name for pair in pairs for name in pair})
        if not pairs:
            self.collision_status.content = "Collisions: **none**"
        else:
            listed = ", ".join(f"*{plain(a)}* ↔ *{plain(b)}*" for a, b in pairs[:MAX_LISTED_PAIRS])
            more = f" and {len(pairs) - MAX_LISTED_PAIRS} more" if len(pairs) > MAX_LISTED_PAIRS else ""
            self.collision_status.content = f"<span style='color:#d22'>**{len(pairs)} colliding pairs:**</span> {listed}{more}"


def run(task: str | Path | None = None, host: str = "127.0.0.1", port: int = 8080, session: str | Path | None = None) -> None:
    """Start the workbench (on a task, or replaying a saved session) and serve until interrupted (Ctrl-C)."""
    workbench = Workbench(task, host, port, session=session)
    print(f"regrasp workbench: open {workbench.url} (Ctrl-C stops it)", file=sys.stderr, flush=True)
    try:
        with sigterm_unwinds():  # SIGTERM ends the server like Ctrl-C: the workers of a running step are killed too
            while True:  # short sleeps: a signal the kernel hands to another thread is handled when the main thread's
                time.sleep(SIGNAL_POLL)  # sleep ends (viser's sleep_forever sleeps an hour at a time)
    except KeyboardInterrupt:
        pass
    finally:
        kept = workbench.close()
        if kept is not None:
            print(f"regrasp workbench: {kept}", file=sys.stderr, flush=True)
