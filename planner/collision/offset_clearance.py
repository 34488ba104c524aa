"""How far bodies moved by world offsets stay from the obstacles, and what an object rests on.

Used to order the directions a held object is lifted off (or set down onto) its support, freest first: the
object and the holding hand are moved rigidly by each offset and their distance to the obstacles measured, up
to a padding (farther counts as free). Obstacles that cannot come within the padding at any offset are left
out by bounding spheres; per offset, body and obstacle a lower bound (the body's sphere to the obstacle's box)
orders the exact distances, nearest first, and skips those that cannot be nearer than the smallest so far.
"""
from __future__ import annotations

from collections.abc import Sequence

import coal
import numpy as np
import pinocchio as pin

from planner.collision.checker import CollisionModel
from planner.collision.hand_placement import world_aabb
from planner.collision.shapes import transform3s
from planner.model.environment import Obstacle

Body = tuple[coal.CollisionGeometry, np.ndarray]  # a shape and its world pose
Placed = tuple[coal.CollisionGeometry, coal.Transform3s, np.ndarray]  # an obstacle's shape, pose and world box


def hand_bodies(cm: CollisionModel, data: pin.Data, q: np.ndarray, arm: str) -> list[Body]:
    """The robot geometries of an arm's hand at q, with their world poses (the shapes are the model's: only read)."""
    gm = cm.geometry
    gd = pin.GeometryData(gm)
    pin.updateGeometryPlacements(cm.robot.model, data, gm, gd, q)
    return [(gm.geometryObjects[g].geometry, gd.oMg[g].homogeneous) for g in range(cm.n_robot_geoms)
            if cm.parts[g] == f"{arm}_hand"]


def bounding_sphere(bodies: Sequence[Body]) -> tuple[np.ndarray, float]:
    """(centre, radius) of a sphere holding every (shape, world pose): meshes by their vertices (the robot's shapes are
    shared: they are only read), primitives by the bounding box they compute (each caller's own fresh shape)."""
    spheres = []
    for shape, placed in bodies:
        if hasattr(shape, "points") or hasattr(shape, "vertices"):
            pts = np.asarray(shape.points() if hasattr(shape, "points") else shape.vertices())
            mid = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
            radius = float(np.linalg.norm(pts - mid, axis=1).max())
        else:
            shape.computeLocalAABB()
            mid, radius = np.asarray(shape.aabb_center), float(shape.aabb_radius)
        spheres.append((placed[:3, :3] @ mid + placed[:3, 3], radius))
    centre = spheres[0][0]
    return centre, max(float(np.linalg.norm(c - centre)) + r for c, r in spheres)


def obstacles_within(bodies: Sequence[Body], environment: Sequence[Obstacle], reach: float) -> list[Placed]:
    """The obstacles whose bounding sphere comes within `reach` of the bodies' (the farthest offset plus the padding):
    the others cannot count at any offset."""
    centre, radius = bounding_sphere(bodies)
    radius += reach
    return [(shape, transform3s(ob.pose), world_aabb(shape, ob.pose)) for ob in environment
            for shape in [ob.coal_shape()] for c, r in [bounding_sphere([(shape, ob.pose)])]
            if np.linalg.norm(c - centre) < r + radius]


def offset_clearances(bodies: Sequence[Body], obstacles: Sequence[Placed], offsets: Sequence[np.ndarray],
                      padding: float) -> list[float]:
    """Per offset, the smallest distance (up to `padding`) of a body moved by it from an obstacle (see the module)."""
    spheres = [bounding_sphere([body]) for body in bodies]
    req, res = coal.DistanceRequest(), coal.DistanceResult()

    def clearance(offset: np.ndarray, bound: np.ndarray) -> float:
        """Nearest first by `bound` (body, obstacle) a lower bound, skipping those no nearer than the smallest so far."""
        out = padding
        for k in np.argsort(bound, axis=None, kind="stable"):
            b, o = np.unravel_index(k, bound.shape)
            if bound[b, o] >= out:
                break
            shape, placed = bodies[b]
            moved = placed.copy()
            moved[:3, 3] += offset
            res.clear()
            out = min(out, coal.distance(shape, transform3s(moved), obstacles[o][0], obstacles[o][1], req, res))
        return out

    # per offset, body and obstacle: the distance from the body's bounding sphere to the obstacle's box
    centres = np.array([c for c, _ in spheres])[None, :, None] + np.array(offsets)[:, None, None]
    boxes = np.array([box for _, _, box in obstacles]).reshape(1, 1, -1, 2, 3)
    gap = np.maximum(np.maximum(boxes[..., 0, :] - centres, centres - boxes[..., 1, :]), 0.0)
    bounds = np.linalg.norm(gap, axis=-1) - np.array([r for _, r in spheres])[None, :, None]
    return [clearance(o, bound) for o, bound in zip(offsets, bounds)]


def supports(shape: coal.CollisionGeometry, pose: np.ndarray, environment: Sequence[Obstacle], within: float = 0.005
             ) -> tuple[str, ...]:
    """The obstacles within `within` of the object (its shape at a world pose): what it rests on."""
    out = []
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    for ob in environment:
        res.clear()
        if coal.distance(shape, transform3s(pose), ob.coal_shape(), transform3s(ob.pose), req, res) < within:
            out.append(ob.name)
    return tuple(out)
