"""The workbench app: a viser server that shows a task or a session, lets a person pose the robot and shows its collisions.

It holds no planning logic: it loads a task with `planner.model.task` or a session with `planner.core.session`,
builds the collision model with `planner.collision.checker` and draws what comes back through one layer per
concern (the session's steps through `session_layers`; the Session panel runs steps via `planner.core.runner`).
"""
from __future__ import annotations

import sys
import threading
from pathlib import Path

import numpy as np
import viser

from planner.collision.checker import CollisionChecker, build_collision_model
from planner.core.errors import RegraspError
from planner.core.forked import sigterm_unwinds
from planner.core.paths import DEFAULT_TASK, PROJECT_ROOT, TASKS_DIR
from planner.core.plain_text import plain
from planner.core.session import MANIFEST, Session
from planner.model.task import Scene, load_task

from .client_guard import ClientGuard
from .collision_layer import CollisionLayer
from .layer_toggles import LayerToggles
from .notify import error_text
from .robot_layer import RobotLayer
from .scene_layer import SceneLayer
from .serving_port import start_server
from .session_layers import SessionLayers
from .session_panel import INITIAL, MOVED, OTHER, SessionPanel
from .session_store import SESSIONS_DIR
from .task_editor import TaskEditor
from .view import CAMERA_LOOK_AT, CAMERA_POSITION, close_up, move_cameras, setup_view

MAX_LISTED_PAIRS = 8
VIEWS = ("overview", "start", "handover", "goal")  # camera buttons: the scene, the object at its start, the exchange, its goal
GRASP_CLOSE_UP = 0.6  # m from the object when a grasp is chosen


