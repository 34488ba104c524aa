"""Tests that settle a collision before coal's exact one in the grasp search, for many posed shapes per numpy call.

A shape certainly hits the object when a point of the object's point set lies inside it: the points
lie on the surface, so a triangle crosses the shape (coal, testing the mesh's triangles, says the
same). Boxes and spheres are tested so (the kd-tree gives the points nearest each posed shape's
centre); other shapes are left to coal. A shape certainly misses the object when its bounding sphere
does: no point of the set lies within the sphere's radius plus `reach`, a distance within which every
point of the surface has a point of the set (bounded through a cover of the surface whose spacing is
known by construction, `surface_cover`). Two shapes certainly miss each other when their bounding
spheres are apart. A screen only ever answers where the exact test's answer is known; a shape it does
not settle goes to coal.
"""
from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
from scipy.spatial import cKDTree

from planner.collision.hand_placement import _bounding_sphere
from planner.collision.shapes import Geometry, transform3s

INSIDE_MARGIN = 1e-5  # m: a shape is shrunk by this before a point in it proves a hit (far beyond coal's tolerance)
SPHERE_MARGIN = 1e-6  # m: bounding spheres must be this far apart to prove a miss
BOX_NEIGHBOURS = 4  # the object points nearest a box's centre that are tested for lying inside it
CLEAR_MARGIN = 1e-4  # m: a bounding sphere must miss the surface by this to prove a miss (far beyond coal's tolerance)


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


def surface_cover(triangles: np.ndarray, spacing: float) -> tuple[np.ndarray, float]:
    """Points on a triangle surface (f, 3, 3) and a distance at most `spacing` within which of one of them every point
    of the surface lies: the centroids of the triangles halved at their longest edge until each triangle's vertices
    lie within `spacing` of its centroid (a point of a triangle is no farther from its centroid than its farthest
    vertex is)."""
    done, left = [], np.asarray(triangles, float).reshape(-1, 3, 3)
    while len(left):
        reach = np.linalg.norm(left - left.mean(axis=1, keepdims=True), axis=2).max(axis=1)
        done.append(left[reach <= spacing])
        left = left[reach > spacing]
        edges = np.roll(left, -1, axis=1) - left  # edge i runs from vertex i to vertex i + 1
        i = np.argmax(np.einsum("tij,tij->ti", edges, edges), axis=1)
        rows = np.arange(len(left))
        a, b, c = left[rows, i], left[rows, (i + 1) % 3], left[rows, (i + 2) % 3]
        middle = 0.5 * (a + b)
        left = np.concatenate([np.stack([a, middle, c], axis=1), np.stack([middle, b, c], axis=1)])
    final = np.concatenate(done)
    centroids = final.mean(axis=1)
    return centroids, float(np.linalg.norm(final - centroids[:, None], axis=2).max(initial=0.0))


class ObjectScreen:
    """Posed shapes that certainly hit the object, and bounding spheres that certainly miss it, found through the
    object's point set (a kd-tree over points on its surface `triangles`)."""

    def __init__(self, tree: cKDTree, triangles: np.ndarray, spacing: float):
        self.tree = tree
        cover, within = surface_cover(triangles, spacing)
        # every surface point lies within `within` of a cover point, and every cover point within the largest of their
        # distances to the point set of a point of it: so every surface point lies within `reach` of a point of the set
        self.reach = within + float(tree.query(cover)[0].max(initial=0.0))

    def clear(self, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """(m, s) True where a sphere (centres (m, s, 3), radii (s,); an infinite radius is never clear), and any shape
        inside it, certainly misses the object: no object point within its radius plus `reach`."""
        out = np.zeros(centres.shape[:2], bool)
        for j, radius in enumerate(radii):
            if len(centres) and np.isfinite(radius):
                d, _ = self.tree.query(centres[:, j], distance_upper_bound=radius + self.reach + CLEAR_MARGIN)
                out[:, j] = np.isinf(d)
        return out

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


class Posed:
    """A shape placed in the object frame: geometry, 4x4 pose, bounding-sphere centre and radius; its coal transform
    is made when first asked for (most placed shapes are only ever screened)."""

    __slots__ = ("geometry", "pose", "centre", "radius", "_transform")

    def __init__(self, geometry: Geometry, pose: np.ndarray, centre: np.ndarray, radius: float,
                 transform: coal.Transform3s | None = None):
        self.geometry, self.pose, self.centre, self.radius, self._transform = geometry, pose, centre, radius, transform

    def transform(self) -> coal.Transform3s:
        """coal's transform of the pose (made once)."""
        if self._transform is None:
            self._transform = transform3s(self.pose)
        return self._transform


def bounding(geometry: coal.CollisionGeometry, pose: np.ndarray) -> tuple[np.ndarray, float]:
    """The bounding sphere (centre, radius) of a shape at a 4x4 pose."""
    return _bounding_sphere(geometry, pose)

