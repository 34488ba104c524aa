"""Shortcuts kept on a screen and checked for the rest only where they survive (the smoothing's lazy checks).

A shortcut of the smoothing (smoothing.py) is kept when its curve passes a screen: its first checks (segments.py),
where nearly every curve that fails is found to fail. Later shortcuts replace much of what earlier ones made, so the
rest of a kept shortcut's checks are made only for the parts of it still in the run's trajectory when the smoothing is
done: the configurations of its own checks that bound those parts, so never more than its whole check. Until then
each kept shortcut holds back the checks its whole check could make, so the run's budget bounds what is spent. A part
that fails is taken back: the run is smoothed again with that attempt refused, the attempts before it replayed from
their outcomes (`Outcome`), not checked again.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from planner.motion.ramps import TINY
from planner.motion.trajectory import Trajectory


@dataclass(frozen=True)
class Outcome:
    """An attempted shortcut between the run's times `times`: the ramp kept (None: refused), what checks it, the checks
    its screen made (or its whole check: `whole`) and the most its whole check could make."""

    times: tuple[float, float]
    shortcut: Trajectory | None = None
    validities: tuple = ()
    checks: int = 0
    most: int = 0
    whole: bool = False


@dataclass(frozen=True)
class Kept:
    """The part [a, b] of a kept shortcut's own time that is still in the run's trajectory, whose time `start` is the
    shortcut's time 0; `seq`: the attempt that kept it."""

    seq: int
    start: float
    a: float
    b: float


class Survivors:
    """The parts of kept shortcuts in a run's trajectory, mapped through each shortcut that replaces a span of it.
    `checked`: per attempt, spans of its shortcut's own time whose checks passed (kept across the run's smoothings)."""

    def __init__(self, checked: dict[int, list[tuple[float, float]]]):
        self.parts: list[Kept] = []
        self.kept: dict[int, Outcome] = {}
        self.checked = checked
        self.reserved = 0  # the checks the rest of the surviving shortcuts' checks could make at most

    def splice(self, seq: int, kept: Outcome) -> None:
        """The shortcut kept by attempt `seq` replaces its span: what lay inside is gone, what lay after moves earlier by
        the time saved."""
        (t1, t2), shortcut = kept.times, kept.shortcut
        gain = t2 - t1 - shortcut.duration
        out = []
        for p in self.parts:  # a part's own times change only where it is cut (so that a part checked stays so)
            lo, hi = p.start + p.a, p.start + p.b
            if lo < t1:
                out.append(dataclasses.replace(p, b=min(p.b, t1 - p.start)))
            if hi > t2:
                out.append(dataclasses.replace(p, start=p.start - gain, a=max(p.a, t2 - p.start)))
        out.append(Kept(seq, t1, 0.0, shortcut.duration))
        self.kept[seq] = kept
        if kept.whole:
            self.checked.setdefault(seq, []).append((0.0, shortcut.duration))
        self.parts = [p for p in out if p.b - p.a > TINY]
        self._reserve()

    def _reserve(self) -> None:
        self.reserved = sum(self.kept[seq].most for seq in self._unchecked())

    def _open(self) -> list[Kept]:
        """The surviving parts not yet checked."""
        return [p for p in self.parts if not any(a <= p.a and p.b <= b for a, b in self.checked.get(p.seq, ()))]

    def _unchecked(self) -> list[int]:
        """The attempts, in order, with a surviving part not yet checked."""
        return sorted({p.seq for p in self._open()})

    def check(self) -> tuple[int | None, int]:
        """(the first attempt, in order, the rest of whose checks fail where its shortcut survives, else None; the
        checks made)."""
        checks, open_parts = 0, self._open()
        for seq in sorted({p.seq for p in open_parts}):
            kept = self.kept[seq]
            spans = [(p.a, p.b) for p in open_parts if p.seq == seq]  # a part checked before is not checked again
            for v in kept.validities:
                before = v.checks
                valid = v.curve_valid(kept.shortcut, spans=np.array(spans))
                checks += v.checks - before
                if not valid:
                    return seq, checks
            self.checked.setdefault(seq, []).extend(spans)
        self._reserve()  # nothing left to hold back
        return None, checks
