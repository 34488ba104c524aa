"""Straight hand motions: IK waypoints of an arm and the torso, the palm of a hand holding the object kept still.

While the other hand holds the object its palm is held by the same IK, so the object does not move. A hand backs
off from a grasp along its approach direction by the pre-grasp distance (see fallbacks.retreat_offsets).
"""
from __future__ import annotations

import time

import numpy as np
import pinocchio as pin

from planner.handover.arm_ik import ArmIK
from planner.handover.reach import approach_direction
from planner.model.robot import Robot
from planner.motion.phase import Phase
from planner.motion.piece import PieceFailed
from planner.motion.result import MotionParams
from planner.motion.transit import TransitStats


class ArmMotions:
    """Palm poses and straight palm motions of the robot; the seconds of its motions go to the phase's `stats`."""

    def __init__(self, robot: Robot, data: pin.Data, params: MotionParams, stats: list[TransitStats]):
        self.robot, self.data, self.p, self.stats = robot, data, params, stats
        self.iks: dict[tuple[str, ...], ArmIK] = {}  # one solver (and its scratch data) per set of arms

    def palm(self, q: np.ndarray, arm: str) -> np.ndarray:
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        return self.data.oMf[self.robot.frame_id(self.robot.palm_frame(arm))].homogeneous.copy()

    def _ik(self, q: np.ndarray, arm: str, target: np.ndarray, keep: str | None, tol: float = 1e-3,
            damping: float = 1e-4) -> np.ndarray | None:
        """q with the torso and the arm moved so its palm is at target; the palm of `keep` (a hand holding the object)
        stays where it is. None when IK misses."""
        arms, targets = (arm,), [target]
        if keep is not None:
            arms, targets = (arm, keep), [target, self.palm(q, keep)]
        if arms not in self.iks:
            self.iks[arms] = ArmIK(self.robot, arms)
        result = self.iks[arms].solve(np.array(targets), q, 60, tol, 10 * tol, damping=damping, stall=20)
        return result.q if result.within(tol, 10 * tol) else None

    def refine(self, q: np.ndarray, arm: str, target: np.ndarray, keep: str | None, phase: Phase, part: str) -> np.ndarray:
        """q with the palm of `arm` at target to 0.1 mm / 1 mrad (the double grasps hold 2 mm), `keep`'s palm still."""
        found = self._ik(q, arm, target, keep, 1e-4, damping=1e-9)
        if found is None:
            raise PieceFailed(phase, part, "the arm cannot put its palm exactly at the grasp")
        return found

    def straight(self, q: np.ndarray, arm: str, offset: np.ndarray, keep: str | None, phase: Phase, part: str) -> np.ndarray:
        """IK waypoints moving the arm's palm by a world offset in a straight line, `keep`'s palm still: (steps+1, nq)."""
        t = time.perf_counter()
        start = self.palm(q, arm)
        out = [q]
        for s in np.linspace(0.0, 1.0, self.p.straight_steps + 1)[1:]:
            target = start.copy()
            target[:3, 3] += s * offset
            nxt = self._ik(out[-1], arm, target, keep)
            if nxt is None:
                raise PieceFailed(phase, part, f"the arm cannot move its palm {np.linalg.norm(offset):.3f} m in a straight line")
            out.append(nxt)
        self.stats[phase].seconds_contact += time.perf_counter() - t
        return np.array(out)

    def backoff(self, q: np.ndarray, arm: str) -> np.ndarray:
        """World offset that backs the arm's palm off along its approach direction by the pre-grasp distance."""
        palm = self.palm(q, arm)
        return -self.p.pregrasp_distance * (palm[:3, :3] @ approach_direction(self.robot, arm))
