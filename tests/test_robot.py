"""The composed robots: DoF, part index sets, rest pose, and forward kinematics checked against an
independent URDF reader (xml.etree + numpy 4x4 transforms, no pinocchio)."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from planner.core.paths import ASSETS, robot_data_file
from planner.model.robot import load_robot
from planner.model.robot_spec import load_robot_spec

# The same resolved paths a task file resolves to, so load_robot's cache is shared with the task tests.
ALEX = ASSETS / "robots" / "alex_allegro.toml"
BAXTER = ASSETS / "robots" / "baxter_allegro.toml"


@pytest.fixture(scope="module")
def alex():
    return load_robot(ALEX)


@pytest.fixture(scope="module")
def baxter():
    return load_robot(BAXTER)


# ---------------------------------------------------------------------------------------------
# An independent URDF forward kinematics: parse origins and axes, chain homogeneous transforms.


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


def rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF roll-pitch-yaw: fixed axes x, then y, then z, i.e. R = Rz(y) Ry(p) Rx(r)."""
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' formula."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def homogeneous(R: np.ndarray, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def floats(text: str | None, default: str) -> np.ndarray:
    return np.array([float(v) for v in (text or default).split()], dtype=float)


class Urdf:
    """The kinematic tree of a URDF: for every child link, the joint that carries it."""

    def __init__(self, path: Path):
        root = ET.parse(path).getroot()
        self.joints = {}
        for j in root.findall("joint"):
            origin = j.find("origin")
            xyz = floats(origin.get("xyz") if origin is not None else None, "0 0 0")
            rpy = floats(origin.get("rpy") if origin is not None else None, "0 0 0")
            axis = j.find("axis")
            limit = j.find("limit")
            self.joints[j.find("child").get("link")] = {
                "name": j.get("name"),
                "type": j.get("type"),
                "parent": j.find("parent").get("link"),
                "origin": homogeneous(rpy_matrix(*rpy), xyz),
                "axis": floats(axis.get("xyz") if axis is not None else None, "1 0 0"),
                "limits": (float(limit.get("lower")), float(limit.get("upper"))) if limit is not None else None,
            }

    def fk(self, link: str, q: dict[str, float]) -> np.ndarray:
        """Pose of `link` in the URDF's root link frame; joints missing from q are at 0."""
        T = np.eye(4)
        while link in self.joints:
            j = self.joints[link]
            value = q.get(j["name"], 0.0)
            if j["type"] in ("revolute", "continuous"):
                motion = homogeneous(axis_angle(j["axis"], value), np.zeros(3))
            elif j["type"] == "prismatic":
                motion = homogeneous(np.eye(3), j["axis"] / np.linalg.norm(j["axis"]) * value)
            else:
                assert j["type"] == "fixed", j["type"]
                motion = np.eye(4)
            T = j["origin"] @ motion @ T
            link = j["parent"]
        return T

    def movable(self) -> dict[str, tuple[float, float]]:
        return {j["name"]: j["limits"] for j in self.joints.values() if j["type"] in ("revolute", "prismatic")}


def expected_hand_frame(robot, q: np.ndarray, arm_name: str, frame: str) -> np.ndarray:
    """World pose of a hand frame: base * body FK(mount frame) * mount * hand FK(frame)."""
    spec = robot.spec
    arm = spec.arm(arm_name)
    values = dict(zip(robot.joint_names(), q.tolist()))
    body_q = {n: v for n, v in values.items()} | dict(spec.locked_joints)
    hand_q = {n[len(arm.hand.prefix):]: v for n, v in values.items() if n.startswith(arm.hand.prefix)}
    base = homogeneous(rpy_matrix(*spec.base_rpy), spec.base_xyz)
    mount = homogeneous(rpy_matrix(*arm.hand.mount_rpy), arm.hand.mount_xyz)
    return base @ Urdf(spec.body_urdf).fk(arm.hand.mount_frame, body_q) @ mount @ Urdf(arm.hand.urdf).fk(frame, hand_q)


def expected_body_frame(robot, q: np.ndarray, link: str) -> np.ndarray:
    spec = robot.spec
    values = dict(zip(robot.joint_names(), q.tolist())) | dict(spec.locked_joints)
    base = homogeneous(rpy_matrix(*spec.base_rpy), spec.base_xyz)
    return base @ Urdf(spec.body_urdf).fk(link, values)


