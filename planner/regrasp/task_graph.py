"""The regrasp graph of one task (graph.py): its edges, from the earlier steps' results.

Picks: every pick grasp with a configuration at the initial placement (the grasp_configs step). Handovers: the
double grasps (their grasp, exchange and place configurations; a direct transfer when one arm picks and places).
Set-downs: the picking hand carries the object to an intermediate placement (the placements step's) and sets it
down with the grasp it picked with; takes: the placing hand takes it there with a grasp it places with, the other
hand (a table handover) or the same hand in another grasp (a same-hand regrasp, when one arm picks and places).
Grasps are in the object's frame, so only the configurations at an intermediate placement are new: found by the
grasp_configs step's sampler, checked against the environment and the object resting there, each once, when the
search first pops an edge that needs it; with its near-rest starts only, the first collision-free one kept (an
intermediate placement is one of many: a grasp those starts miss there is left for the next placement). Placements
tried: the first `table_placements` that both arms reach (a table handover) or that the arm reaches (a same-hand
regrasp); grasps: each hand's `regrasp_grasps` best-scored.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from planner.collision.object_obstacle import ObjectCollision
from planner.grasping.grasp_list import GraspList
from planner.handover.double_grasps import DoubleGrasps
from planner.handover.grasp_configs import ConfigSampler, GraspConfigParams, GraspConfigs
from planner.model.geometry import rotation_angle
from planner.model.task import Scene
from planner.regrasp.graph import FINAL, GOAL, HANDOVER, INITIAL, REGRASP, START, TABLE, Edge, Node, Transition
from planner.regrasp.placements import Placements

CONTACTS = {"pick": 2, "handover": 6, "transfer": 2, "set down": 2, "take": 4, "carry": 2, "place": 2}  # contact motions:
# approach + closing; lift + exchange approach, closing, opening, retreat + set-down; lift + set-down; lift + set-down;
# opening, retreat + approach, closing; lift + set-down; opening + retreat


@dataclass(frozen=True)
class Limits:
    """How much of the graph is built: double grasps, intermediate placements and grasps per hand there."""

    double_grasps: int
    placements: int
    grasps: int


SAME_GRASP = (0.03, 0.35)  # m, rad: palm poses in the object's frame nearer than both are one grasp (taken again in it,
# or a finger's width beside it, the object would be set down for nothing)


def same_grasp(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two palm poses in the object's frame are one grasp (SAME_GRASP)."""
    return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) < SAME_GRASP[0] and rotation_angle(a, b) < SAME_GRASP[1])


