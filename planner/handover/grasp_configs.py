"""Grasp and place configurations of the robot (paper IV-B filter, V-C): the first online step.

Each hand's grasp list is first filtered against the environment at the object's placement (the
picking hand at the initial pose, the placing hand at the final one): a hand that hits the support
can never execute that grasp. For every remaining grasp, whole-robot configurations are sampled:
the torso and the free arm near where the task holds them (the robot's start configuration for the
pick, its end configuration for the place: a free arm sent to another pose only has to come back, and
the roadmap holds those configurations; with `free_around = "rest"`, near the robot's rest, as in the
paper), the grasping arm (with the torso) by IK onto the grasp's palm pose, its fingers at the grasp;
each is checked against self-collision, the environment and the object at its placement. A grasp for
which none of these `attempts` succeeds gets `wide_attempts` more, the torso and the free arm drawn
over their whole ranges (a placement at the edge of the workspace needs the spine bent or the other
arm out of the way). The best-scored configuration of each grasp is kept (see config_score.py).
Budgets: at most (attempts + wide_attempts) IK solves of ik_iterations iterations per grasp clear of
the environment.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.collision.hand_placement import ObstacleTest, environment_filter
from planner.collision.object_obstacle import ObjectCollision
from planner.core.bounds import bounded, described
from planner.core.forked import forked_map
from planner.core.results import array
from planner.core.stages import StageLog
from planner.core.steps import Step, StepContext, StepOutput
from planner.grasping.grasp_list import GraspList
from planner.handover.arm_ik import ArmIK
from planner.handover.config_score import ConfigScorer, ScoreWeights
from planner.model.hand_model import load_hand_model
from planner.model.robot import Robot
from planner.model.task import Scene


@dataclass(frozen=True)
class GraspConfigParams:
    attempts: int = bounded(8, 1, 1000, "IK starts", "IK starts per grasp, torso and free arm near their center (free_around)")
    wide_attempts: int = bounded(
        16, 0, 1000, "IK starts", "more IK starts, torso and free arm over their whole ranges, for a grasp the first ones miss")
    keep: int = bounded(
        2, 1, 100, "configurations", "a grasp stops after this many collision-free configurations; its best-scored one is kept")
    free_around: str = described("task", "torso, free arm sampled and scored around the start (pick, exchange) or end "
                                 "(place) configuration, or the rest", ("task", "rest"))
    torso_sigma: float = bounded(0.1, 0.0, 3.1416, "rad", "spread of the torso joints around their center (free_around)")
    free_arm_sigma: float = bounded(0.1, 0.0, 3.1416, "rad", "spread of the free arm's joints around their center (free_around)")
    position_tolerance: float = bounded(0.002, 1e-5, 0.05, "m", "palm position to its grasp pose, at most")
    rotation_tolerance: float = bounded(0.02, 1e-4, 0.5, "rad", "palm orientation to its grasp pose, at most")
    workers: int = bounded(2, 1, 64, "processes", "worker processes (the two hands are searched in parallel)")
    # converging solves take ~6 iterations, 13 at the 90th percentile on the default task
    ik_iterations: int = bounded(30, 1, 1000, "iterations", "IK iterations per start")
    arm_weight: float = bounded(
        1.0, 0.0, 100.0, "(weight)", "configuration score weight of the grasping arm (its approach towards the robot's base)")
    free_weight: float = bounded(
        1.0, 0.0, 100.0, "(weight)", "configuration score weight of the free arm (near its center, wrist at that height, by the torso)")
    joint_scale: float = bounded(0.5, 0.01, 10.0, "rad", "free-arm joint distance to its center worth one unit of penalty")
    length_scale: float = bounded(
        0.1, 0.001, 10.0, "m", "free-arm wrist height change or distance to the torso plane worth one unit of penalty")

    def weights(self) -> ScoreWeights:
        return ScoreWeights(self.arm_weight, self.free_weight, self.joint_scale, self.length_scale)

    def scorer(self, robot: Robot, task_q: np.ndarray) -> ConfigScorer:
        """The scorer whose reference the torso and free arms are sampled and scored around: `task_q` (where the task
        holds the robot when it grasps) or the robot's rest (`free_around`)."""
        return ConfigScorer(robot, self.weights(), task_q if self.free_around == "task" else robot.q_rest)


@dataclass(frozen=True)
class HandConfigs:
    """One hand's grasps that have a robot configuration: their ranks in the grasp list, configurations and scores."""

    arm: str
    rank: np.ndarray
    q: np.ndarray
    arm_score: np.ndarray
    free_score: np.ndarray
    score: np.ndarray


