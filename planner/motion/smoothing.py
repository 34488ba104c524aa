"""Smoothing the timed motion by checked parabolic shortcuts (Hauser and Ng-Thow-Hing, ICRA 2010).

The pieces are grouped into runs: the robot comes to rest only between runs, where it must (a hand closes on the
object or lets go of it, the object is lifted off or set down, the object's situation changes) and at the task's
ends; fingers shaping before an approach, or opening at the end, may move while the arms do. A run starts
timed rest to rest at every vertex (trajectory.py): exactly the checked polylines. Then, drawn from the plan's
random stream, two times t1 < t2 of the run are joined by the time-optimal ramp between the states (positions and
velocities) there (ramps.py); where it is faster, it is checked as a curve (segments.py: the same displacement
bound between checks as a straight segment) and replaces that span. Inside one piece it is checked with that
piece's own validity (a transit's paddings fitted to its ends, a contact motion's tight paddings); across pieces (a
lift into a transit, a transit into an approach) with the transit profile in the object's situation without its
exceptions (no fingertip nor support may touch), fitted to the ramp's ends: a hand near the object keeps the straight
contact motion. Budgets are attempts and collision checks, never seconds: one seed, one trajectory on any machine.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.collision.situation import Situation
from planner.collision.validity import Validity
from planner.motion.piece import TRANSIT_PARTS, Piece
from planner.motion.ramps import ramp
from planner.motion.trajectory import Trajectory, rest_to_rest
from planner.motion.validities import Validities

RESTS = ("closing", "opening")  # a hand closes on the object or lets go of it: the robot rests before and after


def runs(pieces: list[Piece]) -> list[list[Piece]]:
    """The pieces grouped into runs (see the module): a piece joins the run before it when neither closes a hand on
    the object nor lets go of it, the object is where it was (static at one pose, or held by one hand in one grasp)
    and it is neither set down nor lifted off between them."""
    out: list[list[Piece]] = []
    for piece in pieces:
        if out:
            last = out[-1][-1]
            if (last.part not in RESTS and piece.part not in RESTS and last.part != "set-down"
                    and piece.part != "lift" and last.situation.holder == piece.situation.holder
                    and np.array_equal(last.situation.pose, piece.situation.pose)):
                out[-1].append(piece)
                continue
        out.append([piece])
    return out


@dataclass(frozen=True)
class SmoothedRun:
    """A run's trajectory and the times its pieces end at (each shortcut maps a piece boundary it spans in
    proportion), with the collision checks and shortcuts its smoothing made."""

    pieces: list
    trajectory: Trajectory
    ends: np.ndarray
    checks: int
    shortcuts: int


class Smoother:
    """Smooths runs of pieces with the checks of their situations (`validities`), under per-joint limits."""

    def __init__(self, validities: Validities, vmax: np.ndarray, amax: np.ndarray, attempts: int, budget: int,
                 min_gain: float):
        self.validities, self.vmax, self.amax = validities, vmax, amax
        self.attempts, self.budget, self.min_gain = attempts, budget, min_gain

    def own(self, piece: Piece) -> tuple[Validity, ...]:
        """The validities a piece was checked with: a transit's (full, near: paddings fitted to its ends), a contact
        motion's."""
        path = piece.path
        checks = self.validities.of(piece.situation, path[0], np.flatnonzero(np.ptp(path, axis=0) > 0))
        if piece.part in TRANSIT_PARTS:
            return checks.transit_validities(path[0], path[-1])[1:]
        return (checks.checked(self.validities.contact).validity,)

    def blend(self, pieces: list[Piece], strict: Situation) -> tuple[Validity, ...]:
        """The validity of ramps across pieces: the transit profile in their situation without exceptions (`strict`),
        over the joints any of them moves, its paddings fitted to where the first piece starts and the last ends."""
        moving = np.flatnonzero(np.ptp(np.vstack([p.path for p in pieces]), axis=0) > 0)
        qa, qb = pieces[0].path[0], pieces[-1].path[-1]
        return self.validities.of(strict, qa, moving).transit_validities(qa, qb)[1:]

    def smooth(self, pieces: list[Piece], rng: np.random.Generator) -> SmoothedRun:
        """The run's pieces timed rest to rest at every vertex, then shortened by checked ramps in three passes: from
        the first vertex to the farthest it reaches by a rest-to-rest ramp, and on from there (the path's big
        detours, each ramp checked once); around each vertex left (from halfway along the segment before to halfway
        along the one after: short ramps, few checks, no stop left where one is valid); between random times."""
        timed = [(p, rest_to_rest(p.path, self.vmax, self.amax)) for p in pieces]
        timed = [(p, t) for p, t in timed if t is not None]
        if not timed:
            return SmoothedRun([], None, np.zeros(0), 0, 0)
        run = _Run(self, [p for p, _ in timed], Trajectory.joined([t for _, t in timed]),
                   np.cumsum([t.duration for _, t in timed]))
        run.marks = np.array([0.0] + [float(t) for t, v in zip(run.traj.t[1:-1], run.traj.v[1:]) if not v.any()]
                             + [run.traj.duration])  # the vertices, where the robot rests
        i = 0
        while i < len(run.marks) - 2 and run.checks < self.budget:
            j = next((j for j in range(len(run.marks) - 1, i + 1, -1) if run.attempt(run.marks[i], run.marks[j])), None)
            if j is not None:
                run.marks = np.delete(run.marks, np.arange(i + 1, j))
            i += 1
        for k in range(1, len(run.marks) - 1):
            if run.checks >= self.budget:
                break
            m = run.marks
            run.attempt(0.5 * (m[k - 1] + m[k]), 0.5 * (m[k] + m[k + 1]))
        for _ in range(self.attempts):
            if run.checks >= self.budget:
                break
            run.attempt(*np.sort(rng.uniform(0.0, run.traj.duration, 2)))
        return SmoothedRun(run.pieces, run.traj, run.ends, run.checks, run.shortcuts)


