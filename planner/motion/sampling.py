"""The motion's pieces as one sampled trajectory: each run smoothed (smoothing.py; the runs at once in forked workers,
each with its own random stream drawn from the plan's), slowed to a whole number of sample periods, and read at the
sampling rate.

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
from planner.motion.smoothing import Smoother, runs


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


def sample(pieces: list[Piece], smoother: Smoother, rng: np.random.Generator, dt: float, attempts: int, budget: int) -> Sampled:
    """Every run smoothed, slowed to whole periods of dt and sampled (see the module). The runs share `attempts` random
    shortcuts and a `budget` of collision checks in proportion to what they could save (Smoother.could_save)."""
    out = Sampled()
    grouped = runs(pieces)
    seeds = rng.integers(2**63, size=len(grouped))
    share = np.array([smoother.could_save(run) for run in grouped])
    share = share / max(share.sum(), 1e-12)

    def smooth(i: int):
        return smoother.smooth(grouped[i], np.random.default_rng(seeds[i]), int(attempts * share[i]), int(budget * share[i]))

    order = np.argsort(-share, kind="stable")  # the longest work first: the last worker to finish ends the sooner
    done = dict(zip(order.tolist(), forked_map(smooth, order.tolist())))
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
