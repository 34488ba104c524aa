"""The object in the robot's collision model during a motion: static at a pose, or carried by a hand.

A `Situation` says where the object is (static at a world pose, or attached to an arm's palm by a
grasp: world pose = palm pose · grasp⁻¹), which robot geometries may touch it (the fingertips that
close on it or let it go) and which obstacles it may touch (its support while it is lifted off or
set down). `situation_model` adds the object to a copy of the robot + environment model as one
more geometry: static, it is checked against every moving robot link; carried, it hangs from the
palm's joint (so the local planner's displacement bound covers its points too) and is checked
against the obstacles and every robot link but the holding hand's, whose pose relative to the
object stays fixed while it is carried (it was checked when the grasp was made).

Pairs: a situation's model (`situation_base`) keeps those some joint moves; 'object' (robot–object
pairs, padded by the model's object padding), the object–obstacle pairs in 'env'. For each kind of
motion, `for_motion` names the pairs it can change (whose relative pose depends on a moving joint),
subset 'moving', and of them 'changed', what the offline roadmap did not check: the object's pairs and
every pair of a hand whose fingers are not at the roadmap's hold configuration. All the motions of a
situation share its geometry, so one collision data serves them (see CollisionChecker).
"""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from planner.collision.checker import CollisionModel, moved_by_fingers
from planner.collision.shapes import Geometry
from planner.collision.with_object import OBJECT_PAIRS, moving_geometries, with_object


@dataclass(frozen=True, eq=False)
class Situation:
    """Where the object is: held by `holder` with palm-in-object `pose`, or static at world `pose` (holder None)."""

    holder: str | None
    pose: np.ndarray
    touching: tuple[str, ...] = ()  # robot geometry names whose contact with the object is allowed
    support: tuple[str, ...] = ()  # obstacle names the object may touch (lifted off / set down)

    def object_pose(self, palm: np.ndarray) -> np.ndarray:
        """The object's world pose given the holder's palm pose (ignored when static)."""
        return self.pose if self.holder is None else palm @ self._grasp_inverse

    @functools.cached_property
    def key(self) -> tuple:
        """What the situation is, as a hashable value (a situation compares by identity): situations made alike, as
        each candidate lift makes its own, share one collision model and one collision data."""
        return self.holder, np.asarray(self.pose, dtype=float).tobytes(), self.touching, self.support

    @functools.cached_property
    def _grasp_inverse(self) -> np.ndarray:
        """pose⁻¹, inverted once: a carried object is posed at every sample of the trajectory."""
        return np.linalg.inv(self.pose)


def fingertip_geometries(cm: CollisionModel, arm: str, fingers: list[str]) -> tuple[str, ...]:
    """Names of the geometries on the last link of each named finger of an arm's hand (where its contact is)."""
    robot = cm.robot
    hand = robot.spec.arm(arm).hand
    joints = {robot.model.frames[robot.frame_id(hand.prefixed(f.tip_frame))].parentJoint
              for f in hand.fingers if f.name in fingers}
    return tuple(o.name for o in cm.geometry.geometryObjects[: cm.n_robot_geoms] if o.parentJoint in joints)


def finger_geometries(cm: CollisionModel, arm: str) -> np.ndarray:
    """Indices of the robot geometries moved by an arm's finger joints."""
    return moved_by_fingers(cm.robot, cm.geometry.geometryObjects[: cm.n_robot_geoms], arm)


def situation_model(cm: CollisionModel, shape: Geometry, situation: Situation,
                    moved_hands: tuple[str, ...], moving: np.ndarray, hull: Geometry | None = None) -> CollisionModel:
    """A copy of `cm` with the object in `situation` and the subsets 'object', 'changed' and 'moving' (see the module):
    'moving' and 'changed' keep only the pairs whose relative pose the configuration indices `moving` change. With
    `hull` (the object's convex hull), every pair of the object has a screening twin with the hull, in no subset: a
    check tries the hull first, and the mesh only where the hull is hit (see CollisionChecker.in_collision)."""
    return for_motion(situation_base(cm, shape, situation, hull), moved_hands, moving)


