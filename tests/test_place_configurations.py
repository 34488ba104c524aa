"""Placing from another configuration of the arm: where the configuration the grasp search kept leaves the arm by an
obstacle, the place motions are made from another one holding the same grasp.

On the example session: a block is put where the placing arm's elbow is at the listed place configuration. The
motions cannot be made from it; they are made from another configuration whose palm is where the listed one's is
(pinocchio's forward kinematics, to 0.1 mm), and every configuration of them is clear of the block by the independent
check (the robot's URDF geometry through python-fcl).
"""
from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from oracle import Oracle
from test_motion_parts import _phase_planner

from planner.collision.situation import Situation
from planner.core.session import Session
from planner.model.environment import Obstacle
from planner.motion.phase import Phase
from planner.motion.piece import PieceFailed
from planner.motion.strategies import hand_grasp

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


@pytest.fixture(scope="module")
def placing(tmp_path_factory):
    folder = tmp_path_factory.mktemp("placing") / "example"
    shutil.copytree(EXAMPLE, folder)
    s = Session.open(folder)
    dg = s.result("double_grasps")
    return s.scene, s.result("roadmap"), hand_grasp(s.result("place_grasps"), int(dg.place_rank[0])), dg.q_place[0].copy()


def palm(scene, q: np.ndarray, arm: str) -> np.ndarray:
    model = scene.robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(scene.robot.palm_frame(arm))].homogeneous


def elbow(scene, q: np.ndarray, arm: str) -> np.ndarray:
    """The world position of the arm's fourth joint (the elbow of a 7-joint arm) at q."""
    model, robot = scene.robot.model, scene.robot
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    joint = next(j for j in range(1, model.njoints) if model.idx_qs[j] == int(robot.arm_idx[arm][3]))
    return data.oMi[joint].translation.copy()


def test_other_configurations_hold_the_palm_where_it_was(placing):
    scene, roadmap, b, q = placing
    planner = _phase_planner(scene, roadmap)
    robot = scene.robot
    others = list(planner.arms.others(q, b.arm, np.random.default_rng(1)))
    assert len(others) >= 2, "24 random starts found fewer than two other configurations"
    idx = np.concatenate([robot.torso_idx, robot.arm_idx[b.arm]])
    kept = np.setdiff1d(np.arange(robot.nq), idx)
    seen = [q[idx]]
    for other in others:
        assert np.abs(palm(scene, other, b.arm)[:3, 3] - palm(scene, q, b.arm)[:3, 3]).max() < 1e-4
        assert np.allclose(palm(scene, other, b.arm)[:3, :3], palm(scene, q, b.arm)[:3, :3], atol=1e-3)
        assert np.array_equal(other[kept], q[kept]), "a joint outside the torso and the placing arm moved"
        assert np.all(other >= robot.lower - 1e-9) and np.all(other <= robot.upper + 1e-9)
        assert all(np.abs(other[idx] - x).max() > 0.1 for x in seen), "two configurations are one"
        seen.append(other[idx])


def test_a_block_at_the_elbow_is_placed_around(placing):
    scene, roadmap, b, q = placing
    of = scene.object_final
    block = np.eye(4)
    block[:3, 3] = elbow(scene, q, b.arm)
    blocked = dataclasses.replace(scene, environment=scene.environment + (Obstacle("block", "box", (0.05, 0.05, 0.05), block),))
    g_b = np.linalg.inv(of) @ palm(scene, q, b.arm)

    def place(planner):
        def build(q_down: np.ndarray) -> tuple:
            _, first = planner.set_downs(Phase.PLACE, q_down, b.arm, g_b, of)
            _, released = planner.release(Phase.PLACE, q_down, b, of)
            return q_down, first, released
        return build

    listed = _phase_planner(blocked, roadmap)
    listed.arms.p = dataclasses.replace(listed.arms.p, place_starts=0)
    with pytest.raises(PieceFailed):  # the listed configuration alone: the block is in the elbow's way
        next(listed.placings(q, b.arm, place(listed)))
    planner = _phase_planner(blocked, roadmap)
    q_used, first, released = next(planner.placings(q, b.arm, place(planner)))
    assert np.abs(q_used - q).max() > 0.1, "placed from the listed configuration, which the block is in the way of"
    assert np.abs(palm(scene, q_used, b.arm)[:3, 3] - palm(scene, q, b.arm)[:3, 3]).max() < 1e-4
    oracle = Oracle(blocked)
    for piece in first[1] + released:
        for k in range(len(piece.path)):
            assert not [h for h in oracle.robot_collisions(piece.path[k]) if "block" in h], f"the {piece.part} meets the block"
    assert planner.contact.ready(released[-1].path[-1], Situation(None, of), Phase.PLACE, "retreat") >= 0.0