def configurations(robot, n_random: int = 4, seed: int = 7) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [robot.q_rest] + [rng.uniform(robot.lower, robot.upper) for _ in range(n_random)]


def assert_same_pose(actual: np.ndarray, expected: np.ndarray, tol: float = 1e-9) -> None:
    np.testing.assert_allclose(actual[:3, 3], expected[:3, 3], rtol=0, atol=tol)
    np.testing.assert_allclose(actual[:3, :3], expected[:3, :3], rtol=0, atol=tol)
    np.testing.assert_allclose(actual[3], [0, 0, 0, 1], rtol=0, atol=0)


# ---------------------------------------------------------------------------------------------
# Degrees of freedom and parts.


@pytest.mark.parametrize("which, nq, n_torso", [("alex", 49, 3), ("baxter", 46, 0)])
def test_dof_and_part_index_sets(which, nq, n_torso, request):
    robot = request.getfixturevalue(which)
    assert robot.nq == nq == robot.model.nv
    assert len(robot.joint_names()) == nq
    assert len(robot.torso_idx) == n_torso
    assert set(robot.arm_idx) == set(robot.hand_idx) == set(robot.finger_idx) == {"right", "left"}
    for arm in ("right", "left"):
        assert len(robot.arm_idx[arm]) == 7
        assert len(robot.hand_idx[arm]) == 16
        assert set(robot.finger_idx[arm]) == {"index", "middle", "ring", "thumb"}
        assert all(len(idx) == 4 for idx in robot.finger_idx[arm].values())
        assert sorted(np.concatenate(list(robot.finger_idx[arm].values())).tolist()) == sorted(robot.hand_idx[arm].tolist())
    parts = [robot.torso_idx, *robot.arm_idx.values(), *robot.hand_idx.values()]
    everything = np.concatenate(parts).tolist()
    assert len(everything) == len(set(everything)), "part index sets overlap"
    assert sorted(everything) == list(range(nq))


@pytest.mark.parametrize("which", ["alex", "baxter"])
def test_part_names_and_part_idx(which, request):
    robot = request.getfixturevalue(which)
    names = robot.part_names()
    assert ("torso" in names) == (len(robot.torso_idx) > 0)
    for arm in ("right", "left"):
        assert {arm, f"{arm}_hand", f"{arm}_hand/thumb", f"{arm}_hand/index"} <= set(names)
        np.testing.assert_array_equal(robot.part_idx(arm), robot.arm_idx[arm])
        np.testing.assert_array_equal(robot.part_idx(f"{arm}_hand"), robot.hand_idx[arm])
        np.testing.assert_array_equal(robot.part_idx(f"{arm}_hand/ring"), robot.finger_idx[arm]["ring"])
    with pytest.raises(KeyError, match="unknown part"):
        robot.part_idx("tail")


@pytest.mark.parametrize("which", ["alex", "baxter"])
def test_part_indices_point_at_the_named_joints(which, request):
    robot = request.getfixturevalue(which)
    names = robot.joint_names()
    assert [names[i] for i in robot.torso_idx] == list(robot.spec.torso_joints)
    for arm in robot.spec.arms:
        assert [names[i] for i in robot.arm_idx[arm.name]] == list(arm.joints)
        for finger in arm.hand.fingers:
            assert [names[i] for i in robot.finger_idx[arm.name][finger.name]] == [arm.hand.prefix + j for j in finger.joints]


@pytest.mark.parametrize("which", ["alex", "baxter"])
def test_rest_pose_within_limits_and_as_specified(which, request):
    robot = request.getfixturevalue(which)
    q = robot.q_rest
    assert q.shape == (robot.nq,)
    assert np.all(np.isfinite(robot.lower)) and np.all(np.isfinite(robot.upper))
    assert np.all(robot.lower < robot.upper)
    assert np.all(q >= robot.lower) and np.all(q <= robot.upper)
    assert robot.within_limits(q)
    spec = robot.spec
    np.testing.assert_allclose(q[robot.torso_idx], spec.torso_rest)
    for arm in spec.arms:
        np.testing.assert_allclose(q[robot.arm_idx[arm.name]], arm.rest)
        for finger in arm.hand.fingers:
            np.testing.assert_allclose(q[robot.finger_idx[arm.name][finger.name]], finger.open)


