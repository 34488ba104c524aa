"""Bad robot specs and task files: every case is an InputError naming the file, the field and what was
expected -- never a traceback from a library. The good files are parsed, mutated as data, and written
back to tmp_path (so the cases do not depend on the exact text of the assets, which other work edits)."""
from __future__ import annotations

import copy
import json
import math
import re
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from planner.core.errors import InputError
from planner.core.paths import ASSETS, robot_data_file
from planner.model.robot import build_robot, load_robot
from planner.model.robot_spec import RESERVED_NAMES, load_robot_spec
from planner.model.task import load_task, scene_from_dict

ALEX = ASSETS / "robots" / "alex_allegro.toml"
DEFAULT = ASSETS / "tasks" / "default.toml"
SPEC = tomllib.loads(ALEX.read_text())
# The robot given by absolute path: the same key as a task's resolved path, so load_robot's cache builds it once.
TASK = tomllib.loads(DEFAULT.read_text()) | {"robot": str(ALEX)}


# ---------------------------------------------------------------------------------------------
# A small TOML writer and dotted-path edits of parsed TOML data.


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(v)


def _is_tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(data: dict, prefix: str = "") -> str:
    lines = [f"{_key(k)} = {_value(v)}" for k, v in data.items() if not isinstance(v, dict) and not _is_tables(v)]
    for k, v in data.items():
        if isinstance(v, dict):
            lines += ["", f"[{prefix}{_key(k)}]", dumps(v, f"{prefix}{_key(k)}.")]
        elif _is_tables(v):
            for item in v:
                lines += ["", f"[[{prefix}{_key(k)}]]", dumps(item, f"{prefix}{_key(k)}.")]
    return "\n".join(lines)


def _steps(path: str) -> list:
    return [int(i) if i else k for k, i in re.findall(r"([^.\[\]]+)|\[(\d+)\]", path)]


def _parent(data, path: str):
    *head, last = _steps(path)
    for step in head:
        data = data[step]
    return data, last


def edit(data: dict, *ops) -> dict:
    """A deep copy of data with ops applied: ("set", path, value), ("del", path), ("rename", path, new_key),
    ("copy", path, to_path). Paths are dotted, with [i] for array elements, e.g. "arms.right.hand.fingers[0].open"."""
    data = copy.deepcopy(data)
    for op, path, *arg in ops:
        parent, last = _parent(data, path)
        if op == "set":
            parent[last] = copy.deepcopy(arg[0])
        elif op == "del":
            del parent[last]
        elif op == "rename":
            parent[arg[0]] = parent.pop(last)
        elif op == "copy":
            target, key = _parent(data, arg[0])
            target[key] = copy.deepcopy(parent[last])
        else:
            raise ValueError(op)
    return data


def test_writer_round_trips_the_assets():
    for path in (ALEX, ASSETS / "robots" / "baxter_allegro.toml", DEFAULT, ASSETS / "tasks" / "baxter.toml"):
        data = tomllib.loads(path.read_text())
        assert tomllib.loads(dumps(data)) == data, path
    assert tomllib.loads(dumps({"a": [math.inf, -1.5], "b": {"x.y": True}})) == {"a": [math.inf, -1.5], "b": {"x.y": True}}


def check(err: InputError, source: Path, field: str | None, *phrases: str) -> None:
    """The error names the file and the field, and its message says what was expected."""
    msg = str(err)
    assert err.source == str(source), msg
    assert err.field == field, msg
    assert msg.startswith(str(source) + (f", field '{field}': " if field else ": ")), msg
    for phrase in phrases:
        assert phrase in msg, f"{phrase!r} not in {msg!r}"


def write(tmp_path: Path, name: str, data: dict | str) -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else dumps(data))
    return path


def spec_error(tmp_path: Path, data: dict | str) -> tuple[InputError, Path]:
    """The InputError of reading a bad spec (no robot is built)."""
    path = write(tmp_path, "robot.toml", data)
    with pytest.raises(InputError) as info:
        load_robot_spec(path)
    return info.value, path


