"""The robot's collision model with the manipulated object in it, static among the obstacles and moved by each check.

The grasp, exchange and place configurations (paper V-C) are checked against self-collision, the
environment and the object at its pose. The hands holding the object touch it by construction (their
contacts were checked with a clearance when the grasp was made), so their pairs with the object are
left out; every other robot link is checked against it. The object against the static obstacles is a
separate test (`object_hits_environment`): at the initial and final placements it rests on its support.
`obstacles_penetrated` names the obstacles the object at a pose is inside of (the task's check).
"""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import trimesh

from planner.collision.checker import CollisionChecker, build_collision_model
from planner.collision.hand_placement import ObstacleTest
from planner.collision.pairs import CollisionParams
from planner.collision.shapes import coal_mesh, transform3s
from planner.collision.with_object import object_at_rest
from planner.model.environment import Environment
from planner.model.task import Scene


class ObjectCollision:
    """Checks a robot configuration with the object at a world pose, held by none, one or both hands.

    The collision model is shared read-only; the object's pose goes to the checker's own data at each call,
    so use one `ObjectCollision` (one checker) per thread.
    """

    def __init__(self, scene: Scene, params: CollisionParams = CollisionParams()):
        robot = scene.robot
        cm = object_at_rest(build_collision_model(robot, scene.environment, params), coal_mesh(scene.object_mesh), np.eye(4))
        self.index = len(cm.geometry.geometryObjects) - 1  # the object, added last
        k = np.arange(len(cm.ends))
        with_object = np.isin(k, cm.subsets["object"])
        part = np.array(cm.parts)[cm.ends[:, 0]]  # each pair's first geometry: a robot one (the object's partner)
        subsets = {"robot": k[~with_object]}
        for holding in [()] + [(a,) for a in robot.spec.arm_names] + [tuple(robot.spec.arm_names)]:
            held = np.isin(part, [f"{a}_hand" for a in holding])
            subsets[self.subset(holding)] = k[~with_object | ~held]
        self.model = cm.with_subsets(subsets)
        self.checker: CollisionChecker = self.model.checker()
        self.object_geometry = coal_mesh(scene.object_mesh)
        self.com = np.asarray(scene.object_mesh.center_mass, float)
        fixed = [o for o in cm.geometry.geometryObjects[:cm.n_robot_geoms] if o.parentJoint == 0]  # the robot's fixed base
        self.fixed_base = [(o.geometry, o.placement.homogeneous) for o in fixed]
        self.static = ObstacleTest([(ob.coal_shape(), ob.pose) for ob in scene.environment] + self.fixed_base, params.env_padding)

    @staticmethod
    def subset(holding: tuple[str, ...]) -> str:
        return "object_held_by_" + ("_".join(holding) or "none")

    def in_collision(self, q: np.ndarray, object_pose: np.ndarray, holding: tuple[str, ...] = ()) -> bool:
        """Self-collision, robot vs environment, and robot vs the object at `object_pose` (hands in `holding` excepted)."""
        return self.checker.in_collision(q, self.subset(holding), {self.index: object_pose})

    def object_hits_environment(self, T: np.ndarray) -> bool:
        """The object at world pose T within the security margin of a static obstacle or of the robot's fixed base."""
        return self.static.hits([(self.object_geometry, T)])

    def robot_shapes(self, q: np.ndarray, parts: tuple[str, ...]) -> list[tuple[coal.CollisionGeometry, np.ndarray]]:
        """The robot's collision shapes of the given parts (e.g. 'torso', 'right_hand') with their world poses at q."""
        cm = self.model
        gd = pin.GeometryData(cm.geometry)
        pin.updateGeometryPlacements(cm.robot.model, cm.robot.model.createData(), cm.geometry, gd, q)
        return [(cm.geometry.geometryObjects[i].geometry, gd.oMg[i].homogeneous.copy())
                for i in range(cm.n_robot_geoms) if cm.parts[i] in parts]


def obstacles_penetrated(mesh: trimesh.Trimesh, T: np.ndarray, environment: Environment) -> list[str]:
    """The names of the obstacles the object's mesh at world pose T collides with (no margin)."""
    shape, tf = coal_mesh(mesh), transform3s(T)
    request = coal.CollisionRequest()
    hits = []
    for ob in environment:
        result = coal.CollisionResult()
        if coal.collide(shape, tf, ob.coal_shape(), transform3s(ob.pose), request, result):
            hits.append(ob.name)
    return hits