def task_choices(current: Path) -> dict[str, Path]:
    """Dropdown label -> file for the tasks in assets/tasks, plus the current task if it lives elsewhere."""
    choices = {p.stem: p.resolve() for p in sorted(TASKS_DIR.glob("*.toml"))}
    if current.resolve() not in choices.values():
        label = f"session {current.parent.name}" if current.name == MANIFEST else str(current)  # a replayed session's task
        choices[label] = current.resolve()
    return choices


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
        self.task_roots = (PROJECT_ROOT, scene.source.resolve().parent)  # where "Load file" may read task files
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
        self._syncing_choices = False  # True while _show rewrites the task dropdown: its callbacks must not load a task
        self._posing = False  # True while pose_robot moves the sliders: their callbacks must not redraw joint by joint
        setup_view(self.server)
        self._build_gui(sessions_dir)
        self._show(scene, opened)

    @property
    def url(self) -> str:
        """Where a browser finds the workbench."""
        return f"http://{self.host}:{self.server.get_port()}"

    def close(self) -> None:
        """Stop the server and the workers of a run still going; a collision model still being built is dropped."""
        with self._lock:
            self._generation += 1
        self.session_panel.close()
        self.task_editor.close()
        self.server.stop()

    def _build_gui(self, sessions_dir: Path) -> None:
        """The panel: task choice, view toggles, the session, joint sliders of one part, collision status."""
        gui = self.server.gui
        with gui.add_folder("Task") as task_folder:
            self._task_files = task_choices(self.scene.source)
            self.task_choice = gui.add_dropdown("Task", tuple(self._task_files), initial_value=self._label_of(self.scene.source))
            self.task_path = gui.add_text("Task file", str(self.scene.source))
            self.load_button = gui.add_button("Load file")
            self.task_info = gui.add_markdown("")
            self.task_error = gui.add_markdown("", visible=False)
        self.task_editor = TaskEditor(self, task_folder)
        with gui.add_folder("View"):
            self.show_robot = gui.add_checkbox("Show robot", True)
            self.show_collision = gui.add_checkbox("Show collision geometry", False)
            self.show_steps = gui.add_checkbox("Show step results", True, hint="Every step layer at once (see Layers)")
            self.views = gui.add_button_group("Camera", VIEWS)
        self.layers_folder = gui.add_folder("Layers")
        self.session_panel = SessionPanel(self, sessions_dir)
        with gui.add_folder("Joints") as self._joints:
            parts = self.scene.robot.part_names()
            self.part = gui.add_dropdown("Part", tuple(parts), initial_value=next((p for p in parts if p != "torso"), parts[0]), order=1.0)
            self.reset_button = gui.add_button("Reset", order=3.0, hint="Back to the task's initial configuration")
        self.collision_status = gui.add_markdown("")
        self.task_choice.on_update(lambda e: None if self._syncing_choices else self._load(self._task_files[e.target.value], e.client))
        self.load_button.on_click(lambda e: self._load(self.task_path.value, e.client))
        self.show_robot.on_update(lambda e: self._set_robot_visible(e.target.value))
        self.show_collision.on_update(lambda e: self._set_collision_shown(e.target.value))
        self.show_steps.on_update(lambda e: self._set_steps_visible(e.target.value))
        self.views.on_click(lambda e: self.show_view(e.target.value, e.client))
        self.part.on_update(lambda _: self._rebuild_sliders())
        self.reset_button.on_click(lambda _: self.reset())

    def _label_of(self, path: Path) -> str:
        """The task dropdown's label for a task file."""
        return next(label for label, p in self._task_files.items() if p == path.resolve())

    def typed_task(self, text: str) -> Path:
        """The task file typed in "Task file": a .toml file in the project or in the folder of the task the workbench
        started with (a browser must not make the workbench read any file it likes)."""
        path = Path(text.strip()).expanduser().resolve()
        if path.suffix != ".toml" or not any(path.is_relative_to(root) for root in self.task_roots):
            where = " or ".join(str(root) for root in dict.fromkeys(self.task_roots))
            raise RegraspError(f"Task file: expected a .toml file in {where}, got {text.strip()!r:.200}")
        return path

    def _load(self, chosen: Path | str, client: viser.ClientHandle | None) -> None:
        """Load a task chosen in the GUI (a listed file, or the text typed in "Task file"); a bad file shows its error
        and keeps the current task."""
        try:
            path = chosen if isinstance(chosen, Path) else self.typed_task(chosen)
        except RegraspError as exc:
            self._refuse_task("Could not load the task", str(exc), client)
            return
        if path.resolve() == self.scene.source:
            return
        if self.session_panel.busy():  # the run would throw the new task away when it ends
            self._refuse_task("Not loaded", "a step is running: wait for it to finish, then load the task", client)
            return
        self.task_error.visible = False
        try:
            scene = load_task(path)
        except Exception as exc:  # a bad file must never take the workbench down
            self._refuse_task("Could not load the task", error_text(exc), client)
            return
        self.show_task(scene)

    def show_task(self, scene: Scene) -> None:
        """Show another task (loaded, or edited in the Task tab): the steps shown were planned for the task before and go."""
        with self._lock:
            self._show(scene)
            self.session_panel.scratch = None  # the last task's unsaved steps kept (and said) now, not at the next run

    def _refuse_task(self, title: str, message: str, client: viser.ClientHandle | None) -> None:
        """Say under the task (and to the asking tab) why the task shown stays."""
        self.task_error.content = f"**{title}:** {plain(message)}"
        self.task_error.visible = True
        if client is not None:
            client.add_notification(title, message, color="red", auto_close_seconds=10.0)

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
        self.session_layers = SessionLayers(self.server, session, workbench=self) if session is not None else None
        self.layer_toggles = None
        if self.session_layers is not None:
            self.session_layers.visible = self.show_steps.value
            last = next(iter(reversed(self.session_layers.layers)), None)
            self.layer_toggles = LayerToggles(self.server.gui, self.layers_folder, self.session_layers, last)
        self.session_panel.shown(session, self.session_layers)

    def focus_step(self, step: str) -> None:
        """Show only the layer of `step` (the others hidden, nothing dimmed)."""
        with self._lock:
            self.dim(False)
            if self.layer_toggles is not None:
                self.layer_toggles.focus(step)

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
            self._task_files = task_choices(scene.source)
            self._syncing_choices = True  # viser calls on_update synchronously, within this block
            try:
                self.task_choice.options = tuple(self._task_files)
                self.task_choice.value = self._label_of(scene.source)
            finally:
                self._syncing_choices = False
            # a replayed session's task file is its session.json: show the task it came from (a name or a relative path)
            self.task_path.value = session.manifest.get("task_source", "") if session is not None and scene is session.scene \
                else str(scene.source)
            about = f" — {plain(scene.description)}" if scene.description else ""
            self.task_info.content = f"**{plain(scene.name)}**{about}"
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
            with self._joints:
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
            self.session_panel.showing(MOVED)
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
            self.session_panel.showing(label)
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
            workbench.server.sleep_forever()
    except KeyboardInterrupt:
        pass
    finally:
        workbench.close()
