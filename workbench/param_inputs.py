"""GUI inputs generated from a step's parameter dataclass: a number, checkbox or text field per field."""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import viser

from planner.steps import Step

EDITABLE = (bool, int, float, str)


def recorded_params(step: Step, recorded: Mapping[str, Any]) -> dict[str, Any]:
    """The recorded parameter values the step takes back as they are (JSON keeps bools, numbers and strings)."""
    defaults = step.params()
    out = {}
    for name, value in recorded.items():
        expected = type(getattr(defaults, name, None))
        if expected in EDITABLE and (isinstance(value, expected) or (expected is float and type(value) is int)):
            out[name] = value
    return out


class ParamInputs:
    """One input per editable field of `step`'s parameters, starting at `values` (else the defaults)."""

    def __init__(self, gui: viser.GuiApi, step: Step, values: Mapping[str, Any] | None = None):
        self.step = step
        params = step.make_params(recorded_params(step, values or {}))
        self.handles: dict[str, Any] = {}
        for f in dataclasses.fields(params):
            value = getattr(params, f.name)
            if isinstance(value, bool):
                self.handles[f.name] = gui.add_checkbox(f.name, value)
            elif isinstance(value, int):
                self.handles[f.name] = gui.add_number(f.name, value, step=1)
            elif isinstance(value, float):
                self.handles[f.name] = gui.add_number(f.name, value, step=abs(value) / 10 or 0.01)
            elif isinstance(value, str):
                self.handles[f.name] = gui.add_text(f.name, value)

    def values(self) -> dict[str, Any]:
        """The edited values, each of its field's type."""
        defaults = self.step.params()
        out = {}
        for name, handle in self.handles.items():
            expected = type(getattr(defaults, name))
            out[name] = int(round(handle.value)) if expected is int else expected(handle.value)
        return out

    def remove(self) -> None:
        for handle in self.handles.values():
            handle.remove()
