"""Conversions from pinocchio poses to what viser draws: wxyz quaternions and positions."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation


def poses_wxyz(placements: list[pin.SE3]) -> tuple[np.ndarray, np.ndarray]:
    """(n, 4) wxyz quaternions and (n, 3) positions of a list of SE3 placements."""
    if not placements:
        return np.zeros((0, 4)), np.zeros((0, 3))
    rotations = np.stack([M.rotation for M in placements])
    xyzw = Rotation.from_matrix(rotations).as_quat()
    return xyzw[:, [3, 0, 1, 2]], np.stack([M.translation for M in placements])


def matrix_wxyz(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """wxyz quaternion and position of a 4x4 homogeneous transform."""
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return np.array([w, x, y, z]), np.asarray(T[:3, 3], float)
