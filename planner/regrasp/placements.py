"""The placements step: stable placements of the object on the scene's supports, where a hand may set it down for the
other hand (or itself, in another grasp) to take it.

The object's resting poses (those of the task's placements, where it rests and the grasps were chosen for, then
trimesh's `compute_stable_poses`: the convex hull's faces the centre of mass projects into, with the probability of
landing on each) are put on every support (the top face of an upright box
obstacle: the desk top, a shelf) on a grid of positions, at several headings. A placement is kept when the object
there is clear of every other obstacle and of the robot's fixed base; each arm's reach of its centre of mass is
recorded (reach.py: the fingertip centre brought there by the arm and the torso, collision-free). The stages say how
many were dropped and why. The task's own headings are among them: where the final placement rests on the initial's
face, that face is also put down at the final heading and halfway between the two. Ordered for the table handover:
both arms reaching first, then by how far the object goes from its initial placement through it to its final one
(the distance travelled plus `turn` metres per radian it turns: the hands' grasps were chosen at the task's two
orientations, and a grasp from above stays one where the object turns little), the placement midway between the
two ends first where that ties, then the more probable resting pose first. A step of
its own (needing only the scene) so the motion's strategies read one list, a session keeps it and the workbench draws
it; an empty list fails nothing (the handover needs none).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.collision.checker import build_collision_model
from planner.collision.hand_placement import ObstacleTest
from planner.collision.object_obstacle import ObjectCollision
from planner.collision.shapes import coal_mesh
from planner.core.bounds import bounded
from planner.core.results import array
from planner.core.stages import StageLog
from planner.core.steps import Progress, Step, StepContext, StepOutput, no_progress
from planner.handover.reach import reach
from planner.model.environment import Obstacle
from planner.model.geometry import heading, rotation_angle
from planner.model.task import Scene

UPRIGHT = 0.999  # a box whose z axis is this near the world's vertical has a horizontal top face
LIFTED = 0.001  # m: the object is checked this far above its support (resting on it, it touches)


@dataclass(frozen=True)
class PlacementParams:
    """How the placements are searched."""

    spacing: float = bounded(0.15, 0.01, 1.0, "m", "grid spacing of the positions on each support")
    headings: int = bounded(4, 1, 64, "headings", "headings per position and resting pose")
    min_probability: float = bounded(0.05, 0.0, 1.0, "(probability)", "resting poses less likely are left out")
    seeds: int = bounded(4, 1, 1000, "IK starts", "IK starts per arm and position, to find which arm reaches it")
    tolerance: float = bounded(0.02, 0.001, 0.2, "m", "reach brings the fingertip centre this near the centre of mass")
    turn: float = bounded(0.2, 0.0, 10.0, "m/rad", "ordering: each radian the object turns through a placement counts as this "
                          "much travel")


@dataclass(frozen=True)
class Placements:
    """Stable placements of the object, best first for a table handover, with the supports and each arm's reach."""

    arms: list  # arm names: the columns of `reached`
    support: list  # per placement, the obstacle it rests on
    stages: list  # what each stage kept (and so what it dropped)
    pose: np.ndarray = array("float64", ("n", 4, 4))
    probability: np.ndarray = array("float64", ("n",))  # of the resting pose
    reached: np.ndarray = array("bool", ("n", None))

    def __len__(self) -> int:
        return len(self.probability)

    def stats(self) -> dict:
        reached = {f"reached_by_{arm}": int(self.reached[:, k].sum()) for k, arm in enumerate(self.arms)}
        return {"placements": len(self), "supports": sorted(set(self.support)), **reached,
                "reached_by_both": int(self.reached.all(axis=1).sum()) if len(self) else 0}


def resting_poses(scene: Scene, min_probability: float) -> tuple[list[np.ndarray], list[float], list[float]]:
    """The object's resting poses (object frame to a frame whose origin is under the centre of mass, on the support's
    plane z = 0): first those of the task's initial and final placements (the object rests there, and the hands' grasps
    were chosen for them), then trimesh's stable poses at least `min_probability` likely, most likely first, each
    resting on a face no earlier one rests on. A task's pose takes the probability of trimesh's pose on the same face
    (0 when it has none). Third: the headings the task adds to the first pose (the final placement's and the one
    halfway to it, when the final rests on the initial's face; none else)."""
    mesh = scene.object_mesh
    transforms, probabilities = mesh.compute_stable_poses(center_mass=mesh.center_mass)
    stable = sorted(zip(transforms, probabilities), key=lambda tp: -tp[1])
    out, kept = [], []
    for T, p in [(T, None) for T in (scene.object_initial, scene.object_final)] + stable:
        if (p is not None and p < min_probability) or any(np.dot(down(T), down(U)) > UPRIGHT for U in out):
            continue
        if p is None:
            p = next((q for U, q in stable if np.dot(down(T), down(U)) > UPRIGHT), 0.0)
        T = np.array(T, float)
        com = T[:3, :3] @ mesh.center_mass + T[:3, 3]
        low = float((mesh.vertices @ T[:3, :3].T + T[:3, 3])[:, 2].min())
        T[:3, 3] -= [com[0], com[1], low]
        out.append(T)
        kept.append(float(p))
    extra = []
    if np.dot(down(scene.object_initial), down(scene.object_final)) > UPRIGHT:  # on one face: turned about the vertical
        angle = heading(scene.object_final[:3, :3] @ scene.object_initial[:3, :3].T)
        extra = [a for a in (angle, angle / 2) if abs(angle) > 1e-6]
    return out, kept, extra


def down(T: np.ndarray) -> np.ndarray:
    """The direction, in the object's frame, towards the support it rests on at pose T."""
    return T[:3, :3].T @ np.array([0.0, 0.0, -1.0])