def build_error(tmp_path: Path, data: dict) -> tuple[InputError, Path]:
    """The InputError of building a spec whose fields are well-formed but whose names or values are not (~1 s)."""
    path = write(tmp_path, "robot.toml", data)
    spec = load_robot_spec(path)
    with pytest.raises(InputError) as info:
        build_robot(spec)
    return info.value, path


def task_error(tmp_path: Path, data: dict | str) -> tuple[InputError, Path]:
    path = write(tmp_path, "task.toml", data)
    with pytest.raises(InputError) as info:
        load_task(path)
    return info.value, path.resolve()


# ---------------------------------------------------------------------------------------------
# The good files.


@pytest.fixture(scope="module")
def default():
    return load_task("default")


def test_default_task_loads(default):
    data = tomllib.loads(DEFAULT.read_text())
    assert default.name == "default"
    assert default.source == DEFAULT
    assert len(default.environment) == len(data["obstacles"]) >= 10
    names = [o.name for o in default.environment]
    assert names == [o["name"] for o in data["obstacles"]]
    assert {"desk_top", "desk_leg_fr", "desk_leg_fl", "desk_leg_br", "desk_leg_bl", "lamp_foot", "lamp_lower_arm",
            "lamp_upper_arm", "lamp_shade", "vase"} <= set(names)
    assert default.object_name == "statuette"
    assert abs(len(default.object_mesh.vertices) - 669) <= 5
    assert default.object_mesh.is_watertight
    assert default.robot.nq == 49 and default.robot is load_robot(ALEX)
    assert default.q_initial.shape == (49,) and default.q_final.shape == (49,)
    ready = default.robot.configuration({"RightElbowPitch": -1.5, "LeftElbowPitch": -1.5})
    np.testing.assert_array_equal(default.q_initial, ready)
    np.testing.assert_array_equal(default.q_final, ready)
    xyz, rpy = data["object"]["initial"]["xyz"], data["object"]["initial"]["rpy"]
    np.testing.assert_allclose(default.object_initial[:3, 3], xyz)
    c, s = math.cos(rpy[2]), math.sin(rpy[2])
    assert rpy[:2] == [0.0, 0.0]
    np.testing.assert_allclose(default.object_initial[:3, :3], [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(default.object_final[:3, 3], data["object"]["final"]["xyz"])
    desk = default.environment[names.index("desk_top")]
    assert desk.shape == "box" and desk.size == (0.70, 2.40, 0.04)


def test_default_task_by_other_names(default):
    for name in ("default.toml", DEFAULT, str(DEFAULT)):
        scene = load_task(name)
        assert scene.source == default.source and len(scene.environment) == len(default.environment)


def test_scene_from_its_own_task_data(default):
    again = scene_from_dict(default.task, default.source)
    np.testing.assert_array_equal(again.q_final, default.q_final)
    np.testing.assert_array_equal(again.object_final, default.object_final)
    assert [o.name for o in again.environment] == [o.name for o in default.environment]


def test_baxter_task_loads():
    scene = load_task("baxter")
    assert scene.robot.nq == 46 and scene.robot.spec.name == "baxter-allegro"
    assert scene.q_initial.shape == (46,) and scene.q_final.shape == (46,)
    assert len(scene.environment) >= 10
    assert scene.robot.within_limits(scene.q_initial) and scene.robot.within_limits(scene.q_final)


def test_task_joint_override_is_applied(tmp_path):
    path = write(tmp_path, "task.toml", edit(TASK, ("set", "robot_initial", {
        "named": "rest", "joints": {"SpinePitch": 0.5, "right_hand/joint_0.0": -0.2}})))
    scene = load_task(path)
    names = scene.robot.joint_names()
    assert scene.q_initial[names.index("SpinePitch")] == 0.5
    assert scene.q_initial[names.index("right_hand/joint_0.0")] == -0.2
    assert scene.q_initial[names.index("RightElbowPitch")] == scene.robot.q_rest[names.index("RightElbowPitch")]
    np.testing.assert_array_equal(scene.q_final, scene.robot.configuration(TASK["robot_final"]["joints"]))


def test_task_without_obstacles_or_configurations(tmp_path):
    path = write(tmp_path, "task.toml", edit(TASK, ("del", "obstacles"), ("del", "robot_initial"), ("del", "robot_final")))
    scene = load_task(path)
    assert scene.environment == ()
    np.testing.assert_array_equal(scene.q_initial, scene.robot.q_rest)


# ---------------------------------------------------------------------------------------------
# Robot specs: errors found while reading the TOML.


def test_spec_not_found(tmp_path):
    with pytest.raises(InputError) as info:
        load_robot_spec(tmp_path / "nope.toml")
    check(info.value, tmp_path / "nope.toml", None, "file not found")


def test_spec_not_utf8(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_bytes(b'name = "\xff\xfe"\n')
    with pytest.raises(InputError) as info:
        load_robot_spec(path)
    check(info.value, path, None, "not a UTF-8 text file")


def test_spec_toml_syntax_error(tmp_path):
    text = dumps(SPEC).replace("[body]", "[body", 1)
    err, path = spec_error(tmp_path, text)
    check(err, path, None, "not valid TOML", "line ")


RIGHT = "arms.right"
FINGER0 = "arms.right.hand.fingers[0]"

SPEC_CASES = {
    "missing name": ([("del", "name")], "name", ["missing required field"]),
    "missing body": ([("rename", "body", "bodies")], "bodies", ["unknown field", "body"]),
    "missing body.urdf": ([("del", "body.urdf")], "body.urdf", ["missing required field"]),
    "missing arms": ([("del", "arms")], "arms", ["missing required field"]),
    "missing arms.right.joints": ([("del", f"{RIGHT}.joints")], "arms.right.joints", ["missing required field"]),
    "missing arms.right.rest": ([("del", f"{RIGHT}.rest")], "arms.right.rest", ["missing required field"]),
    "missing hand": ([("del", f"{RIGHT}.hand")], "arms.right.hand", ["missing required field"]),
    "missing thumb": ([("del", f"{RIGHT}.hand.thumb")], "arms.right.hand.thumb", ["missing required field"]),
    "missing finger tip_frame": ([("del", "arms.left.hand.fingers[1].tip_frame")],
                                 "arms.left.hand.fingers[1].tip_frame", ["missing required field"]),
    "unknown top-level field": ([("set", "nmae", "x")], "nmae",
                                ["unknown field", "expected one of: arms, body, description, name"]),
    "unknown body field (typo)": ([("rename", "body.torso_joints", "torso_joint")], "body.torso_joint",
                                  ["unknown field", "torso_joints"]),
    "unknown arm field (typo)": ([("rename", f"{RIGHT}.joints", "jonts")], "arms.right.jonts",
                                 ["unknown field", "joints"]),
    "unknown finger field": ([("rename", f"{FINGER0}.tip_radius", "tip_raduis")], f"{FINGER0}.tip_raduis",
                             ["unknown field", "tip_radius"]),
    "name not a string": ([("set", "name", 3)], "name", ["expected a non-empty string"]),
    "base_xyz a string": ([("set", "body.base_xyz", "0 0 0.75")], "body.base_xyz",
                          ["expected a list of finite numbers"]),
    "base_xyz two numbers": ([("set", "body.base_xyz", [0.0, 0.75])], "body.base_xyz", ["expected 3 numbers, got 2"]),
    "base_rpy with a bool": ([("set", "body.base_rpy", [0.0, False, 0.0])], "body.base_rpy",
                             ["expected a list of finite numbers"]),
    "mount_xyz with nan": ([("set", f"{RIGHT}.hand.mount_xyz", [0.0, math.nan, -0.1])], "arms.right.hand.mount_xyz",
                           ["expected a list of finite numbers"]),
    "torso_joints a string": ([("set", "body.torso_joints", "SpineYaw")], "body.torso_joints",
                              ["expected a list of names"]),
    "arm joints with a number": ([("set", f"{RIGHT}.joints[2]", 3)], "arms.right.joints", ["expected a list of names"]),
    "torso_rest wrong length": ([("set", "body.torso_rest", [0.0, 0.0])], "body.torso_rest",
                                ["expected 3 numbers, got 2"]),
    "arm rest wrong length": ([("set", f"{RIGHT}.rest", [0.0] * 6)], "arms.right.rest", ["expected 7 numbers, got 6"]),
    "arm rest a string value": ([("set", f"{RIGHT}.rest[0]", "0")], "arms.right.rest",
                                ["expected a list of finite numbers"]),
    "finger open wrong length": ([("set", f"{FINGER0}.open", [0.0, 0.1, 0.1])], f"{FINGER0}.open",
                                 ["expected 4 numbers, got 3"]),
    "negative tip radius": ([("set", f"{FINGER0}.tip_radius", -0.012)], f"{FINGER0}.tip_radius",
                            ["expected a positive number, got -0.012"]),
    "fingers not an array of tables": ([("set", "arms.left.hand.fingers", ["index"])], "arms.left.hand.fingers",
                                       ["expected an array of tables"]),
    "locked joint value a string": ([("set", "body.locked_joints", {"NeckYaw": "zero"})],
                                    "body.locked_joints.NeckYaw", ["expected a finite number, got 'zero'"]),
    "locked joints a list": ([("set", "body.locked_joints", ["NeckYaw"])], "body.locked_joints",
                             ["expected a table, got list"]),
    "empty prefix": ([("set", "arms.left.hand.prefix", "")], "arms.left.hand.prefix", ["expected a non-empty string"]),
    "body URDF does not exist": ([("set", "body.urdf", "alex_description/urdf/alex_no_such.urdf")], "body.urdf",
                                 ["'alex_description/urdf/alex_no_such.urdf'", "found neither beside the spec nor"]),
    "hand URDF does not exist": ([("set", "arms.left.hand.urdf", "allegro_hand_description/urdf/third_hand.urdf")],
                                 "arms.left.hand.urdf", ["third_hand.urdf", "found neither"]),
    "unknown thumb": ([("set", f"{RIGHT}.hand.thumb", "pinky")], "arms.right.hand.thumb",
                      ["'pinky' is not one of the fingers (index, middle, ring, thumb)"]),
    "duplicate finger names": ([("set", f"{RIGHT}.hand.fingers[1].name", "index")], "arms.right.hand.fingers",
                               ["finger names must be unique"]),
    "one arm": ([("del", "arms.left")], "arms", ["expected exactly two arms", "got 1"]),
    "three arms": ([("copy", "arms.right", "arms.third")], "arms", ["expected exactly two arms", "got 3"]),
    "arm not a table": ([("set", "arms.left", "LeftShoulderPitch")], "arms.left", ["expected a table, got str"]),
    **{f"arm named {name}": ([("rename", RIGHT, name)], f"arms.{name}", [f"'{name}' cannot name an arm", "rename the arm"])
       for name in (*RESERVED_NAMES, "right_hand", "right_env")},
}


@pytest.mark.parametrize("ops, field, phrases", SPEC_CASES.values(), ids=SPEC_CASES.keys())
def test_bad_spec_field(tmp_path, ops, field, phrases):
    err, path = spec_error(tmp_path, edit(SPEC, *ops))
    check(err, path, field, *phrases)


def test_bad_spec_through_load_robot_is_the_same_error(tmp_path):
    path = write(tmp_path, "robot.toml", edit(SPEC, ("set", "body.base_xyz", [0.0, 0.75])))
    with pytest.raises(InputError) as info:
        load_robot(path)
    check(info.value, path, "body.base_xyz", "expected 3 numbers, got 2")


# ---------------------------------------------------------------------------------------------
# Robot specs: names and values checked against the URDFs when the robot is built. Building the real
# robot loads its meshes (~1 s); most cases use `light`, the same spec on copies of its URDFs without
# <visual>/<collision> (same names, joints and limits; builds in ~20 ms).


@pytest.fixture(scope="module")
def light(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("meshless")
    data = copy.deepcopy(SPEC)
    tables = [data["body"]] + [arm["hand"] for arm in data["arms"].values()]
    for table in tables:
        root = ET.parse(robot_data_file(table["urdf"])).getroot()
        for link in root.iter("link"):
            for tag in ("visual", "collision"):
                for element in link.findall(tag):
                    link.remove(element)
        target = folder / Path(table["urdf"]).name
        ET.ElementTree(root).write(target)
        table["urdf"] = str(target)
    return data


def test_light_spec_is_the_same_robot(tmp_path, light):
    robot = build_robot(load_robot_spec(write(tmp_path, "robot.toml", light)))
    real = load_robot(ALEX)
    assert robot.joint_names() == real.joint_names()
    np.testing.assert_array_equal(robot.lower, real.lower)
    np.testing.assert_array_equal(robot.q_rest, real.q_rest)
    assert len(robot.collision_model.geometryObjects) == 0


def test_torso_joint_not_in_urdf(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "body.torso_joints[2]", "SpinePich")))
    check(err, path, "body.torso_joints", "joint 'SpinePich' is not in the composed robot")


def test_arm_joint_not_in_urdf(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "arms.left.joints[3]", "LeftElbowPich")))
    check(err, path, "arms.left.joints", "joint 'LeftElbowPich' is not in the composed robot")


