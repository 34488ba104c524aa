"""Tests that settle a collision before coal's exact one in the grasp search, for many posed shapes per numpy call.

A shape certainly hits the object when a ball inside it holds a point of the object's point set: the
points lie on the surface, so a triangle crosses the shape (coal, testing the mesh's triangles, says
the same). Two shapes certainly miss each other when their bounding spheres are apart. A screen only
ever answers where the exact test's answer is known; a shape it does not settle goes to coal.
"""
from __future__ import annotations

import coal
import numpy as np
from scipy.spatial import cKDTree

from planner.collision.hand_placement import _bounding_sphere

BALL_MARGIN = 1e-5  # m: a ball is shrunk by this before a point in it proves a hit (far beyond coal's tolerance)
SPHERE_MARGIN = 1e-6  # m: bounding spheres must be this far apart to prove a miss


def inscribed_balls(geometry: coal.CollisionGeometry) -> tuple[np.ndarray, float]:
    """Centres (b, 3) in the shape's frame and the radius of balls inside the shape: a box's smallest half-side along its
    longest axis, a sphere itself; none (b = 0) for other shapes."""
    if isinstance(geometry, coal.Sphere):
        return np.zeros((1, 3)), float(geometry.radius)
    if isinstance(geometry, coal.Box):
        half = np.asarray(geometry.halfSide, float)
        r, axis = float(half.min()), int(np.argmax(half))
        along = np.linspace(r - half[axis], half[axis] - r, int(np.ceil(half[axis] / r)))
        centres = np.zeros((len(along), 3))
        centres[:, axis] = along
        return centres, r
    return np.zeros((0, 3)), 0.0


class ObjectScreen:
    """Posed shapes that certainly hit the object, found through the object's point set (a kd-tree)."""

    def __init__(self, tree: cKDTree):
        self.tree = tree

    def hits(self, world: np.ndarray, balls: list[tuple[np.ndarray, float]]) -> np.ndarray:
        """(m,) True where one of a posed set of shapes (`world` (m, s, 4, 4), their `balls` from `inscribed_balls`)
        certainly hits the object."""
        hit = np.zeros(len(world), bool)
        for j, (centres, radius) in enumerate(balls):
            if len(centres) == 0 or radius <= BALL_MARGIN or len(world) == 0:
                continue
            posed = centres @ world[:, j, :3, :3].transpose(0, 2, 1) + world[:, j, None, :3, 3]
            d, _ = self.tree.query(posed.reshape(-1, 3), distance_upper_bound=radius - BALL_MARGIN)
            hit |= np.isfinite(d).reshape(len(world), -1).any(axis=1)
        return hit


Posed = tuple[coal.CollisionGeometry, coal.Transform3s, np.ndarray, float]
"""A shape placed in the object frame: geometry, coal transform, bounding-sphere centre and radius."""


def bounding(geometry: coal.CollisionGeometry, pose: np.ndarray) -> tuple[np.ndarray, float]:
    """The bounding sphere (centre, radius) of a shape at a 4x4 pose."""
    return _bounding_sphere(geometry, pose)

