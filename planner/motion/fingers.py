"""Finger motions of one hand: values opened from a grasp, the orders in which fingers may move, the first valid way,
and the search that opens each colliding finger a level further (pre-shaping, letting go).

A finger curling onto a rounded surface sweeps its middle link through it when its joints move together; hooking
its tip first keeps it outside. So a hand's fingers move all at once, else in stages of joint depths, else one
finger after the other, each its own first valid way.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from planner.collision.checker import CollisionModel
from planner.collision.situation import finger_geometries
from planner.motion.piece import HandGrasp
from planner.motion.validities import Checked


def finger_orders(fingers: list[np.ndarray]) -> list[list[np.ndarray]]:
    """Ways for fingers (their joint indices) to move, as stages of joints moving together: all at once, else each
    finger's last joint first, else last, else one joint depth after the other from the tip to the base, else from
    the base to the tip."""
    every = np.concatenate(fingers)
    last = np.array([idx[-1] for idx in fingers])
    rest = np.setdiff1d(every, last)
    by_depth = [np.array([idx[-1 - k] for idx in fingers if k < len(idx)]) for k in range(max(map(len, fingers)))]
    return [[every], [last, rest], [rest, last], by_depth, by_depth[::-1]]


def staged(q: np.ndarray, target: np.ndarray, order: list[np.ndarray]) -> np.ndarray:
    """The polyline from q moving each stage's joints to their values in target, stage after stage (stages that move
    nothing dropped; joints in no stage stay as at q)."""
    path = [q]
    for joints in order:
        step = path[-1].copy()
        step[joints] = target[joints]
        if not np.allclose(step, path[-1]):
            path.append(step)
    return np.array(path)


class Fingers:
    """The hands' finger joints of a robot (its collision model names their geometries); `open`: the open hands."""

    def __init__(self, cm: CollisionModel):
        self.robot = robot = cm.robot
        self.open = robot.q_rest
        self.names = {arm: _finger_of_geometry(cm, arm) for arm in robot.spec.arm_names}  # geometry name -> finger name

    def set(self, q: np.ndarray, arm: str, values: np.ndarray) -> np.ndarray:
        """q with the arm's hand at `values`."""
        q = q.copy()
        q[self.robot.hand_idx[arm]] = values
        return q

    def opened(self, grasp: HandGrasp, fraction: float, touching_only: bool = False) -> np.ndarray:
        """Finger values with the flexing joints `fraction` of the way from the grasp to the open hand (each finger's first
        joint, which spreads it sideways, stays: opening it swings the finger across the object); only the touching
        fingers' when `touching_only` (letting go: the others stay clear of the object where they are)."""
        hand = self.robot.hand_idx[grasp.arm]
        fingers = self.robot.finger_idx[grasp.arm]
        names = grasp.touching if touching_only else list(fingers)
        flexing = np.concatenate([fingers[f][1:] for f in names])  # a finger's first joint spreads it: it stays
        step = np.where(np.isin(hand, flexing), fraction * (self.open[hand] - grasp.fingers), 0.0)
        return grasp.fingers + step

    def motions(self, q: np.ndarray, arm: str, values: np.ndarray) -> list[np.ndarray]:
        """The distinct polylines of the whole hand's fingers from q to `values` by finger_orders; nothing when they are
        there."""
        target = self.set(q, arm, values)
        paths: list[np.ndarray] = []
        for order in finger_orders(list(self.robot.finger_idx[arm].values())):
            path = staged(q, target, order)
            if len(path) > 1 and not any(path.shape == p.shape and np.allclose(path, p) for p in paths):
                paths.append(path)
        return paths

    def path(self, q: np.ndarray, arm: str, values: np.ndarray, checked: Checked) -> np.ndarray | None:
        """A valid motion of the fingers from q to `values`: the first valid of `motions`, else the fingers one after the
        other, each the first valid of its own ways (the others where they are: a thumb closing all at once beside a
        ring finger hooking its tip first); None when a finger has no valid way."""
        for path in self.motions(q, arm, values):
            if checked.valid(path):
                return path
        target = self.set(q, arm, values)
        path = q[None]
        for idx in self.robot.finger_idx[arm].values():
            ways = [staged(path[-1], target, order) for order in finger_orders([idx])]
            way = next((w for w in ways if len(w) == 1 or checked.valid(w)), None)
            if way is None:
                return None
            path = np.concatenate([path, way[1:]])
        return path

    def per_finger(self, grasp: HandGrasp, levels: list[np.ndarray], collisions: Callable[[np.ndarray], list]) -> np.ndarray:
        """Finger values with each finger at one of `levels` (hand values, in order of preference): all start at the
        first; while `collisions` of the values names pairs, every finger in them moves to its next level (opening a
        finger swings it out, into the support or the other hand as often as away from the object). Stops when nothing
        collides, or when a colliding pair has no finger of this hand or a finger is at its last level (the last values
        are returned: the piece built from them fails with its message)."""
        arm = grasp.arm
        hand, fingers, of_geometry = self.robot.hand_idx[arm], self.robot.finger_idx[arm], self.names[arm]
        level = dict.fromkeys(fingers, 0)
        while True:
            values = grasp.fingers.copy()
            for f, idx in fingers.items():
                at = np.isin(hand, idx)
                values[at] = levels[level[f]][at]
            per_pair = [{of_geometry[n] for n in pair if n in of_geometry} for pair in collisions(values)]
            hit = set().union(*per_pair)
            if not per_pair or not all(per_pair) or any(level[f] == len(levels) - 1 for f in hit):
                return values
            for f in hit:
                level[f] += 1


def _finger_of_geometry(cm: CollisionModel, arm: str) -> dict[str, str]:
    """Geometry name -> finger name, for the geometries an arm's finger joints move."""
    robot, objects = cm.robot, cm.geometry.geometryObjects
    joint_finger = {int(j): f for f, idx in robot.finger_idx[arm].items() for j in idx}
    return {objects[g].name: joint_finger[robot.model.joints[objects[g].parentJoint].idx_q]
            for g in finger_geometries(cm, arm).tolist()}
