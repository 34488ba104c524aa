"""The local planner: straight lines in joint space, checked at a bound on how far any robot point moves.

Resolution: along q(s) = qa + s (qb - qa), a point of the robot moves at most sum_j |dq_j| R_j, where
R_j bounds the distance from joint j's axis to any point of the geometry it carries (link lengths down
the chain + the hull's bounding sphere; configuration-independent). A segment is checked at
n = ceil(sum_j |dq_j| R_j / step) + 1 evenly spaced configurations, so no point moves more than
`step` between two checks and every point of the continuous motion is within step / 2 of a checked
position. With robot-obstacle pairs padded by p_env and robot-robot pairs by p_self, a segment whose
checks all pass keeps obstacle distance >= p_env - step / 2 and robot-robot distance >= p_self - step
along the whole continuous motion (see `CollisionParams` and `RoadmapParams`).
The checks run in van der Corput order (midpoint first), so colliding segments fail early.
"""
from __future__ import annotations

import numpy as np

from ..collision import CollisionChecker, CollisionModel


def joint_radii(cm: CollisionModel) -> np.ndarray:
    """(nq,) R_j: an upper bound on the distance from joint j's axis to any robot geometry it moves."""
    model = cm.robot.model
    radii = np.zeros(model.nq)
    for obj in cm.geometry.geometryObjects[: cm.n_robot_geoms]:
        geom = obj.geometry
        geom.computeLocalAABB()
        reach = float(np.linalg.norm(obj.placement.act(np.asarray(geom.aabb_center)))) + float(geom.aabb_radius)
        chain = list(model.supports[obj.parentJoint])[1:]
        for i, j in enumerate(chain):
            if not model.joints[j].shortname().startswith(("JointModelR", "JointModelRevolute")):
                raise ValueError(f"joint '{model.names[j]}' is not revolute: the displacement bound assumes revolute joints")
            down = sum(np.linalg.norm(model.jointPlacements[k].translation) for k in chain[i + 1:])
            q = model.joints[j].idx_q
            radii[q] = max(radii[q], down + reach)
    return radii


def segment_steps(qa: np.ndarray, qb: np.ndarray, radii: np.ndarray, step: float) -> np.ndarray:
    """Number of configurations checked on each segment qa[i] -> qb[i] (vectorised; both ends included)."""
    sweep = np.abs(np.atleast_2d(qb) - np.atleast_2d(qa)) @ radii
    return np.ceil(sweep / step).astype(int) + 1


def van_der_corput(n: int) -> np.ndarray:
    """The n parameters 0, 1/(n-1), ..., 1 in bisection order: ends first, then midpoints, coarse to fine."""
    if n <= 1:
        return np.zeros(max(n, 0))
    order, seen = [0, n - 1], {0, n - 1}
    intervals = [(0, n - 1)]
    while intervals:
        nxt = []
        for a, b in intervals:
            if b - a > 1:
                m = (a + b) // 2
                if m not in seen:
                    seen.add(m)
                    order.append(m)
                nxt += [(a, m), (m, b)]
        intervals = nxt
    return np.asarray(order, dtype=float) / (n - 1)


class SegmentChecker:
    """Checks straight segments for one collision model at one resolution (per process: owns a checker)."""

    def __init__(self, cm: CollisionModel, step: float, checker: CollisionChecker | None = None):
        self.checker = checker or cm.checker()
        self.radii = joint_radii(cm)
        self.step = step

    @property
    def checks(self) -> int:
        return self.checker.checks

    def free(self, q: np.ndarray, subset: str) -> bool:
        return not self.checker.in_collision(q, subset)

    def segment_free(self, qa: np.ndarray, qb: np.ndarray, subset: str, ends: bool = True) -> bool:
        """True if every check of the segment passes (ends skipped when already known free)."""
        n = int(segment_steps(qa, qb, self.radii, self.step)[0])
        s = van_der_corput(n)
        if not ends:
            s = s[2:]
        dq = qb - qa
        return not any(self.checker.in_collision(qa + t * dq, subset) for t in s)