def test_allowed_collision_link_not_in_urdf(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "body.allowed_collisions", [["Torso", "LeftElbowLink"]])))
    check(err, path, "body.allowed_collisions", "link 'LeftElbowLink' is not in the composed robot")


@pytest.mark.parametrize("value", [["Torso", "Head"], [["Torso"]], [["Torso", 3]], "Torso"])
def test_allowed_collisions_must_be_name_pairs(tmp_path, value):
    err, path = spec_error(tmp_path, edit(SPEC, ("set", "body.allowed_collisions", value)))
    check(err, path, "body.allowed_collisions", "expected a list of name pairs")


def test_finger_joint_not_in_urdf(tmp_path):
    err, path = build_error(tmp_path, edit(SPEC, ("set", f"{FINGER0}.joints[2]", "joint_2.5")))
    check(err, path, "arms.right.hand.fingers", "joint_2.5", "is not in the composed robot")


def test_arm_rest_outside_joint_limits_names_the_joint(tmp_path):
    i = SPEC["arms"]["right"]["joints"].index("RightElbowPitch")  # limits [-2.356, 0.175]
    err, path = build_error(tmp_path, edit(SPEC, ("set", f"{RIGHT}.rest[{i}]", 1.0)))
    check(err, path, "arms.right.rest", "outside the joint limits", "RightElbowPitch")
    assert "RightShoulder" not in str(err) and "Left" not in str(err)