@dataclass(frozen=True)
class GraspConfigs:
    """The grasp lists filtered at the placements, and the robot configuration of each grasp that has one."""

    picking_arm: str
    placing_arm: str
    stages: list
    failure: str  # empty when both hands have configurations; else which stage emptied, with the counts
    pick_env_free: np.ndarray = array("bool", ("n_pick",))  # per grasp of the pick list: hand free of the environment
    place_env_free: np.ndarray = array("bool", ("n_place",))
    pick_rank: np.ndarray = array("int64", ("a",))
    pick_q: np.ndarray = array("float64", ("a", "nq"))
    pick_arm_score: np.ndarray = array("float64", ("a",))
    pick_free_score: np.ndarray = array("float64", ("a",))
    pick_score: np.ndarray = array("float64", ("a",))
    place_rank: np.ndarray = array("int64", ("b",))
    place_q: np.ndarray = array("float64", ("b", "nq"))
    place_arm_score: np.ndarray = array("float64", ("b",))
    place_free_score: np.ndarray = array("float64", ("b",))
    place_score: np.ndarray = array("float64", ("b",))

    def hand(self, role: str) -> HandConfigs:
        """'pick' or 'place'."""
        arm = self.picking_arm if role == "pick" else self.placing_arm
        return HandConfigs(arm, *(getattr(self, f"{role}_{f}") for f in ("rank", "q", "arm_score", "free_score", "score")))

    def stats(self) -> dict:
        return {"pick_env_free": int(self.pick_env_free.sum()), "place_env_free": int(self.place_env_free.sum()),
                "pick_configs": len(self.pick_rank), "place_configs": len(self.place_rank),
                **({"failure": self.failure} if self.failure else {})}


class ConfigSampler:
    """Whole-robot configurations putting one or two hands at grasp poses, checked with the object in place; the torso
    and the free arms sampled around the configuration the scorer scores them against (the robot's rest without one)."""

    def __init__(self, robot: Robot, collision: ObjectCollision, scorer: ConfigScorer | None, p: GraspConfigParams):
        self.robot, self.collision, self.scorer, self.p = robot, collision, scorer, p
        self.center = robot.q_rest if scorer is None else scorer.reference
        self.ik = {a: ArmIK(robot, a) for a in robot.spec.arm_names}
        self.both = ArmIK(robot, tuple(robot.spec.arm_names))

    def body(self, rng: np.random.Generator, free_arms: list[str], wide: bool = False) -> np.ndarray:
        """The center with the torso and the free arms sampled around it (Gaussian, clipped to the limits), or
        uniformly over their ranges when `wide`."""
        robot, p, center = self.robot, self.p, self.center
        q = center.copy()
        for idx, sigma in [(robot.torso_idx, p.torso_sigma)] + [(robot.arm_idx[a], p.free_arm_sigma) for a in free_arms]:
            q[idx] = rng.uniform(robot.lower[idx], robot.upper[idx]) if wide else center[idx] + rng.normal(0.0, sigma, len(idx))
        return robot.clip(q)

    def reach(self, hands: dict[str, tuple[np.ndarray, np.ndarray]], q: np.ndarray) -> np.ndarray | None:
        """q with the torso and the arms of `hands` (arm -> (palm pose, finger q)) moved by IK so each palm is at its
        pose, the fingers set; None if IK misses. One arm, or every arm of the robot at once."""
        q = q.copy()
        for arm, (_, finger_q) in hands.items():
            q[self.robot.hand_idx[arm]] = finger_q
        if len(hands) == 1:
            ik = self.ik[next(iter(hands))]
        else:
            ik, hands = self.both, {a: hands[a] for a in self.robot.spec.arm_names}
        result = ik.solve(np.array([palm for palm, _ in hands.values()]), q, self.p.ik_iterations, self.p.position_tolerance,
                          self.p.rotation_tolerance, stall=8)
        return result.q if result.within(self.p.position_tolerance, self.p.rotation_tolerance) else None

    def grasp_configuration(self, arm: str, palm: np.ndarray, finger_q: np.ndarray, object_pose: np.ndarray,
                            start: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, object] | None:
        """The best-scored collision-free configuration found with `arm` holding the object at a grasp, or None."""
        robot, p = self.robot, self.p
        free = [a for a in robot.spec.arm_names if a != arm]
        com = object_pose[:3, :3] @ np.asarray(self.collision.com) + object_pose[:3, 3]
        best, found = None, 0
        idx = np.concatenate([robot.torso_idx, robot.arm_idx[arm]])
        for attempt in range(p.attempts + p.wide_attempts):
            wide = attempt >= p.attempts
            if wide and best is not None:
                break  # the wide starts are for grasps the near-rest ones missed
            q = self.body(rng, free, wide)
            if attempt == 0:
                q[idx] = start[idx]
            elif attempt > 1:
                i = robot.arm_idx[arm]
                q[i] = rng.uniform(robot.lower[i], robot.upper[i])
            q = self.reach({arm: (palm, finger_q)}, q)
            if q is None or self.collision.in_collision(q, object_pose, (arm,)):
                continue
            score = self.scorer.score(q, arm, com)
            if best is None or score.total > best[1].total:
                best = (q, score)
            found += 1
            if found >= p.keep:
                break
        return best


