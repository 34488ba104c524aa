"""OMPL's RRTConnect on a box-bounded joint space whose validity is given by plain Python callables.

Used to reconnect two configurations when the lazy roadmap search fails, and as the single-query
baseline of the benchmark. Validity is decided only by the caller's callables (never by OMPL's own
discrete motion checking) and RRTConnect's raw path is returned: the project shortcuts it itself.
"""
from __future__ import annotations

import contextlib
import math
import operator
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from planner.core.results import frozen

StateValid = Callable[[np.ndarray], bool]
MotionValid = Callable[[np.ndarray, np.ndarray], bool]

_MAX_SEED = 2**32 - 2  # OMPL takes an unsigned 32-bit seed and rejects 0; we pass seed + 1


@dataclass(frozen=True)
class RRTResult:
    """The outcome of one RRTConnect query (path in the caller's reduced coordinates)."""

    found: bool
    path: np.ndarray  # (k, d) waypoints from start to goal; (0, d) when not found; read-only
    states: int  # vertices in both trees when the planner stopped (OMPL's PlannerData)
    seconds: float  # wall time of the solve (a measurement, not a contract)
    message: str  # why it failed, in words; "" when found


class _CallableMotionValidator(ob.MotionValidator):
    """A motion validator deciding a segment with the caller's callables instead of OMPL's resolution.

    The nanobind bindings expose a C++ trampoline: Python overrides only ``checkMotion(s1, s2)``.
    The last-valid overload ``checkMotion(s1, s2, lastValid)`` is fixed in that trampoline (it
    forwards here and leaves ``lastValid`` untouched) and cannot be overridden from Python;
    RRTConnect never calls it, which is why this validator is only used with RRTConnect.
    OMPL's contract assumes only ``s1`` is valid, and RRTConnect's start tree relies on the
    validator to reject an invalid ``s2``, so ``state_valid(s2)`` is checked before the segment.
    """

    def __init__(self, si: ob.SpaceInformation, dim: int, state_valid: StateValid, motion_valid: MotionValid):
        super().__init__(si)
        self._dim = dim
        self._state_valid = state_valid
        self._motion_valid = motion_valid
        self.motions = 0  # motions checked so far (a budget in these is the same however fast the machine)

    def checkMotion(self, s1: ob.State, s2: ob.State) -> bool:
        """Whether RRTConnect may join s1 to s2: s2 is a valid state and the segment is free."""
        self.motions += 1
        b = _to_array(s2, self._dim)
        return bool(self._state_valid(b)) and bool(self._motion_valid(_to_array(s1, self._dim), b))


def _to_array(state: ob.State, dim: int) -> np.ndarray:
    """A numpy copy of an OMPL real-vector state (the slice copies; OMPL may reuse the state's memory)."""
    return np.array(state[0:dim], dtype=float)


@contextlib.contextmanager
def _ompl_log_level(level: ou.LogLevel) -> Iterator[None]:
    """Run a block with OMPL's console log level set to `level`, restoring the previous level after."""
    previous = ou.getLogLevel()
    ou.setLogLevel(level)
    try:
        yield
    finally:
        ou.setLogLevel(previous)


def _checked_inputs(lower: np.ndarray, upper: np.ndarray, start: np.ndarray, goal: np.ndarray, seed: int,
                    time_limit: float, range_: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """The inputs as float arrays and an int seed, or a ValueError naming what is wrong."""
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    if lower.ndim != 1 or lower.size == 0 or upper.shape != lower.shape:
        raise ValueError(f"lower and upper must be 1-D of the same length d >= 1, got {lower.shape} and {upper.shape}")
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(lower < upper)):
        raise ValueError(f"bounds must be finite with lower < upper in every coordinate: {lower} / {upper}")
    arrays = []
    for name, q in (("start", start), ("goal", goal)):
        q = np.asarray(q, dtype=float)
        if q.shape != lower.shape:
            raise ValueError(f"{name} must have shape {lower.shape}, got {q.shape}")
        outside = np.flatnonzero(~((q >= lower) & (q <= upper)))
        if outside.size:
            raise ValueError(f"{name} is outside the bounds in coordinates {outside.tolist()}: {q[outside]}")
        arrays.append(q)
    seed = operator.index(seed)
    if not 0 <= seed <= _MAX_SEED:
        raise ValueError(f"seed must be in [0, {_MAX_SEED}], got {seed}")
    if not (math.isfinite(time_limit) and time_limit > 0):
        raise ValueError(f"time_limit must be a positive number of seconds, got {time_limit}")
    if not (math.isfinite(range_) and range_ >= 0):
        raise ValueError(f"range_ must be >= 0 (0: OMPL's default), got {range_}")
    return lower, upper, arrays[0], arrays[1], seed


