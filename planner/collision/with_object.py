"""The manipulated object in a robot + environment collision model: one geometry, `OBJECT`, static or carried.

`with_object` is the one way the object enters a collision model (a copy of it): static at a world pose
(on the universe joint) or hanging from a palm's joint at the grasp, paired with the robot geometries
and obstacles its caller names. Its robot pairs form the subset 'object' (padded by the model's object
padding), its obstacle pairs join 'env', and `OBJECT_PAIRS` holds them all. The motion puts it in each
situation (planner/collision/situation.py); `object_at_rest` stands it among the obstacles for the
task's start and end configurations (planner/check.py) and the grasp, exchange and place configurations
(planner/collision/object_obstacle.py).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from planner.collision.checker import CollisionModel, joint_support
from planner.collision.shapes import Geometry
from planner.model.geometry import se3

OBJECT = "object"  # the object's geometry name in a collision model
OBJECT_HULL = f"{OBJECT} hull"  # the geometry of its convex hull, when it screens the mesh
OBJECT_PAIRS = "object mesh"  # the subset of every pair of the object's mesh (with the robot and the obstacles)


def with_object(cm: CollisionModel, shape: Geometry, parent: int, placement: np.ndarray, robot_partners: Sequence[int],
                env_partners: Sequence[int] = (), hull: Geometry | None = None) -> CollisionModel:
    """A copy of `cm` with the object on joint `parent` (0: static in the world) at `placement` in that joint's frame,
    paired with the obstacles `env_partners` then the robot geometries `robot_partners` (geometry indices), added after
    the model's own pairs. With `hull` (the object's convex hull), each of its pairs has a screening twin with the hull,
    in no subset: a check tries the hull first, and the mesh only where the hull is hit (see CollisionChecker.in_collision)."""
    gm = cm.geometry.copy()
    o = len(gm.geometryObjects)
    bodies = [(OBJECT, shape)] + ([] if hull is None else [(OBJECT_HULL, hull)])
    for name, geometry in bodies:
        gm.addGeometryObject(pin.GeometryObject(name, parent, 0, se3(placement), geometry))
    n_pairs = len(gm.collisionPairs)
    partners = list(env_partners) + list(robot_partners)
    for body in range(len(bodies)):
        for g in partners:
            gm.addCollisionPair(pin.CollisionPair(g, o + body))
    new_env = np.arange(n_pairs, n_pairs + len(env_partners))
    new_robot = np.arange(n_pairs + len(env_partners), n_pairs + len(partners))
    new = np.arange(n_pairs, n_pairs + len(partners))
    subsets = {**cm.subsets,
               "all": np.concatenate([cm.subsets["all"], new]),
               "env": np.concatenate([cm.subsets["env"], new_env]),
               "object": new_robot, OBJECT_PAIRS: new}
    ends = np.concatenate([cm.ends] + [np.array([(g, o + body) for g in partners], np.int64).reshape(-1, 2)
                                       for body in range(len(bodies))])
    twins = None
    if hull is not None:  # the hull's pairs stand for the mesh's
        twins = np.full(len(ends), -1, dtype=np.int64)
        twins[n_pairs + len(partners):] = new
    support = np.concatenate([cm.support, joint_support(cm.robot.model, [parent] * len(bodies))])
    return dataclasses.replace(cm, geometry=gm, subsets=subsets, ends=ends, support=support, twins=twins)


def moving_geometries(cm: CollisionModel, but: Sequence[str] = ()) -> list[int]:
    """The robot geometries some joint moves (the fixed base's are not), but those named in `but`."""
    objs = cm.geometry.geometryObjects
    return [g for g in range(cm.n_robot_geoms) if objs[g].parentJoint > 0 and objs[g].name not in but]


def object_at_rest(cm: CollisionModel, shape: Geometry, pose: np.ndarray) -> CollisionModel:
    """A copy of `cm` with the object static at world `pose`, paired with every robot geometry some joint moves and
    padded as an obstacle is (it stands among them, before any hand holds it or after it is let go)."""
    model = with_object(cm, shape, 0, pose, moving_geometries(cm))
    return dataclasses.replace(model, params=dataclasses.replace(cm.params, object_padding=cm.params.env_padding))