def test_finger_open_outside_joint_limits_names_the_joint(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", f"{FINGER0}.open[3]", 9.0)))
    joint = SPEC["arms"]["right"]["hand"]["fingers"][0]["joints"][3]
    check(err, path, "arms.right.hand.fingers.open", "outside the joint limits", "right_hand/" + joint)


def test_locked_joint_not_in_urdf(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "body.locked_joints.NeckRoll", 0.0)))
    check(err, path, "body.locked_joints", "joint 'NeckRoll' is not in the body URDF")


def test_joint_in_no_part(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("del", "body.locked_joints.NeckPitch")))
    check(err, path, "body.locked_joints", "joints belong to no part", "NeckPitch")


def test_mount_frame_not_in_body(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "arms.left.hand.mount_frame", "LeftGripperLink")))
    check(err, path, "arms.left.hand.mount_frame", "no frame 'LeftGripperLink' in the body URDF")


def test_tip_frame_not_in_hand(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "arms.right.hand.fingers[3].tip_frame", "link_15.0_top")))
    check(err, path, "arms.right.hand.fingers", "no tip frame 'link_15.0_top' in allegro_right_hand.urdf")


def test_both_hands_with_one_prefix(tmp_path, light):
    # Was a raw pinocchio ValueError ("The two models have conflicting frame names.").
    err, path = build_error(tmp_path, edit(light, ("set", "arms.left.hand.prefix", "right_hand/")))
    check(err, path, "arms.left.hand.prefix", "'right_hand/'", "clash", "give each hand its own prefix")


