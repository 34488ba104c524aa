"""The motion step end to end, re-checked independently: on the default task (the example session's earlier steps), a
handover; and on the issue's one-arm case (the statuette 7 cm nearer the robot: the left arm reaches both placements), a
direct transfer.

The oracle shares no code with the planner's checker: the URDFs' own collision geometry (full link
meshes, not hulls; the fingers' boxes and spheres) through python-fcl, posed by forward kinematics.
Every trajectory sample and nine more configurations between consecutive samples (on the chord between
them: the trajectory's parabolic pieces leave it by at most a dt^2 / 8, 0.3 mrad at 30 Hz and 2 rad/s^2) are
checked: robot against the obstacles; robot against the object at the pose the result gives (the
holding hand, and the hand working at the object during its contact motions, touch it by design: no
deeper than the motion allows them, their fingertips a little more while the fingers close or open);
the object while carried against the obstacles (its support excepted while it is lifted or set down);
and links of different parts (each arm with its hand, the torso) against each other, except pairs the
oracle itself finds touching at rest or joined by a joint.
"""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from generated_objects import TASK_TEXT_ROBOT
from oracle import Oracle, grasp_offset, motion_collisions
from test_motion_workers import sampled_runs, transit_runs

from planner.core.forked import cpu_budget
from planner.core.runner import run_pipeline
from planner.core.session import Session
from planner.model.task import load_task
from planner.motion.smoothing import _Run

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


@pytest.fixture(scope="module")
def direct(tmp_path_factory):
    """The whole pipeline on the one-arm task, with the session tests' seed (grasp lists from the test cache) and the
    desk's roadmap without the task's sites (those of another task cost a build of their own; test_task_roadmap.py
    tests them)."""
    folder = tmp_path_factory.mktemp("direct")
    task = folder / "near.toml"
    task.write_text(TASK_TEXT_ROBOT.replace("initial = { xyz = [0.45, -0.85, 0.72]", "initial = { xyz = [0.45, -0.78, 0.72]"))
    session = Session.create(folder / "session", load_task(task), 3)
    run_pipeline(session, params={"roadmap": {"task_nodes": 0}})
    return session, session.result("motion")


@pytest.fixture(params=["handover", "direct"])
def either(request):
    """The default task's motion (a handover), then the one-arm task's (a direct transfer)."""
    return request.getfixturevalue("planned" if request.param == "handover" else "direct")


def test_the_default_task_hands_over_in_the_air(planned):
    """Where a double grasp works, the handover (tried first) moves: the motion is the paper's, no configuration at an
    intermediate placement was made, and the motion says why the other strategies were not taken."""
    _, m = planned
    assert m.strategy == "handover" and not m.intermediate
    rejected = {a["strategy"]: a["failure"] for a in m.alternatives}
    assert set(rejected) == {"table", "regrasp"} and rejected["table"].startswith("not tried: the handover moved"), rejected
    graph = next(s for s in m.stages if s["stage"] == "regrasp graph")
    assert graph["count"] == 0 and graph["note"] == "not searched: the handover moved", graph
    assert tuple(m.phase_names) == ("Grasp", "Carry", "Place", "Rest")


def test_one_arm_carries_the_object_itself(direct):
    session, m = direct
    arms, dg = session.result("arms"), session.result("double_grasps")
    assert (arms.picking_arm, arms.placing_arm, arms.handover) == ("left", "left", False)
    assert "no handover is needed" in arms.choice and not session.result("exchange").best.size
    k = m.double_grasp
    assert dg.pick_rank[k] == dg.place_rank[k] and np.array_equal(dg.q_exch[k], dg.q_place[k])
    assert set(m.holder[m.holder >= 0]) == {m.arms.index("left")}, "another hand held the object"


