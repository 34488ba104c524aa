"""The base of a step layer: it owns the scene nodes drawing one step's result under one root."""
from __future__ import annotations

from typing import Any

import numpy as np
import viser

from planner.task import Scene


class StepLayer:
    """Draws one step's result; `update(result)` (re)draws it and fills `poses`: robot configurations worth showing, by label."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Any = None):
        self.server = server
        self.scene = scene
        self.workbench = workbench  # the live Workbench whose robot a layer may pose; None in an HTML export
        self.name = root
        self.root = server.scene.add_frame(root, show_axes=False)
        self.poses: dict[str, np.ndarray] = {}

    def update(self, result: Any) -> None:
        """Draw `result`, replacing what was drawn before."""
        raise NotImplementedError

    @property
    def visible(self) -> bool:
        return self.root.visible

    @visible.setter
    def visible(self, value: bool) -> None:
        self.root.visible = value

    def remove(self) -> None:
        """Take the layer's nodes out of the scene."""
        self.root.remove()