def rrt_connect(lower: np.ndarray, upper: np.ndarray,
                state_valid: StateValid,
                motion_valid: MotionValid,
                start: np.ndarray, goal: np.ndarray, *, seed: int, time_limit: float = 30.0,
                range_: float = 0.0, more_goals: np.ndarray | None = None, max_motions: int | None = None) -> RRTResult:
    """Plan from `start` to `goal` (or to any of `more_goals`, (k, d) valid states: the goal tree grows from each) in the
    box [lower, upper] with OMPL's RRTConnect; the raw path, unsimplified.

    `state_valid(q)` and `motion_valid(a, b)` get numpy copies; `motion_valid` decides whether the
    straight segment a-b is free and must be symmetric (the goal tree asks for its edges from the
    new state towards the tree). `range_` is RRTConnect's extension length (0: OMPL's default,
    a fifth of the space's extent). The same inputs and seed give the same path when the solve
    ends before `time_limit`: OMPL's seed generator is reseeded before anything random is made
    (process-wide, so concurrent OMPL use in other threads would break this). With `max_motions` the
    solve stops after that many motion checks instead of after `time_limit`: the same inputs and seed
    then give the same result however fast or busy the machine.
    """
    lower, upper, start, goal, seed = _checked_inputs(lower, upper, start, goal, seed, time_limit, range_)
    d = lower.size
    goals = np.concatenate([goal[None], np.zeros((0, d)) if more_goals is None else np.asarray(more_goals, dtype=float)])
    if goals.ndim != 2 or goals.shape[1] != d or not np.all((goals >= lower) & (goals <= upper)):
        raise ValueError(f"more_goals must be (k, {d}) states within the bounds")
    if not state_valid(start.copy()):
        return RRTResult(False, frozen(np.empty((0, d))), 0, 0.0, "start invalid")
    if not state_valid(goal.copy()):
        return RRTResult(False, frozen(np.empty((0, d))), 0, 0.0, "goal invalid")

    with _ompl_log_level(ou.LOG_WARN):
        # setSeed after OMPL's first random number logs an error but does reseed the generator that
        # seeds every later RNG (sampler, nearest-neighbour structure), which is what makes this repeatable.
        with _ompl_log_level(ou.LOG_NONE):
            ou.RNG.setSeed(seed + 1)
        space = ob.RealVectorStateSpace(d)
        bounds = ob.RealVectorBounds(d)
        for i in range(d):
            bounds.setLow(i, float(lower[i]))
            bounds.setHigh(i, float(upper[i]))
        space.setBounds(bounds)
        si = ob.SpaceInformation(space)
        si.setStateValidityChecker(lambda s: bool(state_valid(_to_array(s, d))))
        validator = _CallableMotionValidator(si, d, state_valid, motion_valid)
        si.setMotionValidator(validator)
        si.setup()

        start_state = si.allocState()
        start_state[0:d] = start.tolist()
        goal_set = ob.GoalStates(si)
        for g in goals:
            state = si.allocState()
            state[0:d] = g.tolist()
            goal_set.addState(state)
        pdef = ob.ProblemDefinition(si)
        pdef.addStartState(start_state)
        pdef.setGoal(goal_set)
        planner = og.RRTConnect(si)
        planner.setRange(float(range_))
        planner.setProblemDefinition(pdef)
        planner.setup()

        t0 = time.perf_counter()
        if max_motions is None:
            status = planner.solve(float(time_limit))
        else:
            status = planner.solve(ob.PlannerTerminationCondition(lambda: validator.motions >= max_motions))
        seconds = time.perf_counter() - t0

        data = ob.PlannerData(si)
        planner.getPlannerData(data)
        states = data.numVertices()
        kind = status.getStatus()
        if kind == ob.PlannerStatus.EXACT_SOLUTION:
            path = pdef.getSolutionPath()
            waypoints = np.array([path.getState(i)[0:d] for i in range(path.getStateCount())], dtype=float)
            return RRTResult(True, frozen(waypoints), states, seconds, "")
    if kind in (ob.PlannerStatus.TIMEOUT, ob.PlannerStatus.APPROXIMATE_SOLUTION):
        message = f"no path within {time_limit:g} s" if max_motions is None else f"no path within {max_motions} motion checks"
    else:
        message = f"RRTConnect stopped: {status.asString()}"
    return RRTResult(False, frozen(np.empty((0, d))), states, seconds, message)


