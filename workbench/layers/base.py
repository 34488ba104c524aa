"""The base of a step layer: it owns the scene nodes drawing one step's result under one root."""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import viser

from planner.core.errors import RegraspError
from planner.core.session import Session
from planner.model.task import Scene
from planner.pipeline import step_named

from ..robot_layer import RobotLayer
from ..rooted import Rooted
from ..scene_layer import SceneLayer

if TYPE_CHECKING:
    from ..pose_choice import PoseChoice
    from ..tabs import PanelTabs


class Host(Protocol):
    """What a layer may use of the live workbench: its robot (posed fully, or only its meshes), the scene's object, and
    what the layers share (the layer toggles, the camera)."""

    q: np.ndarray
    robot_layer: RobotLayer | None
    scene_layer: SceneLayer | None
    tabs: PanelTabs  # a layer's controls beyond its folder go into these tabs (the motion's into Playback)
    pose_choice: PoseChoice  # "Robot at": says what the robot shows

    def pose_robot(self, q: np.ndarray, object_pose: np.ndarray | None = None, label: str = ...) -> None:
        """Put the robot at q and the object at `object_pose` (None: where it is); "Robot at" shows `label`."""


@dataclass(frozen=True, eq=False)
class Pose:
    """A whole pose a step found: the robot's configuration and where the object is then (on the desk, in a hand, in both)."""

    q: np.ndarray
    object_pose: np.ndarray  # 4x4, world frame


class StepLayer(Rooted, ABC):
    """Draws one step's result; `update(result)` (re)draws it and fills `poses`: whole poses worth showing, by label."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Host | None = None,
                 session: Session | None = None):
        super().__init__(server, root)
        self.server = server
        self.scene = scene
        self.workbench = workbench  # the live workbench whose robot a layer may pose; None in an HTML export
        self.session = session  # the drawn Session: a layer reads the earlier steps' results it needs from it
        self.name = root
        self.poses: dict[str, Pose] = {}
        self.folder: viser.GuiFolderHandle | None = None  # the layer's GUI, if it has one: removed with the layer

    @property
    def step(self) -> str:
        """The name of the step this layer draws (its root's last part)."""
        return self.name.rsplit("/", 1)[-1]

    def earlier(self, name: str) -> Any:
        """An earlier step's result from the drawn session (e.g. the grasp lists that a later step refers to by rank)."""
        if self.session is None:
            raise RegraspError(f"{type(self).__name__} needs the session to read step '{name}'")
        return self.session.result(name)

    def params_of(self, name: str) -> Any:
        """The frozen parameters the drawn session ran step `name` with (what its result was computed with)."""
        if self.session is None:
            raise RegraspError(f"{type(self).__name__} needs the session to read the parameters of step '{name}'")
        return step_named(name).recorded_params(self.session.record_of(name)["params"])

    @abstractmethod
    def update(self, result: Any) -> None:
        """Draw `result`, replacing what was drawn before."""

    def remove_folder(self) -> None:
        """Take the layer's GUI folder out of the panel (before a redraw builds a new one)."""
        if self.folder is not None:
            self.folder.remove()
            self.folder = None

    def remove(self) -> None:
        self.remove_folder()
        super().remove()