@pytest.mark.parametrize("which", ["alex", "baxter"])
def test_limits_are_the_urdf_limits(which, request):
    robot = request.getfixturevalue(which)
    limits = dict(Urdf(robot.spec.body_urdf).movable())
    for arm in robot.spec.arms:
        limits |= {arm.hand.prefix + n: lim for n, lim in Urdf(arm.hand.urdf).movable().items()}
    for i, name in enumerate(robot.joint_names()):
        assert (robot.lower[i], robot.upper[i]) == pytest.approx(limits[name], abs=1e-12), name


@pytest.mark.parametrize("which", ["alex", "baxter"])
def test_two_hands_have_distinct_prefixed_names(which, request):
    robot = request.getfixturevalue(which)
    names = robot.joint_names()
    right = {names[i] for i in robot.hand_idx["right"]}
    left = {names[i] for i in robot.hand_idx["left"]}
    assert right.isdisjoint(left)
    assert all(n.startswith("right_hand/") for n in right)
    assert all(n.startswith("left_hand/") for n in left)
    assert {n.removeprefix("right_hand/") for n in right} == {n.removeprefix("left_hand/") for n in left}
    assert len(names) == len(set(names))
    robot.frame_id("right_hand/link_3.0_tip")
    robot.frame_id("left_hand/link_3.0_tip")


def test_alex_neck_is_locked(alex):
    names = alex.joint_names()
    assert "NeckYaw" not in names and "NeckPitch" not in names
    assert dict(alex.spec.locked_joints) == {"NeckYaw": 0.0, "NeckPitch": 0.0}
    assert names[:3] == ["SpineYaw", "SpineRoll", "SpinePitch"]


def test_unknown_frame_is_a_key_error(alex):
    with pytest.raises(KeyError, match="no frame 'Nowhere'"):
        alex.frame_placement(alex.q_rest, "Nowhere")


# ---------------------------------------------------------------------------------------------
# Forward kinematics against the independent URDF reader.


def test_independent_reader_reads_the_installed_urdfs():
    body = Urdf(robot_data_file("alex_description/urdf/alex_nub_hands.urdf"))
    chain, link = [], "RightGripperYawLink"
    while link in body.joints:
        chain.append(body.joints[link]["name"])
        link = body.joints[link]["parent"]
    assert link == "Pelvis"
    assert chain[::-1] == ["SpineYaw", "SpineRoll", "SpinePitch", "RightShoulderPitch", "RightShoulderRoll",
                           "RightShoulderYaw", "RightElbowPitch", "RightWristYaw", "RightWristRoll", "RightGripperYaw"]


@pytest.mark.parametrize("frame", ["RightGripperYawLink", "LeftGripperYawLink", "Torso", "RightElbowPitchLink"])
def test_alex_body_fk_matches_the_urdf(alex, frame):
    assert alex.spec.base_xyz == (0.0, 0.0, 0.75)  # a non-trivial base placement is part of the check
    for q in configurations(alex):
        assert_same_pose(alex.frame_placement(q, frame), expected_body_frame(alex, q, frame))


@pytest.mark.parametrize("arm, frame", [("right", "link_3.0_tip"), ("right", "link_15.0_tip"),
                                        ("left", "link_7.0_tip"), ("left", "palm_link")])
def test_alex_fingertip_fk_matches_the_urdf(alex, arm, frame):
    prefix = alex.spec.arm(arm).hand.prefix
    for q in configurations(alex):
        assert_same_pose(alex.frame_placement(q, prefix + frame), expected_hand_frame(alex, q, arm, frame))


@pytest.mark.parametrize("arm, frame", [("right", "link_3.0_tip"), ("left", "link_15.0_tip")])
def test_baxter_fingertip_fk_matches_the_urdf(baxter, arm, frame):
    assert baxter.spec.base_xyz == (-0.2, 0.0, 1.05)
    prefix = baxter.spec.arm(arm).hand.prefix
    for q in configurations(baxter, n_random=2):
        assert_same_pose(baxter.frame_placement(q, prefix + frame), expected_hand_frame(baxter, q, arm, frame))


def test_fk_moves_with_the_joints(alex):
    """Sanity of the comparison itself: a different configuration gives a different fingertip."""
    q1, q2 = configurations(alex, n_random=2)[1:]
    p1 = alex.frame_placement(q1, "right_hand/link_3.0_tip")[:3, 3]
    p2 = alex.frame_placement(q2, "right_hand/link_3.0_tip")[:3, 3]
    assert np.linalg.norm(p1 - p2) > 1e-3


