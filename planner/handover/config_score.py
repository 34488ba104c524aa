"""The robot configuration score of a grasp (paper V-C): how natural the robot looks holding it.

Grasping arm: the cosine between the grasp's approach direction (palm origin towards the grasp
centre) and the direction from the robot's base to the object: grasps coming from the far side
score badly. Free arm: its joint distance to a reference configuration (the robot's rest, or where
the task holds the robot: see grasp_configs.py), its wrist's (the hand's mount frame's) height
difference to the reference and its wrist's distance to the plane through the torso and both shoulders, each divided by
a scale and mapped through exp(-sum) into (0, 1]. The score is arm_weight * (1 + cos) / 2 +
free_weight * free score.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from planner.handover.reach import approach_direction
from planner.model.robot import Robot, joint_at


@dataclass(frozen=True)
class ScoreWeights:
    arm_weight: float = 1.0
    free_weight: float = 1.0
    joint_scale: float = 0.5  # rad of free-arm joint distance to the reference worth one unit of penalty
    length_scale: float = 0.1  # m of wrist height change or distance to the torso plane worth one unit


@dataclass(frozen=True)
class ConfigScore:
    arm: float  # cosine in [-1, 1]
    free: float  # in (0, 1]
    total: float


class ConfigScorer:
    """Scores configurations of one robot against a reference configuration (its rest when None); holds its own
    pinocchio Data (one per thread)."""

    def __init__(self, robot: Robot, weights: ScoreWeights = ScoreWeights(), reference: np.ndarray | None = None):
        self.robot, self.w = robot, weights
        self.reference = robot.q_rest if reference is None else np.asarray(reference, dtype=float)
        self.data = robot.model.createData()
        model = robot.model
        self.palm = {a: robot.frame_id(robot.palm_frame(a)) for a in robot.spec.arm_names}
        self.approach = {a: approach_direction(robot, a) for a in robot.spec.arm_names}
        self.shoulder = {a: joint_at(model, int(idx[0])) for a, idx in robot.arm_idx.items()}
        self.wrist = {a: robot.frame_id(robot.wrist_frame(a)) for a in robot.spec.arm_names}
        self.torso = joint_at(model, int(robot.torso_idx[0])) if len(robot.torso_idx) else 0
        pin.forwardKinematics(model, self.data, self.reference)
        self.base = self.data.oMi[self.torso].translation.copy()
        self.reference_wrist_z = {a: float(pin.updateFramePlacement(model, self.data, f).translation[2]) for a, f in self.wrist.items()}

    def score(self, q: np.ndarray, arm: str, object_position: np.ndarray) -> ConfigScore:
        """The score of q with `arm` grasping an object whose centre of mass is at `object_position`."""
        robot, data, w = self.robot, self.data, self.w
        pin.forwardKinematics(robot.model, data, q)
        palm = pin.updateFramePlacement(robot.model, data, self.palm[arm])
        to_object = object_position - self.base
        cos = float(palm.rotation @ self.approach[arm] @ to_object / np.linalg.norm(to_object))
        free = [a for a in robot.spec.arm_names if a != arm]
        free_score = float(np.mean([self._free(q, a) for a in free])) if free else 1.0
        return ConfigScore(cos, free_score, w.arm_weight * (1.0 + cos) / 2.0 + w.free_weight * free_score)

    def _free(self, q: np.ndarray, arm: str) -> float:
        """exp(-penalty) of a free arm at q (forward kinematics already done)."""
        robot, data, w = self.robot, self.data, self.w
        idx = robot.arm_idx[arm]
        joints = float(np.linalg.norm(q[idx] - self.reference[idx]))
        wrist = pin.updateFramePlacement(robot.model, data, self.wrist[arm]).translation
        height = abs(float(wrist[2]) - self.reference_wrist_z[arm])
        shoulders = [data.oMi[j].translation for j in self.shoulder.values()]
        torso = data.oMi[self.torso].translation
        normal = np.cross(shoulders[0] - torso, shoulders[-1] - torso)
        plane = abs(float((wrist - torso) @ normal / np.linalg.norm(normal))) if np.linalg.norm(normal) > 1e-9 else 0.0
        return float(np.exp(-(joints / w.joint_scale + (height + plane) / w.length_scale)))