@pytest.mark.slow
def test_a_direct_transfer_smooths_its_runs_in_the_transit_workers(direct, tmp_path, monkeypatch):
    """A direct transfer's transit jobs (Carry, Rest, Grasp) each smooth, in their worker, the run their transit
    completes: none is left to smooth after the transits (its layout of the jobs is right)."""
    sampled = sampled_runs(monkeypatch)
    session, m = direct
    again = session.branch(tmp_path / "again", "motion")
    run_pipeline(again)
    (pieces, made), = sampled
    transits = transit_runs(pieces)
    assert len(transits) == 3 and set(transits) == set(made)
    assert np.array_equal(again.result("motion").q, m.q)  # the same motion as the session's


def test_trajectory_passes_the_task_configurations(either):
    session, m = either
    scene, dg = session.scene, session.result("double_grasps")
    assert not m.failure and m.double_grasp >= 0
    k = m.double_grasp
    assert np.array_equal(m.q[0], scene.q_initial) and np.array_equal(m.q[-1], scene.q_final)
    model = scene.robot.model
    assert list(m.joint_names) == [model.names[j] for j in range(1, model.njoints)]  # q's columns, named as the model has them
    for key, q in zip(m.keyframes[1:4], (dg.q_grasp[k], dg.q_exch[k], dg.q_place[k])):
        arms = np.concatenate([scene.robot.torso_idx] + [scene.robot.arm_idx[a] for a in m.arms])
        assert np.abs(m.q[key][arms] - q[arms]).max() < 0.05  # within the IK refinement that makes hand-overs exact
    direct = m.keyframes[2] == m.keyframes[3]  # no exchange: Carry takes the object to above its placement
    assert list(m.phase[m.keyframes]) == ([0, 0, 2, 2, 3] if direct else [0, 0, 1, 2, 3])
    assert np.all(np.diff(m.phase) >= 0) and set(np.unique(m.phase)) == {0, 1, 2, 3}


def test_object_pose_is_continuous_and_ends_at_the_placements(either):
    session, m = either
    scene = session.scene
    assert np.allclose(m.object_pose[0], scene.object_initial, atol=1e-9)
    assert np.allclose(m.object_pose[-1], scene.object_final, atol=1e-9)
    # between two samples the object moves no more than the arms and torso move it: it turns by at most the sum of their
    # joints' turns, and no point of it is a metre from their axes (so a change of hands or of grasp that jumps shows,
    # while the arms stand still, beyond the 0.1 mm the grasps are refined to)
    robot = scene.robot
    moved = np.abs(np.diff(m.q[:, np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in m.arms])], axis=0)).sum(axis=1)
    step = np.linalg.norm(np.diff(m.object_pose[:, :3, 3], axis=0), axis=1)
    assert np.all(step <= 1.0 * moved + 5e-4), f"the object jumps {np.max(step - moved):.4f} m more than the arms move it"
    turn = np.array([np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1))
                     for a, b in zip(m.object_pose[:-1], m.object_pose[1:])])
    assert np.all(turn <= moved + 1e-3), "the object turns more than the arms turn it"
    # it is carried: it leaves the initial pose only in a hand, and is static exactly where nobody holds it
    static = m.holder < 0
    before = static & (np.arange(len(m.t)) < m.keyframes[1])
    assert np.allclose(m.object_pose[before], scene.object_initial)
    assert np.allclose(m.object_pose[static & (np.arange(len(m.t)) > m.keyframes[3])], scene.object_final, atol=1e-4)


def test_velocity_limits_hold(either):
    session, m = either
    robot = session.scene.robot
    p = session.record_of("motion")["params"]
    vmax = np.minimum(np.asarray(robot.model.velocityLimit), p["max_velocity"])
    v = np.abs(np.diff(m.q, axis=0)) / np.diff(m.t)[:, None]
    assert np.all(v <= vmax * (1 + 1e-6))
    assert np.allclose(np.diff(m.t), 1.0 / p["rate"])


