"""The test oracle (tests/oracle.py) on the committed example session: the hands touching the object are let touch it
only as deep as the motion allows, and a hand pushed 5 mm further into the object is found."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from oracle import CONTACT_DEPTH, Oracle

from planner.core.session import Session

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"
DEEPER = 0.005  # m: how much further into the object a mutation pushes a fingertip


@pytest.fixture(scope="module")
def example():
    session = Session.open(EXAMPLE)
    return session, session.result("motion"), Oracle(session.scene)


def _held(example) -> tuple[int, str, int]:
    """A carried sample of the example motion whose fingers stand still, its holder and the holder's deepest fingertip
    geometry touching the object."""
    session, m, oracle = example
    fingers = np.concatenate([session.scene.robot.hand_idx[a] for a in m.arms])
    still = np.all(np.diff(m.q[:, fingers], axis=0) == 0, axis=1)
    k = int(np.flatnonzero((m.holder[1:] >= 0) & (m.active[1:] < 0) & still)[0]) + 1
    holder = m.arms[m.holder[k]]
    poses = oracle._posed(m.q[k])[0]
    depth = {g: oracle.depth_in_object(g, poses[g], m.object_pose[k]) for g in oracle.tips[holder]}
    tip = max(depth, key=depth.get)
    assert 0 < depth[tip] <= CONTACT_DEPTH, "the example's holding fingertip touches the object"
    return k, holder, tip


def test_the_example_motion_keeps_the_hands_out_of_the_object(example):
    """Every sample of the committed motion: touching hands no deeper than the motion allows, nothing else touching."""
    session, m, oracle = example
    robot = session.scene.robot
    lifting = (m.holder >= 0) & (m.active == m.holder)
    bad = []
    for k in range(len(m.t)):
        holder = m.arms[m.holder[k]] if m.holder[k] >= 0 else None
        active = m.arms[m.active[k]] if m.active[k] >= 0 else None
        fingers = robot.hand_idx[active] if active else []
        closing = k > 0 and bool(np.any(m.q[k - 1, fingers] != m.q[k, fingers]))
        if found := oracle.collisions(m.q[k], m.object_pose[k], holder, active, bool(lifting[k]), closing):
            bad.append((k, found[:3]))
    assert not bad, f"{len(bad)} colliding samples, first: {bad[:3]}"


def _closed_further(example, q0: np.ndarray, holder: str, tip: int) -> np.ndarray:
    """q0 with the distal joint of `tip`'s finger turned on (the way it closed) until the fingertip has moved DEEPER."""
    session, m, oracle = example
    robot = session.scene.robot
    q = q0.copy()
    joint = robot.model.joints[oracle.gm.geometryObjects[tip].parentJoint].idx_q
    hand = robot.spec.arm(holder).hand
    finger = next(f for f in hand.fingers if robot.model.frames[robot.frame_id(hand.prefixed(f.tip_frame))].parentJoint
                  == oracle.gm.geometryObjects[tip].parentJoint)
    closing = np.sign(q[joint] - finger.open[-1]) or 1.0
    start = oracle._posed(q)[0][tip][:3, 3]
    for turn in np.linspace(0.0, 0.5, 501):
        q[joint] = q0[joint] + closing * turn
        if np.linalg.norm(oracle._posed(q)[0][tip][:3, 3] - start) >= DEEPER:
            break
    return q


@pytest.mark.slow
def test_a_finger_closed_further_into_the_object_is_found(example):
    """A touching finger of the holding hand closed on (its distal joint turned the way it closed until the fingertip
    has moved 5 mm): the one whose fingertip then moves most against the surface's outward normal (a fingertip on the
    surface may roll along it instead)."""
    session, m, oracle = example
    k, holder, _ = _held(example)
    mesh, pose = session.scene.object_mesh, m.object_pose[k]
    poses = oracle._posed(m.q[k])[0]

    def inward(tip: int) -> float:
        start = np.linalg.solve(pose, poses[tip])[:3, 3]
        moved = np.linalg.solve(pose, oracle._posed(_closed_further(example, m.q[k], holder, tip))[0][tip])[:3, 3]
        normal = mesh.vertex_normals[int(np.argmin(np.linalg.norm(mesh.vertices - start, axis=1)))]
        return float(-(moved - start) @ normal)

    touching = [g for g in oracle.tips[holder] if oracle.depth_in_object(g, poses[g], pose) > -5e-4]
    tip = max(touching, key=inward)
    assert inward(tip) > DEEPER / 2, "no touching finger closes into the object"
    q = _closed_further(example, m.q[k], holder, tip)
    assert not oracle.collisions(m.q[k], pose, holder, None, False)
    found = oracle.collisions(q, pose, holder, None, False)
    assert any("into the object" in f for f in found), found


def test_a_hand_pushed_into_the_object_is_found(example):
    """The object moved 5 mm against the holding hand's deepest fingertip, along the surface's outward normal there."""
    session, m, oracle = example
    k, holder, tip = _held(example)
    mesh = session.scene.object_mesh
    pose = m.object_pose[k].copy()
    centre = np.linalg.solve(pose, oracle._posed(m.q[k])[0][tip])[:3, 3]
    nearest = int(np.argmin(np.linalg.norm(mesh.vertices - centre, axis=1)))
    pose[:3, 3] += pose[:3, :3] @ mesh.vertex_normals[nearest] * DEEPER
    found = oracle.collisions(m.q[k], pose, holder, None, False)
    assert any("into the object" in f for f in found), found
