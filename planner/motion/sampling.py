"""The motion's pieces as one sampled trajectory: each run smoothed (smoothing.py; most in the transit stages' workers
as soon as their pieces exist, the rest here at once in forked workers; each with its own random stream, from the
plan's and the run's pieces), slowed to a whole number of sample periods, and read at the sampling rate.

Slowing a run by the fraction of a period it needs keeps every limit and puts its ends, where the robot rests
(a hand closed, the object set down), on samples; every sample lies on the checked continuous motion. Each sample
belongs to the piece whose (shortcut-mapped) time span holds it: its phase, the object's situation, the working hand.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from planner.core.forked import forked_map
from planner.motion.piece import Piece
from planner.motion.runs import run_key, runs
from planner.motion.smoothing import SmoothedRun, Smoother


@dataclass
class Sampled:
    """Configurations after the first, with their velocities and accelerations, the index into `pieces` of each one's
    piece, and the smoothing's figures per run (its first piece's phase and its SmoothedRun: checks, shortcuts kept,
    and per pass attempts, shortcuts kept and seconds saved)."""

    q: list = field(default_factory=list)
    v: list = field(default_factory=list)
    a: list = field(default_factory=list)
    start_a: np.ndarray | None = None  # the acceleration the motion starts with (the first run's at its start)
    owner: list = field(default_factory=list)
    pieces: list = field(default_factory=list)
    figures: list = field(default_factory=list)


def sample(pieces: list[Piece], smoother: Smoother, dt: float, made: dict[tuple, SmoothedRun]) -> Sampled:
    """Every run smoothed (Smoother.smooth_run; those smoothed already, `made` by run_key, as they were), slowed to whole
    periods of dt and sampled (see the module)."""
    out = Sampled()
    grouped = runs(pieces)
    done = {i: made[run_key(run)] for i, run in enumerate(grouped) if run_key(run) in made}
    budgets = {i: smoother.budget(run) for i, run in enumerate(grouped) if i not in done}

    busy = sorted((i for i, b in budgets.items() if any(b)), key=lambda i: -budgets[i][1])  # the longest work first
    smooth = (forked_map if len(busy) > 1 else map)(lambda i: smoother.smooth_run(grouped[i], budgets[i]), busy)
    done.update(zip(busy, smooth))
    for i in budgets.keys() - done.keys():  # no budget: timed rest to rest, nothing to fork for
        done[i] = smoother.smooth_run(grouped[i], budgets[i])
    for smoothed in (done[i] for i in range(len(grouped))):
        if smoothed.trajectory is None:
            continue
        n = max(1, math.ceil(smoothed.trajectory.duration / dt - 1e-9))
        factor = n * dt / smoothed.trajectory.duration
        traj, ends = smoothed.trajectory.scaled(factor), smoothed.ends * factor
        times = np.arange(1, n + 1) * dt
        q, v = traj.states(times)
        q[-1], v[-1] = traj.end, 0.0  # a run ends at rest
        owner = np.minimum(np.searchsorted(ends, times - 1e-9, side="left"), len(smoothed.pieces) - 1)
        out.q.append(q)
        out.v.append(v)
        out.a.append(traj.accelerations(times))
        if out.start_a is None:
            out.start_a = traj.accelerations(np.zeros(1))
        out.owner += (owner + len(out.pieces)).tolist()
        out.pieces += smoothed.pieces
        out.figures.append((smoothed.pieces[0].phase, smoothed))
    return out