class TaskGraph:
    """The edges out of each node (see the module), for the strategies in `allowed`."""

    def __init__(self, scene: Scene, pick: GraspList, place: GraspList, configs: GraspConfigs, params: GraspConfigParams,
                 dg: DoubleGrasps, placements: Placements | None, limits: Limits, allowed: set[str], rng: np.random.Generator):
        self.scene, self.pick, self.place, self.dg, self.placements, self.rng = scene, pick, place, dg, placements, rng
        self.a, self.b = configs.picking_arm, configs.placing_arm
        self.hp, self.hq = configs.hand("pick"), configs.hand("place")
        self.limits, self.allowed = limits, set(allowed)
        quick = dataclasses.replace(params, wide_attempts=0, keep=1)
        scorer = quick.scorer(scene.robot, scene.q_initial)  # the free arm as the task starts, like the pick's
        self.sampler = ConfigSampler(scene.robot, ObjectCollision(scene), scorer, quick)
        self.take = REGRASP if self.a == self.b else TABLE  # what taking the object at an intermediate placement is
        both = np.zeros(0, int)
        if placements is not None and len(placements):  # none given: the handover alone
            both = np.flatnonzero(placements.reached[:, [placements.arms.index(arm) for arm in (self.a, self.b)]].all(axis=1))
        self.spots = [int(k) for k in both[: limits.placements]]  # the intermediate placements, best first
        self.best_pick = set(self.hp.rank[np.lexsort((np.arange(len(self.hp.rank)), -self.hp.score))][: limits.grasps].tolist())
        self.best_place = np.lexsort((np.arange(len(self.hq.rank)), -self.hq.score))[: limits.grasps]
        self.made: dict[tuple, np.ndarray | None] = {}

    def remaining(self, node: Node) -> int:
        """The contact motions still to make from `node` at least (A*'s estimate, with the distance; see graph.py)."""
        if node == GOAL:
            return 0
        if node.at == FINAL:
            return CONTACTS["place"]
        if node.at == INITIAL:  # picked (or not yet): a direct transfer is the least, then the place
            return CONTACTS["transfer"] + CONTACTS["place"] + (CONTACTS["pick"] if not node.hand else 0)
        return CONTACTS["carry"] + CONTACTS["place"] + (0 if node.grasps == "place" else CONTACTS["take"])  # taken, or set down

    def handover_edges(self, k: int) -> list[Edge]:
        """The edges of the sequence through double grasp k: pick, hand over (or carry: a direct transfer), place."""
        dg = self.dg
        picked = Node(dg.picking_arm, "pick", int(dg.pick_rank[k]), INITIAL)
        return [Edge("pick", picked, CONTACTS["pick"], dg.q_grasp[k][None])] + [
            e for e in self._handovers(picked) if e.rank == k] + [Edge("place", GOAL, CONTACTS["place"], self.scene.q_final[None])]

    def expand(self, node: Node, path: tuple[Transition, ...]) -> list[Edge]:
        if node == START:
            return [Edge("pick", Node(self.a, "pick", int(r), INITIAL), CONTACTS["pick"], self.hp.q[i][None])
                    for i, r in enumerate(self.hp.rank)]
        if node.at == FINAL:
            return [Edge("place", GOAL, CONTACTS["place"], self.scene.q_final[None])]
        if node.at == INITIAL:
            return self._handovers(node) + self._set_downs(node)
        if node.hand == self.a and node.grasps == "pick":  # set down at an intermediate placement
            return self._takes(node)
        j = int(np.flatnonzero(self.hq.rank == node.grasp)[0])  # taken at an intermediate placement: carry it on
        return [Edge("carry", Node(node.hand, "place", node.grasp, FINAL), CONTACTS["carry"], self.hq.q[j][None])]

    def _handovers(self, node: Node) -> list[Edge]:
        dg = self.dg
        if HANDOVER not in self.allowed or dg.failure:
            return []
        direct = dg.picking_arm == dg.placing_arm
        out = []
        for k in np.flatnonzero(dg.pick_rank[: self.limits.double_grasps] == node.grasp):
            target = Node(dg.placing_arm, "place", int(dg.place_rank[k]), FINAL)
            if direct:
                out.append(Edge("transfer", target, CONTACTS["transfer"], dg.q_place[k][None], rank=int(k)))
            else:
                out.append(Edge("handover", target, CONTACTS["handover"], np.stack([dg.q_exch[k], dg.q_place[k]]), rank=int(k)))
        return out

    def _set_downs(self, node: Node) -> list[Edge]:
        if self.take not in self.allowed or node.grasp not in self.best_pick:
            return []
        i = int(np.flatnonzero(self.hp.rank == node.grasp)[0])
        return [Edge("set down", Node(self.a, "pick", node.grasp, k), CONTACTS["set down"],
                     make=lambda k=k: self._configuration(self.a, "pick", node.grasp, k, self.hp.q[i]),
                     why="the picking hand cannot set it down there with its grasp") for k in self.spots]

    def _takes(self, node: Node) -> list[Edge]:
        """The placing hand taking the object at the node's placement; the same hand (a regrasp) only in another grasp."""
        held = self.pick.hand_pose[node.grasp]
        return [Edge("take", Node(self.b, "place", int(self.hq.rank[j]), node.at), CONTACTS["take"],
                     make=lambda j=j: self._configuration(self.b, "place", int(self.hq.rank[j]), node.at, self.hq.q[j]),
                     why="the placing hand cannot take it there with its grasp") for j in self.best_place
                if self.take == TABLE or not same_grasp(held, self.place.hand_pose[int(self.hq.rank[j])])]

    def _configuration(self, arm: str, role: str, rank: int, k: int, start: np.ndarray) -> np.ndarray | None:
        """(1, nq): the robot with `arm` holding the object at placement k in grasp `rank`, the other arm out of the way
        (as at the start, where the task's author posed it, when that is collision-free; else as sampled, near rest);
        None when the sampler finds none. Made once per (arm, list, grasp, placement)."""
        key = (arm, role, rank, k)
        if key not in self.made:
            grasps = self.pick if role == "pick" else self.place
            T = self.placements.pose[k]
            found = self.sampler.grasp_configuration(arm, T @ grasps.hand_pose[rank], grasps.finger_q[rank], T, start, self.rng)
            self.made[key] = None if found is None else self._tucked(found[0], arm, T)[None]
        return self.made[key]

    def _tucked(self, q: np.ndarray, arm: str, T: np.ndarray) -> np.ndarray:
        robot = self.scene.robot
        out = q.copy()
        for free in robot.spec.arm_names:
            if free != arm:
                out[robot.arm_idx[free]] = self.scene.q_initial[robot.arm_idx[free]]
        return q if self.sampler.collision.in_collision(out, T, (arm,)) else out
