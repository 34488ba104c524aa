"""Whole-arm inverse kinematics: put a hand's palm frame at a pose with the arm (and optionally the torso).

Damped least squares on the 6-D pose error (log map of SE(3)), clipped to joint limits; cheap
enough (~20 µs an iteration) to run from several starts per target.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .robot import Robot


@dataclass(frozen=True)
class IKResult:
    q: np.ndarray
    position_error: float  # m
    rotation_error: float  # rad
    iterations: int

    def within(self, position_tol: float, rotation_tol: float) -> bool:
        return self.position_error <= position_tol and self.rotation_error <= rotation_tol


class ArmIK:
    """IK for one arm's palm frame; holds its own pinocchio Data (one per thread)."""

    def __init__(self, robot: Robot, arm: str, with_torso: bool = True):
        self.robot = robot
        hand = robot.spec.arm(arm).hand
        self.frame = robot.frame_id(hand.prefixed(hand.palm_frame))
        self.idx = np.concatenate([robot.torso_idx, robot.arm_idx[arm]]) if with_torso else robot.arm_idx[arm]
        self.data = robot.model.createData()

    def palm(self, q: np.ndarray) -> pin.SE3:
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        return self.data.oMf[self.frame]

    def solve(self, target: np.ndarray, q0: np.ndarray, iterations: int = 80, position_tol: float = 1e-3,
              rotation_tol: float = 1e-2, damping: float = 1e-4) -> IKResult:
        """Move the palm frame to the 4x4 world pose `target`, starting from q0 (other joints untouched)."""
        model, data, idx = self.robot.model, self.data, self.idx
        lo, hi = self.robot.lower[idx], self.robot.upper[idx]
        goal = pin.SE3(target[:3, :3].copy(), target[:3, 3].copy())
        q = q0.copy()
        for it in range(iterations):
            pin.forwardKinematics(model, data, q)
            current = pin.updateFramePlacement(model, data, self.frame)
            err = pin.log6(current.actInv(goal)).vector  # in the palm frame
            pos_err = float(np.linalg.norm(goal.translation - current.translation))
            rot_err = float(np.linalg.norm(err[3:]))
            if pos_err <= position_tol and rot_err <= rotation_tol:
                return IKResult(q, pos_err, rot_err, it)
            J = pin.computeFrameJacobian(model, data, q, self.frame, pin.LOCAL)[:, idx]
            J = pin.Jlog6(current.actInv(goal)) @ J
            dq = J.T @ np.linalg.solve(J @ J.T + damping * np.eye(6), err)
            step = np.max(np.abs(dq))
            if step > 0.4:
                dq *= 0.4 / step
            q[idx] = np.clip(q[idx] + dq, lo, hi)
        current = self.palm(q)
        return IKResult(q, float(np.linalg.norm(goal.translation - current.translation)),
                        float(np.linalg.norm(pin.log3(current.rotation.T @ goal.rotation))), iterations)