def test_alex_right_wrist_by_hand_at_zero(alex):
    """All joints at zero: the wrist position is the sum of the chain's origin offsets, the shoulder's
    roll of -0.698132 rad (undone by the next joint's +0.698132) turning only RightShoulderRoll's offset."""
    q = np.zeros(alex.nq)
    a = -0.698132
    y_roll, z_roll = -0.15676, -0.013  # RightShoulderRoll's origin, expressed in the rolled frame
    x = -0.015 + 0.015 - 0.015  # SpineRoll, RightElbowPitch, RightWristYaw
    y = -0.12799 + (y_roll * math.cos(a) - z_roll * math.sin(a)) - 0.035 + 0.013 - 0.013
    z = (0.75  # spec base_xyz
         + 0.1045 + 0.0528 + 0.035  # SpineYaw, SpineRoll, SpinePitch
         + 0.235694  # RightShoulderPitch
         + (y_roll * math.sin(a) + z_roll * math.cos(a))  # RightShoulderRoll
         - 0.3127 - 0.25 - 0.031)  # RightElbowPitch, RightWristRoll, RightGripperYaw
    T = alex.frame_placement(q, "RightGripperYawLink")
    np.testing.assert_allclose(T[:3, 3], [x, y, z], rtol=0, atol=1e-12)
    np.testing.assert_allclose(T[:3, :3], np.eye(3), rtol=0, atol=1e-12)
    # The left arm is the mirror image (y -> -y).
    L = alex.frame_placement(q, "LeftGripperYawLink")
    np.testing.assert_allclose(L[:3, 3], [x, -y, z], rtol=0, atol=1e-12)


def test_alex_fingertip_by_hand_at_zero(alex):
    """All joints at zero: the index tip is the palm-frame offset of the straight finger, turned by the mount."""
    q = np.zeros(alex.nq)
    wrist = alex.frame_placement(q, "RightGripperYawLink")
    # mount_rpy = (pi, 0, pi/2): R = Rz(pi/2) Rx(pi)
    R_mount = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]], dtype=float)
    r = -0.08726646255  # joint_0.0's origin roll
    # In the palm frame: joint_0.0 at (0, 0.0435, -0.001542), then the straight finger along its rolled z.
    length = 0.0164 + 0.054 + 0.0384 + 0.0267
    tip_in_palm = np.array([0.0, 0.0435 - length * math.sin(r), -0.001542 + length * math.cos(r)])
    np.testing.assert_allclose(wrist[:3, :3], np.eye(3), rtol=0, atol=1e-12)
    # mount_xyz is in the wrist frame; the palm frame is then turned by R_mount.
    expected = wrist[:3, 3] + np.array([0, 0, -0.116]) + R_mount @ tip_in_palm
    T = alex.frame_placement(q, "right_hand/link_3.0_tip")
    np.testing.assert_allclose(T[:3, 3], expected, rtol=0, atol=1e-7)  # the spec writes pi to 8 decimals


def test_frame_placement_does_not_depend_on_a_shared_data(alex):
    q = configurations(alex, n_random=1)[1]
    data = alex.model.createData()
    a = alex.frame_placement(q, "left_hand/link_11.0_tip", data)
    alex.frame_placement(alex.q_rest, "left_hand/link_11.0_tip", data)
    b = alex.frame_placement(q, "left_hand/link_11.0_tip")
    np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------------------------------
# Finding and caching specs.


def test_spec_by_bare_name_is_found_in_assets_robots():
    spec = load_robot_spec("alex_allegro.toml")
    assert spec.source == ALEX.resolve()
    assert spec.name == "alex-allegro"
    assert spec.body_urdf == robot_data_file("alex_description/urdf/alex_nub_hands.urdf")
    assert spec.arm_names == ("right", "left")
    assert spec.arm("right").hand.prefix == "right_hand/" and spec.arm("left").hand.prefix == "left_hand/"
    assert spec.arm("left").hand.mount_rpy == (3.14159265, 0.0, -1.57079633)
    with pytest.raises(KeyError, match="no arm 'middle'"):
        spec.arm("middle")


def test_baxter_spec_by_bare_name():
    spec = load_robot_spec("baxter_allegro.toml")
    assert spec.source == BAXTER.resolve()
    assert spec.torso_joints == () and spec.torso_rest == ()


def test_load_robot_caches_by_path(alex):
    assert load_robot(ALEX) is alex
