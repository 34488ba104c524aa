"""Time parameterisation of a piecewise-linear path under per-joint velocity and acceleration limits.

Each straight segment is timed rest to rest with the time-optimal trapezoidal (or triangular)
speed profile along it; stopping at every corner keeps the timed motion exactly on the segments
that were collision-checked (a spline through the waypoints, as toppra's interpolators build,
would leave them). Each segment's duration is rounded up to a whole number of sample periods
(slowing it, which keeps the limits), so every waypoint is a sample of the trajectory.
"""
from __future__ import annotations

import math

import numpy as np


def segment_duration(dq: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> tuple[float, float, float]:
    """(duration, peak path speed, path acceleration) of the fastest rest-to-rest motion along dq (path parameter 0..1)."""
    moving = np.abs(dq) > 0
    if not moving.any():
        return 0.0, 0.0, 0.0
    v = float(np.min(vmax[moving] / np.abs(dq[moving])))
    a = float(np.min(amax[moving] / np.abs(dq[moving])))
    if v * v / a >= 1.0:  # triangle: never reaches v
        return 2.0 * math.sqrt(1.0 / a), math.sqrt(a), a
    return 1.0 / v + v / a, v, a


def _progress(tau: np.ndarray, duration: float, v: float, a: float) -> np.ndarray:
    """Path parameter at times tau of the trapezoid (duration, peak speed v, acceleration a)."""
    ta = v / a
    s = np.where(tau < ta, 0.5 * a * tau**2, 0.5 * a * ta**2 + v * (tau - ta))
    tail = tau > duration - ta
    return np.where(tail, 1.0 - 0.5 * a * (duration - tau) ** 2, s)


def sample_polyline(path: np.ndarray, vmax: np.ndarray, amax: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(per-sample segment index, per-sample configuration) after the first waypoint, at period dt.

    Each segment takes a whole number of periods; its last sample is its end waypoint exactly.
    """
    seg_of, out = [], []
    for k, (qa, qb) in enumerate(zip(path[:-1], path[1:])):
        dq = qb - qa
        duration, v, a = segment_duration(dq, vmax, amax)
        if duration == 0.0:
            continue
        n = max(1, math.ceil(duration / dt - 1e-9))
        tau = np.arange(1, n + 1) * (duration / n)  # the stretched clock, read on the original profile
        s = np.clip(_progress(tau, duration, v, a), 0.0, 1.0)
        q = qa + s[:, None] * dq
        q[-1] = qb  # exactly, not qa + (qb - qa)
        out.append(q)
        seg_of += [k] * n
    if not out:
        return np.zeros(0, dtype=np.int64), np.zeros((0, path.shape[1]))
    return np.array(seg_of, dtype=np.int64), np.concatenate(out)