def support_grid(support: Obstacle, margin: float, spacing: float) -> np.ndarray:
    """(k, 3) positions on the top face of an upright box obstacle, at least `margin` inside its edges; empty for any
    other obstacle."""
    R = support.pose[:3, :3]
    if support.shape != "box" or abs(R[2, 2]) < UPRIGHT:
        return np.zeros((0, 3))
    half = np.asarray(support.size[:2], float) / 2 - margin
    if np.any(half < 0):
        return np.zeros((0, 3))
    axes = [np.arange(-h, h + 1e-9, spacing) if h >= spacing else np.zeros(1) for h in half]
    axes = [a - (a[-1] + a[0]) / 2 for a in axes]  # centred on the face
    xy = np.array([(x, y) for x in axes[0] for y in axes[1]])
    top = support.pose[2, 3] + support.size[2] / 2
    world = (R[:2, :2] @ xy.T).T + support.pose[:2, 3]
    return np.column_stack([world, np.full(len(world), top)])


def yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def stable_placements(scene: Scene, p: PlacementParams, progress: Progress = no_progress) -> tuple[Placements, list[float]]:
    """Every stable placement of the object on the scene's supports (see the module), best first, and the seconds of
    each stage."""
    log = StageLog()
    rests, probabilities, extra = resting_poses(scene, p.min_probability)
    log.done("resting poses", len(rests), f"the task's, then others at least {p.min_probability:g} likely")
    mesh = scene.object_mesh
    com = np.asarray(mesh.center_mass, float)
    margin = float(np.linalg.norm((mesh.vertices - com)[:, :2], axis=1).max())
    env = scene.environment
    grids = {ob.name: support_grid(ob, margin, p.spacing) for ob in env}
    positions = [(name, x) for name, grid in grids.items() for x in grid]
    log.done("positions on supports", len(positions), f"{sum(1 for g in grids.values() if len(g))} supports, "
             f"{p.spacing:g} m apart, {margin:.3f} m inside the edges")
    headings = [[2 * np.pi * h / p.headings for h in range(p.headings)] + (extra if k == 0 else []) for k in range(len(rests))]
    candidates = [(name, x, k, a) for name, x in positions for k in range(len(rests)) for a in headings[k]]
    log.done("candidate placements", len(candidates), f"x {len(rests)} resting poses x {p.headings} headings"
             + (f", and the task's {len(extra)} on its first" if extra else ""))
    shape = coal_mesh(mesh)
    collision = ObjectCollision(scene)
    tests = {name: ObstacleTest([(ob.coal_shape(), ob.pose) for ob in env if ob.name != name] + collision.fixed_base,
                                collision.static.margin) for name, grid in grids.items() if len(grid)}
    clear = []
    for name, x, k, a in candidates:
        T = yaw(a) @ rests[k]
        T[:3, 3] += x + [0.0, 0.0, LIFTED]
        if not tests[name].hits([(shape, T)]):
            T[2, 3] -= LIFTED
            clear.append((name, T, probabilities[k]))
    log.done("clear of obstacles", len(clear), "the object clear of every other obstacle and of the robot's base")
    robot = scene.robot
    checker = build_collision_model(robot, env).checker()
    arms = list(robot.spec.arm_names)
    reached: dict[tuple, list[bool]] = {}
    flags = []
    for i, (_, T, _) in enumerate(clear):
        target = T[:3, :3] @ com + T[:3, 3]
        key = tuple(np.round(target, 2))
        if key not in reached:
            progress(i / max(len(clear), 1), f"reach of placement {i + 1} of {len(clear)}")
            reached[key] = [reach(robot, checker, a, target, np.random.default_rng([len(reached), j]), p.seeds, p.tolerance).reachable
                            for j, a in enumerate(arms)]
        flags.append(reached[key])
    flags_arr = np.array(flags, bool).reshape(-1, len(arms))
    log.done("reached by an arm", int(flags_arr.any(axis=1).sum()), f"{len(reached)} positions tried, {p.seeds} IK starts per arm")
    log.done("reached by both arms", int(flags_arr.all(axis=1).sum()), "where one hand can set it down for the other")
    ends = (scene.object_initial, scene.object_final)
    way = [_way(T, ends, com, p.turn) for _, T, _ in clear]
    order = sorted(range(len(clear)), key=lambda i: (-int(flags_arr[i].all()), *way[i], -clear[i][2], i))
    return Placements(arms, [clear[i][0] for i in order], log.stages,
                      np.array([clear[i][1] for i in order]).reshape(-1, 4, 4), np.array([clear[i][2] for i in order]),
                      flags_arr[order].reshape(-1, len(arms))), log.seconds



def _way(T: np.ndarray, ends: tuple[np.ndarray, np.ndarray], com: np.ndarray, turn: float) -> tuple[float, float]:
    """(how far the object goes from the first end through T to the second: metres travelled plus `turn` per radian
    turned; how much farther it is from one end than from the other), in whole centimetres: positions of a grid row
    along the way tie on the first, and the second puts the middle one first."""
    d = [float(np.linalg.norm(T[:3, :3] @ com + T[:3, 3] - (E[:3, :3] @ com + E[:3, 3]))) for E in ends]
    turned = sum(rotation_angle(T, E) for E in ends)
    return round(sum(d) + turn * turned, 2), round(abs(d[0] - d[1]), 2)


def run(ctx: StepContext) -> StepOutput:
    placements, seconds = stable_placements(ctx.scene, ctx.params, ctx.progress)
    return StepOutput(placements, tuple(seconds))


NAME = "placements"
STEP = Step(NAME, "stable placements of the object on the supports, and which arm reaches each (issue 36)", (), PlacementParams,
            Placements, run)
