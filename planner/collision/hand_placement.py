"""A hand placed at a grasp: its collision shapes against the object, the environment or the other hand.

The grasp search (paper IV-A.2) places the fingers one by one against the object's mesh and the
fingers placed before (`ObjectTest`). Grasp lists are filtered before any robot configuration is
sought (paper IV-B): a grasp whose hand hits the support at the object's placement can never be
executed, whatever the arm does. Shapes come from the standalone hand model (the hand URDF's
geometries, meshes as convex hulls).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import coal
import numpy as np
import trimesh

from planner.collision.shapes import coal_mesh, transform3s
from planner.model.environment import Environment
from planner.model.hand_model import HandModel, load_hand_model

if TYPE_CHECKING:
    from planner.grasping.grasp_list import GraspList
    from planner.model.robot import Robot


def posed_shapes(hand: HandModel, finger_q: np.ndarray, palm: np.ndarray) -> list[tuple[coal.CollisionGeometry, np.ndarray]]:
    """Every hand shape with its 4x4 world pose, the palm frame at `palm` and the fingers at `finger_q`."""
    return [(shape.geometry, palm @ pose) for shape, pose in hand.shape_poses(finger_q)]


class ObjectTest:
    """Shapes posed in the object's frame against the object's exact mesh, and against shapes placed before (no margin)."""

    def __init__(self, mesh: trimesh.Trimesh):
        self.object_geometry = coal_mesh(mesh)
        self.identity = coal.Transform3s()
        self.request = coal.CollisionRequest()

    def hits_object(self, geometry: coal.CollisionGeometry, tf: coal.Transform3s) -> bool:
        """True if the shape at `tf` (see shapes.transform3s: made once, also for `hits_placed`) touches the object."""
        return bool(coal.collide(geometry, tf, self.object_geometry, self.identity, self.request, coal.CollisionResult()))

    def hits_placed(self, shape: tuple[coal.CollisionGeometry, coal.Transform3s], placed: list) -> bool:
        """True if the shape (geometry, transform) touches one of the shapes placed before (each geometry, transform)."""
        geometry, tf = shape
        for other, other_tf in placed:
            result = coal.CollisionResult()
            if coal.collide(geometry, tf, other, other_tf, self.request, result):
                return True
        return False


def _ensure_aabb(geometry: coal.CollisionGeometry) -> None:
    """Compute a shape's local box once (shapes are never changed after they are made)."""
    if geometry.aabb_radius < 0:
        geometry.computeLocalAABB()


def _bounding_sphere(geometry: coal.CollisionGeometry, pose: np.ndarray) -> tuple[np.ndarray, float]:
    _ensure_aabb(geometry)
    centre = pose[:3, :3] @ np.asarray(geometry.aabb_center) + pose[:3, 3]
    return centre, float(geometry.aabb_radius)


class ObstacleTest:
    """Posed shapes against a fixed set of obstacle shapes within a margin (coal narrow phase behind a bounding-sphere test)."""

    def __init__(self, obstacles: list[tuple[coal.CollisionGeometry, np.ndarray]], margin: float):
        self.obstacles = [(g, transform3s(T), *_bounding_sphere(g, T)) for g, T in obstacles]
        self.boxes = np.array([world_aabb(g, T) for g, T in obstacles]).reshape(-1, 2, 3)
        self.request = coal.CollisionRequest()
        self.request.security_margin = margin
        self.margin = margin

    @staticmethod
    def of_environment(environment: Environment, margin: float) -> "ObstacleTest":
        return ObstacleTest([(ob.coal_shape(), ob.pose) for ob in environment], margin)

    def hits(self, shapes: list[tuple[coal.CollisionGeometry, np.ndarray]]) -> bool:
        """True if any of the posed shapes comes within the margin of an obstacle."""
        for geometry, pose in shapes:
            centre, radius = _bounding_sphere(geometry, pose)
            tf = None
            for ob, ob_tf, ob_centre, ob_radius in self.obstacles:
                if np.linalg.norm(centre - ob_centre) > radius + ob_radius + self.margin:
                    continue
                tf = tf or transform3s(pose)
                if coal.collide(geometry, tf, ob, ob_tf, self.request, coal.CollisionResult()):
                    return True
        return False


    def spheres_hit(self, centres: np.ndarray, radius: float) -> np.ndarray:
        """Per centre (k, 3): True if a sphere of `radius` there comes within the margin of an obstacle.
        Boxes around the obstacles screen all centres at once; coal tests only the centres inside one."""
        reach = radius + self.margin
        inside = np.all((centres[:, None] >= self.boxes[None, :, 0] - reach) & (centres[:, None] <= self.boxes[None, :, 1] + reach), axis=2)
        hit = np.zeros(len(centres), dtype=bool)
        sphere, T = coal.Sphere(radius), np.eye(4)
        for k in np.flatnonzero(inside.any(axis=1)):
            T[:3, 3] = centres[k]
            tf = transform3s(T)
            hit[k] = any(coal.collide(sphere, tf, self.obstacles[o][0], self.obstacles[o][1], self.request, coal.CollisionResult())
                         for o in np.flatnonzero(inside[k]))
        return hit


def world_aabb(geometry: coal.CollisionGeometry, pose: np.ndarray) -> np.ndarray:
    """(2, 3): the world box around a posed shape (its local box's corners transformed)."""
    _ensure_aabb(geometry)
    lo, hi = np.asarray(geometry.aabb_local.min_), np.asarray(geometry.aabb_local.max_)
    corners = np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    world = corners @ pose[:3, :3].T + pose[:3, 3]
    return np.array([world.min(axis=0), world.max(axis=0)])


def hands_collide(a: list[tuple[coal.CollisionGeometry, np.ndarray]], b: list[tuple[coal.CollisionGeometry, np.ndarray]],
                  margin: float = 0.0) -> bool:
    """True if any shape of one posed hand comes within `margin` of a shape of the other."""
    sa = [_bounding_sphere(g, T) for g, T in a]
    sb = [_bounding_sphere(g, T) for g, T in b]
    ca, ra = np.array([c for c, _ in sa]), np.array([r for _, r in sa])
    cb, rb = np.array([c for c, _ in sb]), np.array([r for _, r in sb])
    near = np.linalg.norm(ca[:, None] - cb[None], axis=2) <= ra[:, None] + rb[None] + margin
    if not near.any():
        return False
    request = coal.CollisionRequest()
    request.security_margin = margin
    for i, j in zip(*np.nonzero(near)):
        if coal.collide(a[i][0], transform3s(a[i][1]), b[j][0], transform3s(b[j][1]), request, coal.CollisionResult()):
            return True
    return False


def environment_filter(robot: Robot, grasps: GraspList, object_pose: np.ndarray, test: ObstacleTest) -> np.ndarray:
    """Per grasp: True if the hand at that grasp, the object at `object_pose`, is clear of the environment."""
    hand = load_hand_model(robot.spec.arm(grasps.hand).hand)
    return np.array([not test.hits(posed_shapes(hand, grasps.finger_q[r], object_pose @ grasps.hand_pose[r]))
                     for r in range(len(grasps))], dtype=bool)