def test_accelerations_hold_and_the_robot_rests_where_a_hand_closes_or_lets_go(either):
    """Second differences of the samples stay within max_acceleration (+10 % for sampling); the arms and torso stand
    still while a hand closes on the object or lets go of it, and at the keyframes (grasped, exchanged, placed)."""
    session, m = either
    robot = session.scene.robot
    p = session.record_of("motion")["params"]
    dt = 1.0 / p["rate"]
    acc = np.abs(np.diff(m.q, 2, axis=0)) / dt**2
    assert acc.max() <= 1.1 * p["max_acceleration"], f"{acc.max():.2f} rad/s^2"
    arms = np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in m.arms])
    fingers = np.concatenate([robot.hand_idx[a] for a in m.arms])
    for key in m.keyframes[1:4]:  # a hand has just closed on the object (grasped, exchanged) or set it down (placed)
        assert np.abs(m.q[key + 1, arms] - m.q[key, arms]).max() <= 0.5 * p["max_acceleration"] * dt**2 * 1.01  # from rest
        k = key
        while k > 0 and np.any(m.q[k, fingers] != m.q[k - 1, fingers]):  # the fingers closing before it
            assert np.array_equal(m.q[k, arms], m.q[k - 1, arms]), "the arms move while a hand closes on the object"
            k -= 1
        assert k < key or m.keyframes[3] == key  # a hand closed (the placement: the object set down, then let go)


def test_the_default_task_moves_in_at_most_25_seconds(planned):
    """The issue's bound on the example's motion, with today's limits (1 rad/s, 2 rad/s^2): 49 s before smoothing."""
    session, m = planned
    p = session.record_of("motion")["params"]
    assert (p["max_velocity"], p["max_acceleration"]) == (1.0, 2.0)
    assert m.duration <= 25.0


def test_every_configuration_is_collision_free_by_an_independent_oracle(either):
    session, m = either
    bad = motion_collisions(session, m)
    assert not bad, f"{len(bad)} colliding configurations, first: {bad[:3]}"


def test_every_hand_holds_the_object_at_a_listed_grasp(either):
    """To 0.2 mm: the grasp configurations hold their grasps to 2 mm, so the motion refines them (a thumb 1.7 mm into a
    cube before it did)."""
    session, m = either
    assert grasp_offset(session, m) < 2e-4


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


RATE = 60.0  # collision checks per second a run could save: a budget the example's runs reach


def unsmoothed_duration(folder: Path) -> float:
    """The example's motion planned again without shortcuts (both smoothing rates 0), in `folder`: its duration is at
    least the sum of its runs' times rest to rest, each of which bounds what that run could save."""
    bare = Session.open(EXAMPLE).branch(folder, "motion")
    with cpu_budget(1):
        run_pipeline(bare, params={"motion": {"smooth_checks_per_s": 0.0, "smooth_attempts_per_s": 0.0}})
    return bare.result("motion").duration


def test_the_smoothing_makes_no_more_checks_than_its_budget(tmp_path, monkeypatch):
    """A ramp whose curve could need more checks than its run has left is not checked: each run's smoothing checks stay
    within `smooth_checks_per_s` times what it could save, so the motion's stay within that rate times its duration
    timed rest to rest, even when the rate is small (the passes test the budget before each attempt, the curve's count
    bounds the attempt). The checks held back for the kept shortcuts are made early once too little is left (as here,
    in the runs smoothed in this process), and the motion still passes the independent oracle."""
    early = []
    settle = _Run.settle

    def counted(self):
        early.append(sys._getframe(1).f_code.co_name == "_try")
        return settle(self)

    monkeypatch.setattr(_Run, "settle", counted)
    shutil.copytree(EXAMPLE, tmp_path / "example")
    session = Session.open(tmp_path / "example").branch(tmp_path / "small", "motion")
    with cpu_budget(1):
        run_pipeline(session, params={"motion": {"smooth_checks_per_s": RATE}})
    motion = session.result("motion")
    spent = sum(phase["smoothing_checks"] for phase in motion.phases)
    assert 0 < spent <= RATE * unsmoothed_duration(tmp_path / "bare")
    assert any(early), "no run made its kept shortcuts' checks early"
    bad = motion_collisions(session, motion)
    assert not bad, f"{len(bad)} colliding configurations, first: {bad[:3]}"
