"""The motion step end to end on the default task (the example session's earlier steps), re-checked independently.

The oracle shares no code with the planner's checker: the URDFs' own collision geometry (full link
meshes, not hulls; the fingers' boxes and spheres) through python-fcl, posed by forward kinematics.
Every trajectory sample and nine more configurations between consecutive samples (the samples of
one straight segment are collinear, corners are samples, so these lie on the planned path) are
checked: robot against the obstacles; robot against the object at the pose the result gives (the
holding hand, and the hand working at the object during its contact motions, excepted: they touch it
by design); the object while carried against the obstacles (its support excepted while it is lifted
or set down); and links of different parts (each arm with its hand, the torso) against each other,
except pairs the oracle itself finds touching at rest or joined by a joint.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from oracle import Oracle

from planner.runner import run_pipeline
from planner.session import Session

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"
pytestmark = pytest.mark.slow


def _planned(folder: Path) -> Session:
    shutil.copytree(EXAMPLE, folder)
    session = Session.open(folder)
    if "motion" in session.finished():
        session = session.branch(folder.parent / (folder.name + "-branch"), "motion")
    run_pipeline(session)
    return session


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    session = _planned(tmp_path_factory.mktemp("motion") / "a")
    return session, session.result("motion")


def _object_between(session, motion, k: int, q: np.ndarray) -> np.ndarray:
    """The object's pose at q on the way to sample k (which holds for the whole interval before it): carried rigidly by
    the holder's palm, else where sample k has it."""
    h = int(motion.holder[k])
    if h < 0:
        return motion.object_pose[k]
    robot = session.scene.robot
    frame = robot.palm_frame(motion.arms[h])
    grasp = np.linalg.inv(robot.frame_placement(motion.q[k], frame)) @ motion.object_pose[k]
    return robot.frame_placement(q, frame) @ grasp


def test_trajectory_passes_the_task_configurations(planned):
    session, m = planned
    scene, dg = session.scene, session.result("double_grasps")
    assert not m.failure and m.double_grasp >= 0
    k = m.double_grasp
    assert np.array_equal(m.q[0], scene.q_initial) and np.array_equal(m.q[-1], scene.q_final)
    for key, q in zip(m.keyframes[1:4], (dg.q_grasp[k], dg.q_exch[k], dg.q_place[k])):
        arms = np.concatenate([scene.robot.torso_idx] + [scene.robot.arm_idx[a] for a in m.arms])
        assert np.abs(m.q[key][arms] - q[arms]).max() < 0.05  # within the IK refinement that makes hand-overs exact
    assert list(m.phase[m.keyframes]) == [0, 0, 1, 2, 3]
    assert np.all(np.diff(m.phase) >= 0) and set(np.unique(m.phase)) == {0, 1, 2, 3}


def test_object_pose_is_continuous_and_ends_at_the_placements(planned):
    session, m = planned
    scene = session.scene
    assert np.allclose(m.object_pose[0], scene.object_initial, atol=1e-9)
    assert np.allclose(m.object_pose[-1], scene.object_final, atol=1e-9)
    step = np.linalg.norm(np.diff(m.object_pose[:, :3, 3], axis=0), axis=1)
    assert step.max() < 0.05, f"the object jumps {step.max():.3f} m between two samples"
    turn = [np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1)) for a, b in zip(m.object_pose[:-1], m.object_pose[1:])]
    assert max(turn) < 0.1
    # it is carried: it leaves the initial pose only in a hand, and is static exactly where nobody holds it
    static = m.holder < 0
    before = static & (np.arange(len(m.t)) < m.keyframes[1])
    assert np.allclose(m.object_pose[before], scene.object_initial)
    assert np.allclose(m.object_pose[static & (np.arange(len(m.t)) > m.keyframes[3])], scene.object_final, atol=1e-4)


def test_velocity_limits_hold(planned):
    session, m = planned
    robot = session.scene.robot
    p = session.record_of("motion")["params"]
    vmax = np.minimum(np.asarray(robot.model.velocityLimit), p["max_velocity"])
    v = np.abs(np.diff(m.q, axis=0)) / np.diff(m.t)[:, None]
    assert np.all(v <= vmax * (1 + 1e-6))
    assert np.allclose(np.diff(m.t), 1.0 / p["rate"])


def test_every_configuration_is_collision_free_by_an_independent_oracle(planned):
    session, m = planned
    oracle = Oracle(session.scene)
    arms = m.arms
    bad = []
    lifting = {int(i) for i in np.flatnonzero((m.holder >= 0) & (m.active == m.holder))}  # lift and set-down
    assert not oracle.collisions(m.q[0], m.object_pose[0], None, None, False)
    for k in range(1, len(m.t)):  # the interval before sample k belongs to sample k's motion
        holder = arms[m.holder[k]] if m.holder[k] >= 0 else None
        active = arms[m.active[k]] if m.active[k] >= 0 else None
        for s in np.linspace(0.1, 1.0, 10):
            q = m.q[k - 1] + s * (m.q[k] - m.q[k - 1])
            found = oracle.collisions(q, _object_between(session, m, k, q), holder, active, k in lifting)
            if found:
                bad.append((k, round(float(s), 1), found[:3]))
    assert not bad, f"{len(bad)} colliding configurations, first: {bad[:3]}"


def test_oracle_catches_a_collision(planned):
    """The oracle is not blind: the object pushed into the torso at a carried sample is found."""
    session, m = planned
    oracle = Oracle(session.scene)
    k = int(np.flatnonzero(m.holder >= 0)[0])
    pose = m.object_pose[k].copy()
    torso = session.scene.robot.frame_placement(m.q[k], session.scene.robot.model.frames[2].name)
    pose[:3, 3] = torso[:3, 3] - np.asarray(session.scene.object_mesh.center_mass)
    assert oracle.collisions(m.q[k], pose, None, None, False)


def test_same_seed_same_motion(planned, tmp_path):
    session, m = planned
    again = _planned(tmp_path / "b")
    for name in ("motion.npz", "motion.json"):
        assert (session.folder / name).read_bytes() == (again.folder / name).read_bytes()
