"""The range, unit and meaning of every value a user sets: step parameters (declared with `bounded`, or `described`
when they are not numbers) and seeds.

A parameter's range, unit, one-line hint and (for a name) its choices sit in its declaration in its step's parameter
dataclass; `--set`, `regrasp params`, the workbench's inputs (their limits, hints and dropdowns) and a session's
recorded parameters all read them from there, so one declaration bounds and explains them all. The ranges are
generous but keep a run's memory and time bounded (a grid step, a node count, a sampling rate).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

BOUND, HINT, CHOICES = "bound", "hint", "choices"  # the dataclass field metadata keys


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


def bounded(default: float, low: float, high: float, unit: str, hint: str = "") -> Any:
    """A numeric parameter field: its default, the range it accepts, its unit and what it does in one line (read back by
    `field_bound` and `field_hint`)."""
    return dataclasses.field(default=default, metadata={BOUND: Bound(low, high, unit), HINT: hint})


def described(default: bool | str, hint: str, choices: tuple[str, ...] = ()) -> Any:
    """A flag or name parameter field: its default, what it does in one line and, for a name, the values it accepts
    (none: any text the step checks itself)."""
    return dataclasses.field(default=default, metadata={HINT: hint, CHOICES: tuple(choices)})


def field_bound(field: dataclasses.Field) -> Bound | None:
    """The range a parameter field declares (None: a flag or a name, which has no range)."""
    return field.metadata.get(BOUND)


def field_hint(field: dataclasses.Field) -> str:
    """What a parameter field does, in one line ('' when it declares nothing)."""
    return field.metadata.get(HINT, "")


def field_choices(field: dataclasses.Field) -> tuple[str, ...]:
    """The values a name parameter accepts (empty: it declares none)."""
    return field.metadata.get(CHOICES, ())


SEED = Bound(0, 2**64 - 1, "")  # a session seed: what numpy's SeedSequence takes and a session file stores


def seed_problem(value: Any) -> str:
    """What is wrong with a session seed ('' when it is a whole number in SEED's range)."""
    if isinstance(value, bool) or not isinstance(value, int):
        shown = repr(value) if len(repr(value)) <= 40 else f"a {type(value).__name__} of {len(repr(value))} characters"
        return f"expected a seed (a whole number) {SEED.describe()}, got {shown}"
    return SEED.problem(value, "expected a seed")
