"""Every finished step of a session drawn by its layer, from the saved results (nothing is recomputed)."""
from __future__ import annotations

import viser

from planner.core.session import Session

from .layers import LAYERS, StepLayer
from .layers.base import Host, Pose
from .notify import error_text
from .rooted import Rooted

ROOT = "/steps"


class SessionLayers(Rooted):
    """Owns one layer per finished step that has one (see `layers.LAYERS`); other steps are only listed.

    A layer that fails to draw is dropped and its error kept in `errors`, so one bad layer never hides the rest."""

    def __init__(self, server: viser.ViserServer, session: Session, root: str = ROOT, workbench: Host | None = None):
        super().__init__(server, root)
        self.layers: dict[str, StepLayer] = {}
        self.errors: dict[str, str] = {}
        for name in session.finished():
            if name in LAYERS:
                layer = LAYERS[name](server, session.scene, f"{root}/{name}", workbench, session)
                try:
                    layer.update(session.result(name))
                except Exception as exc:  # a drawing bug must not take the replay down
                    layer.remove()
                    self.errors[name] = error_text(exc)
                    continue
                self.layers[name] = layer

    def poses(self) -> dict[str, Pose]:
        """The whole poses every layer offers, by label, in pipeline order."""
        return {label: pose for layer in self.layers.values() for label, pose in layer.poses.items()}

    def remove(self) -> None:
        """Take every layer (its scene nodes and GUI) out of the workbench."""
        for layer in self.layers.values():
            layer.remove()
        super().remove()
