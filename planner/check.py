"""`regrasp check`: validate a task and summarise it (parts, pairs, collisions, reachability)."""
from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np

from .collision import CollisionModel, build_collision_model
from .environment import Obstacle
from .geometry import coal_mesh, transform3s
from .reach import ReachResult, reach
from .task import Scene

RESTING_CONTACT = 0.003  # m: an object standing on a support may sink this deep into it


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
    problems: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return not self.problems

    def render(self) -> str:
        lines = [f"task {self.task}  robot {self.robot}", "", "degrees of freedom"]
        lines += [f"  {part:<14}{n:>4}" for part, n in self.dof.items()]
        lines += ["", "collision pairs"] + [f"  {k:<28}{v:>6}" for k, v in self.pairs.items()]
        lines += ["", "robot configurations"]
        for name, hits in self.config_collisions.items():
            lines.append(f"  {name:<10}" + ("collision-free" if not hits else "IN COLLISION: " + ", ".join(f"{a}~{b}" for a, b in hits[:6])))
        lines += ["", "object placements"]
        for name, hits in self.placement_collisions.items():
            lines.append(f"  {name:<10}" + ("collision-free" if not hits else "IN COLLISION with " + ", ".join(hits)))
        lines += ["", "reachability (grasp centre to the object's centre of mass, arm + torso, collision-free)"]
        for placement, per_arm in self.reach.items():
            cells = [f"{arm}: {'yes' if r.reachable else 'no'} ({r.distance * 100:.1f} cm)" for arm, r in per_arm.items()]
            lines.append(f"  {placement:<10}" + "   ".join(cells))
        lines += [""] + ([f"PROBLEM: {p}" for p in self.problems] or ["OK: a valid two-hand regrasping task"])
        return "\n".join(lines)


def object_collisions(scene: Scene, T: np.ndarray) -> list[str]:
    """Obstacles the object placed at T penetrates deeper than resting contact (it is tested raised by that)."""
    raised = T.copy()
    raised[2, 3] += RESTING_CONTACT
    shape, tf = coal_mesh(scene.object_mesh), transform3s(raised)
    request = coal.CollisionRequest()
    hits = []
    for ob in scene.environment:
        result = coal.CollisionResult()
        if coal.collide(shape, tf, ob.coal_shape(), transform3s(ob.pose), request, result):
            hits.append(ob.name)
    return hits


def object_obstacle(scene: Scene, name: str, T: np.ndarray) -> Obstacle:
    """The object at a placement, as a static obstacle for the robot."""
    return Obstacle(f"object_{name}", "mesh", (), T, mesh=scene.object_mesh)


def check_task(scene: Scene, rng: np.random.Generator, cm: CollisionModel | None = None) -> TaskReport:
    """Run every check of a task; problems are collected, not raised, so the summary is complete."""
    robot = scene.robot
    cm = cm or build_collision_model(robot, scene.environment)
    checker = cm.checker()
    dof = {"total": robot.nq, "torso": len(robot.torso_idx)}
    for arm in robot.spec.arm_names:
        dof[arm] = len(robot.arm_idx[arm])
        dof[f"{arm}_hand"] = len(robot.hand_idx[arm])
    pairs = {
        "self (kept)": len(cm.subsets["self"]),
        "robot-environment": len(cm.subsets["env"]),
        "disabled: adjacent links": cm.pair_set.adjacent,
        "disabled: touching at rest": cm.pair_set.at_rest,
        "pruned: never within margin": cm.pair_set.pruned,
    }
    problems: list[str] = []
    configs = {}
    for name, q, T in (("initial", scene.q_initial, scene.object_initial), ("final", scene.q_final, scene.object_final)):
        with_object = build_collision_model(robot, scene.environment + (object_obstacle(scene, name, T),), cm.params)
        hits = with_object.checker().colliding_pairs(q)
        configs[name] = hits
        if hits:
            problems.append(f"the robot's {name} configuration is in collision ({len(hits)} pairs)")
    placements = {"initial": object_collisions(scene, scene.object_initial), "final": object_collisions(scene, scene.object_final)}
    for name, hits in placements.items():
        if hits:
            problems.append(f"the object's {name} placement penetrates {', '.join(hits)}")
    com = np.asarray(scene.object_mesh.center_mass)
    reaches: dict[str, dict[str, ReachResult]] = {}
    for name, T in (("initial", scene.object_initial), ("final", scene.object_final)):
        target = T[:3, :3] @ com + T[:3, 3]
        reaches[name] = {arm: reach(robot, checker, arm, target, rng) for arm in robot.spec.arm_names}
    init_arms = [a for a, r in reaches["initial"].items() if r.reachable]
    final_arms = [a for a, r in reaches["final"].items() if r.reachable]
    if len(init_arms) != 1:
        problems.append(f"the initial placement must be reachable by exactly one arm (reached by: {', '.join(init_arms) or 'none'})")
    if len(final_arms) != 1:
        problems.append(f"the final placement must be reachable by exactly one arm (reached by: {', '.join(final_arms) or 'none'})")
    if len(init_arms) == 1 and init_arms == final_arms:
        problems.append(f"both placements are reached by the {init_arms[0]} arm only: no regrasp is needed")
    return TaskReport(scene.name, robot.spec.name, dof, pairs, configs, placements, reaches, tuple(problems))
