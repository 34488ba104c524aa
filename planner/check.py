"""Task validation: what `check` reports, and the part of it that `plan`, `grasps` and the workbench run before any step.

`validate_task` finds what makes a task unplannable whatever the arms (the robot's start or end
configuration in collision, a placement inside an obstacle) and what is suspicious (an object the
hands cannot hold, by the spec's hand geometry); `check_task` adds each arm's reach of each
placement and the arm assignment the arms step would make. The messages are the same in both.
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner.collision.checker import CollisionModel, build_collision_model
from planner.collision.object_obstacle import obstacles_penetrated
from planner.collision.shapes import coal_mesh
from planner.collision.with_object import object_at_rest
from planner.core.errors import RegraspError
from planner.handover.arms import ArmsParams, decide
from planner.handover.reach import ReachResult, placement_reach
from planner.model.hand_model import load_hand_model
from planner.model.object_mesh import OBJECT_LIMITS, likely_unit
from planner.model.robot_spec import HandSpec
from planner.model.task import Scene

RESTING_CONTACT = 0.003  # m: an object standing on a support may sink this deep into it
OPENING_SAMPLES = 400  # finger configurations sampled per finger to measure a hand's largest opening


class InvalidTask(RegraspError):
    """A task that `check` rejects: no step runs on it."""


@dataclass(frozen=True)
class Validation:
    """Problems (the task cannot be planned) and warnings (it probably will not be) found before any step."""

    config_collisions: dict[str, list[tuple[str, str]]]
    placement_collisions: dict[str, list[str]]
    problems: tuple[str, ...]
    warnings: tuple[str, ...]

@dataclass(frozen=True)
class TaskReport:
    """Everything `regrasp check` prints; `ok` is true when the task is a valid regrasping task."""

    task: str
    robot: str
    dof: dict[str, int]
    pairs: dict[str, int]
    config_collisions: dict[str, list[tuple[str, str]]]
    placement_collisions: dict[str, list[str]]
    reach: dict[str, dict[str, ReachResult]]
    tolerance: float
    arms: str  # the arm assignment the arms step would make, or why none
    handover: bool  # false: one arm reaches both placements and the task does not ask for a handover
    problems: tuple[str, ...]
    warnings: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return not self.problems

    def render(self) -> str:
        lines = [f"task {self.task}  robot {self.robot}", "", "degrees of freedom"]
        lines += [f"  {part:<14}{n:>4}" for part, n in self.dof.items()]
        lines += ["", "collision pairs"] + [f"  {k:<28}{v:>6}" for k, v in self.pairs.items()]
        lines += ["", "robot configurations"]
        for name, hits in self.config_collisions.items():
            verdict = "collision-free" if not hits else "IN COLLISION: " + ", ".join(f"{a}~{b}" for a, b in hits[:6])
            lines.append(f"  {name:<10}" + verdict)
        lines += ["", "object placements"]
        for name, hits in self.placement_collisions.items():
            lines.append(f"  {name:<10}" + ("collision-free" if not hits else "IN COLLISION with " + ", ".join(hits)))
        lines += ["", "reachability: can the arm (with the torso) bring its hand's fingertip centre (the open fingertips' mean) to",
                  "the object's centre of mass at the placement, collision-free? The distance is the closest that centre came;",
                  f"within {self.tolerance * 100:.1f} cm counts, unless every such configuration collides ('collides')."]
        for placement, per_arm in self.reach.items():
            cells = [f"{arm}: {r.describe(self.tolerance)}" for arm, r in per_arm.items()]
            lines.append(f"  {placement:<10}" + "   ".join(cells))
        lines += ["", f"arms: {self.arms}", ""] + [f"WARNING: {w}" for w in self.warnings]
        ok = "OK: a valid two-hand regrasping task" if self.handover else "OK: a valid pick-and-place task for one arm (no handover)"
        lines += [f"PROBLEM: {p}" for p in self.problems] or [ok]
        return "\n".join(lines)


def object_collisions(scene: Scene, T: np.ndarray) -> list[str]:
    """Obstacles the object placed at T penetrates deeper than resting contact (it is tested raised by that)."""
    raised = T.copy()
    raised[2, 3] += RESTING_CONTACT
    return obstacles_penetrated(scene.object_mesh, raised, scene.environment)


@functools.lru_cache(maxsize=8)
def hand_opening(hand: HandSpec) -> float:
    """The widest object (m) a hand can close on: the largest gap between the thumb's tip sphere and another's."""
    model = load_hand_model(hand)
    rng = np.random.default_rng(0)
    tips = [f.tip_positions(rng.uniform(f.lower, f.upper, (OPENING_SAMPLES, f.dof))) for f in model.fingers]
    thumb = model.finger_names.index(hand.thumb)
    gaps = [np.linalg.norm(tips[thumb][:, None] - tips[i][None], axis=2).max() - model.fingers[thumb].tip_radius - f.tip_radius
            for i, f in enumerate(model.fingers) if i != thumb]
    return float(max(gaps))


def size_warnings(scene: Scene) -> list[str]:
    """Warnings for an object the robot's hands cannot hold: wider than any hand opens, or smaller than a fingertip."""
    extents = np.sort(scene.object_mesh.extents)
    hands = [scene.robot.spec.arm(a).hand for a in scene.robot.spec.arm_names]
    opening = max(hand_opening(h) for h in hands)
    tip = min(f.tip_radius for h in hands for f in h.fingers)
    if extents[0] > opening:
        return [(f"the object is {extents[0]:.3g} m across at its narrowest, wider than the robot's hands open "
                 f"({opening:.3g} m between the thumb's and another fingertip, from the robot spec's hands): no grasp can "
                 f"close on it ({likely_unit(extents[-1], OBJECT_LIMITS.typical)})")]
    if extents[-1] < 4 * tip:
        return [(f"the object is {extents[-1]:.3g} m long at its largest, less than four fingertip radii ({4 * tip:.3g} m, "
                 f"from the robot spec's hands): three fingertips cannot touch it at once "
                 f"({likely_unit(extents[-1], OBJECT_LIMITS.typical)})")]
    return []


