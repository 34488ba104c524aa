"""The base of a step layer: it owns the scene nodes drawing one step's result under one root."""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
import viser

from planner.task import Scene

from ..rooted import Rooted


class StepLayer(Rooted, ABC):
    """Draws one step's result; `update(result)` (re)draws it and fills `poses`: robot configurations worth showing, by label."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Any = None, session: Any = None):
        super().__init__(server, root)
        self.server = server
        self.scene = scene
        self.workbench = workbench  # the live Workbench whose robot a layer may pose; None in an HTML export
        self.session = session  # the drawn Session: a layer reads the earlier steps' results it needs from it
        self.name = root
        self.poses: dict[str, np.ndarray] = {}

    @abstractmethod
    def update(self, result: Any) -> None:
        """Draw `result`, replacing what was drawn before."""
