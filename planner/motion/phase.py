"""The four phases of the task (paper V-B) as named values; results and sessions store them as their integers."""
from __future__ import annotations

import enum


class Phase(enum.IntEnum):
    """A phase of the task; its integer is the one stored in a motion's `phase` array and its Table I row."""

    GRASP = 0
    CARRY = 1
    PLACE = 2
    REST = 3

    @property
    def title(self) -> str:
        """The phase's name as the paper, the results and the failure messages spell it ('Grasp', ...)."""
        return self.name.capitalize()