def hand_configurations(sampler: ConfigSampler, grasps: GraspList, ranks: np.ndarray, object_pose: np.ndarray,
                        start: np.ndarray, rng: np.random.Generator) -> HandConfigs:
    """The configuration of every grasp in `ranks` that has one."""
    out = []
    for r in ranks:
        found = sampler.grasp_configuration(grasps.hand, object_pose @ grasps.hand_pose[r], grasps.finger_q[r], object_pose, start, rng)
        if found is not None:
            out.append((int(r), found[0], found[1]))
    nq = sampler.robot.nq
    return HandConfigs(grasps.hand, np.array([o[0] for o in out], np.int64), np.array([o[1] for o in out]).reshape(-1, nq),
                       *(np.array([getattr(o[2], f) for o in out], float) for f in ("arm", "free", "total")))


@dataclass(frozen=True)
class HandJob:
    """One hand's share of the step: its list filtered at a placement, then its configurations."""

    role: str  # 'pick' or 'place'
    scene: Scene
    collision: ObjectCollision  # built once before the fork; each process places the object in its own copy of the checker data
    params: GraspConfigParams
    grasps: GraspList
    object_pose: np.ndarray
    start: np.ndarray  # the arm step's witness configuration: the first IK start
    rng: np.random.Generator


def hand_job(job: HandJob) -> tuple[np.ndarray, HandConfigs, StageLog]:
    """(environment-free mask, configurations, stage log) of one hand."""
    scene, grasps = job.scene, job.grasps
    log = StageLog()
    collision = job.collision
    placement = "initial" if job.role == "pick" else "final"
    obstacles = ObstacleTest.of_environment(scene.environment, collision.model.params.env_padding)
    free = environment_filter(scene.robot, grasps, job.object_pose, obstacles)
    log.done(f"{job.role} grasps clear of the environment", free.sum(), f"of {len(grasps)} at the {placement} pose")
    scorer = job.params.scorer(scene.robot, scene.q_initial if job.role == "pick" else scene.q_final)
    sampler = ConfigSampler(scene.robot, collision, scorer, job.params)
    configs = hand_configurations(sampler, grasps, np.flatnonzero(free), job.object_pose, job.start, job.rng)
    log.done(f"{job.role} grasp configurations", len(configs.rank), f"collision-free, object at the {placement} pose")
    return free, configs, log


def run(ctx: StepContext) -> StepOutput:
    scene, p = ctx.scene, ctx.params
    arms = ctx.inputs["arms"]
    rngs = ctx.rng.spawn(2)
    collision = ObjectCollision(scene)
    pick, place = ctx.inputs["pick_grasps"], ctx.inputs["place_grasps"]
    for grasps in (pick, place):
        load_hand_model(scene.robot.spec.arm(grasps.hand).hand)  # loaded once here, inherited by the processes
    jobs = [HandJob("pick", scene, collision, p, pick, scene.object_initial, arms.q_pick, rngs[0]),
            HandJob("place", scene, collision, p, place, scene.object_final, arms.q_place, rngs[1])]
    ctx.progress(0.0, "pick and place configurations (one process per hand)")
    (pick_free, pick_cfg, pick_log), (place_free, place_cfg, place_log) = forked_map(hand_job, jobs, p.workers)
    log = StageLog()
    log.stages, log.seconds = pick_log.stages + place_log.stages, pick_log.seconds + place_log.seconds
    failure = ""
    if not len(pick_cfg.rank):
        failure = log.failure(f"no collision-free pick grasp: the {arms.picking_arm} hand has no grasp with a robot configuration")
    elif not len(place_cfg.rank):
        failure = log.failure(f"no collision-free place grasp: the {arms.placing_arm} hand has no grasp with a robot configuration")
    ctx.progress(1.0, f"{len(pick_cfg.rank)} pick, {len(place_cfg.rank)} place configurations")
    fields = {f"{role}_{f}": getattr(h, f) for role, h in (("pick", pick_cfg), ("place", place_cfg))
              for f in ("rank", "q", "arm_score", "free_score", "score")}
    return StepOutput(GraspConfigs(arms.picking_arm, arms.placing_arm, log.stages, failure, pick_free, place_free, **fields),
                      tuple(log.seconds))


NAME = "grasp_configs"
STEP = Step(NAME, "grasp lists filtered at the placements; robot grasp and place configurations (IV-B, V-C)",
            ("arms", "pick_grasps", "place_grasps"), GraspConfigParams, GraspConfigs, run)
