"""Task editing in the browser (the Task tab's "Edit the task" folder): the object's placements (typed, or dragged with
the handles in the 3-D view), its mesh (uploaded), the robot spec, obstacles moved, resized, added and removed, each
edit checked live (`regrasp check`'s checks) and "Save task as" writing a task file `regrasp plan` reads.

An edit builds the task's scene at once (a bad edit is refused with the loader's message and the controls go back); the
workbench shows it a moment later, when the edits pause (`LiveCheck`), which drops the steps shown: they were planned
for the task before (a scratch session's unsaved steps are kept, as when another task is loaded). The task data edited
is what the task file holds; `planner.model.task_edit` makes each change, `planner.model.task_file` writes the file.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from planner.core.errors import RegraspError
from planner.core.paths import TASKS_DIR
from planner.core.plain_text import plain
from planner.model.geometry import heading, pose
from planner.model.robot import load_robot
from planner.model.task import OBJECTS_DIR, ROBOTS_DIR, Scene, load_task, scene_from_dict
from planner.model.task_edit import (
    MAX_STEP,
    TaskData,
    rest_on_support,
    support_top,
    with_new_obstacle,
    with_object_mesh,
    with_obstacle_pose,
    with_obstacle_size,
    with_placement,
    with_robot,
    without_obstacle,
)
from planner.model.task_file import check_task_name, file_reference, task_path, write_task

from .live_check import LiveCheck
from .mesh_upload import ACCEPTED, UPLOADS_DIR, store_upload
from .meshes import matrix_wxyz
from .notify import error_text
from .task_handles import TaskHandles

if TYPE_CHECKING:
    from .app import Workbench

NO_OBSTACLE = "(no obstacle)"
EDITED = "*Edited, not saved: steps run now plan the edited task; **Save task as** keeps it as a file.*"


def _heading_deg(T: np.ndarray) -> float:
    return round(float(np.degrees(heading(T))), 1)


class TaskEditor:
    """The editing controls in `container` (a GUI folder or tab) and the handles in the 3-D view; `shown` is told of every
    task the workbench shows, `close` stops the live check."""

    def __init__(self, workbench: Workbench, container: Any, uploads_dir: Path = UPLOADS_DIR, tasks_dir: Path = TASKS_DIR):
        self.wb = workbench
        self.uploads_dir, self.tasks_dir = uploads_dir, tasks_dir
        self._lock = threading.RLock()
        self._syncing = False  # True while the controls are set from the task: their callbacks must not edit
        self._scene: Scene = workbench.scene  # the task as edited (the newest edit)
        self._data: TaskData = {}
        self._source = Path()
        self._robot_path: Path | None = None
        self._applying: Scene | None = None  # the edited scene being handed to the workbench
        self._asking: viser.ClientHandle | None = None  # the tab asked about unsaved steps an edit would drop, until it answers
        self.edited = False
        self._closed = False
        self.handles = TaskHandles(workbench.server, self._handle_moved)
        self.live = LiveCheck(self._apply, self._show_check)
        gui = workbench.server.gui
        specs = tuple(p.name for p in sorted(ROBOTS_DIR.glob("*.toml")))
        with container, gui.add_folder("Edit the task", expand_by_default=False):
            self.show_handles = gui.add_checkbox("Handles in 3-D", False, hint="Drag the start, the goal and the chosen "
                                                 "obstacle in the view; placements rest on the support under them")
            self.initial = gui.add_vector3("Start x, y, °", (0.0, 0.0, 0.0), step=0.01, hint="The object's initial "
                                           "placement: x, y (m) and heading (degrees); its height comes from the support")
            self.final = gui.add_vector3("Goal x, y, °", (0.0, 0.0, 0.0), step=0.01, hint="The object's final placement")
            self.robot_spec = gui.add_dropdown("Robot spec", specs, hint="The robot specs in assets/robots")
            self.upload = gui.add_upload_button("Upload object mesh", mime_type=ACCEPTED, hint="An object mesh in metres, "
                                                f"z up ({ACCEPTED}); checked as `regrasp check` checks a task's mesh")
            self.obstacle = gui.add_dropdown("Obstacle", (NO_OBSTACLE,), hint="The obstacle the fields below and its "
                                             "handle move")
            self.obstacle_xyz = gui.add_vector3("Obstacle x, y, z", (0.0, 0.0, 0.0), step=0.01, hint="Its centre (m)")
            self.box_size = gui.add_vector3("Box size", (0.1, 0.1, 0.1), step=0.01, min=(0.001,) * 3, visible=False,
                                            hint="Length along x, y and z (m)")
            self.cylinder_size = gui.add_vector2("Radius, length", (0.05, 0.1), step=0.01, min=(0.001,) * 2, visible=False,
                                                 hint="Radius and length along its axis (m)")
            self.add_box = gui.add_button("Add a box")
            self.add_cylinder = gui.add_button("Add a cylinder")
            self.remove_obstacle = gui.add_button("Remove the obstacle")
            self.status = gui.add_markdown("")
            self.check = gui.add_markdown("*Check: waiting for the task…*")
            self.save_name = gui.add_text("Save as", "", hint=f"A task name: saved as {tasks_dir}/<name>.toml")
            self.save_button = gui.add_button("Save task as")
            self.revert_button = gui.add_button("Revert", hint="The task as its file has it: the edits go")
        self.show_handles.on_update(lambda e: setattr(self.handles, "visible", e.target.value))
        for which, vector in (("initial", self.initial), ("final", self.final)):
            vector.on_update(lambda e, which=which: self._typed_placement(which, e.target.value, e.client))
        self.robot_spec.on_update(lambda e: self._robot_chosen(e.target.value, e.client))
        self.upload.on_upload(lambda e: self._uploaded(e.target.value, e.client))
        self.obstacle.on_update(lambda _: None if self._syncing else self._sync())
        self.obstacle_xyz.on_update(lambda e: self._typed_obstacle(e.target.value, e.client))
        for control in (self.box_size, self.cylinder_size):
            control.on_update(lambda e: self._edit(lambda d: with_obstacle_size(d, self.obstacle.value, e.target.value), e.client))
        self.add_box.on_click(lambda e: self._add("box", e.client))
        self.add_cylinder.on_click(lambda e: self._add("cylinder", e.client))
        self.remove_obstacle.on_click(lambda e: self._edit(lambda d: without_obstacle(d, self.obstacle.value), e.client))
        self.save_button.on_click(lambda e: self._save_clicked(e.client))
        self.revert_button.on_click(lambda e: self._revert(e.client))

    # -- the task shown --------------------------------------------------------------------------

    def shown(self, scene: Scene) -> None:
        """The workbench shows `scene`: an edit of ours is kept; any other task (loaded, replayed) is edited from scratch."""
        with self._lock:
            if scene is self._applying:
                return
            self._scene, self._data, self._source = scene, scene.task, scene.source
            self._robot_path = scene.robot.spec.source
            self.edited = False
            self.save_name.value = scene.name
            self._sync()
        self.live.request(scene)

    def _sync(self) -> None:
        """Set every control and handle from the edited task (their callbacks do not edit meanwhile)."""
        with self._lock:
            scene, self._syncing = self._scene, True
            try:
                for vector, T in ((self.initial, scene.object_initial), (self.final, scene.object_final)):
                    vector.value = (round(float(T[0, 3]), 4), round(float(T[1, 3]), 4), _heading_deg(T))
                self.handles.place("initial", scene.object_initial)
                self.handles.place("final", scene.object_final)
                robot = str(self._data.get("robot", ""))
                if robot not in self.robot_spec.options:
                    self.robot_spec.options = (*[o for o in self.robot_spec.options if o.endswith(".toml")], robot)
                self.robot_spec.value = robot
                names = tuple(o.name for o in scene.environment) or (NO_OBSTACLE,)
                chosen = self.obstacle.value if self.obstacle.value in names else names[0]
                self.obstacle.options, self.obstacle.value = names, chosen
                self._sync_obstacle(chosen)
                self.status.content = EDITED if self.edited else ""
                self.revert_button.disabled = not self.edited or self._source.suffix != ".toml"
            finally:
                self._syncing = False

    def _sync_obstacle(self, name: str) -> None:
        obstacle = next((o for o in self._scene.environment if o.name == name), None)
        self.handles.choose_obstacle(name if obstacle else None, obstacle.pose if obstacle else None)
        for control in (self.obstacle_xyz, self.remove_obstacle):
            control.disabled = obstacle is None
        if obstacle is not None:
            self.obstacle_xyz.value = tuple(round(float(v), 4) for v in obstacle.pose[:3, 3])
        self.box_size.visible = obstacle is not None and obstacle.shape == "box"
        self.cylinder_size.visible = obstacle is not None and obstacle.shape == "cylinder"
        if self.box_size.visible:
            self.box_size.value = tuple(obstacle.size)
        if self.cylinder_size.visible:
            self.cylinder_size.value = tuple(obstacle.size)

    # -- edits -----------------------------------------------------------------------------------

    def _edit(self, change: Callable[[TaskData], TaskData], client: viser.ClientHandle | None,
              robot_path: Path | None = None) -> bool:
        """Apply `change` to the task data: the new scene is built now (a failure is said and the controls go back); once
        the steps shown are dealt with (unsaved ones: asked in `client`'s tab), the workbench shows it and it is checked
        when the edits pause. False when the edit was refused or waits for the answer."""
        with self._lock:
            if self._syncing:
                return False
            try:
                if self.wb.session_panel.busy():
                    raise RegraspError("a step is running: wait for it to finish, then edit the task")
                if self._asking is not None and self._asking.client_id in self.wb.server.get_clients():
                    raise RegraspError("answer the question about the steps run first")
                data = change(self._data)
                scene = scene_from_dict(data, self._source, robot_path or self._robot_path, self._scene.meshes)
            except Exception as exc:  # a refused edit never takes the workbench down
                self._sync()  # the controls go back, then say why
                self._refuse(error_text(exc), client)
                return False
            done: list[bool] = []

            def commit() -> None:
                with self._lock:
                    self._asking = None
                    self._scene, self._data, self.edited = scene, data, True
                    self._robot_path = robot_path or self._robot_path
                    self._sync()
                self.check.content = "*Check: running…*"
                self.live.request(scene)
                done.append(True)

            def cancelled() -> None:
                with self._lock:
                    self._asking = None
                    self._sync()
            self._asking = client
            self.wb.session_panel.ask_unsaved(client, "edit the task", commit, cancelled)
            return bool(done)

    def _refuse(self, message: str, client: viser.ClientHandle | None) -> None:
        self.status.content = f"<span style='color:#d22'>**Edit refused:**</span> {plain(message)}"
        if client is not None:
            client.add_notification("Edit refused", message, color="red", auto_close_seconds=10.0)

    def _typed_placement(self, which: str, value: tuple[float, float, float], client: viser.ClientHandle) -> None:
        T = self._scene.object_initial if which == "initial" else self._scene.object_final
        x, y, degrees = value
        self._edit(lambda d: with_placement(d, which, rest_on_support(self._scene, which, (x, y, T[2, 3]), np.radians(degrees))),
                   client)

    def _typed_obstacle(self, xyz: tuple[float, float, float], client: viser.ClientHandle) -> None:
        obstacle = next((o for o in self._scene.environment if o.name == self.obstacle.value), None)
        if obstacle is not None:
            self._edit(lambda d: with_obstacle_pose(d, obstacle.name, xyz, heading(obstacle.pose)), client)

    def _handle_moved(self, name: str, position: np.ndarray, yaw: float, ended: bool, client: viser.ClientHandle | None) -> None:
        """A handle dragged: a placement previewed resting on its support while it moves, and edited when it is let go."""
        if name == "obstacle":
            obstacle = self.handles.obstacle
            if ended and obstacle is not None:
                self._edit(lambda d: with_obstacle_pose(d, obstacle, position, yaw), client)
            return
        try:
            placement = rest_on_support(self._scene, name, position, yaw)
        except RegraspError as exc:
            self._refuse(str(exc), client)
            return
        if ended:
            self._edit(lambda d: with_placement(d, name, placement), client)
            return
        layer, T = self.wb.scene_layer, pose(placement["xyz"], placement["rpy"])
        if layer is not None and name == "initial":
            layer.place_object(T)
        elif layer is not None:
            layer.ghost.wxyz, layer.ghost.position = matrix_wxyz(T)

    def _robot_chosen(self, name: str, client: viser.ClientHandle) -> None:
        path = ROBOTS_DIR / name
        if self._syncing or not path.is_file():
            return
        try:
            joints = load_robot(path).joint_names()
        except Exception as exc:  # a broken spec file: said, the task stays
            self._sync()
            self._refuse(error_text(exc), client)
            return
        dropped: list[str] = []

        def change(data: TaskData) -> TaskData:
            new, dropped[:] = with_robot(data, name, joints)
            return new
        if self._edit(change, client, robot_path=path) and dropped:
            self.status.content = EDITED + f"\n\nJoints not on this robot, dropped from the start and end: {plain(', '.join(dropped))}"

    def _uploaded(self, upload: viser.UploadedFile, client: viser.ClientHandle) -> None:
        """Keep an uploaded mesh (checked as a task's mesh) and make it the object."""
        try:
            path = store_upload(upload.name, upload.content, self.uploads_dir)
        except Exception as exc:  # refused with the loader's message
            self._refuse(error_text(exc), client)
            return
        reference = file_reference(path, self._source.parent, OBJECTS_DIR)
        up = "y" if path.suffix == ".glb" else "z"  # glTF files are y-up
        if self._edit(lambda d: with_object_mesh(d, reference, up), client) and client is not None:
            client.add_notification("Mesh uploaded", f"the object is now {path.name}", color="blue", auto_close_seconds=5.0)

    def _add(self, shape: str, client: viser.ClientHandle) -> None:
        """A new obstacle standing on the support between the two placements, chosen for moving."""
        scene = self._scene
        x, y, z = (scene.object_initial[:3, 3] + scene.object_final[:3, 3]) / 2
        top = support_top(scene.environment, x, y, z + MAX_STEP)
        added: list[str] = []

        def change(data: TaskData) -> TaskData:
            new, name = with_new_obstacle(data, shape, (x, y, top))
            added.append(name)
            return new
        if self._edit(change, client):
            self.obstacle.value = added[0]

    # -- showing and checking ----------------------------------------------------------------------

    def _apply(self, scene: Scene) -> None:
        """The live check's thread, once the edits pause: the workbench shows the edited task (unless it already does). A
        task only shown (loaded, replayed, a run's session) is never applied: the workbench may already show another
        object of the same task, and applying the older one would replace its session."""
        with self._lock:
            if not self.edited or scene is not self._scene or scene is self.wb.scene or self.wb.session_panel.busy():
                return
            self._applying = scene
        self.wb.replace_task(scene)  # the person was asked about unsaved steps when the edit was made

    def _show_check(self, text: str) -> None:
        self.check.content = text

    # -- saving ----------------------------------------------------------------------------------

    def _save_clicked(self, client: viser.ClientHandle) -> None:
        """Save under the name typed; an existing task file is replaced only after the person confirms."""
        try:
            path = task_path(self.tasks_dir, self.save_name.value)
        except RegraspError as exc:
            self._refuse(str(exc), client)
            return
        if path.exists():
            with client.gui.add_modal(f"Overwrite {path.name}?") as modal:
                client.gui.add_markdown(f"*{plain(path)}* already exists. Replace it with the task as edited?")
                overwrite = client.gui.add_button("Overwrite", color="red")
                cancel = client.gui.add_button("Cancel")
            overwrite.on_click(lambda _: (modal.close(), self._save_reporting(path, client, overwrite=True)))
            cancel.on_click(lambda _: modal.close())
            return
        self._save_reporting(path, client)

    def save(self, path: Path, overwrite: bool = False) -> Path:
        """Write the task as edited to `path` (its `name` becomes the file's), then show it from there if no step is shown."""
        with self._lock:
            data = {**self._data, "name": check_task_name(path.stem)}
            write_task(data, self._source, path, overwrite)
        if self.wb.session is None or not self.wb.session.finished():
            self.wb.replace_task(load_task(path))
        return path

    def _save_reporting(self, path: Path, client: viser.ClientHandle, overwrite: bool = False) -> None:
        try:
            self.save(path, overwrite)
        except Exception as exc:  # e.g. a read-only folder, or the file appeared meanwhile
            self._refuse(error_text(exc), client)
            return
        self.status.content = f"Saved as *{plain(path)}*: `regrasp plan {plain(path.stem)}` plans it."
        client.add_notification("Task saved", str(path), color="blue", auto_close_seconds=5.0)

    def _revert(self, client: viser.ClientHandle) -> None:
        """Show the task as its file has it (asking about unsaved steps, as loading a task does)."""
        try:
            scene = load_task(self._source)
        except Exception as exc:  # the file changed meanwhile and is bad now
            self._refuse(error_text(exc), client)
            return
        self.wb.replace_task(scene, client)

    def close(self) -> None:
        """Stop the live check and take the handles out of the view (once: closing again does nothing)."""
        with self._lock:
            closed, self._closed = self._closed, True
        if not closed:
            self.live.close()
            self.handles.remove()

