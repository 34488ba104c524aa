"""The exchange position (paper V-C, figure 6): where in the air the object passes from hand to hand.

A 3-D grid covers the region both hands reach (the intersection of each arm's reach sphere about
its shoulder, the reach estimated by sampling the arm). A node is free when the object's bounding
sphere about its centre of mass, centred there, clears the environment and the robot's torso at
rest. Each node costs the palms' travel ig + ge + ef + ie + ep + pf (exchange_grid.py), the grasp
and place palms taken from the best-scored grasp and place configurations; the cheapest free nodes
are kept, best first. The exchange orientation depends on the double grasp (double_grasps.py).
A direct transfer (one arm picks and places) has no exchange: the step records that, with no grid.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from planner.collision.hand_placement import ObstacleTest
from planner.collision.object_obstacle import ObjectCollision
from planner.core.bounds import bounded
from planner.core.results import array
from planner.core.stages import StageLog
from planner.core.steps import Step, StepContext, StepOutput
from planner.handover.exchange_grid import PalmWaypoints, best_nodes, exchange_costs, grid_nodes
from planner.handover.reach import fingertip_centre
from planner.model.robot import Robot, joint_at
from planner.model.task import Scene


@dataclass(frozen=True)
class ExchangeParams:
    step: float = bounded(0.05, 0.01, 0.5, "m", "spacing of the exchange grid")
    reach_fraction: float = bounded(0.8, 0.1, 1.0, "(fraction)", "a node is reachable within this fraction of each arm's reach")
    reach_samples: int = bounded(1500, 10, 100000, "configurations", "arm configurations sampled to estimate an arm's reach")
    keep: int = bounded(5, 1, 1000, "nodes", "best free nodes kept")


@dataclass(frozen=True)
class Exchange:
    """The grid, its costs and free nodes, and the best exchange positions (object centre of mass, world)."""

    stages: list
    failure: str
    step: float
    shoulders: list  # per arm (spec order): the shoulder position at rest
    reach: list  # per arm: the reach radius used, m
    grid_nodes: int  # nodes of the whole grid box; only those both hands reach are kept below
    nodes: np.ndarray = array("float64", ("k", 3))
    cost: np.ndarray = array("float64", ("k",))
    free: np.ndarray = array("bool", ("k",))  # collision-free
    best: np.ndarray = array("int64", ("m",))  # indices into nodes, cheapest first
    waypoints: np.ndarray = array("float64", (6, 3))  # PalmWaypoints fields, in order

    @property
    def position(self) -> np.ndarray:
        """The best exchange position."""
        return self.nodes[self.best[0]]

    def stats(self) -> dict:
        return {"reachable_nodes": len(self.nodes), "free": int(self.free.sum()),
                "best_cost": round(float(self.cost[self.best[0]]), 4) if len(self.best) else None,
                **({"failure": self.failure} if self.failure else {})}


def arm_reach(robot: Robot, arm: str, samples: int, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """(the shoulder position at rest, the largest shoulder-to-grasp-centre distance over sampled arm configurations)."""
    model, data = robot.model, robot.model.createData()
    idx = robot.arm_idx[arm]
    shoulder_joint = joint_at(model, int(idx[0]))
    palm = robot.frame_id(robot.palm_frame(arm))
    offset = fingertip_centre(robot, arm)
    pin.forwardKinematics(model, data, robot.q_rest)
    shoulder = data.oMi[shoulder_joint].translation.copy()
    q = robot.q_rest.copy()
    reach = 0.0
    for _ in range(samples):
        q[idx] = rng.uniform(robot.lower[idx], robot.upper[idx])
        pin.forwardKinematics(model, data, q)
        centre = pin.updateFramePlacement(model, data, palm).act(offset)
        reach = max(reach, float(np.linalg.norm(centre - shoulder)))
    return shoulder, reach


def palm_position(robot: Robot, arm: str, q: np.ndarray) -> np.ndarray:
    """The world position of an arm's palm frame at q (the point whose travel the exchange cost measures)."""
    return robot.frame_placement(q, robot.palm_frame(arm))[:3, 3]


