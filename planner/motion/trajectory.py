"""A timed joint trajectory: piecewise parabolic, every joint at constant acceleration between common breakpoints.

The motion's pieces are joined into these (smoothing.py shortens them with checked parabolic ramps, ramps.py). A
polyline timed rest to rest, each straight segment with the time-optimal trapezoidal speed profile along it, is the
start: it stays exactly on the segments that were checked. Positions and velocities are continuous; the state at
any time is read in closed form, so the sampled result and the collision checks of a curve (segments.py) read the
same motion.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Trajectory:
    """On [t[k], t[k+1]] joint j moves as q[k, j] + v[k, j] tau + a[k, j] tau^2 / 2 (tau = time - t[k]); `end` is
    the last position exactly."""

    t: np.ndarray  # (K + 1,) from 0
    q: np.ndarray  # (K, n)
    v: np.ndarray  # (K, n)
    a: np.ndarray  # (K, n)
    end: np.ndarray  # (n,)

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def states(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions, velocities) at the given times (clipped to the trajectory), the end exactly at its time."""
        times = np.clip(np.asarray(times, float), 0.0, self.duration)
        k = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.q) - 1)
        tau = (times - self.t[k])[:, None]
        q = self.q[k] + self.v[k] * tau + 0.5 * self.a[k] * tau**2
        v = self.v[k] + self.a[k] * tau
        at_end = times >= self.duration
        q[at_end] = self.end
        v[at_end] = self.v[-1] + self.a[-1] * (self.t[-1] - self.t[-2])
        return q, v

    def positions(self, times: np.ndarray) -> np.ndarray:
        return self.states(times)[0]

    def accelerations(self, times: np.ndarray) -> np.ndarray:
        """The accelerations at the given times (clipped to the trajectory): the piece's each time starts, the last
        piece's at the end (constant over a piece: at a breakpoint, the one after it)."""
        times = np.clip(np.asarray(times, float), 0.0, self.duration)
        return self.a[np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.q) - 1)]

    def speed_bounds(self, split: int = 4) -> tuple[np.ndarray, np.ndarray]:
        """(breakpoints, (K * split, n) per part and joint the largest speed in it), each piece cut in `split` equal
        parts: velocity is linear in a piece, so its largest magnitude in a part is at one of the part's ends. A joint
        moves at most bound x time within a part; the collision check of a curve spaces its checks by this (see
        segments.py), which overcounts a joint accelerating from rest by (split + 1) / split."""
        h = np.diff(self.t)
        frac = np.arange(split + 1) / split
        t = np.append((self.t[:-1, None] + h[:, None] * frac[None, :-1]).ravel(), self.t[-1])
        v = self.v[:, None, :] + self.a[:, None, :] * (h[:, None] * frac)[:, :, None]  # (K, split + 1, n)
        bound = np.maximum(np.abs(v[:, :-1]), np.abs(v[:, 1:]))
        return t, bound.reshape(-1, self.v.shape[1])

    def scaled(self, factor: float) -> "Trajectory":
        """The same path slowed by `factor` >= 1 (velocities / factor, accelerations / factor^2): limits still hold."""
        return Trajectory(self.t * factor, self.q, self.v / factor, self.a / factor**2, self.end)

    def splice(self, t1: float, t2: float, middle: "Trajectory") -> "Trajectory":
        """This trajectory with [t1, t2] replaced by `middle` (which starts at the state at t1 and ends at the one
        at t2)."""
        k1 = int(np.searchsorted(self.t, t1, side="right")) - 1
        head = k1 + 1 if t1 - self.t[k1] > 1e-12 else k1  # pieces kept before t1 (the last one cut at t1)
        parts = [(self.t[:head], self.q[:head], self.v[:head], self.a[:head]),
                 (t1 + middle.t[:-1], middle.q, middle.v, middle.a)]
        shift = t1 + middle.duration - t2
        if t2 < self.duration - 1e-12:
            k2 = min(int(np.searchsorted(self.t, t2, side="right")) - 1, len(self.q) - 1)
            q2, v2 = self.states(np.array([t2]))
            parts.append((np.append(t2, self.t[k2 + 1:-1]) + shift, np.vstack([q2, self.q[k2 + 1:]]),
                          np.vstack([v2, self.v[k2 + 1:]]), self.a[k2:]))
        t, q, v, a = (np.concatenate([p[i] for p in parts]) for i in range(4))
        return Trajectory(np.append(t, self.duration + shift), q, v, a, self.end)

    @staticmethod
    def joined(parts: list["Trajectory"]) -> "Trajectory":
        """One trajectory running the parts one after another (each starting where the one before ends)."""
        t = np.concatenate([[0.0]] + [p.t[1:] + sum(x.duration for x in parts[:i]) for i, p in enumerate(parts)])
        return Trajectory(t, *(np.vstack([getattr(p, f) for p in parts]) for f in ("q", "v", "a")), parts[-1].end)


def trapezoid(dq: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> tuple[float, float, float]:
    """(duration, peak path speed, path acceleration) of the fastest rest-to-rest motion along dq (path parameter 0..1)."""
    moving = np.abs(dq) > 0
    if not moving.any():
        return 0.0, 0.0, 0.0
    v = float(np.min(vmax[moving] / np.abs(dq[moving])))
    a = float(np.min(amax[moving] / np.abs(dq[moving])))
    if v * v / a >= 1.0:  # triangle: never reaches v
        return 2.0 * math.sqrt(1.0 / a), math.sqrt(a), a
    return 1.0 / v + v / a, v, a


def rest_to_rest(path: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> Trajectory | None:
    """The polyline timed segment by segment, each from rest to rest along its straight line (None: it never moves)."""
    t, q, v, a = [0.0], [], [], []
    for qa, qb in zip(path[:-1], path[1:]):
        dq = qb - qa
        duration, peak, acc = trapezoid(dq, vmax, amax)
        if duration == 0.0:
            continue
        ta = min(peak / acc, 0.5 * duration)
        speed = acc * ta
        cruise = duration - 2.0 * ta
        now = t[-1]
        s_cruise = 0.5 * acc * ta**2
        rows = [(ta, 0.0, 0.0, acc), (cruise, s_cruise, speed, 0.0), (ta, s_cruise + speed * cruise, speed, -acc)]
        for length, s, ds, dds in rows:
            if length <= 1e-12:
                continue
            now += length
            t.append(now)
            q.append(qa + s * dq)
            v.append(ds * dq)
            a.append(dds * dq)
    if not q:
        return None
    return Trajectory(np.array(t), np.array(q), np.array(v), np.array(a), path[-1].copy())
