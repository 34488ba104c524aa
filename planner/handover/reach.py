"""Reachability: can an arm (with the torso) bring its hand's fingertip centre to a point, collision-free?

The fingertip centre is the mean of the fingertips at the hand's open configuration, in the palm
frame: where an object sits when the hand closes on it. Position-only damped least squares from
several seeds; a solution counts only if it respects joint limits and the arm and the palm collide
with nothing (the manipulated object itself is not in the collision model). The fingers are left
out: open, they reach past the fingertip centre into the support of a low object, and they close on
the object anyway; each grasp's fingers are checked with its configuration (grasp_configs.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from planner.collision.checker import CollisionChecker
from planner.core.steps import Progress, no_progress
from planner.model.robot import Robot
from planner.model.task import Scene

REACH_SEED = 0  # reachability is a property of the task: `check` and the arms step draw the same starts


@dataclass(frozen=True)
class ReachResult:
    """Whether an arm brings its fingertip centre to a target, how close it came, and the configuration that did."""

    arm: str
    reachable: bool
    distance: float  # m: the fingertip centre to the target, at q
    q: np.ndarray  # when reachable a collision-free configuration achieving it, else the closest one found
    closest_collides: bool = False  # not reachable although a start came within tolerance: every such one collides

    def describe(self, tolerance: float) -> str:
        """'yes (0.3 cm)', 'no: 12.5 cm short' or 'no: collides (0.1 cm)', for reports."""
        cm = f"{self.distance * 100:.1f} cm"
        if self.reachable:
            return f"yes ({cm})"
        if self.closest_collides:
            return f"no: collides ({cm})"
        return f"no: {cm} short" if self.distance > tolerance else f"no ({cm})"


def fingertip_centre(robot: Robot, arm: str) -> np.ndarray:
    """The mean of the open hand's fingertips (rest configuration) in its palm frame: what reach aims at the object.

    Not the grasp list's `grasps.grasp_centre`, the point of the fingers' workspaces that grasp frames are centred on."""
    hand = robot.spec.arm(arm).hand
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_rest)
    palm = data.oMf[robot.frame_id(robot.palm_frame(arm))]
    tips = [data.oMf[robot.frame_id(hand.prefixed(f.tip_frame))].translation for f in hand.fingers]
    return palm.actInv(np.mean(tips, axis=0))


def approach_direction(robot: Robot, arm: str) -> np.ndarray:
    """The unit direction, in the palm frame, from the palm towards the fingertip centre: where the hand approaches from."""
    c = fingertip_centre(robot, arm)
    return c / np.linalg.norm(c)


def solve_position(robot: Robot, arm: str, target: np.ndarray, q0: np.ndarray, offset: np.ndarray,
                   iterations: int = 150, tol: float = 1e-3) -> np.ndarray:
    """Damped least squares on torso + arm joints moving the point `offset` of the palm frame to `target` from q0."""
    model, fid = robot.model, robot.frame_id(robot.palm_frame(arm))
    idx = np.concatenate([robot.torso_idx, robot.arm_idx[arm]])
    lower, upper = robot.lower[idx], robot.upper[idx]
    data = model.createData()
    damping = 1e-3 * np.eye(3)
    q = q0.copy()
    for _ in range(iterations):  # the operations of np.cross and np.clip written out (most of an iteration was their overhead)
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacement(model, data, fid)
        M = data.oMf[fid]
        err = target - M.act(offset)
        if np.linalg.norm(err) < tol:
            break
        J6 = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)[:, idx]
        p, w = M.rotation @ offset, J6[3:]
        J = J6[:3] - np.stack([p[1] * w[2] - p[2] * w[1], p[2] * w[0] - p[0] * w[2], p[0] * w[1] - p[1] * w[0]], axis=1).T  # p x w
        dq = J.T @ np.linalg.solve(J @ J.T + damping, err)
        q[idx] = np.minimum(np.maximum(q[idx] + np.minimum(np.maximum(dq, -0.3), 0.3), lower), upper)
    return q


def reach(robot: Robot, checker: CollisionChecker, arm: str, target: np.ndarray, rng: np.random.Generator,
          seeds: int = 32, tolerance: float = 0.02) -> ReachResult:
    """Try `seeds` starts (rest first, then random torso+arm); reachable if one ends within tolerance, collision-free."""
    idx = np.concatenate([robot.torso_idx, robot.arm_idx[arm]])
    offset = fingertip_centre(robot, arm)
    data = robot.model.createData()
    best, closest, collided = np.inf, robot.q_rest, False
    for s in range(seeds):
        q0 = robot.q_rest.copy()
        if s:
            q0[idx] = rng.uniform(robot.lower[idx], robot.upper[idx])
        q = solve_position(robot, arm, target, q0, offset)
        centre = pin.SE3(robot.frame_placement(q, robot.palm_frame(arm), data)).act(offset)
        d = float(np.linalg.norm(centre - target))
        if d < best:
            best, closest = d, q
        if d <= tolerance:
            if not checker.in_collision(q, f"{arm}_no_fingers"):
                return ReachResult(arm, True, d, q)
            collided = True
    return ReachResult(arm, False, best, closest, collided)


def placement_reach(scene: Scene, checker: CollisionChecker, seeds: int = 32, tolerance: float = 0.02,
                    progress: Progress = no_progress) -> dict[str, dict[str, ReachResult]]:
    """placement ('initial', 'final') -> arm -> whether it reaches the object's centre of mass there (fixed starts)."""
    robot = scene.robot
    com = np.asarray(scene.object_mesh.center_mass)
    arms = robot.spec.arm_names
    out: dict[str, dict[str, ReachResult]] = {}
    for i, (name, T) in enumerate((("initial", scene.object_initial), ("final", scene.object_final))):
        target = T[:3, :3] @ com + T[:3, 3]
        out[name] = {}
        for j, arm in enumerate(arms):
            progress((i * len(arms) + j) / (2 * len(arms)), f"{arm} arm to the {name} placement")
            out[name][arm] = reach(robot, checker, arm, target, np.random.default_rng([REACH_SEED, i, j]), seeds, tolerance)
    return out
