"""Whole-arm inverse kinematics: put one or several hands' palm frames at poses with their arms (and the torso).

Damped least squares on the stacked 6-D pose errors (log map of SE(3)), with an active set at the
joint limits; cheap enough to run from several starts per target.
Two arms solved together share the torso, so neither undoes what the other needs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from planner.model.robot import Robot


@dataclass(frozen=True)
class IKResult:
    q: np.ndarray
    position_error: float  # m, the worst over the frames
    rotation_error: float  # rad, the worst over the frames
    iterations: int

    def within(self, position_tol: float, rotation_tol: float) -> bool:
        return self.position_error <= position_tol and self.rotation_error <= rotation_tol


class ArmIK:
    """IK for the palm frames of one arm or several (a name or a tuple), with the torso unless `torso=False` (an arm
    that must not move what the other hand holds); holds its own pinocchio Data (one per thread)."""

    def __init__(self, robot: Robot, arms: str | tuple[str, ...], torso: bool = True):
        arms = (arms,) if isinstance(arms, str) else tuple(arms)
        self.robot = robot
        self.frames = [robot.frame_id(robot.palm_frame(a)) for a in arms]
        self.idx = np.concatenate(([robot.torso_idx] if torso else []) + [robot.arm_idx[a] for a in arms])
        self.data = robot.model.createData()

    def palm(self, q: np.ndarray, k: int = 0) -> pin.SE3:
        """The k-th palm frame's world pose at q."""
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        return self.data.oMf[self.frames[k]]

    def _errors(self, q: np.ndarray, goals: list[pin.SE3]) -> tuple[list[pin.SE3], np.ndarray, float, float]:
        """Each goal seen from its palm frame, the stacked log errors, and the worst position and rotation errors
        (the distance between origins is the relative translation's norm; the angle is the log's rotation part)."""
        model, data = self.robot.model, self.data
        pin.forwardKinematics(model, data, q)
        relative = [pin.updateFramePlacement(model, data, f).actInv(g) for f, g in zip(self.frames, goals)]
        logs = [pin.log6(r).vector for r in relative]
        err = np.concatenate(logs)
        # np.linalg.norm's own arithmetic, without its overhead (most of this function's time)
        position = max(math.sqrt(t.dot(t)) for t in (r.translation for r in relative))
        rotation = max(math.sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5]) for v in logs)
        return relative, err, position, rotation

    def solve(self, target: np.ndarray, q0: np.ndarray, iterations: int = 100, position_tol: float = 1e-3,
              rotation_tol: float = 1e-2, damping: float = 1e-4, stall: int = 15) -> IKResult:
        """Move the palm frame(s) to the world pose(s) `target` ((4, 4), or (k, 4, 4) in arm order), from q0.

        Joints outside the arms (and torso) are untouched. Joints at a limit that the step would push
        further are left out of that step (an active set), so one saturated joint does not stall the
        others; gives up once the error has not dropped by 1 % over `stall` iterations (a local minimum:
        another start is cheaper than more iterations).
        """
        model, data, idx = self.robot.model, self.data, self.idx
        lo, hi = self.robot.lower[idx], self.robot.upper[idx]
        targets = np.asarray(target, float).reshape(-1, 4, 4)
        goals = [pin.SE3(T[:3, :3].copy(), T[:3, 3].copy()) for T in targets]
        regulariser = damping * np.eye(6 * len(goals))
        q = q0.copy()
        history: list[float] = []
        for it in range(iterations):
            relative, err, pos_err, rot_err = self._errors(q, goals)
            if pos_err <= position_tol and rot_err <= rotation_tol:
                return IKResult(q, pos_err, rot_err, it)
            history.append(math.sqrt(err.dot(err)))
            if len(history) > stall and history[-1] > 0.99 * history[-1 - stall]:
                return IKResult(q, pos_err, rot_err, it)
            J = np.vstack([pin.Jlog6(r) @ pin.computeFrameJacobian(model, data, q, f, pin.LOCAL)[:, idx]
                           for r, f in zip(relative, self.frames)])
            x = q[idx]
            free = np.ones(len(idx), dtype=bool)
            for _ in range(3):
                Jf = J[:, free]
                dq = np.zeros(len(idx))
                dq[free] = Jf.T @ np.linalg.solve(Jf @ Jf.T + regulariser, err)
                step = np.abs(dq).max()
                if step > 0.4:
                    dq *= 0.4 / step
                blocked = free & (((x <= lo) & (dq < 0)) | ((x >= hi) & (dq > 0)))
                if not blocked.any():
                    break
                free &= ~blocked
            q[idx] = np.minimum(np.maximum(x + dq, lo), hi)
        _, _, pos_err, rot_err = self._errors(q, goals)
        return IKResult(q, pos_err, rot_err, iterations)
