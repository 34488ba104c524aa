"""Finger motions: letting go opens a finger less where its opening would hit an obstacle; a closing or opening moves
joint by joint, from the tip and from the base, where the straight motion is not valid."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from oracle import Oracle
from test_lazy_transit import example_inputs, phase_planner

from planner.motion.result import MotionParams

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    return example_inputs(tmp_path_factory)


def test_a_finger_whose_opening_would_hit_an_obstacle_opens_less(example):
    """Letting go at the example's placement with a small block put where one touching finger's tip goes when it opens
    by the release fraction: that finger opens less (or stays), the others open fully, and the opening motion found is
    free of the block by the independent check (the robot's URDF geometry through python-fcl, 50 samples)."""
    import dataclasses

    from planner.collision.situation import Situation, fingertip_geometries
    from planner.core.session import Session
    from planner.model.environment import Obstacle
    from planner.motion.strategies import hand_grasp

    scene, roadmap, _ = example
    session = Session.open(EXAMPLE)
    dg, place = session.result("double_grasps"), session.result("place_grasps")
    b = hand_grasp(place, int(dg.place_rank[0]))
    robot, p = scene.robot, MotionParams()
    finger = b.touching[0]
    idx = robot.finger_idx[b.arm][finger]

    def tip(q):
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, q)
        frame = robot.spec.arm(b.arm).hand.prefixed(next(f.tip_frame for f in robot.spec.arm(b.arm).hand.fingers if f.name == finger))
        return data.oMf[robot.frame_id(frame)].translation.copy()

    q = dg.q_place[0]
    opened = phase_planner(scene, roadmap).hand.opened(b, p.release, True)
    reached = q.copy()
    reached[robot.hand_idx[b.arm]] = opened
    block = np.eye(4)
    block[:3, 3] = tip(reached)
    blocked = dataclasses.replace(scene, environment=scene.environment + (Obstacle("block", "box", (0.015, 0.015, 0.015), block),))
    planner = phase_planner(blocked, roadmap)
    situation = Situation(None, scene.object_final, fingertip_geometries(planner.validities.cm, b.arm, b.touching))
    values = planner.contact.letting_go(b, q, situation)
    hand = robot.hand_idx[b.arm]
    at = np.isin(hand, idx)
    assert not np.allclose(values[at], opened[at]), "the blocked finger opened into the block"
    assert np.allclose(values[~at], opened[~at]), "the other fingers did not open by the release fraction"
    oracle = Oracle(blocked)
    end = q.copy()
    end[hand] = values
    for s in np.linspace(0.0, 1.0, 50):
        hits = [h for h in oracle.collisions(q + s * (end - q), scene.object_final, None, b.arm, False) if "block" in h]
        assert not hits, f"the opening finger hits the block at s={s:.2f}: {hits}"


def test_finger_motions_move_joint_by_joint_from_the_tip_and_from_the_base(example):
    """The ways a hand's fingers close: all joints at once first; among the others, one moving every finger's joints one
    depth at a time from the tip to the base and one from the base to the tip (a finger curling onto a rounded surface
    hooks its tip first); every way starts at q and ends at the target, and no two are the same."""
    from planner.motion.validities import Checked

    scene, roadmap, _ = example
    robot = scene.robot
    planner = phase_planner(scene, roadmap)
    arm = robot.spec.arm_names[0]
    hand, fingers = robot.hand_idx[arm], list(robot.finger_idx[arm].values())
    q = robot.q_rest.copy()
    target = robot.lower[hand] + 0.5 * (robot.upper[hand] - robot.lower[hand])
    paths = planner.hand.motions(q, arm, target)
    assert len(paths[0]) == 2, "the first way is not all joints at once"
    for path in paths:
        assert np.allclose(path[0], q) and np.allclose(path[-1, hand], target)
        assert np.allclose(np.delete(path, hand, axis=1), np.delete(q, hand)), "a joint outside the hand moved"
    assert len({path.round(9).tobytes() for path in paths}) == len(paths), "the same way offered twice"
    depth = max(len(idx) for idx in fingers)

    def moved_depths(path):
        """Per step of a path, the depths (0: a finger's last joint) of the hand joints it moves."""
        out = []
        for a, b in zip(path[:-1], path[1:]):
            out.append({len(idx) - 1 - k for idx in fingers for k, j in enumerate(idx) if not np.isclose(a[j], b[j])})
        return out

    orders = [moved_depths(path) for path in paths]
    assert [{d} for d in range(depth)] in orders, "no way closes one joint depth at a time from the tip"
    assert [{d} for d in reversed(range(depth))] in orders, "no way closes one joint depth at a time from the base"
    assert planner.hand.motions(q, arm, q[hand]) == [], "fingers already there moved"

    # a hand where one finger must close from the tip to the base while another must close all at once: no hand-wide
    # order fits both, the fingers one after the other do
    names = list(robot.finger_idx[arm])
    hook, whole = robot.finger_idx[arm][names[0]], robot.finger_idx[arm][names[1]]

    class Rule:
        """Valid: `hook` moves one joint at a time, tip before base; `whole` moves all its joints at once (a path that
        breaks the rule fails at its first configuration)."""

        def path_hit(self, path):
            return None if self.follows(path) else path[0]

        def follows(self, path):
            steps = list(zip(path[:-1], path[1:]))
            if any(np.sum(~np.isclose(a[hook], b[hook])) > 1 for a, b in steps):
                return False
            if sum(not np.allclose(a[whole], b[whole]) for a, b in steps) > 1:
                return False
            order = [min(k for k in range(len(path) - 1) if not np.isclose(path[k, j], path[k + 1, j])) for j in hook
                     if not np.isclose(path[0, j], path[-1, j])]
            return order == sorted(order, reverse=True)

    found = planner.hand.path(q, arm, target, Checked(Rule()))
    assert found is not None and Rule().follows(found), "no valid way found finger by finger"
    assert np.allclose(found[0], q) and np.allclose(found[-1, hand], target)
