"""Task files written back (planner/model/task_file.py) and task edits (planner/model/task_edit.py): what is written
loads as the task it was (tomllib and the task loader are the oracles), text of any kind reads back as it was, a file is
never replaced unasked, a typed name stays in its folder; edits put the object down on its support."""
from __future__ import annotations

import random
import tomllib
from pathlib import Path

import numpy as np
import pytest
import trimesh

from planner.core.errors import RegraspError
from planner.core.toml_text import toml_text
from planner.core.tomlread import load_toml
from planner.model.task import Scene, find_task, load_task, scene_from_dict
from planner.model.task_edit import (
    rest_on_support,
    support_top,
    with_new_obstacle,
    with_object_mesh,
    with_obstacle_pose,
    with_placement,
    with_robot,
)
from planner.model.task_file import check_task_name, task_path, write_task
from workbench.cli import main as regrasp

DESK_TOP = 0.72  # m: the default task's desk top (its box: centre z 0.70, 0.04 thick)
STAND_TOP = 0.66  # m: the robot's stand (centre z 0.33, 0.66 tall)


def _same_task(a: Scene, b: Scene) -> None:
    """Everything a task sets, compared field by field (not through the writer or the editor)."""
    assert (a.name, a.description, a.handover) == (b.name, b.description, b.handover)
    assert a.robot.spec.name == b.robot.spec.name
    for left, right in ((a.object_initial, b.object_initial), (a.object_final, b.object_final),
                        (a.q_initial, b.q_initial), (a.q_final, b.q_final)):
        assert np.array_equal(left, right)
    assert np.array_equal(a.object_mesh.vertices, b.object_mesh.vertices)
    assert [(o.name, o.shape, o.size, o.color) for o in a.environment] == [(o.name, o.shape, o.size, o.color) for o in b.environment]
    assert all(np.array_equal(o.pose, p.pose) for o, p in zip(a.environment, b.environment))


@pytest.mark.parametrize("name", ["default", "baxter"])
def test_a_shipped_task_round_trips(name: str, tmp_path: Path) -> None:
    scene = load_task(name)
    written = write_task(scene.task, scene.source, tmp_path / f"{name}.toml")
    assert load_toml(written) == load_toml(find_task(name))  # its references need no change: the robot by name
    _same_task(scene, load_task(written))
    again = write_task(load_task(written).task, written, tmp_path / "again.toml")
    assert again.read_text() == written.read_text()


def test_file_references_are_rebased_for_the_new_folder(tmp_path: Path) -> None:
    """A mesh named beside the task is still found from another folder; the robot spec keeps its name in assets/robots."""
    (tmp_path / "a" / "meshes").mkdir(parents=True)
    box = trimesh.creation.box(extents=(0.05, 0.06, 0.1))
    box.apply_translation((0, 0, 0.05))
    box.export(tmp_path / "a" / "meshes" / "box.stl")
    data = load_toml(find_task("default"))
    data["object"]["mesh"] = "meshes/box.stl"
    source = tmp_path / "a" / "task.toml"
    source.write_text(toml_text(data))
    target = tmp_path / "b" / "c" / "task.toml"
    write_task(load_task(source).task, source, target)
    written = load_toml(target)
    assert written["object"]["mesh"] == "../../a/meshes/box.stl" and written["robot"] == "alex_allegro.toml"
    _same_task(load_task(source), load_task(target))


def test_an_existing_file_is_replaced_only_when_asked(tmp_path: Path) -> None:
    scene = load_task("default")
    target = tmp_path / "task.toml"
    target.write_text("# the user's own file\n")
    with pytest.raises(RegraspError, match="already exists"):
        write_task(scene.task, scene.source, target)
    assert target.read_text() == "# the user's own file\n"
    assert [p.name for p in tmp_path.iterdir()] == ["task.toml"]  # no staging file left behind
    write_task(scene.task, scene.source, target, overwrite=True)
    _same_task(scene, load_task(target))


@pytest.mark.parametrize("name", ["../x", "a/b", "", ".hidden", "-x", "x" * 81, "tab\tname", "a\\b", "C:x", "..", "é"])
def test_task_names_that_are_no_plain_name_are_refused(name: str) -> None:
    with pytest.raises(RegraspError, match="task name"):
        check_task_name(name)


def test_a_task_name_names_a_file_in_the_folder(tmp_path: Path) -> None:
    assert task_path(tmp_path, " my_task-2 ") == tmp_path / "my_task-2.toml"
    assert task_path(tmp_path, "edited.toml") == tmp_path / "edited.toml"


def test_any_text_reads_back_as_written() -> None:
    """Random texts over characters TOML escapes (quotes, backslashes, control characters, DEL, line separators, emoji)
    and TOML's own syntax: tomllib reads back each text, as a value and as a key."""
    alphabet = ['"', "\\", "'", "\n", "\r", "\t", "\b", "\f", "\x00", "\x1b", "\x7f", "\u2028", "\ufeff", "😀", "é", "[",
                "]", "=", "#", "{", "}", ",", ".", " ", "a", "Z", "0", '"""', "'''"]
    rng = random.Random(0)
    for _ in range(300):
        text = "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 24)))
        data = {"name": text, "description": text, text or "k": 1, "object": {text or "t": text}, "obstacles": [{"name": text}]}
        assert tomllib.loads(toml_text(data)) == data


def test_text_that_is_no_unicode_is_refused() -> None:
    with pytest.raises(ValueError, match="surrogate"):
        toml_text({"name": "bad \ud800 text"})


