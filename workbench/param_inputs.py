"""GUI inputs generated from a step's parameter dataclass: a number, checkbox, dropdown or text field per field, each
with its parameter's one-line hint."""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import viser

from planner.core.bounds import field_choices, field_hint
from planner.core.steps import Step, param_bounds

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


def whole(value: Any) -> Any:
    """A number input's whole value as an int (it may arrive as 8.0); anything else as it came, for the range check to judge."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


class ParamInputs:
    """One input per editable field of `step`'s parameters, starting at `values` (else the defaults); a number's limits,
    a name's choices (a dropdown) and every hint (what it does, range and unit, default) are those its parameter
    declares (planner/core/bounds.py), as `--set` and `regrasp params` use them."""

    def __init__(self, gui: viser.GuiApi, step: Step, values: Mapping[str, Any] | None = None):
        self.step = step
        params = step.make_params(recorded_params(step, values or {}))
        bounds, defaults = param_bounds(step.params), step.params()
        self.handles: dict[str, Any] = {}
        for f in dataclasses.fields(params):
            value, bound, choices = getattr(params, f.name), bounds.get(f.name), field_choices(f)
            hint = "; ".join(x for x in (field_hint(f), bound.describe() if bound else "", f"default {getattr(defaults, f.name)!r}") if x)
            limits = {"min": bound.low, "max": bound.high} if bound else {}
            if isinstance(value, bool):
                self.handles[f.name] = gui.add_checkbox(f.name, value, hint=hint)
            elif choices:
                self.handles[f.name] = gui.add_dropdown(f.name, choices, initial_value=value, hint=hint)
            elif isinstance(value, int):
                self.handles[f.name] = gui.add_number(f.name, value, step=1, hint=hint, **limits)
            elif isinstance(value, float):
                self.handles[f.name] = gui.add_number(f.name, value, step=abs(value) / 10 or 0.01, hint=hint, **limits)
            elif isinstance(value, str):
                self.handles[f.name] = gui.add_text(f.name, value, hint=hint)

    def values(self) -> dict[str, Any]:
        """The edited values as the inputs hold them (a whole number as an int): `Step.make_params` checks them."""
        return {name: whole(handle.value) for name, handle in self.handles.items()}

    def remove(self) -> None:
        for handle in self.handles.values():
            handle.remove()
