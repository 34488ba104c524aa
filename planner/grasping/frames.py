"""Grasp frames (paper IV-A.1): positions on a uniform grid in the object's bounding box, orientations uniform on SO(3).

Orientations follow Yershova et al.'s Hopf-fibration construction: a rotation is a point of S^2
(the image of the fingers' axis, cos(theta) and phi uniform) and an angle psi about it, and the
product of the uniform measures on S^2 and S^1 is the uniform measure on SO(3). The three
coordinates come from a Halton sequence, so the orientations are deterministic and incremental:
every prefix of the sequence is spread evenly (low dispersion), whatever count is asked for.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import qmc


def hopf_rotations(n: int) -> np.ndarray:
    """The first n rotations (n, 3, 3) of the incremental Hopf-Halton sequence on SO(3)."""
    u = qmc.Halton(d=3, scramble=False).random(n)
    theta = np.arccos(1.0 - 2.0 * u[:, 0])
    phi, psi = 2.0 * np.pi * u[:, 1], 2.0 * np.pi * u[:, 2]
    quat = np.stack([np.cos(theta / 2) * np.cos(psi / 2), np.cos(theta / 2) * np.sin(psi / 2),
                     np.sin(theta / 2) * np.cos(phi + psi / 2), np.sin(theta / 2) * np.sin(phi + psi / 2)], axis=1)
    return Rotation.from_quat(quat).as_matrix()


def box_grid(lower: np.ndarray, upper: np.ndarray, count: int, offset: np.ndarray | None = None) -> np.ndarray:
    """About `count` cell centres of a uniform cubic grid filling the box; `offset` (in cells, within ±0.5) shifts them."""
    extent = np.maximum(np.asarray(upper, float) - lower, 1e-9)
    cell = (np.prod(extent) / max(count, 1)) ** (1.0 / 3.0)
    n = np.maximum(1, np.round(extent / cell)).astype(int)
    step = extent / n
    shift = np.zeros(3) if offset is None else np.asarray(offset, float)
    axes = [lower[i] + (np.arange(n[i]) + 0.5 + shift[i]) * step[i] for i in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