def test_an_edited_task_is_written_so_that_check_accepts_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = load_task("default")
    data = with_placement(scene.task, "final", rest_on_support(scene, "final", (0.5, 0.88, 0.72), np.radians(150)))
    data, _ = with_new_obstacle(data, "box", (0.62, 0.3, DESK_TOP))
    data["description"] = 'A "quoted" text\nwith a [table] header = 1 and \\ backslash'
    target = write_task(data, scene.source, tmp_path / "edited.toml")
    _same_task(scene_from_dict(data, scene.source), load_task(target))
    assert regrasp(["check", str(target)]) == 0
    assert "OK: a valid two-hand regrasping task" in capsys.readouterr().out


def test_support_top_finds_the_highest_surface_below(default_scene: Scene) -> None:
    env = default_scene.environment
    assert support_top(env, 0.6, -0.5, 1.0) == pytest.approx(DESK_TOP)
    assert support_top(env, 0.6, -0.5, 0.6) == 0.0  # below the desk top: the floor
    assert support_top(env, -0.02, 0.0, 0.7) == pytest.approx(STAND_TOP)
    assert support_top(env, 5.0, 5.0, 10.0) == 0.0
    assert support_top(env, 0.55, 0.05, 2.0) == pytest.approx(0.87 + 0.15)  # the vase's top


@pytest.mark.parametrize("tilt", [(0.0, 0.0), (np.pi / 2, 0.0), (0.3, -0.4)])
def test_a_placement_rests_on_its_support_with_the_heading_asked(default_scene: Scene, tilt: tuple[float, float]) -> None:
    """Its lowest vertex (the mesh moved by the pose, here) touches the desk top; roll and pitch stay, yaw is taken."""
    data = with_placement(default_scene.task, "initial", {"xyz": [0.45, -0.85, 0.9], "rpy": [*tilt, 0.0]})
    scene = scene_from_dict(data, default_scene.source, meshes=default_scene.meshes)
    placement = rest_on_support(scene, "initial", (0.5, -0.6, 0.95), 2.0)
    moved = scene_from_dict(with_placement(data, "initial", placement), scene.source, meshes=scene.meshes)
    T = moved.object_initial
    lowest = (default_scene.object_mesh.vertices @ T[:3, :3].T + T[:3, 3])[:, 2].min()
    assert lowest == pytest.approx(DESK_TOP, abs=2e-4)
    assert T[:2, 3] == pytest.approx([0.5, -0.6])
    assert placement["rpy"] == pytest.approx([*tilt, 2.0], abs=1e-4)


@pytest.mark.parametrize("xyz", [(np.nan, 0.0, 0.7), (0.0, np.inf, 0.7), (500.0, 0.0, 0.7), (0.0, 0.0)])
def test_a_placement_of_no_place_is_refused(default_scene: Scene, xyz: tuple[float, ...]) -> None:
    with pytest.raises(RegraspError, match="placement"):
        rest_on_support(default_scene, "final", xyz, 0.0)


def test_obstacle_edits_load(default_scene: Scene) -> None:
    data, name = with_new_obstacle(default_scene.task, "cylinder", (0.6, 0.2, DESK_TOP))
    data, second = with_new_obstacle(data, "cylinder", (0.6, 0.3, DESK_TOP))
    assert (name, second) == ("cylinder_1", "cylinder_2")
    data = with_obstacle_pose(data, "vase", (0.6, 0.0, 0.87), np.pi / 2)
    scene = scene_from_dict(data, default_scene.source, meshes=default_scene.meshes)
    added = next(o for o in scene.environment if o.name == name)
    assert added.to_trimesh().bounds[0][2] == pytest.approx(DESK_TOP)  # standing on the desk
    vase = next(o for o in scene.environment if o.name == "vase")
    assert vase.pose[:3, 3] == pytest.approx([0.6, 0.0, 0.87]) and vase.pose[:3, 0] == pytest.approx([0, 1, 0], abs=1e-4)
    with pytest.raises(RegraspError, match="no obstacle named"):
        with_obstacle_pose(data, "nothing", (0, 0, 0), 0.0)


def test_another_robot_keeps_only_its_joints(default_scene: Scene) -> None:
    from planner.model.robot import load_robot
    from planner.model.task import ROBOTS_DIR

    baxter = load_robot(ROBOTS_DIR / "baxter_allegro.toml")
    data, dropped = with_robot(default_scene.task, "baxter_allegro.toml", baxter.joint_names())
    assert dropped == ["LeftElbowPitch", "RightElbowPitch"]
    scene = scene_from_dict(data, default_scene.source, meshes=default_scene.meshes)
    assert scene.robot.spec.name == "baxter-allegro" and np.array_equal(scene.q_initial, baxter.configuration({}))


def test_a_y_up_mesh_is_turned_upright(tmp_path: Path, default_scene: Scene) -> None:
    """A mesh whose long side is its file's y axis, given up = y, stands with that side vertical."""
    tall = trimesh.creation.box(extents=(0.05, 0.2, 0.06))
    tall.export(tmp_path / "tall.stl")
    data = with_object_mesh(default_scene.task, str(tmp_path / "tall.stl"), "y")
    scene = scene_from_dict(data, default_scene.source, meshes=default_scene.meshes)
    assert scene.object_mesh.extents == pytest.approx([0.05, 0.06, 0.2])
    assert "up" not in with_object_mesh(data, "statuette")["object"]