class _Run:
    """One run being smoothed: its trajectory, the times its pieces end, times to follow (`marks`, mapped with each
    shortcut), the validities made so far and the figures."""

    def __init__(self, smoother: Smoother, pieces: list[Piece], traj: Trajectory, ends: np.ndarray):
        self.smoother, self.pieces, self.traj, self.ends = smoother, pieces, traj, ends
        self.own: list[tuple[Validity, ...] | None] = [None] * len(pieces)
        self.blends: dict[tuple[int, int], tuple[Validity, ...]] = {}
        self.strict = next((p.situation for p in pieces if not p.situation.touching and not p.situation.support),
                           Situation(pieces[0].situation.holder, pieces[0].situation.pose))
        self.checks = self.shortcuts = 0
        self.marks = np.zeros(0)

    def validities(self, t1: float, t2: float) -> tuple[Validity, ...]:
        """What checks a ramp from t1 to t2: its piece's own validity, or the blend of the pieces it spans."""
        i, j = (min(int(np.searchsorted(self.ends, t, side="left")), len(self.pieces) - 1) for t in (t1, t2))
        if i == j:
            if self.own[i] is None:
                self.own[i] = self.smoother.own(self.pieces[i])
            return self.own[i]
        if (i, j) not in self.blends:
            self.blends[i, j] = self.smoother.blend(self.pieces[i: j + 1], self.strict)
        return self.blends[i, j]

    def attempt(self, t1: float, t2: float) -> bool:
        """Whether the ramp from the state at t1 to the one at t2 is faster and valid; then it replaces that span, and
        the pieces' ends and the marks are mapped onto the new timing."""
        p = self.smoother
        if t2 - t1 <= p.min_gain:
            return False
        (qa, qb), (va, vb) = self.traj.states(np.array([t1, t2]))
        shortcut = ramp(qa, va, qb, vb, p.vmax, p.amax, t2 - t1 - p.min_gain)
        if shortcut is None:
            return False
        validities = self.validities(t1, t2)
        before = sum(v.checks for v in validities)
        ok = all(v.curve_valid(shortcut) for v in validities)
        self.checks += sum(v.checks for v in validities) - before
        if not ok:
            return False
        self.shortcuts += 1
        gain = t2 - t1 - shortcut.duration

        def mapped(times: np.ndarray) -> np.ndarray:
            inside = (times > t1) & (times < t2)
            return np.where(times >= t2, times - gain, np.where(inside, t1 + (times - t1) * shortcut.duration / (t2 - t1), times))

        self.traj = self.traj.splice(t1, t2, shortcut)
        self.ends, self.marks = mapped(self.ends), mapped(self.marks)
        self.ends[-1] = self.traj.duration
        return True
