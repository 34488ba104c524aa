"""Smoothing the timed motion by checked parabolic shortcuts (Hauser and Ng-Thow-Hing, ICRA 2010).

The pieces are grouped into runs (runs.py): the robot comes to rest only between runs, where it must, and at the
task's ends; fingers shaping before an approach, or opening at the end, may move while the arms do. A run starts
timed rest to rest at every vertex (trajectory.py): exactly the checked polylines. Then, drawn from the run's
random stream (from the plan's and the run's pieces), two times t1 < t2 of the run are joined by the time-optimal
ramp between the states (positions and velocities) there (ramps.py); where it is faster, its configurations at
its middle, quarters and eighths are free (PROBES: checked before it is made, most ramps that fail fail there) and
its curve passes a screen (its first checks: segments.py), it replaces that span, and the rest of its checks are
made at the end, where it survives later shortcuts (tentative.py: the same displacement bound between checks as a
straight segment; should one fail, that attempt is refused and the run smoothed again, the attempts before it
replayed, the new ones checked whole). Inside one piece it is checked with that piece's own validity (a
transit's paddings fitted to its ends, a contact motion's tight paddings); across pieces (a lift into a transit, a
transit into an approach) with the transit profile in the object's situation without its exceptions (no fingertip nor
support may touch), fitted to the ramp's ends: a hand near the object keeps the straight contact motion. Budgets are
attempts and collision checks per run, never seconds: one seed, one trajectory however fast or busy the machine
(across processor kinds, to rounding: docs/design.md, Determinism).
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass

import numpy as np

from planner.collision.situation import Situation
from planner.collision.validity import Validity
from planner.motion.piece import TRANSIT_PARTS, Piece
from planner.motion.ramps import TINY, Planned, between, min_times, moving, pieces, plan, positions
from planner.motion.runs import ends_run, run_key, runs, starts_run
from planner.motion.tentative import Outcome, Survivors
from planner.motion.trajectory import Trajectory, rest_to_rest
from planner.motion.validities import Validities

LEAVING, REACHING = ("lift", "retreat"), ("approach", "set-down")  # contact motions starting / ending at the object
CORNERS = (0.5, 0.25, 0.1)  # a vertex's corner cut spans this share of the segments before and after it, tried in turn
CORNER_ROUNDS = 2  # rounds of corner cuts: the second, between the first's ramps, joins them (docs/benchmarks.md)
CHUNK = 256  # random shortcuts judged at once, the most promising attempted first
PASSES = ("vertices", "corners", "random")  # the passes of `passes`, in their order
PROBES = (0.5, 0.25, 0.75, 0.125, 0.625, 0.375, 0.875)  # a ramp's configurations checked before it is made, as shares
# of its duration, coarse to fine (docs/benchmarks.md: most ramps that fail fail there, before their curve's set-up)


@dataclass(frozen=True)
class SmoothedRun:
    """A run's trajectory and the times its pieces end at (each shortcut maps a piece boundary it spans in
    proportion), with the collision checks and shortcuts its smoothing made; per pass (PASSES), the shortcuts it
    attempted anew (in every smoothing of the run: replays not counted), those the result kept and the seconds they
    saved (summed: the run's time rest to rest at every vertex less its duration)."""

    pieces: list
    trajectory: Trajectory
    ends: np.ndarray
    checks: int
    shortcuts: int
    attempts: tuple = (0,) * len(PASSES)
    kept: tuple = (0,) * len(PASSES)
    saved: tuple = (0.0,) * len(PASSES)


class Smoother:
    """Smooths runs of pieces with the checks of their situations (`validities`), under per-joint limits."""

    def __init__(self, validities: Validities, vmax: np.ndarray, amax: np.ndarray, min_gain: float, attempts_per_s: float,
                 checks_per_s: float, seed: int):
        self.validities, self.vmax, self.amax, self.min_gain = validities, vmax, amax, min_gain
        self.attempts_per_s, self.checks_per_s = attempts_per_s, checks_per_s
        self.seed = seed  # with a run's pieces, its random stream (see stream)

    def rest_to_rest(self, pieces: list[Piece]) -> float:
        """How long the pieces take timed rest to rest at every vertex (before smoothing)."""
        return sum(t.duration for t in (rest_to_rest(p.path, self.vmax, self.amax) for p in pieces) if t is not None)

    def could_save(self, pieces: list[Piece]) -> float:
        """How much smoothing could shorten the pieces: their time rest to rest at every vertex less the least any
        motion between their ends takes (each joint from rest to rest over its own distance, at its limits); nothing
        for one straight motion (a hand closing on the object)."""
        zero = np.zeros(len(self.vmax))
        least = min_times(pieces[-1].path[-1] - pieces[0].path[0], zero, zero, self.vmax, self.amax).max(initial=0.0)
        return max(self.rest_to_rest(pieces) - float(least), 0.0)

    def budget(self, pieces: list[Piece]) -> tuple[int, int]:
        """(random shortcuts, collision checks) the run's smoothing may make: per second it could save."""
        could = self.could_save(pieces)
        return int(self.attempts_per_s * could), int(self.checks_per_s * could)

    def stream(self, pieces: list[Piece]) -> np.random.Generator:
        """The run's random stream: from the smoother's seed and what the run is, so that a run smoothed in a transit
        stage's worker or after the transits, in any order, is smoothed alike."""
        digest = hashlib.blake2b(repr(run_key(pieces)).encode(), digest_size=8).digest()
        return np.random.default_rng([self.seed, int.from_bytes(digest, "little")])

    def smooth_run(self, pieces: list[Piece], budget: tuple[int, int] | None = None) -> "SmoothedRun":
        """The run smoothed with its budget (`budget`, when computed already) and its stream."""
        return self.smooth(pieces, self.stream(pieces), *(budget or self.budget(pieces)))

    def smooth_runs(self, pieces: list[Piece], owned: list[Piece], open_start: bool, open_end: bool
                    ) -> tuple[dict[tuple, "SmoothedRun"], float]:
        """(run_key -> the run smoothed (smooth_run), the seconds that took), for each run of `pieces` that holds a
        transit of `owned` (a transit stage's pieces, `pieces` those with the motion's pieces before and after them)
        and is whole: where pieces not known yet come before (`open_start`) or after (`open_end`), a run reaching that
        edge is whole only where it starts or ends whatever is there."""
        mine = {id(p) for p in owned if p.part in TRANSIT_PARTS}
        out, start = {}, time.perf_counter()
        for run in runs(pieces):
            whole = ((run[0] is not pieces[0] or not open_start or starts_run(run[0]))
                     and (run[-1] is not pieces[-1] or not open_end or ends_run(run[-1])))
            if whole and any(id(p) in mine for p in run):
                out[run_key(run)] = self.smooth_run(run)
        return out, time.perf_counter() - start

    def own(self, piece: Piece, moving: np.ndarray) -> tuple[Validity, ...]:
        """The validity a piece was checked with (a transit's, its paddings fitted to its ends; a contact motion's),
        over the pairs the joints `moving` change."""
        path = piece.path
        checks = self.validities.of(piece.situation, path[0], moving)
        if piece.part in TRANSIT_PARTS:
            return checks.transit_validities(path[0], path[-1])[1:]
        return (checks.validity(self.validities.contact),)

    def blend(self, pieces: list[Piece], strict: Situation, moving: np.ndarray) -> tuple[Validity, ...]:
        """The validity of ramps across pieces: the transit profile in their situation without exceptions (`strict`),
        over the pairs the joints `moving` change, its paddings fitted to the clearances of the span's ends as a transit sees
        them: where the span begins with a motion leaving the object (lift, retreat), the end of that motion; where it
        ends with one reaching it (approach, set-down), its start. A ramp nearer the object than those fails: the
        contact motion keeps its straight line there. Fingers moving (a hand shaped, or opened at the end, while the
        arms move) keep their hand's own links apart as a finger motion does: at the contact profile."""
        first, last = pieces[0], pieces[-1]
        qa = first.path[-1] if first.part in LEAVING else first.path[0]
        qb = last.path[0] if last.part in REACHING else last.path[-1]
        checks = self.validities.of(strict, qa, moving)
        outer = checks.transit_validities(qa, qb)[1].on("moving_outer")
        if not len(checks.model.subsets["moving_inner"]):
            return (outer,)
        return outer, checks.validity(self.validities.contact).on("moving_inner")

    def smooth(self, pieces: list[Piece], rng: np.random.Generator, attempts: int, budget: int) -> SmoothedRun:
        """The run's pieces timed rest to rest at every vertex, then shortened by shortcuts in three passes (see
        `passes`) kept on a screen, the rest of their checks made where they survive (tentative.py). Should a surviving
        part fail, the run is smoothed again with that attempt refused, the ones before it replayed from their
        outcomes and the new ones checked whole; the checks made, replays' and failures' included, stay within
        `budget`."""
        timed = [(p, rest_to_rest(p.path, self.vmax, self.amax)) for p in pieces]
        timed = [(p, t) for p, t in timed if t is not None]
        if not timed:
            return SmoothedRun([], None, np.zeros(0), 0, 0)
        draws = rng.random((attempts, 2))  # each random shortcut's two times, as shares of the run's duration then
        start = ([p for p, _ in timed], Trajectory.joined([t for _, t in timed]), np.cumsum([t.duration for _, t in timed]))
        record: list[Outcome] = []
        checked: dict[int, list[tuple[float, float]]] = {}
        spent, made = 0, np.zeros(len(PASSES), dtype=int)
        checks_of: dict[tuple[int, int, bool, bytes], tuple[Validity, ...]] = {}  # made once for every smoothing of the run
        while True:
            run = _Run(self, *start, budget, record, Survivors(checked), spent, bool(record), checks_of)
            try:
                passes(run, draws)
                failed = run.settle()
            except Retake as retake:
                failed = retake.seq
            spent, made = run.spent, made + run.made
            if failed is None:
                return SmoothedRun(run.pieces, run.traj, run.ends, spent, run.shortcuts, tuple(made.tolist()),
                                   tuple(run.kept.tolist()), tuple(run.saved.tolist()))
            record = run.log[:failed] + [Outcome(run.log[failed].times)]
            checked = {seq: spans for seq, spans in checked.items() if seq < failed}


def passes(run: "_Run", draws: np.ndarray) -> None:
    """A run shortened in three passes: from the first vertex to the farthest it reaches by a rest-to-rest ramp, and
    on from there (the path's big detours, each ramp tried once); around each vertex left (from halfway along the
    segment before to halfway along the one after, else a quarter, a tenth of the way: short ramps, few checks, no
    stop left where one is valid; CORNER_ROUNDS times, a later round joining the ramps an earlier one cut); between
    random times (`draws`, shares of the duration). Each pass stops once the run's checks reach its budget, and no
    ramp is tried whose whole check needs more checks than the budget has left."""
    budget = run.budget
    run.current = 0
    run.marks = np.array([0.0] + [float(t) for t, v in zip(run.traj.t[1:-1], run.traj.v[1:]) if not v.any()]
                         + [run.traj.duration])  # the vertices, where the robot rests
    i = 0
    while i < len(run.marks) - 2 and run.checks < budget:
        far = np.arange(len(run.marks) - 1, i + 1, -1)  # the farthest first, their ramps planned at once
        p = run.smoother
        _, known = between(run.traj, np.full(len(far), run.marks[i]), run.marks[far], p.vmax, p.amax, p.min_gain,
                           np.array(PROBES))
        j = next((int(j) for j, k in zip(far, known) if run.attempt(run.marks[i], run.marks[j], k)), None)
        if j is not None:
            run.marks = np.delete(run.marks, np.arange(i + 1, j))
        i += 1
    run.current = 1
    for k in list(range(1, len(run.marks) - 1)) * CORNER_ROUNDS:
        for part in CORNERS:  # a corner cut nearer the vertex leaves the checked path less: more likely valid
            if run.checks >= budget:
                break
            m = run.marks
            if run.attempt(m[k] - part * (m[k] - m[k - 1]), m[k] + part * (m[k + 1] - m[k])):
                break
    run.current = 2
    k = run.next_draw(draws)
    while k is not None and run.checks < budget:
        if run.attempt(*np.sort(draws[k] * run.traj.duration), run.judged.get(k)):
            run.gains = None  # the trajectory changed: the draws left are judged again on the new one
        k = run.next_draw(draws)


class Retake(Exception):
    """A kept shortcut failed the rest of its checks while the run was being smoothed: attempt `seq` is to be refused."""

    def __init__(self, seq: int):
        super().__init__(seq)
        self.seq = seq


class _Run:
    """One run being smoothed: its trajectory, the times its pieces end, times to follow (`marks`, mapped with each
    shortcut), the validities made so far and the figures."""

    def __init__(self, smoother: Smoother, pieces: list[Piece], traj: Trajectory, ends: np.ndarray, budget: int,
                 record: list[Outcome], survivors: Survivors, spent: int, eager: bool,
                 checks_of: dict[tuple[int, int, bool, bytes], tuple[Validity, ...]]):
        self.smoother, self.pieces, self.traj, self.ends = smoother, pieces, traj, ends
        self.budget = budget  # the collision checks the smoothing may make
        self.record, self.log = record, []  # the outcomes to replay; this smoothing's
        self.survivors = survivors
        self.spent = spent  # the checks made, by the run's smoothings before this one too
        self.screens = 0  # the checks of this smoothing's attempts (screens, or whole checks), replayed ones included
        self.eager = eager  # new shortcuts checked whole (a screen of this run has let a colliding one through)
        self.moves = np.array([np.ptp(p.path, axis=0) > 0 for p in pieces])  # the joints each piece moves
        robot = smoother.validities.robot
        fingers = np.isin(np.arange(robot.nq), np.concatenate([robot.hand_idx[a] for a in robot.spec.arm_names]))
        contact = np.array([p.part in LEAVING + REACHING for p in pieces])
        self.still = fingers & ~self.moves & contact[:, None]  # per piece, the fingers a contact motion keeps still
        self.checks_of = checks_of  # the validities of ramps by the pieces they span and the joints they move
        self.strict = next((p.situation for p in pieces if not p.situation.touching and not p.situation.support),
                           Situation(pieces[0].situation.holder, pieces[0].situation.pose))
        self.shortcuts = 0
        self.current = 0  # the pass attempting (an index of PASSES)
        self.made = np.zeros(len(PASSES), dtype=int)  # per pass: this smoothing's attempts made anew,
        self.kept, self.saved = np.zeros(len(PASSES), dtype=int), np.zeros(len(PASSES))  # shortcuts kept, seconds saved
        self.marks = np.zeros(0)
        self.drawn = 0  # the random pass: the draws its chunks have taken so far,
        self.pending: np.ndarray | None = None  # the chunk's draws not attempted yet,
        self.gains: np.ndarray | None = None  # and the most each could save (None: to judge on the trajectory as it is),
        self.judged: dict[int, Planned] = {}  # with, by draw, its ramp as planned then (ramps.between)

    def validities(self, t1: float, t2: float, ramp_moves: np.ndarray) -> tuple[Validity, ...] | None:
        """What checks a ramp from t1 to t2: its piece's own validity, or the blend of the pieces it spans (also for one
        piece when the ramp moves joints it does not: a shortcut made before may carry the other arm's motion into an
        approach), over the pairs changed by the joints their pieces move and the ramp does. None when the ramp would
        move fingers in a contact motion that keeps them still (a hand is shaped before it approaches)."""
        i, j = (min(int(np.searchsorted(self.ends, t, side="left")), len(self.pieces) - 1) for t in (t1, t2))
        if np.any(self.still[i: j + 1] & ramp_moves):
            return None
        spanned = self.moves[i: j + 1].any(axis=0)
        moving = np.flatnonzero(spanned | ramp_moves)
        own = i == j and not np.any(ramp_moves & ~spanned)  # moving more than its piece: checked as a blend
        key = (i, j, own, moving.tobytes())
        if key not in self.checks_of:
            self.checks_of[key] = (self.smoother.own(self.pieces[i], moving) if own else
                                   self.smoother.blend(self.pieces[i: j + 1], self.strict, moving))
        return self.checks_of[key]

    def next_draw(self, draws: np.ndarray) -> int | None:
        """The next random shortcut to attempt: among the draws of the chunk being tried (pairs of shares of the
        duration, CHUNK at a time, in order), the one whose ramp could save the most on the trajectory as it is, by a
        bound that `attempt` never beats (the slowest joint's shortest move); None when no draw is left that could
        save the least gain."""
        while True:
            if self.pending is None or not len(self.pending):
                if self.drawn >= len(draws):
                    return None
                self.pending, self.gains = np.arange(self.drawn, min(self.drawn + CHUNK, len(draws))), None
                self.drawn += CHUNK
            if self.gains is None:
                self.gains, known = self._judge(draws[self.pending])
                self.judged = dict(zip(self.pending.tolist(), known))
                keep = self.gains > 0
                self.pending, self.gains = self.pending[keep], self.gains[keep]
                continue
            best = int(np.argmax(self.gains))
            k = int(self.pending[best])
            self.pending, self.gains = np.delete(self.pending, best), np.delete(self.gains, best)
            return k

    def _judge(self, draws: np.ndarray) -> tuple[np.ndarray, list[Planned | None]]:
        """Per draw, the most a ramp between its two times could save (0 where it cannot save the least gain), and its
        ramp as planned (ramps.between)."""
        times = np.sort(draws * self.traj.duration, axis=1)
        p = self.smoother
        fastest, known = between(self.traj, times[:, 0], times[:, 1], p.vmax, p.amax, p.min_gain, np.array(PROBES))
        span = times[:, 1] - times[:, 0]
        hopeful = (span - p.min_gain > fastest) & (fastest > TINY)
        return np.where(hopeful, span - fastest, 0.0), known

    @property
    def checks(self) -> int:
        """What the passes count against the budget: this smoothing's attempts' checks (replayed ones too, so that a
        replay follows the same course) and what the surviving shortcuts' checks could make."""
        return self.screens + self.survivors.reserved

    def attempt(self, t1: float, t2: float, known: Planned | None = None) -> bool:
        """Whether the ramp from the state at t1 to the one at t2 is faster and passes its screen, or did so when this
        attempt was made before (replayed while the attempts are those made before); then it replaces that span, and
        the pieces' ends and the marks are mapped onto the new timing."""
        seq = len(self.log)
        out = self.record[seq] if seq < len(self.record) and self.record[seq].times == (t1, t2) else None
        if out is None or (out.shortcut is not None and not out.whole and out.most > self._left()):  # no longer a replay
            self.record = self.record[:seq]
            out = self._try(t1, t2, known)
            self.made[self.current] += 1
        self.log.append(out)
        self.screens += out.checks
        if out.shortcut is None:
            return False
        self.shortcuts += 1
        shortcut = out.shortcut
        gain = t2 - t1 - shortcut.duration
        self.kept[self.current] += 1
        self.saved[self.current] += gain

        def mapped(times: np.ndarray) -> np.ndarray:
            inside = (times > t1) & (times < t2)
            return np.where(times >= t2, times - gain, np.where(inside, t1 + (times - t1) * shortcut.duration / (t2 - t1), times))

        self.traj = self.traj.splice(t1, t2, shortcut)
        self.survivors.splice(seq, out)
        self.ends, self.marks = mapped(self.ends), mapped(self.marks)
        self.ends[-1] = self.traj.duration
        return True

    def settle(self) -> int | None:
        """The rest of the surviving shortcuts' checks made now (see Survivors.check): the first attempt whose shortcut
        fails them, else None."""
        failed, checks = self.survivors.check()
        self.spent += checks
        return failed

    def _left(self) -> int:
        """The checks the budget has left beyond those made and those held back for the surviving shortcuts."""
        return self.budget - self.spent - self.survivors.reserved

    def _try(self, t1: float, t2: float, known: Planned | None = None) -> Outcome:
        """A new attempt (see attempt). A ramp's probes (PROBES: its middle, quarters, eighths) are checked first, each
        while the budget has room for it: a ramp through a colliding configuration is refused before it is made and its
        curve's checks are planned. Then it is screened while the budget has left what its screen and its whole check
        could need (the surviving shortcuts' checks made at once first, should what they hold back leave less); else it
        is checked whole, as far as its whole check fits, else not tried. `known`: the ramp's ends, plan (ramps.plan)
        and probes, when planned with others at once on the trajectory as it is (ramps.between)."""
        p, refused = self.smoother, Outcome((t1, t2))
        if t2 - t1 <= p.min_gain:
            return refused
        if known is None:
            (qa, qb), (va, vb) = self.traj.states(np.array([t1, t2]))
            planned = plan(qa, va, qb, vb, p.vmax, p.amax, t2 - t1 - p.min_gain)
            if planned is None:
                return refused
            known = Planned(qa, va, qb, vb, planned, positions(qa, va, vb, planned[1], planned[2], planned[0],
                                                                np.array(PROBES) * planned[0]))
        qa, va, qb, vb, (T, a, vc), probes = known
        validities = self.validities(t1, t2, moving(va, vb, a, vc))
        if validities is None or len(validities) > self._left():
            return refused
        before = sum(v.checks for v in validities)
        clear = True
        for k, q in enumerate(probes):  # on the ramp: a collision refuses it
            if k and len(validities) > self._left() - (sum(v.checks for v in validities) - before):
                break
            clear = all(v.state_valid(q) for v in validities)
            if not clear:
                break
        first = sum(v.checks for v in validities) - before
        self.spent += first
        if not clear:
            return Outcome((t1, t2), None, validities, first, 0, True)
        shortcut = pieces(qa, va, qb, vb, a, vc, T)
        most = sum(v.curve_checks(shortcut) for v in validities)
        if 2 * most > self._left() and self.survivors.reserved:  # what is held back is far more than the checks need
            failed = self.settle()
            if failed is not None:
                raise Retake(failed)
        if most > self._left():
            return refused
        whole = self.eager or 2 * most > self._left()
        checks = 0
        for v in validities:
            before = v.checks
            valid = v.curve_valid(shortcut, screen=not whole)
            checks += v.checks - before
            if not valid:
                break
        self.spent += checks
        return Outcome((t1, t2), shortcut if valid else None, validities, first + checks, most, whole)
