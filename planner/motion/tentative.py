"""Shortcuts kept on a screen and checked for the rest only where they survive (the smoothing's lazy checks).

A shortcut of the smoothing (smoothing.py) is kept when its curve passes a screen: its first checks (segments.py),
where nearly every curve that fails is found to fail. Later shortcuts replace much of what earlier ones made, so the
rest of a kept shortcut's checks are made only for the parts of it still in the run's trajectory when the smoothing is
done: the configurations of its own checks that bound those parts, so never more than its whole check. Until then
each kept shortcut holds back the checks its whole check could make, so the run's budget bounds what is spent.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from planner.motion.ramps import TINY
from planner.motion.trajectory import Trajectory


@dataclass(frozen=True)
class Kept:
    """The part [a, b] of a kept shortcut's own time that is still in the run's trajectory, whose time `start` is the
    shortcut's time 0; `seq`: which shortcut (in the order kept)."""

    seq: int
    start: float
    a: float
    b: float


class Survivors:
    """The parts of kept shortcuts in a run's trajectory, mapped through each shortcut that replaces a span of it, with
    what checks each shortcut and how many checks its whole check could make."""

    def __init__(self):
        self.parts: list[Kept] = []
        self.shortcuts: list[tuple[Trajectory, tuple, int]] = []  # (curve, validities, most checks) per seq

    @property
    def reserved(self) -> int:
        """The checks the rest of the surviving shortcuts' checks could make at most."""
        return sum(self.shortcuts[seq][2] for seq in {p.seq for p in self.parts})

    def splice(self, t1: float, t2: float, shortcut: Trajectory, validities: tuple, most: int) -> None:
        """The span [t1, t2] replaced by `shortcut`, whose whole check could make `most` checks: what lay inside is gone,
        what lay after moves earlier by the time saved."""
        gain = t2 - t1 - shortcut.duration
        out = []
        for p in self.parts:
            lo, hi = p.start + p.a, p.start + p.b
            if lo < t1:
                out.append(dataclasses.replace(p, b=min(hi, t1) - p.start))
            if hi > t2:
                out.append(dataclasses.replace(p, start=p.start - gain, a=max(lo, t2) - p.start))
        out.append(Kept(len(self.shortcuts), t1, 0.0, shortcut.duration))
        self.shortcuts.append((shortcut, validities, most))
        self.parts = [p for p in out if p.b - p.a > TINY]

    def check(self) -> tuple[bool, int]:
        """(whether the rest of each surviving shortcut's checks pass where it survives, the checks made), in the order
        the shortcuts were kept, stopping at the first that fails."""
        checks = 0
        for seq in sorted({p.seq for p in self.parts}):
            curve, validities, _ = self.shortcuts[seq]
            spans = np.array([(p.a, p.b) for p in self.parts if p.seq == seq])
            for v in validities:
                before = v.checks
                valid = v.curve_valid(curve, spans=spans)
                checks += v.checks - before
                if not valid:
                    return False, checks
        return True, checks