def test_hand_urdf_not_xml(tmp_path, light):
    # Was a raw xml.etree ParseError. The URDF is given relative to the spec file.
    (tmp_path / "hand.urdf").write_text("this is not a URDF\n")
    err, path = build_error(tmp_path, edit(light, ("set", "arms.left.hand.urdf", "hand.urdf")))
    check(err, path, "arms.left.hand.urdf", str(tmp_path / "hand.urdf"), "is not a URDF (not valid XML")


def test_body_urdf_binary(tmp_path, light):
    # Was a raw UnicodeDecodeError.
    (tmp_path / "body.urdf").write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00\x00")
    err, path = build_error(tmp_path, edit(light, ("set", "body.urdf", "body.urdf")))
    check(err, path, "body.urdf", str(tmp_path / "body.urdf"), "is not a text file; expected a URDF")


def test_body_urdf_not_a_urdf(tmp_path):
    (tmp_path / "body.urdf").write_text("<robot name='x'><joint name='j'/></robot>\n")
    path = write(tmp_path, "robot.toml", edit(SPEC, ("set", "body.urdf", "body.urdf")))
    with pytest.raises(InputError) as info:
        build_robot(load_robot_spec(path))
    check(info.value, tmp_path / "body.urdf", None, "pinocchio could not load this URDF")


