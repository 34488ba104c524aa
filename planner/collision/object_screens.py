"""Tests that settle a collision before coal's exact one in the grasp search, for many posed shapes per numpy call.

A shape certainly hits the object when a point of the object's point set lies inside it: the points
lie on the surface, so a triangle crosses the shape (coal, testing the mesh's triangles, says the
same). Boxes and spheres are tested so (the kd-tree gives the points nearest each posed shape's
centre); other shapes are left to coal. Two shapes certainly miss each other when their bounding spheres are apart.
A screen only ever answers where the exact test's answer is known; a shape it does not settle goes
to coal.
"""
from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
from scipy.spatial import cKDTree

from planner.collision.hand_placement import _bounding_sphere

INSIDE_MARGIN = 1e-5  # m: a shape is shrunk by this before a point in it proves a hit (far beyond coal's tolerance)
SPHERE_MARGIN = 1e-6  # m: bounding spheres must be this far apart to prove a miss
BOX_NEIGHBOURS = 4  # the object points nearest a box's centre that are tested for lying inside it


@dataclass(frozen=True, eq=False)
class Inside:
    """The part of a shape (in its own frame, centred on it) whose object points prove a hit: a box's half-sides or a
    sphere's radius, shrunk by `INSIDE_MARGIN`."""

    half: np.ndarray | None  # (3,) for a box
    radius: float  # the sphere's, or the box's half diagonal (how far its points can lie from its centre)


def inside_of(geometry: coal.CollisionGeometry) -> Inside | None:
    """What the screen tests of a shape: boxes and spheres; None for other shapes (or ones thinner than the margin)."""
    if isinstance(geometry, coal.Sphere) and geometry.radius > INSIDE_MARGIN:
        return Inside(None, float(geometry.radius) - INSIDE_MARGIN)
    if isinstance(geometry, coal.Box) and min(geometry.halfSide) > INSIDE_MARGIN:
        half = np.asarray(geometry.halfSide, float) - INSIDE_MARGIN
        return Inside(half, float(np.linalg.norm(half)))
    return None


class ObjectScreen:
    """Posed shapes that certainly hit the object, found through the object's point set (a kd-tree)."""

    def __init__(self, tree: cKDTree):
        self.tree = tree

    def hits(self, world: np.ndarray, insides: list[Inside | None]) -> np.ndarray:
        """(m,) True where one of a posed set of shapes (`world` (m, s, 4, 4), each shape's `inside_of`) certainly hits the
        object."""
        hit = np.zeros(len(world), bool)
        for j, inside in enumerate(insides):
            if inside is None or len(world) == 0:
                continue
            centres = world[:, j, :3, 3]
            if inside.half is None:
                hit |= np.isfinite(self.tree.query(centres, distance_upper_bound=inside.radius)[0])
                continue
            d, points = self.tree.query(centres, k=BOX_NEIGHBOURS, distance_upper_bound=inside.radius)
            rows, nearest = np.nonzero(np.isfinite(d))
            local = np.einsum("ki,kij->kj", self.tree.data[points[rows, nearest]] - centres[rows], world[rows, j, :3, :3])
            hit[rows[np.all(np.abs(local) < inside.half, axis=1)]] = True
        return hit


Posed = tuple[coal.CollisionGeometry, coal.Transform3s, np.ndarray, float]
"""A shape placed in the object frame: geometry, coal transform, bounding-sphere centre and radius."""


def bounding(geometry: coal.CollisionGeometry, pose: np.ndarray) -> tuple[np.ndarray, float]:
    """The bounding sphere (centre, radius) of a shape at a 4x4 pose."""
    return _bounding_sphere(geometry, pose)

