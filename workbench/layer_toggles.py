"""The Layers folder: one checkbox per drawn step layer, so one thing is in focus at a time."""
from __future__ import annotations

import viser

from .session_layers import SessionLayers

LABELS = {"roadmap": "roadmap (Super Graph)"}  # a checkbox's label, when not the step's name


class LayerToggles:
    """Checkboxes inside `folder` showing or hiding each layer of `layers`; `focus(step)` shows that step's layer alone."""

    def __init__(self, gui: viser.GuiApi, folder: viser.GuiFolderHandle, layers: SessionLayers, focus: str | None):
        self.layers = layers
        self.boxes: dict[str, viser.GuiCheckboxHandle] = {}
        with folder:
            for name, layer in layers.layers.items():
                box = gui.add_checkbox(LABELS.get(name, name), name == focus, hint=f"Show the {name} step's result")
                box.on_update(lambda e, layer=layer: setattr(layer, "visible", e.target.value))
                layer.visible = box.value
                self.boxes[name] = box

    def focus(self, step: str) -> None:
        """Show the layer of `step` and hide the others (a step without a layer hides them all)."""
        for name, box in self.boxes.items():
            box.value = name == step
            self.layers.layers[name].visible = box.value

    def shown(self) -> list[str]:
        """The steps whose layers are shown."""
        return [name for name, box in self.boxes.items() if box.value]

    def remove(self) -> None:
        """Take the checkboxes out of the panel."""
        for box in self.boxes.values():
            box.remove()
