"""The "Robot at" dropdown (Joints tab): the whole poses the task and the drawn steps offer, and what the robot shows."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import viser

from .layers.base import Pose

INITIAL = "task: initial configuration"
MOVED = "joints moved by hand"
OTHER = "another configuration"


class PoseChoice:
    """Choosing a label poses the robot (through `pose`); `showing` makes the dropdown say what the robot shows."""

    def __init__(self, gui: viser.GuiApi, pose: Callable[[np.ndarray, np.ndarray, str], None], order: float | None = None):
        self._pose = pose
        self.poses: dict[str, Pose] = {}
        self._syncing = False  # True while the dropdown is rewritten here: its callback must not pose the robot
        self._watcher: Callable[[str], None] | None = None
        self.dropdown = gui.add_dropdown("Robot at", (INITIAL,), hint="The robot and the object as the task or a step found "
                                         "them; says what is shown", order=order)
        self.dropdown.on_update(lambda e: self._chosen(e.target.value))

    def offer(self, poses: dict[str, Pose], label: str) -> None:
        """Offer `poses` (by label) and say the robot shows `label`; the robot stays where it is (a run keeps it there)."""
        self.poses = dict(poses)
        self._syncing = True
        try:
            self.dropdown.options = tuple(self.poses)
        finally:
            self._syncing = False
        self.showing(label)

    def _chosen(self, label: str) -> None:
        if label in self.poses and not self._syncing:
            pose = self.poses[label]
            self._pose(pose.q, pose.object_pose, label)

    def watch(self, watcher: Callable[[str], None] | None) -> None:
        """Tell `watcher` (one at a time: the motion's timeline; None: nobody) each label the robot is shown at."""
        self._watcher = watcher

    def showing(self, label: str) -> None:
        """Make the dropdown say what the robot is shown at (a label it does not offer yet is added)."""
        if self._watcher is not None:
            self._watcher(label)
        if self.dropdown.value == label:
            return
        self._syncing = True
        try:
            if label not in self.dropdown.options:
                self.dropdown.options = (*self.poses, label)
            self.dropdown.value = label
        finally:
            self._syncing = False
