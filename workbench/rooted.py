"""A group of scene nodes under one root frame: shown, hidden and removed together."""
from __future__ import annotations

import viser


class Rooted:
    """Owns the root frame `root`; everything a layer draws goes below it."""

    def __init__(self, server: viser.ViserServer, root: str):
        self.root = server.scene.add_frame(root, show_axes=False)

    @property
    def visible(self) -> bool:
        return self.root.visible

    @visible.setter
    def visible(self, value: bool) -> None:
        self.root.visible = value

    def remove(self) -> None:
        """Take the nodes out of the scene."""
        self.root.remove()
