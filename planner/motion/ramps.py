"""Time-optimal parabolic ramps between two states (Hauser and Ng-Thow-Hing, ICRA 2010; KrisLibrary's ParabolicRamp).

One joint goes from (x0, v0) to (x1, v1) with |v| <= vmax and |a| <= amax by a ramp: constant acceleration to a
cruising velocity, cruise, constant acceleration to v1 (either ramp may be empty, the cruise too). Its shortest
duration is the bang-bang profile (or the bang-cruise-bang one when the peak would pass vmax). Several joints move
together: the slowest joint sets the duration T, and every other joint takes, for that T, the ramp of least
acceleration (closed forms, see fixed_time). Some T above a joint's shortest duration admit no ramp (Hauser's
inoperative intervals, when v0 and v1 point away from the goal): the duration is then lengthened step by step, and a
ramp none admits is not made.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from planner.motion.trajectory import Trajectory

TINY = 1e-12
STRETCH = (1.0, 1.002, 1.01, 1.03, 1.07, 1.15, 1.3, 1.6, 2.0, 3.0)  # durations tried, times the slowest joint's shortest


def min_times(d: np.ndarray, v0: np.ndarray, v1: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> np.ndarray:
    """Per joint, the shortest duration of a move by d from velocity v0 to v1 (inf where none: |v0| or |v1| > vmax)."""
    best = np.full(np.shape(d), np.inf)
    for s in (1.0, -1.0):
        peak2 = s * amax * d + 0.5 * (v0**2 + v1**2)
        peak = s * np.sqrt(np.maximum(peak2, 0.0))
        t1, t2 = (peak - v0) / (s * amax), (peak - v1) / (s * amax)
        ok = (peak2 >= 0.0) & (t1 >= -1e-12) & (t2 >= -1e-12)
        bang = ok & (np.abs(peak) <= vmax)
        c1, c2 = (s * vmax - v0) / (s * amax), (s * vmax - v1) / (s * amax)
        cruise = (d - s * ((vmax**2 - v0**2) + (vmax**2 - v1**2)) / (2.0 * amax)) / (s * vmax)
        capped = ok & ~bang & (cruise >= -1e-12) & (c1 >= -1e-12) & (c2 >= -1e-12)
        best = np.minimum(best, np.where(bang, t1 + t2, np.where(capped, c1 + np.maximum(cruise, 0.0) + c2, np.inf)))
    return np.where((np.abs(v0) > vmax * (1 + 1e-9)) | (np.abs(v1) > vmax * (1 + 1e-9)), np.inf, best)


def fixed_time(d: np.ndarray, v0: np.ndarray, v1: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
               T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(acceleration, cruising velocity, feasible) per joint: the least-acceleration ramp of duration T, in closed form.

    Without a cruise the two ramps meet at vc = (v0 + v1 + sign a T) / 2, and the distance covered gives a quadratic in
    a with one root >= 0 (sign: up when d exceeds what constant acceleration from v0 to v1 covers, (v0 + v1) T / 2,
    down otherwise). Where that vc passes vmax, the ramp cruises at sign vmax and a follows from the distance."""
    s, dv = v0 + v1, v0 - v1
    sign = np.where(d >= 0.5 * s * T, 1.0, -1.0)
    b = sign * (4.0 * d - 2.0 * s * T)
    a = (b + np.sqrt(b * b + 4.0 * T * T * dv * dv)) / (2.0 * T * T)
    vc = 0.5 * (s + sign * a * T)
    capped = np.abs(vc) > vmax
    room = vmax * T - sign * d  # what a cruise at sign vmax would cover beyond d
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(capped, ((vmax - sign * v0) ** 2 + (vmax - sign * v1) ** 2) / (2.0 * room), a)
        vc = np.where(capped, sign * vmax, vc)
        ramps = (np.abs(vc - v0) + np.abs(v1 - vc)) / a
    still = (a <= TINY) & (np.abs(dv) < TINY)  # constant velocity already
    ok = still | ((a <= amax * (1 + 1e-9)) & (~capped | (room > 0)) & (ramps <= T * (1 + 1e-9)))
    return np.where(still, 0.0, a), np.where(still, v0, vc), ok


def plan(q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
         within: float = np.inf) -> tuple[float, np.ndarray, np.ndarray] | None:
    """(duration T, per joint acceleration and cruising velocity) of the synchronised ramp from (q0, v0) to (q1, v1):
    T set by the slowest joint (see the module); None when no duration tried admits a ramp for every joint, or none
    shorter than `within`."""
    d = q1 - q0
    fastest = float(np.max(min_times(d, v0, v1, vmax, amax), initial=0.0))
    if not fastest < within or fastest <= TINY:  # too slow, or the same state: nothing to move
        return None
    for stretch in STRETCH:
        if fastest * stretch >= within:
            return None
        T = fastest * stretch
        a, vc, ok = fixed_time(d, v0, v1, vmax, amax, T)
        if ok.all():
            return T, a, vc
    return None