def test_body_urdf_with_a_missing_mesh(tmp_path):
    urdf = robot_data_file("alex_description/urdf/alex_nub_hands.urdf").read_text()
    assert "meshes/ALX02_02_A01_BaseLink.obj" in urdf
    (tmp_path / "body.urdf").write_text(urdf.replace("meshes/ALX02_02_A01_BaseLink.obj", "meshes/NoSuchMesh.obj"))
    path = write(tmp_path, "robot.toml", edit(SPEC, ("set", "body.urdf", "body.urdf")))
    with pytest.raises(InputError) as info:
        build_robot(load_robot_spec(path))
    check(info.value, tmp_path / "body.urdf", None, "pinocchio could not load this URDF", "NoSuchMesh.obj")


def test_joint_in_two_parts(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "body.torso_joints", ["SpineYaw", "SpineRoll", "SpinePitch",
                                                                                "RightShoulderPitch"]),
                                           ("set", "body.torso_rest", [0.0] * 4)))
    check(err, path, "body.torso_joints", "RightShoulderPitch")


def test_locked_joint_value_outside_limits(tmp_path, light):
    err, path = build_error(tmp_path, edit(light, ("set", "body.locked_joints.NeckPitch", 5.0)))
    check(err, path, "body.locked_joints.NeckPitch", "NeckPitch")


# ---------------------------------------------------------------------------------------------
# Task files.


def test_task_not_found(tmp_path):
    with pytest.raises(InputError) as info:
        load_task(tmp_path / "nope.toml")
    assert "nope.toml" in str(info.value) and "file not found" in str(info.value)
    with pytest.raises(InputError, match="file not found"):
        load_task("no_such_task")


def test_task_toml_syntax_error(tmp_path):
    err, path = task_error(tmp_path, dumps(TASK).replace("[object]", "[object", 1))
    check(err, path, None, "not valid TOML", "line ")


OB0 = "obstacles[0]"

