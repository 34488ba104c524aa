"""The configuration space of one motion (OMPL's StateSpace): which coordinates move, their bounds, distance, interpolation.

Every planner here (the Super Graph search, RRTConnect, the shortcutter) works in a `JointSpace`:
the coordinates `idx` move, every other coordinate stays at `base` (e.g. the hands while the arms
travel). Distance is Euclidean over the moving coordinates; interpolation is the straight line.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.core.results import frozen


@dataclass(frozen=True, eq=False)
class JointSpace:
    """Moving coordinates `idx` within [lower, upper]; the others held at `base` (a full configuration)."""

    idx: np.ndarray
    lower: np.ndarray  # bounds of the moving coordinates
    upper: np.ndarray
    base: np.ndarray

    @staticmethod
    def of(robot_lower: np.ndarray, robot_upper: np.ndarray, idx: np.ndarray, base: np.ndarray) -> "JointSpace":
        """The space moving `idx` of a robot with these joint limits, the rest at `base`."""
        idx = np.asarray(idx, dtype=np.int64)
        return JointSpace(*(frozen(np.array(a)) for a in (idx, robot_lower[idx], robot_upper[idx], base)))

    @property
    def dimension(self) -> int:
        return len(self.idx)

    def full(self, x: np.ndarray) -> np.ndarray:
        """Full configurations from reduced ones ((d,) or (n, d)): the held coordinates from `base`."""
        x = np.asarray(x, float)
        q = np.broadcast_to(self.base, x.shape[:-1] + self.base.shape).copy()
        q[..., self.idx] = x
        return q

    def reduce(self, q: np.ndarray) -> np.ndarray:
        """The moving coordinates of full configurations."""
        return np.asarray(q, float)[..., self.idx]

    def holds(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        """True if q keeps every held coordinate at `base` (q belongs to this space)."""
        held = np.ones(len(self.base), dtype=bool)
        held[self.idx] = False
        return bool(np.all(np.abs(np.asarray(q)[..., held] - self.base[held]) <= tol))

    def distance(self, qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
        """Euclidean distance over the moving coordinates (broadcasts over leading axes)."""
        return np.linalg.norm(self.reduce(qb) - self.reduce(qa), axis=-1)

    @staticmethod
    def interpolate(qa: np.ndarray, qb: np.ndarray, s: float) -> np.ndarray:
        return qa + s * (qb - qa)