def validate_task(scene: Scene, cm: CollisionModel | None = None) -> Validation:
    """The checks that need no arm: the robot's start and end configurations and the object's placements collision-free."""
    robot = scene.robot
    cm = cm or build_collision_model(robot, scene.environment)
    problems: list[str] = []
    configs = {}
    for name, q, T in (("initial", scene.q_initial, scene.object_initial), ("final", scene.q_final, scene.object_final)):
        hits = object_at_rest(cm, coal_mesh(scene.object_mesh), T).checker().colliding_pairs(q)
        configs[name] = hits
        if hits:
            problems.append(f"the robot's {name} configuration is in collision ({len(hits)} pairs)")
    placements = {"initial": object_collisions(scene, scene.object_initial), "final": object_collisions(scene, scene.object_final)}
    for name, hits in placements.items():
        if hits:
            problems.append(f"the object's {name} placement penetrates {', '.join(hits)}")
    return Validation(configs, placements, tuple(problems), tuple(size_warnings(scene)))


def require_valid(scene: Scene, warn: Callable[[str], None]) -> Validation:
    """Validate a task before any step: InvalidTask with `check`'s problem messages, each warning passed to `warn`."""
    v = validate_task(scene)
    for w in v.warnings:
        warn(f"warning: task {scene.source}: {w}")
    if v.problems:
        raise InvalidTask(f"task {scene.source}: " + "; ".join(v.problems) + " (run `regrasp check` for the full report)")
    return v


def check_task(scene: Scene, cm: CollisionModel | None = None, params: ArmsParams | None = None) -> TaskReport:
    """Run every check of a task; problems are collected, not raised, so the summary is complete."""
    params = params or ArmsParams()
    robot = scene.robot
    cm = cm or build_collision_model(robot, scene.environment)
    dof = {"total": robot.nq, "torso": len(robot.torso_idx)}
    for arm in robot.spec.arm_names:
        dof[arm] = len(robot.arm_idx[arm])
        dof[f"{arm}_hand"] = len(robot.hand_idx[arm])
    pairs = {
        "self (kept)": len(cm.subsets["self"]),
        "robot-environment": len(cm.subsets["env"]),
        "disabled: adjacent links": cm.pair_set.adjacent,
        "disabled: touching at rest": cm.pair_set.at_rest,
        "disabled: allowed by the robot spec": cm.pair_set.allowed,
        "pruned: never within margin": cm.pair_set.pruned,
    }
    v = validate_task(scene, cm)
    reaches = placement_reach(scene, cm.checker(), params.seeds, params.tolerance)
    decision = decide(scene, reaches)
    problems = list(v.problems) + ([decision.failure] if decision.failure and decision.handover else [])
    who = (f"the {decision.picking_arm} arm picks and places" if decision.picking_arm == decision.placing_arm
           else f"{decision.picking_arm} picks, {decision.placing_arm} places")
    arms = decision.choice if decision.failure else f"{who} ({decision.choice})"
    return TaskReport(scene.name, robot.spec.name, dof, pairs, v.config_collisions, v.placement_collisions, reaches,
                      params.tolerance, arms, decision.handover, tuple(problems), v.warnings)