TASK_CASES = {
    "missing robot": ([("del", "robot")], "robot", ["missing required field"]),
    "missing name": ([("del", "name")], "name", ["missing required field"]),
    "robot not a string": ([("set", "robot", 3)], "robot", ["expected a non-empty string"]),
    "robot file not found": ([("set", "robot", "alex_allegro_v2.toml")], "robot",
                             ["'alex_allegro_v2.toml' not found", "looked beside the task file and in"]),
    "robot file a folder": ([("set", "robot", str(ASSETS / "robots"))], "robot", ["is a directory", "expected a file"]),
    "missing object": ([("rename", "object", "objekt")], "objekt", ["unknown field", "object"]),
    "missing object.initial": ([("del", "object.initial")], "object.initial", ["missing required field"]),
    "missing object.final": ([("del", "object.final")], "object.final", ["missing required field"]),
    "missing object.mesh": ([("del", "object.mesh")], "object.mesh", ["missing required field"]),
    "object.initial not a table": ([("set", "object.initial", [0.5, -0.9, 0.72])], "object.initial",
                                   ["expected a table, got list"]),
    "missing xyz": ([("del", "object.initial.xyz")], "object.initial.xyz", ["missing required field"]),
    "unknown field: obstacle for obstacles": ([("rename", "obstacles", "obstacle")], "obstacle",
                                              ["unknown field", "obstacles"]),
    "unknown field: xzy": ([("rename", "object.initial.xyz", "xzy")], "object.initial.xzy",
                           ["unknown field (expected one of: rpy, xyz)"]),
    "unknown obstacle field": ([("set", f"{OB0}.colour", [1, 2, 3])], f"{OB0}.colour", ["unknown field", "color"]),
    "unknown configuration field": ([("set", "robot_initial", {"name": "rest"})], "robot_initial.name",
                                    ["unknown field (expected one of: joints, named)"]),
    "xyz a string": ([("set", "object.initial.xyz", "0.50 -0.92 0.72")], "object.initial.xyz",
                     ["expected a list of finite numbers"]),
    "xyz two numbers": ([("set", "object.initial.xyz", [0.50, -0.92])], "object.initial.xyz",
                        ["expected 3 numbers, got 2"]),
    "rpy with a bool": ([("set", f"{OB0}.rpy", [True, 0.25, 0.0])], f"{OB0}.rpy", ["expected a list of finite numbers"]),
    "obstacles not an array of tables": ([("set", "obstacles", [1, 2])], "obstacles", ["expected an array of tables"]),
    "unknown obstacle shape": ([("set", f"{OB0}.shape", "cube")], f"{OB0}.shape",
                               ["expected one of box, cylinder, sphere, capsule, mesh, got 'cube'"]),
    "negative box size": ([("set", f"{OB0}.shape", "box"), ("set", f"{OB0}.size", [0.7, -2.4, 0.04])],
                          f"{OB0}.size", ["expected positive dimensions"]),
    "zero cylinder radius": ([("set", f"{OB0}.shape", "cylinder"), ("set", f"{OB0}.size", [0.0, 0.3])],
                             f"{OB0}.size", ["expected positive dimensions"]),
    "box size two numbers": ([("set", f"{OB0}.shape", "box"), ("set", f"{OB0}.size", [0.7, 2.4])],
                             f"{OB0}.size", ["expected 3 numbers, got 2"]),
    "sphere size three numbers": ([("set", f"{OB0}.shape", "sphere"), ("set", f"{OB0}.size", [0.1, 0.1, 0.1])],
                                  f"{OB0}.size", ["expected 1 numbers, got 3"]),
    "infinite size": ([("set", f"{OB0}.shape", "box"), ("set", f"{OB0}.size", [0.7, math.inf, 0.04])],
                      f"{OB0}.size", ["expected a list of finite numbers"]),
    "obstacle without a name": ([("del", "obstacles[1].name")], "obstacles[1].name", ["missing required field"]),
    "mesh obstacle without a mesh": ([("set", f"{OB0}.shape", "mesh")], f"{OB0}.mesh", ["missing required field"]),
    "mesh obstacle file missing": ([("set", f"{OB0}.shape", "mesh"), ("del", f"{OB0}.size"), ("set", f"{OB0}.mesh", "no_such_lamp.obj")],
                                   f"{OB0}.mesh", ["'no_such_lamp.obj' not found"]),
    "color a string": ([("set", f"{OB0}.color", "brown")], f"{OB0}.color", ["expected a list of finite numbers"]),
    "duplicate obstacle names": ([("set", "obstacles[0].name", "twin"), ("set", "obstacles[2].name", "twin")],
                                 "obstacles", ["obstacle names must be unique"]),
    "object mesh file missing": ([("set", "object.mesh", "no_such_statuette.obj")], "object.mesh",
                                 ["'no_such_statuette.obj' not found", "looked beside the task file and in"]),
    "object mesh not a string": ([("set", "object.mesh", 3)], "object.mesh", ["expected a non-empty string"]),
    "unknown named configuration": ([("set", "robot_final", {"named": "home"})], "robot_final.named",
                                    ["unknown configuration 'home' (known: rest)"]),
    "robot_initial joint outside limits": ([("set", "robot_initial", {"joints": {"SpinePitch": 2.0}})],
                                           "robot_initial.joints.SpinePitch",
                                           ["2.0 is outside the joint limits [-0.524, 0.785]"]),
    "robot_final hand joint outside limits": ([("set", "robot_final", {"joints": {"left_hand/joint_1.0": -1.0}})],
                                              "robot_final.joints.left_hand/joint_1.0",
                                              ["-1.0 is outside the joint limits"]),
    "robot_initial unknown joint": ([("set", "robot_initial", {"named": "rest", "joints": {"SpinePich": 0.1}})],
                                    "robot_initial.joints.SpinePich", ["the robot has no joint 'SpinePich'"]),
    "robot_initial locked joint": ([("set", "robot_initial", {"joints": {"NeckYaw": 0.1}})],
                                   "robot_initial.joints.NeckYaw", ["the robot has no joint 'NeckYaw'"]),
    "robot_initial joint value a string": ([("set", "robot_initial", {"joints": {"SpinePitch": "0.1"}})],
                                           "robot_initial.joints.SpinePitch", ["expected a finite number"]),
    "robot_initial joints a list": ([("set", "robot_initial", {"joints": [0.1, 0.2]})], "robot_initial.joints",
                                    ["expected a table, got list"]),
    "robot_initial a string": ([("set", "robot_initial", "rest")], "robot_initial", ["expected a table, got str"]),
}


