"""Small geometry helpers: 4x4 poses from translations and angles, their pinocchio SE3, headings and rotation angles."""
from __future__ import annotations

import numpy as np
import pinocchio as pin


def pose(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 homogeneous transform from a translation and roll-pitch-yaw angles."""
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(*map(float, rpy))
    T[:3, 3] = xyz
    return T


def se3(T: np.ndarray) -> pin.SE3:
    return pin.SE3(np.asarray(T[:3, :3], float), np.asarray(T[:3, 3], float))


def heading(T: np.ndarray) -> float:
    """The heading (rad) of a pose: the angle of its x axis about the vertical (the yaw of its roll-pitch-yaw)."""
    return float(np.arctan2(T[1, 0], T[0, 0]))


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (rad, in [0, pi]) of the rotation between two poses' orientations."""
    return float(np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
