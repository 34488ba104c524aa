"""What the stages make: pieces of the motion (checked polylines), the failure of one, and a hand's grasp."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner.collision.situation import Situation
from planner.motion.phase import Phase

TRANSIT_PARTS = ("transit", "arm away")  # the parts transit stages make (the others are contact motions)


@dataclass(frozen=True)
class Piece:
    """A checked polyline of one phase, with the object's situation along it."""

    phase: Phase
    part: str
    path: np.ndarray  # (k, nq), k >= 2
    situation: Situation
    hand: str | None = None  # the arm whose hand works near the object in a contact motion (None: transit)


class PieceFailed(Exception):
    """A piece that cannot be made; `why` may be a function, called only when the message is read (naming the
    colliding pairs takes a full check, and most failures are of candidates that are never reported)."""

    def __init__(self, phase: Phase, part: str, why: str | Callable[[], str]):
        super().__init__(phase, part)
        self.phase, self.part, self._why = phase, part, why

    @property
    def why(self) -> str:
        if callable(self._why):
            self._why = self._why()
        return self._why

    def __str__(self) -> str:
        return f"{self.phase.title} phase, {self.part}: {self.why}"


@dataclass(frozen=True)
class HandGrasp:
    """One hand's grasp: its arm, the palm pose in the object frame, the finger values and the touching fingers."""

    arm: str
    palm_in_object: np.ndarray
    fingers: np.ndarray
    touching: list


def pairs_text(pairs: list[tuple[str, str]], most: int = 3) -> str:
    """Colliding pairs in words, for failure messages."""
    text = ", ".join(f"{a} with {b}" for a, b in pairs[:most])
    return text + (f" and {len(pairs) - most} more pairs" if len(pairs) > most else "")