@pytest.mark.parametrize("ops, field, phrases", TASK_CASES.values(), ids=TASK_CASES.keys())
def test_bad_task_field(tmp_path, ops, field, phrases):
    err, path = task_error(tmp_path, edit(TASK, *ops))
    check(err, path, field, *phrases)


def test_task_with_a_bad_robot_spec_names_the_spec(tmp_path):
    spec = write(tmp_path, "robot.toml", edit(SPEC, ("set", "hands", 2)))
    err, _ = task_error(tmp_path, edit(TASK, ("set", "robot", "robot.toml")))  # relative to the task file
    check(err, spec.resolve(), "hands", "unknown field")


def test_task_with_a_spec_of_one_arm(tmp_path):
    spec = write(tmp_path, "robot.toml", edit(SPEC, ("del", "arms.left")))
    err, _ = task_error(tmp_path, edit(TASK, ("set", "robot", str(spec))))
    check(err, spec.resolve(), "arms", "expected exactly two arms", "got 1")


def test_task_whose_robot_is_a_task(tmp_path):
    err, _ = task_error(tmp_path, edit(TASK, ("set", "robot", "../tasks/default.toml")))
    # resolved against assets/robots/: the task file given as a robot spec is rejected by its first unknown field
    check(err, DEFAULT, "robot", "unknown field")


def test_task_object_mesh_of_an_unsupported_format(tmp_path):
    (tmp_path / "statue.txt").write_text("not a mesh\n")
    err, task = task_error(tmp_path, edit(TASK, ("set", "object.mesh", "statue.txt")))
    check(err, task, "object.mesh", "the object mesh", str(tmp_path / "statue.txt"), "unsupported mesh format '.txt'")
