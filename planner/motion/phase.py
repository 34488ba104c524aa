"""The phases of the task as named values; results and sessions store them as their integers.

The paper's four (V-B) come first: a handover (or a direct transfer) moves in them. A table handover, where the
picking hand sets the object down for the placing hand to take, adds two: Set down (the lift, the carry to the
intermediate placement, setting down, letting go, the retreat) and Regrasp (the placing hand to the object there, its
approach and closing), between Grasp and Carry in time.
"""
from __future__ import annotations

import enum


class Phase(enum.IntEnum):
    """A phase of the task; its integer is the one stored in a motion's `phase` array and indexes its Table I rows."""

    GRASP = 0
    CARRY = 1
    PLACE = 2
    REST = 3
    SET_DOWN = 4
    REGRASP = 5

    @property
    def title(self) -> str:
        """The phase's name as the results and the failure messages spell it ('Grasp', 'Set down', ...)."""
        return self.name.replace("_", " ").capitalize()
