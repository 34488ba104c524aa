"""The task editor's handles in the 3-D view: a transform gizmo on the object's initial placement, one on its final
placement (both slide over the support and turn about the vertical only: their height comes from the support), and
one on the obstacle chosen in the panel.

A drag previews the placement as it goes (the object drawn where it would rest) and is handed to the editor when it
ends; the handles know nothing of tasks beyond the poses they are given.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import viser

from planner.model.geometry import heading

ROOT = "/task_editor"
PLACEMENT_SCALE = 0.18  # m: a placement handle's arm length
OBSTACLE_SCALE = 0.25
# (handle name, position, heading in rad, whether the drag ended, the dragging tab)
Moved = Callable[[str, np.ndarray, float, bool, viser.ClientHandle | None], None]


def wxyz_heading(wxyz: np.ndarray) -> float:
    """The heading (rad) of a rotation given as wxyz: the angle of its x axis about the vertical."""
    w, x, y, z = (float(v) for v in wxyz)
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def yaw_wxyz(yaw: float) -> np.ndarray:
    """The wxyz quaternion of a turn `yaw` (rad) about the vertical."""
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


class TaskHandles:
    """The gizmos under ROOT: `initial`, `final` and `obstacle` (that one only while an obstacle is chosen); every pose
    change goes to `moved`."""

    def __init__(self, server: viser.ViserServer, moved: Moved):
        self.server = server
        self._moved = moved
        self.root = server.scene.add_frame(ROOT, show_axes=False, visible=False)
        self.gizmos: dict[str, viser.TransformControlsHandle] = {}
        for name in ("initial", "final"):
            self.gizmos[name] = self._gizmo(name, PLACEMENT_SCALE, (True, True, False))
        self.obstacle: str | None = None  # the obstacle the obstacle handle moves

    def _gizmo(self, name: str, scale: float, axes: tuple[bool, bool, bool]) -> viser.TransformControlsHandle:
        gizmo = self.server.scene.add_transform_controls(f"{ROOT}/{name}", scale=scale, active_axes=axes,
                                                         disable_sliders=True, depth_test=False)

        def changed(event: viser.TransformControlsEvent) -> None:
            if event.phase != "start":
                self._moved(name, np.array(event.target.position, float), wxyz_heading(event.target.wxyz),
                            event.phase == "end", event.client)
        gizmo.on_update(changed)
        return gizmo

    @property
    def visible(self) -> bool:
        return self.root.visible

    @visible.setter
    def visible(self, value: bool) -> None:
        self.root.visible = value

    def place(self, name: str, T: np.ndarray) -> None:
        """Put handle `name` at the pose T (its heading only: the handle turns about the vertical)."""
        T = np.asarray(T, float)
        gizmo = self.gizmos[name]
        gizmo.position = T[:3, 3]
        gizmo.wxyz = yaw_wxyz(heading(T))

    def choose_obstacle(self, name: str | None, T: np.ndarray | None = None) -> None:
        """Put the obstacle handle on obstacle `name` at its pose T (None: no obstacle handle)."""
        if name != self.obstacle and "obstacle" in self.gizmos:
            self.gizmos.pop("obstacle").remove()
        self.obstacle = name
        if name is None or T is None:
            return
        if "obstacle" not in self.gizmos:
            self.gizmos["obstacle"] = self._gizmo("obstacle", OBSTACLE_SCALE, (True, True, True))
        self.place("obstacle", T)

    def remove(self) -> None:
        self.root.remove()

