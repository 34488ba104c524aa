"""The robot's configurations for a table handover: the picking hand setting the object down at an intermediate
placement and the placing hand taking it there.

Grasps are in the object's frame, so a hand's grasp list holds at any pose of the object: the picking hand keeps the
grasp it picked with (a pick configuration of the grasp_configs step) and puts the object down with it; the placing
hand takes it with a grasp it also places with (a place configuration), so only their configurations at the
intermediate placement are new, found by the grasp_configs step's sampler and checked against the environment and
the object resting there. Candidates come placement by placement (best first), then pick grasps and place grasps by
their configuration scores; the reasons candidates were dropped are counted.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from planner.collision.object_obstacle import ObjectCollision
from planner.grasping.grasp_list import GraspList
from planner.handover.config_score import ConfigScorer
from planner.handover.grasp_configs import ConfigSampler, GraspConfigParams, GraspConfigs
from planner.model.task import Scene
from planner.regrasp.placements import Placements


@dataclass(frozen=True)
class TableCandidate:
    """One table handover to plan: the placement (its index and pose), the grasps' ranks in their lists and the
    configurations: picking, setting down, taking, placing."""

    placement: int
    pose: np.ndarray
    pick_rank: int
    place_rank: int
    q_grasp: np.ndarray
    q_set: np.ndarray
    q_take: np.ndarray
    q_place: np.ndarray


def table_candidates(scene: Scene, pick: GraspList, place: GraspList, configs: GraspConfigs, params: GraspConfigParams,
                     placements: Placements, max_placements: int, dropped: Counter, rng: np.random.Generator
                     ) -> Iterator[TableCandidate]:
    """The candidates at the first `max_placements` placements both hands' arms reach, in order (see the module);
    `dropped` counts why the others were: the picking hand cannot set the object down there with its grasp, or the
    placing hand cannot take it there."""
    robot = scene.robot
    a, b = configs.picking_arm, configs.placing_arm
    hp, hq = configs.hand("pick"), configs.hand("place")
    sampler = ConfigSampler(robot, ObjectCollision(scene), ConfigScorer(robot, params.weights()), params)
    columns = [placements.arms.index(a), placements.arms.index(b)]
    both = np.flatnonzero(placements.reached[:, columns].all(axis=1))
    pick_order = np.lexsort((np.arange(len(hp.rank)), -hp.score))
    place_order = np.lexsort((np.arange(len(hq.rank)), -hq.score))
    def tucked(q: np.ndarray, arm: str, free: str, T: np.ndarray) -> np.ndarray:
        """q with the free arm as it is at the start (out of the way, as the task's author posed it) when that is
        collision-free, else as sampled (near rest)."""
        out = q.copy()
        out[robot.arm_idx[free]] = scene.q_initial[robot.arm_idx[free]]
        return q if sampler.collision.in_collision(out, T, (arm,)) else out

    for k in both[:max_placements]:
        T = placements.pose[k]
        takes: dict[int, np.ndarray | None] = {}
        for i in pick_order:
            r = int(hp.rank[i])
            found = sampler.grasp_configuration(a, T @ pick.hand_pose[r], pick.finger_q[r], T, hp.q[i], rng)
            if found is None:
                dropped["the picking hand cannot set it down there with its grasp"] += 1
                continue
            for j in place_order:
                s = int(hq.rank[j])
                if j not in takes:
                    got = sampler.grasp_configuration(b, T @ place.hand_pose[s], place.finger_q[s], T, hq.q[j], rng)
                    takes[j] = None if got is None else tucked(got[0], b, a, T)
                if takes[j] is None:
                    dropped["the placing hand cannot take it there with its grasp"] += 1
                    continue
                yield TableCandidate(int(k), T, r, s, hp.q[i], tucked(found[0], a, b, T), takes[j], hq.q[j])
