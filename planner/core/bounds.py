"""The range and unit of every number a user sets: step parameters (declared with `bounded`) and seeds.

A parameter's range sits next to its declaration in its step's parameter dataclass; `--set`, the workbench's inputs
(their limits and hints) and a session's recorded parameters all read it from there, so one declaration bounds them
all. The ranges are generous but keep a run's memory and time bounded (a grid step, a node count, a sampling rate).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

BOUND = "bound"  # the dataclass field metadata key


@dataclass(frozen=True)
class Bound:
    """A closed range of numbers and their unit ('m', 'rad', 'Hz', or what a count counts)."""

    low: float
    high: float
    unit: str

    def describe(self) -> str:
        """'from 0.01 to 0.5 m': the range as messages and hints say it."""
        return f"from {_number(self.low)} to {_number(self.high)}" + (f" {self.unit}" if self.unit else "")

    def problem(self, value: float, expected: str = "expected a value") -> str:
        """What is wrong with `value` ('' when it lies in the range): '`expected` from 0.01 to 0.5 m, got 0.001'."""
        return "" if self.low <= value <= self.high else f"{expected} {self.describe()}, got {_number(value)}"


def _number(value: float) -> str:
    """A number as a person reads it: a float short, an integer whole (2**64 - 1 so; a huge one by its size)."""
    if not isinstance(value, int):
        return f"{value:g}"
    if value >= 2**32 and (value + 1).bit_count() == 1:
        return f"2**{(value + 1).bit_length() - 1} - 1"
    return str(value) if abs(value) < 10**30 else f"an integer of {abs(value).bit_length()} bits"


def bounded(default: float, low: float, high: float, unit: str) -> Any:
    """A parameter field: its default, the range it accepts and its unit (read back by `field_bound`)."""
    return dataclasses.field(default=default, metadata={BOUND: Bound(low, high, unit)})


def field_bound(field: dataclasses.Field) -> Bound | None:
    """The range a parameter field declares (None: a flag or a name, which has no range)."""
    return field.metadata.get(BOUND)


SEED = Bound(0, 2**64 - 1, "")  # a session seed: what numpy's SeedSequence takes and a session file stores


def seed_problem(value: Any) -> str:
    """What is wrong with a session seed ('' when it is a whole number in SEED's range)."""
    if isinstance(value, bool) or not isinstance(value, int):
        shown = repr(value) if len(repr(value)) <= 40 else f"a {type(value).__name__} of {len(repr(value))} characters"
        return f"expected a seed (a whole number) {SEED.describe()}, got {shown}"
    return SEED.problem(value, "expected a seed")