def for_motion(base: CollisionModel, moved_hands: tuple[str, ...], moving: np.ndarray) -> CollisionModel:
    """A situation's model (see situation_base) for motions of the configuration indices `moving`, the hands
    `moved_hands` away from the roadmap's hold configuration: 'moving' the pairs whose relative pose they change, 'changed'
    those of them the offline roadmap did not check (see the module); 'moving_inner' those between two links of one hand
    (fingers closing come as near their palm as a grasp needs), 'moving_outer' the others. The geometry is the base's, so one collision data
    serves all of a situation's motions (see CollisionChecker)."""
    stands_in = base.twins >= 0 if base.twins is not None else np.zeros(len(base.ends), dtype=bool)
    changes = base.relative_joints()[:, moving].any(axis=1) & ~stands_in
    moved = np.concatenate([finger_geometries(base, arm) for arm in moved_hands] + [np.zeros(0, np.int64)])
    changed = np.isin(base.ends, moved).any(axis=1)
    changed[base.subsets[OBJECT_PAIRS]] = True
    parts = np.array(base.parts + ("",) * (len(base.geometry.geometryObjects) - base.n_robot_geoms))
    a, b = parts[base.ends[:, 0]], parts[base.ends[:, 1]]
    inner = (a == b) & np.char.endswith(a.astype(str), "_hand")  # a hand's own links: only its fingers move them
    return base.with_subsets({"moving": np.flatnonzero(changes), "changed": np.flatnonzero(changes & changed),
                              "moving_outer": np.flatnonzero(changes & ~inner), "moving_inner": np.flatnonzero(changes & inner)})


def situation_base(cm: CollisionModel, shape: Geometry, situation: Situation, hull: Geometry | None = None) -> CollisionModel:
    """A copy of `cm` with the object in `situation` (and its hull screening it: see situation_model), keeping only the
    pairs some joint moves relative to each other; subsets 'object' (robot–object pairs) and OBJECT_PAIRS (every pair of
    the object's own mesh), the obstacle pairs in 'env' (see planner/collision/with_object.py)."""
    robot = cm.robot
    objs = cm.geometry.geometryObjects
    if situation.holder is None:
        model = with_object(cm, shape, 0, situation.pose, moving_geometries(cm, situation.touching), (), hull)
    else:
        palm = robot.model.frames[robot.frame_id(robot.palm_frame(situation.holder))]
        hand = f"{situation.holder}_hand"
        robot_partners = [g for g in range(cm.n_robot_geoms) if cm.parts[g] != hand and objs[g].name not in situation.touching]
        env = [e for e in range(cm.n_robot_geoms, len(objs)) if objs[e].name.removeprefix("env/") not in situation.support]
        model = with_object(cm, shape, palm.parentJoint, palm.placement.homogeneous @ np.linalg.inv(situation.pose),
                            robot_partners, env, hull)
    return _moving_only(model, model.relative_joints().any(axis=1))


def _moving_only(cm: CollisionModel, keep: np.ndarray) -> CollisionModel:
    """A copy of `cm` with the pairs `keep` (a flag per pair) alone in its geometry model, ordered as pinocchio orders
    them (by their two geometry indices), its subsets renumbered: no motion checks another pair, and pinocchio's
    collision data of a model costs memory per pair to allocate and to free."""
    ends = np.sort(cm.ends[keep], axis=1)
    order = np.lexsort((ends[:, 1], ends[:, 0]))
    ends = ends[order]
    n = len(cm.geometry.geometryObjects)
    table = np.zeros((n, n), dtype=bool)
    table[ends[:, 0], ends[:, 1]] = True
    gm = cm.geometry.copy()
    gm.setCollisionPairs(table, True)
    renumber = np.full(len(cm.ends), -1, dtype=np.int64)
    renumber[np.flatnonzero(keep)[order]] = np.arange(len(ends))
    subsets = {name: np.sort(renumber[idx][renumber[idx] >= 0]) for name, idx in cm.subsets.items()}
    twins = None
    if cm.twins is not None:  # a twin's relative pose is its screening pair's: both are kept or neither
        twins = np.full(len(ends), -1, dtype=np.int64)
        screening = np.flatnonzero((cm.twins >= 0) & keep)
        twins[renumber[screening]] = renumber[cm.twins[screening]]
    return dataclasses.replace(cm, geometry=gm, subsets=subsets, ends=ends, twins=twins)
