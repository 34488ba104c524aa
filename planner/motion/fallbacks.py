"""The candidate loops of the contact stages: each stage offers candidates in order of preference, and the next one
is tried where a piece built from the last cannot be made (or its transit cannot be found).

Candidates: the directions a hand backs off from a grasp (its pre-grasp: along its approach direction by the
pre-grasp distance, farther or nearer, then tilted from it), the directions the object is lifted off or set down
(freest first), and through them the pre-shapes and the double grasps (the step tries the next one).
"""
from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from planner.motion.arm_motion import ArmMotions
from planner.motion.phase import Phase
from planner.motion.piece import Piece, PieceFailed

FREE_ENOUGH = 0.75  # an end keeping three quarters of every transit padding is taken without looking further


def options(phase: Phase, part: str, candidates: Iterator, build: Callable) -> Iterator:
    """What `build` makes of each candidate for which it raises no PieceFailed, in order; past the last, the last
    failure is raised."""
    failure = None
    for candidate in candidates:
        try:
            yield build(candidate)
        except PieceFailed as exc:
            failure = exc
    raise failure or PieceFailed(phase, part, "the arm cannot back its hand off in a straight line")


def freest(candidates: Iterator[tuple]) -> Iterator[tuple]:
    """Options ((q, pieces, freedom) with freedom as ContactStages.ready gives it) in order while they are free enough,
    the others after them, freest first: a transit from a free end checks sparsely and leaves it easily."""
    held = []
    try:
        for option in candidates:
            if option[2] >= FREE_ENOUGH:
                yield option
            else:
                held.append(option)
    except PieceFailed:
        if not held:
            raise
    yield from sorted(held, key=lambda o: -o[2])


def raise_first(results: list[list[Piece] | PieceFailed]) -> None:
    """Raise the first failure among the transits' results (given in phase order)."""
    failed = next((r for r in results if isinstance(r, PieceFailed)), None)
    if failed is not None:
        raise failed


def retreats(arms: ArmMotions, q: np.ndarray, arm: str, keep: str | None, hover: bool, phase: Phase, part: str,
             leaving: bool = False) -> list[Iterator[np.ndarray]]:
    """Two groups of candidate IK polylines from q (the palm at a grasp) backing off by the pre-grasp distance: along
    the approach direction (that distance, farther, nearer), then rising by the lift height when `hover` (the object
    rests on a support there; elsewhere rising is the last resort); then tilted 30° and 55° from the approach
    direction in six directions each (where fingers moving along it would sweep the object or a support), rising
    likewise. Each group is computed only when it is reached; candidates the arm cannot follow are skipped.
    `leaving` (a hand letting go in the air): farther first. Its fingers, opened part way, can still be a millimetre
    from the object after the pre-grasp distance, and the transit that follows checks as densely as its ends need."""
    back = arms.backoff(q, arm)
    rises = (1.0, 1.0, 2.0, 1.0) if hover else (0.0, 0.0, 0.0, 1.0)
    scales = (1.0, 1.7, 1.0, 0.5) if hover else (1.7, 1.0, 0.5, 1.0) if leaving else (1.0, 1.7, 0.5, 1.0)
    along = [(scale * back, rise) for scale, rise in zip(scales, rises)]
    axis = back / np.linalg.norm(back)
    u = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    tilted = [(np.linalg.norm(back) * (np.cos(t) * axis + np.sin(t) * (np.cos(az) * u + np.sin(az) * v)), rises[0])
              for t in np.radians([30.0, 55.0]) for az in np.radians(np.arange(0.0, 360.0, 60.0))]
    return [_backing(arms, q, arm, keep, offsets, phase, part) for offsets in (along, tilted)]


def _backing(arms: ArmMotions, q: np.ndarray, arm: str, keep: str | None, offsets: list[tuple[np.ndarray, float]],
             phase: Phase, part: str) -> Iterator[np.ndarray]:
    """The IK polylines moving the palm from q by each world offset, then up by `rise` lift heights (see retreats)."""
    up = np.array([0.0, 0.0, arms.p.lift])
    for offset, rise in offsets:
        try:
            path = arms.straight(q, arm, offset, keep, phase, part)
            if rise:
                path = np.concatenate([path, arms.straight(path[-1], arm, rise * up, keep, phase, part)[1:]])
        except PieceFailed:
            continue
        yield path


def lift_offsets(lift: float) -> list[np.ndarray]:
    """World offsets to lift an object off its support (reversed: to set it down): up, then tilted 30°, 55° and 75°
    from the vertical in eight directions, each by the lift distance and twice as far."""
    dirs = [np.array([0.0, 0.0, 1.0])]
    for tilt in np.radians([30.0, 55.0, 75.0]):
        dirs += [np.array([np.sin(tilt) * np.cos(a), np.sin(tilt) * np.sin(a), np.cos(tilt)])
                 for a in np.radians(np.arange(0.0, 360.0, 45.0))]
    return [scale * lift * d for scale in (1.0, 2.0) for d in dirs]