def palm_waypoints(scene: Scene, picking: str, placing: str, q_grasp: np.ndarray, q_place: np.ndarray) -> PalmWaypoints:
    """The picking palm at the initial, grasp and final configurations, the placing palm at the initial, place and final ones."""
    stops = ((picking, scene.q_initial), (picking, q_grasp), (picking, scene.q_final),
             (placing, scene.q_initial), (placing, q_place), (placing, scene.q_final))
    return PalmWaypoints(*(palm_position(scene.robot, arm, q) for arm, q in stops))


def run(ctx: StepContext) -> StepOutput:
    scene, p = ctx.scene, ctx.params
    robot = scene.robot
    configs = ctx.inputs["grasp_configs"]
    log = StageLog()
    if configs.picking_arm == configs.placing_arm:
        log.done("no exchange", 0, f"a direct transfer: the {configs.picking_arm} arm picks and places")
        none = np.zeros(0)
        return StepOutput(Exchange(log.stages, "", p.step, [], [], 0, np.zeros((0, 3)), none, none.astype(bool), none.astype(np.int64),
                                   np.zeros((6, 3))), tuple(log.seconds))
    pick, place = configs.hand("pick"), configs.hand("place")
    ctx.progress(0.0, "arm reach")
    reach = [arm_reach(robot, a, p.reach_samples, ctx.rng) for a in robot.spec.arm_names]
    shoulders = np.array([s for s, _ in reach])
    radii = np.array([r for _, r in reach]) * p.reach_fraction
    lower = np.max(shoulders - radii[:, None], axis=0)
    upper = np.min(shoulders + radii[:, None], axis=0)
    box = grid_nodes(lower, upper, p.step) if np.all(upper > lower) else np.zeros((0, 3))
    nodes = box[np.all(np.linalg.norm(box[:, None] - shoulders[None], axis=2) <= radii[None], axis=1)]
    log.done("grid nodes reachable by both hands", len(nodes), f"of {len(box)}, {p.step:g} m grid")
    ctx.progress(0.4, "free nodes")
    collision = ObjectCollision(scene)
    radius = float(np.max(np.linalg.norm(scene.object_mesh.vertices - collision.com, axis=1)))
    blocking = ObstacleTest([(ob.coal_shape(), ob.pose) for ob in scene.environment]
                            + collision.robot_shapes(robot.q_rest, ("torso",)), collision.model.params.env_padding)
    free = ~blocking.spheres_hit(nodes, radius)
    log.done("free nodes", free.sum(), f"object bounding sphere ({radius:.3f} m) clear of obstacles and torso")
    failure, best, costs = "", np.zeros(0, np.int64), np.zeros(len(nodes))
    w = np.zeros((6, 3))
    if not len(pick.rank) or not len(place.rank):
        failure = log.failure("no exchange position: a hand has no grasp configuration")
    else:
        a, b = configs.picking_arm, configs.placing_arm
        q_grasp, q_place = pick.q[np.argmax(pick.score)], place.q[np.argmax(place.score)]
        waypoints = palm_waypoints(scene, a, b, q_grasp, q_place)
        w = np.array([waypoints.pick_initial, waypoints.pick_grasp, waypoints.pick_final,
                      waypoints.place_initial, waypoints.place_place, waypoints.place_final])
        costs = exchange_costs(nodes, waypoints)
        best = best_nodes(costs, free, p.keep)
        log.done("best exchange positions", len(best), "cheapest free nodes")
        if not len(best):
            failure = log.failure("no exchange position: no grid node both hands reach is collision-free")
    ctx.progress(1.0, f"{int(free.sum())} free nodes")
    return StepOutput(Exchange(log.stages, failure, p.step, shoulders.tolist(), radii.tolist(), len(box), nodes, costs, free, best, w),
                      tuple(log.seconds))


NAME = "exchange"
STEP = Step(NAME, "exchange position: 3-D grid of the palms' travel (V-C, fig. 6)", ("grasp_configs",), ExchangeParams, Exchange, run)