def first_plans(q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
                within: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`plan` for many ramps at once (rows), at their slowest joint's shortest duration only: (that duration, T, a, vc,
    planned), planned False where that duration admits no ramp for every joint or is not shorter than `within` (`plan`
    may then still find a longer one)."""
    d = q1 - q0
    fastest = np.max(min_times(d, v0, v1, vmax, amax), axis=-1, initial=0.0)
    T = np.where(np.isfinite(fastest) & (fastest > TINY), fastest, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a, vc, ok = fixed_time(d, v0, v1, vmax, amax, T[..., None])
    return fastest, T, a, vc, (fastest < within) & (fastest > TINY) & ok.all(axis=-1)


def moving(v0: np.ndarray, v1: np.ndarray, a: np.ndarray, vc: np.ndarray) -> np.ndarray:
    """The joints a planned ramp moves (its every other joint stays at rest throughout)."""
    return (v0 != 0) | (v1 != 0) | (vc != 0) | (a > 0)


def positions(q0: np.ndarray, v0: np.ndarray, v1: np.ndarray, a: np.ndarray, vc: np.ndarray, T: np.ndarray | float,
              taus: np.ndarray) -> np.ndarray:
    """A planned ramp's positions at times `taus` (shape (..., k), from its start) in closed form: (..., k, n)."""
    q0, v0, v1, a, vc = (np.asarray(x)[..., None, :] for x in (q0, v0, v1, a, vc))
    return _state(_profile(q0, v0, v1, a, vc), q0, v0, vc, np.asarray(T, float)[..., None, None],
                  np.asarray(taus, float)[..., :, None])[0]


def ramp(q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
         within: float = np.inf) -> Trajectory | None:
    """The synchronised ramp from (q0, v0) to (q1, v1) (see `plan`) as a trajectory; None where `plan` finds none."""
    planned = plan(q0, v0, q1, v1, vmax, amax, within)
    return None if planned is None else pieces(q0, v0, q1, v1, planned[1], planned[2], planned[0])


def _profile(q0, v0, v1, a, vc) -> tuple:
    """Per joint: the first ramp's and the last ramp's durations and accelerations, the position the first ends at."""
    safe = np.where(a > 0, a, 1.0)
    t1 = np.where(a > 0, np.abs(vc - v0) / safe, 0.0)
    t2 = np.where(a > 0, np.abs(v1 - vc) / safe, 0.0)
    s1, s2 = np.sign(vc - v0) * a, np.sign(v1 - vc) * a
    return t1, t2, s1, s2, q0 + v0 * t1 + 0.5 * s1 * t1**2


def _state(profile: tuple, q0, v0, vc, T, tau) -> tuple[np.ndarray, np.ndarray]:
    """(positions, velocities) at times tau (broadcast against the joints) of the ramps `profile` describes."""
    t1, t2, s1, s2, pos0 = profile
    first = tau < t1
    last = tau > T - t2
    late = tau - (T - t2)
    q = np.where(first, q0 + v0 * tau + 0.5 * s1 * tau**2,
                 np.where(last, pos0 + vc * (T - t2 - t1) + vc * late + 0.5 * s2 * late**2, pos0 + vc * (tau - t1)))
    v = np.where(first, v0 + s1 * tau, np.where(last, vc + s2 * late, vc))
    return q, v


def pieces(q0, v0, q1, v1, a, vc, T: float) -> Trajectory:
    """The ramps (per joint: accelerate to vc, cruise, accelerate to v1) as one piecewise-parabolic trajectory."""
    profile = _profile(q0, v0, v1, a, vc)
    t1, t2, s1, s2, _ = profile
    cuts = np.unique(np.clip(np.concatenate([[0.0, T], t1, T - t2]), 0.0, T))
    cuts = cuts[np.concatenate([[True], np.diff(cuts) > 1e-9])]
    cuts[-1] = T
    starts = cuts[:-1]
    mids = 0.5 * (cuts[:-1] + cuts[1:])
    q, v = _state(profile, q0, v0, vc, T, starts[:, None])
    tm = mids[:, None]
    acc = np.where(tm < t1, s1, np.where(tm > T - t2, s2, 0.0))
    return Trajectory(cuts, q, v, acc, q1.copy())


class Planned(NamedTuple):
    """A ramp planned, not yet made: its ends' states, its plan (`plan`: T, a, vc) and its positions at some shares of
    its duration (the probes a smoothing attempt checks before it makes the ramp: `pieces`)."""

    qa: np.ndarray
    va: np.ndarray
    qb: np.ndarray
    vb: np.ndarray
    plan: tuple[float, np.ndarray, np.ndarray]
    probes: np.ndarray


def between(traj: Trajectory, t1: np.ndarray, t2: np.ndarray, vmax: np.ndarray, amax: np.ndarray, min_gain: float,
            shares: np.ndarray) -> tuple[np.ndarray, list[Planned | None]]:
    """(per ramp from the trajectory's state at t1 to its state at t2, its slowest joint's shortest move; each ramp
    planned with its positions at `shares` of its duration, at once with the others where that duration admits one
    shorter than t2 - t1 - min_gain, else None: a smoothing attempt plans it alone)."""
    (qa, va), (qb, vb) = traj.states(t1), traj.states(t2)
    fastest, T, a, vc, planned = first_plans(qa, va, qb, vb, vmax, amax, t2 - t1 - min_gain)
    known: list[Planned | None] = [None] * len(t1)
    rows = np.flatnonzero(planned)
    at = positions(qa[rows], va[rows], vb[rows], a[rows], vc[rows], T[rows], T[rows, None] * shares)
    for i, probes in zip(rows.tolist(), at):
        known[i] = Planned(qa[i], va[i], qb[i], vb[i], (float(T[i]), a[i], vc[i]), probes)
    return fastest, known
