"""Issue 13 and issue 11 item 9: meshes from the wild (seams, holes, non-manifold edges, units, up axis), task values
validated, one validation shared by `check` and `plan`, the grasp steps failing on an empty list, the arm assignment
(both arms reach, one arm reaches both), and `grasps` and `plan` sharing a cached list."""
from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import trimesh
from generated_objects import TASK_TEXT_ROBOT
from sandbox import forbid

from planner.check import (
    InvalidTask,
    check_task,
    hand_opening,
    require_valid,
    validate_task,
)
from planner.core.errors import InputError
from planner.core.runner import run_pipeline
from planner.core.session import Session
from planner.core.steps import StepFailed
from planner.grasping.grasp_list import PICK_STEP, PLACE_STEP, session_grasp_seed
from planner.handover.arms import decide, geometric_median
from planner.handover.reach import placement_reach
from planner.model.geometry import pose
from planner.model.object_mesh import OBSTACLE_LIMITS, load_mesh, load_object_mesh
from planner.model.statuette import STATUETTE_PATH
from planner.model.task import MAX_OBSTACLES, load_task

TASK_TEXT = TASK_TEXT_ROBOT


def _task(tmp_path: Path, text: str = TASK_TEXT, name: str = "task.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _with_object(tmp_path: Path, mesh_line: str, initial: str | None = None) -> Path:
    """The default task with its object table's mesh line (and optionally its initial placement) replaced."""
    text = TASK_TEXT.replace('mesh = "statuette"', mesh_line)
    if initial:
        text = text.replace("initial = { xyz = [0.45, -0.85, 0.72], rpy = [0.0, 0.0, 1.2] }", initial)
    return _task(tmp_path, text)


def _error(path: Path) -> InputError:
    with pytest.raises(InputError) as info:
        load_task(path)
    return info.value


def _obj_with_seams(mesh: trimesh.Trimesh) -> str:
    """An OBJ of a mesh in which every face has its own three vertices, each with its own UV (seams everywhere)."""
    lines = []
    for k, face in enumerate(mesh.faces):
        for v in mesh.vertices[face]:
            lines.append(f"v {v[0]:.6f} {v[1]:.6f} {v[2]:.6f}")
        lines += [f"vt {0.1 * (k % 7):.2f} {0.05 * j:.2f}" for j in range(3)]
    lines += [f"f {3 * k + 1}/{3 * k + 1} {3 * k + 2}/{3 * k + 2} {3 * k + 3}/{3 * k + 3}" for k in range(len(mesh.faces))]
    return "\n".join(lines) + "\n"


# --- mesh loading ---------------------------------------------------------------------------------

def test_closed_mesh_with_duplicated_seam_vertices_loads(tmp_path):
    cylinder = trimesh.creation.cylinder(radius=0.04, height=0.12, sections=24)
    path = tmp_path / "seams.obj"
    path.write_text(_obj_with_seams(cylinder))
    raw = trimesh.load(path, force="mesh", process=False)
    assert len(raw.vertices) == 3 * len(cylinder.faces) and not raw.is_watertight  # as a UV-aware loader sees it
    mesh = load_object_mesh(path)
    assert mesh.is_watertight and len(mesh.vertices) == len(cylinder.vertices)
    assert mesh.volume == pytest.approx(cylinder.volume, rel=1e-4)


def test_mesh_with_a_hole_is_repaired(tmp_path):
    box = trimesh.creation.box([0.1, 0.1, 0.1])
    box.update_faces(box.face_normals[:, 2] < 0.5)  # the whole top side missing: a four-edge hole
    assert not box.is_watertight
    path = tmp_path / "open_box.stl"
    box.export(path)
    mesh = load_object_mesh(path)
    assert mesh.is_watertight and mesh.volume == pytest.approx(0.001, rel=1e-5)


def test_non_manifold_mesh_fails_naming_its_non_manifold_edges(tmp_path):
    a = trimesh.creation.box([0.1, 0.1, 0.1])
    b = trimesh.creation.box([0.1, 0.1, 0.1], transform=trimesh.transformations.translation_matrix([0.1, 0.1, 0.0]))
    two = trimesh.util.concatenate([a, b])  # two cubes touching along one vertical edge: four faces meet there
    path = tmp_path / "bowtie.obj"
    path.write_text(trimesh.exchange.obj.export_obj(two, include_normals=False, include_texture=False))
    with pytest.raises(InputError) as info:
        load_object_mesh(path)
    message = str(info.value)
    assert str(path) in message and "non-manifold edges (edges shared by more than two triangles)" in message
    assert int(message.split(" non-manifold edges")[0].split()[-1]) >= 1  # with a count


def test_y_up_mesh_with_up_y_stands_upright(tmp_path):
    tall = trimesh.creation.cylinder(radius=0.03, height=0.2, sections=32)
    tall.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # its axis along +y, as glTF
    tall.apply_translation([0, 0.1, 0])  # standing on y = 0
    tall.export(tmp_path / "bottle.glb")
    lying = load_task(_with_object(tmp_path, 'mesh = "bottle.glb"'))
    assert lying.object_mesh.extents[1] == pytest.approx(0.2, abs=1e-6)
    upright = load_task(_with_object(tmp_path, 'mesh = "bottle.glb"\nup = "y"'))
    assert upright.object_mesh.extents == pytest.approx([0.06, 0.06, 0.2], abs=2e-3)
    assert upright.object_mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-6)  # on its base, not hanging below it
    assert not validate_task(upright).problems


def test_millimetre_mesh_needs_its_scale(tmp_path):
    statuette = load_object_mesh(STATUETTE_PATH)
    mm = statuette.copy().apply_scale(1000.0)
    mm.export(tmp_path / "horse_mm.stl")
    err = _error(_with_object(tmp_path, 'mesh = "horse_mm.stl"'))
    assert err.field == "object.mesh" and err.source == str(tmp_path / "task.toml")
    assert str(tmp_path / "horse_mm.stl") in str(err) and "millimetres" in str(err) and "scale = 0.001" in str(err)
    scene = load_task(_with_object(tmp_path, 'mesh = "horse_mm.stl"\nscale = 0.001'))
    assert np.allclose(scene.object_mesh.bounds, statuette.bounds, atol=1e-6)
    assert not validate_task(scene).problems and not validate_task(scene).warnings


def test_obstacles_have_their_own_size_limits(tmp_path):
    wall = trimesh.creation.box([3.0, 0.1, 2.0])
    wall.export(tmp_path / "wall.stl")
    obstacle = '\n[[obstacles]]\nname = "wall"\nshape = "mesh"\nmesh = "wall.stl"\nxyz = [3.0, 0.0, 1.0]\n'
    scene = load_task(_task(tmp_path, TASK_TEXT + obstacle))  # a 3 m obstacle is fine
    assert scene.environment[-1].mesh.extents.max() == pytest.approx(3.0)
    err = _error(_with_object(tmp_path, 'mesh = "wall.stl"'))  # a 3 m object is not
    assert err.field == "object.mesh" and "absurd size for an object" in str(err)
    huge = trimesh.creation.box([OBSTACLE_LIMITS.high * 2, 1.0, 1.0])
    huge.export(tmp_path / "huge.stl")
    err = _error(_task(tmp_path, TASK_TEXT + obstacle.replace("wall.stl", "huge.stl")))
    assert err.field == "obstacles[11].mesh" and "absurd size for an obstacle" in str(err)
    assert "the obstacle mesh" in str(err) and str(tmp_path / "huge.stl") in str(err)
    with pytest.raises(InputError, match="absurd size for an obstacle"):
        load_mesh(tmp_path / "huge.stl", OBSTACLE_LIMITS)


# --- task values (issue 11 item 9) ----------------------------------------------------------------

OB = '\n[[obstacles]]\nname = "extra"\nshape = "box"\nsize = [0.1, 0.1, 0.1]\nxyz = [2.0, 0.0, 0.5]\n'


@pytest.mark.parametrize(("extra", "field", "phrase"), [
    ('color = [300, 0, 0]', "obstacles[11].color", "three integers from 0 to 255"),
    ('color = [-1, 0, 0]', "obstacles[11].color", "three integers from 0 to 255"),
    ('color = [0.5, 0, 0]', "obstacles[11].color", "three integers from 0 to 255"),
    ('rpy = [0.0, 0.0, 90.0]', "obstacles[11].rpy", "degrees given as radians?"),
], ids=["colour-300", "colour-negative", "colour-fraction", "degrees"])
def test_obstacle_values_are_checked(tmp_path, extra, field, phrase):
    err = _error(_task(tmp_path, TASK_TEXT + OB + extra + "\n"))
    assert err.field == field and phrase in str(err) and str(err).startswith(str(tmp_path / "task.toml"))


def test_placement_of_1e300_is_refused(tmp_path):
    err = _error(_task(tmp_path, TASK_TEXT.replace("final = { xyz = [0.50, 0.85, 0.72]", "final = { xyz = [1e300, 0.85, 0.72]")))
    assert err.field == "object.final.xyz" and "within 100 m of the robot" in str(err)
    err = _error(_task(tmp_path, TASK_TEXT + OB.replace("[2.0, 0.0, 0.5]", "[0.0, -1e300, 0.5]")))
    assert err.field == "obstacles[11].xyz"


def test_a_directory_given_as_a_mesh_is_named(tmp_path):
    (tmp_path / "horse.obj").mkdir()
    err = _error(_with_object(tmp_path, 'mesh = "horse.obj"'))
    assert err.field == "object.mesh" and "is a directory" in str(err) and "not found" not in str(err)


def test_mesh_errors_name_the_task_file_and_field(tmp_path):
    (tmp_path / "broken.ply").write_bytes(b"\x00\x01garbage\xff" * 40)
    err = _error(_with_object(tmp_path, 'mesh = "broken.ply"'))
    assert err.source == str(tmp_path / "task.toml") and err.field == "object.mesh"
    assert str(tmp_path / "broken.ply") in str(err) and "could not be parsed as a PLY mesh" in str(err)
    err = _error(_with_object(tmp_path, 'mesh = "statuette"\nup = "w"'))
    assert err.field == "object.up" and "glTF files are y-up" in str(err)
    err = _error(_with_object(tmp_path, 'mesh = "statuette"\nscale = 0'))
    assert err.field == "object.scale" and "positive" in str(err)


def test_thousands_of_obstacles_are_refused_at_once(tmp_path):
    data = tomllib.loads(TASK_TEXT)
    many = "".join(OB.replace('"extra"', f'"box{i}"') for i in range(5000))
    err = _error(_task(tmp_path, TASK_TEXT + many))
    assert err.field == "obstacles" and f"more than the {MAX_OBSTACLES} allowed" in str(err) and "5,011" in str(err)
    assert len(data["obstacles"]) < MAX_OBSTACLES


# --- one validation for check, plan and grasps -----------------------------------------------------

def test_hand_size_comes_from_the_spec_and_warns_with_the_unit(tmp_path, default_scene):
    spec = default_scene.robot.spec
    opening = max(hand_opening(spec.arm(a).hand) for a in spec.arm_names)
    assert 0.15 < opening < 0.35  # an Allegro hand, thumb and a finger spread
    assert not validate_task(default_scene).warnings
    big = dataclasses.replace(default_scene, object_mesh=default_scene.object_mesh.copy().apply_scale(8.0))
    (warning,) = validate_task(big).warnings
    assert "wider than the robot's hands open" in warning and f"({opening:.3g} m" in warning
    assert "centimetres? then set scale = 0.01" in warning or "decimetres? then set scale = 0.1" in warning


@pytest.mark.slow
def test_plan_refuses_a_placement_inside_an_obstacle_with_checks_message(tmp_path):
    inside = TASK_TEXT.replace("final = { xyz = [0.50, 0.85, 0.72]", "final = { xyz = [0.55, 0.05, 0.72]")  # in the vase
    path = _task(tmp_path, inside)
    scene = load_task(path)
    report = check_task(scene)
    assert "the object's final placement penetrates vase" in report.problems
    with pytest.raises(InvalidTask) as info:
        require_valid(scene, lambda message: None)
    assert "the object's final placement penetrates vase" in str(info.value)
    out = tmp_path / "session"
    run = subprocess.run([sys.executable, "-m", "workbench.cli", "plan", str(path), "--out", str(out), "--until", "arms"],
                         check=False, capture_output=True, text=True, timeout=300)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "the object's final placement penetrates vase" in run.stderr and not out.exists()
    check = subprocess.run([sys.executable, "-m", "workbench.cli", "check", str(path)], check=False, capture_output=True, text=True,
                           timeout=300)
    assert check.returncode == 1 and "PROBLEM: the object's final placement penetrates vase" in check.stdout
    session = Session.create(tmp_path / "direct", scene, 0)  # the workbench's way in: run_pipeline validates too
    with pytest.raises(InvalidTask, match="penetrates vase"):
        run_pipeline(session, "arms")
    assert session.finished() == []


@pytest.mark.slow
def test_check_says_what_the_reach_distance_is():
    run = subprocess.run([sys.executable, "-m", "workbench.cli", "check", "default"], check=False, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert "The distance is the closest that centre came" in run.stdout and "cm short" in run.stdout
    assert "arms: right picks, left places" in run.stdout


# --- the grasp steps fail on an empty list -------------------------------------------------------

@pytest.mark.slow
def test_an_object_with_no_force_closed_grasp_fails_at_the_grasp_step(tmp_path):
    slab = trimesh.creation.box([0.45, 0.45, 0.32])  # wider than the hand opens every way
    slab.apply_translation([0, 0, 0.16])
    slab.export(tmp_path / "slab.stl")
    path = _with_object(tmp_path, 'mesh = "slab.stl"', "initial = { xyz = [0.72, -0.75, 0.72], rpy = [0.0, 0.0, 0.0] }")
    text = path.read_text().replace("final = { xyz = [0.50, 0.85, 0.72], rpy = [0.0, 0.0, 2.7] }",
                                    "final = { xyz = [0.72, 0.55, 0.72], rpy = [0.0, 0.0, 0.0] }")
    path.write_text(text.replace('name = "default"', 'name = "slab"\nhandover = true'))
    session = Session.create(tmp_path / "s", load_task(path), 0)
    warned: list[str] = []
    few = {"positions": 6, "orientations": 6}
    with pytest.raises(StepFailed) as info:
        run_pipeline(session, "double_grasps", {"pick_grasps": few, "place_grasps": few}, warn=warned.append)
    assert info.value.step == "pick_grasps" and "no force-closed grasp of the right hand" in info.value.failure
    stats = session.record_of("pick_grasps")["stats"]
    assert f"frames tried: {stats['frames']}" in info.value.failure and stats["frames"] > 0
    assert "force-closed: 0" in info.value.failure and stats["failure"] == info.value.failure
    assert session.finished() == ["arms", "pick_grasps"]  # the placing hand's list was never computed
    assert any("wider than the robot's hands open" in w for w in warned)


# --- arm assignment ------------------------------------------------------------------------------

def _placed(scene, initial_xy, final_xy=None, handover=False):
    final = scene.object_final if final_xy is None else pose(np.array([*final_xy, 0.72]), np.array([0.0, 0.0, 2.7]))
    return dataclasses.replace(scene, object_initial=pose(np.array([*initial_xy, 0.72]), np.array([0.0, 0.0, 1.2])),
                               object_final=final, handover=handover)


def test_both_arms_reach_both_placements_the_lower_exchange_cost_is_chosen(default_scene, default_collision):
    scene = _placed(default_scene, (0.45, -0.45), (0.45, 0.30), handover=True)
    reaches = placement_reach(scene, default_collision.checker())
    assert all(r.reachable for per_arm in reaches.values() for r in per_arm.values())
    d = decide(scene, reaches)
    assert not d.failure and d.handover and set(d.costs) == {"right>left", "left>right"}
    assert d.costs[f"{d.picking_arm}>{d.placing_arm}"] == min(d.costs.values())
    assert (d.picking_arm, d.placing_arm) == ("right", "left")  # not crossing the arms over the desk
    assert "lower estimated exchange cost" in d.choice


def test_one_arm_reaches_both_no_handover_unless_asked(tmp_path, default_scene):
    # the case: the statuette 7 cm nearer the robot is reached by both arms, so the left reaches both placements
    # and carries the object itself (planned through the motion in test_motion.py)
    path = _with_object(tmp_path, 'mesh = "statuette"', "initial = { xyz = [0.45, -0.78, 0.72], rpy = [0.0, 0.0, 1.2] }")
    session = Session.create(tmp_path / "direct", load_task(path), 0)
    run_pipeline(session, "arms")
    arms = session.result("arms")
    assert (arms.picking_arm, arms.placing_arm, arms.handover, arms.failure) == ("left", "left", False, "")
    assert "no handover is needed: the left arm reaches both placements" in arms.choice
    assert "handover = true" in arms.choice and "--set arms.picking_arm" in arms.choice
    asked = _task(tmp_path, path.read_text().replace('name = "default"', 'name = "asked"\nhandover = true'), "asked.toml")
    session = Session.create(tmp_path / "asked", load_task(asked), 0)
    run_pipeline(session, "arms")
    arms = session.result("arms")
    assert (arms.picking_arm, arms.placing_arm, arms.handover) == ("right", "left", True)
    assert "the task asks for a handover" in arms.choice


@pytest.mark.slow
def test_no_pair_of_arms_fails_with_the_forcing_hint(default_scene, default_collision):
    scene = _placed(default_scene, (0.45, -1.6))  # beyond every arm
    d = decide(scene, placement_reach(scene, default_collision.checker()))
    assert "the initial placement is reached by no arm" in d.failure and "--set arms.picking_arm=ARM" in d.failure
    assert check_task(scene).problems[-1] == d.failure  # check reports it in the same words


def test_geometric_median_minimises_the_distance_sum():
    points = np.random.default_rng(3).normal(size=(4, 3))
    m = geometric_median(points)
    total = lambda e: np.linalg.norm(points - e, axis=1).sum()
    assert all(total(m) <= total(m + d) + 1e-9 for d in 1e-3 * np.vstack([np.eye(3), -np.eye(3)]))


# --- shared seeds and caches ---------------------------------------------------------------------

@pytest.mark.slow
def test_grasps_and_plan_share_a_cached_list(tmp_path, monkeypatch):
    assert PICK_STEP.seed(7) == PLACE_STEP.seed(7) and session_grasp_seed(7) != session_grasp_seed(8)
    listing = tmp_path / "list.json"
    run = subprocess.run([sys.executable, "-m", "workbench.cli", "grasps", "default", "--hand", "right", "--frames", "80",
                          "--seed", "5", "--json", str(listing)], check=False, capture_output=True, text=True, timeout=300)
    assert run.returncode in (0, 1), run.stderr
    computed = json.loads(listing.read_text())
    session = Session.create(tmp_path / "s", load_task("default"), 5)
    forbid(monkeypatch, "planner.grasping.grasp_list.compute_grasp_list")  # the very entry `grasps` wrote, not a recomputation
    try:
        run_pipeline(session, "pick_grasps", {"pick_grasps": {"orientations": 1, "min_clear": 0}})  # no denser search
    except StepFailed:
        pass
    planned = session.result("pick_grasps")
    assert planned.frames_tried == computed["frames_tried"] and len(planned) == len(computed["grasps"])


def test_reach_is_the_same_in_check_and_the_arms_step(tmp_path, default_scene):
    report = check_task(default_scene)
    session = Session.create(tmp_path / "s", default_scene, 123)
    run_pipeline(session, "arms")
    arms = session.result("arms")
    for placement, per_arm in report.reach.items():
        for arm, r in per_arm.items():
            assert math.isclose(arms.distances[placement][arm], r.distance)


# --- grasp and place configurations --------------------------------------------------------------

def test_wide_starts_find_place_configurations_the_near_rest_ones_miss(default_scene):
    from planner.collision.hand_placement import ObstacleTest, environment_filter
    from planner.collision.object_obstacle import ObjectCollision
    from planner.grasping.grasp_list import GraspParams, grasp_list
    from planner.handover.config_score import ConfigScorer
    from planner.handover.grasp_configs import ConfigSampler, GraspConfigParams, hand_configurations

    robot = default_scene.robot
    grasps, _ = grasp_list(robot.spec, "left", default_scene.object_mesh, GraspParams(positions=30, orientations=30), 1)
    collision = ObjectCollision(default_scene)
    free = environment_filter(robot, grasps, default_scene.object_final,
                              ObstacleTest.of_environment(default_scene.environment, collision.model.params.env_padding))
    found = {}
    for wide in (0, 16):
        p = GraspConfigParams(wide_attempts=wide)
        sampler = ConfigSampler(robot, collision, ConfigScorer(robot, p.weights()), p)
        configs = hand_configurations(sampler, grasps, np.flatnonzero(free), default_scene.object_final, robot.q_rest,
                                      np.random.default_rng(0))
        found[wide] = set(configs.rank.tolist())
        for q in configs.q:
            assert robot.within_limits(q) and not collision.in_collision(q, default_scene.object_final, ("left",))
    assert found[0] < found[16]  # the same grasps and more: the wide starts only run for grasps the first ones missed
    spread = np.std([ConfigSampler(robot, collision, None, GraspConfigParams()).body(np.random.default_rng(k), ["right"], wide=True)
                     [robot.torso_idx] for k in range(50)], axis=0)
    t = robot.torso_idx
    uniform = (robot.upper[t] - robot.lower[t]) / np.sqrt(12)  # the spread of a uniform draw over each range
    assert np.all(np.abs(spread / uniform - 1) < 0.3) and np.all(spread > 2 * GraspConfigParams().torso_sigma)


def test_free_arm_and_torso_stay_near_where_the_task_holds_them(default_scene):
    """The pick configurations keep the free arm and the torso near the robot's start configuration (the default
    task's elbows are bent, the rest's straight), the place ones near its end; `free_around = "rest"` near the rest."""
    from planner.collision.object_obstacle import ObjectCollision
    from planner.grasping.grasp_list import GraspParams, grasp_list
    from planner.handover.grasp_configs import GraspConfigParams, HandJob, hand_job

    robot, scene = default_scene.robot, default_scene
    collision = ObjectCollision(scene)
    for role, arm, placed, task_q in (("pick", "right", scene.object_initial, scene.q_initial),
                                    ("place", "left", scene.object_final, scene.q_final)):
        grasps, _ = grasp_list(robot.spec, arm, scene.object_mesh, GraspParams(positions=30, orientations=30), 1)
        free_arm = robot.arm_idx["left" if arm == "right" else "right"]
        body = np.concatenate([robot.torso_idx, free_arm])
        assert np.linalg.norm(task_q[body] - robot.q_rest[body]) > 1.0  # the two centres are far apart
        for around, center in (("task", task_q), ("rest", robot.q_rest)):
            p = GraspConfigParams(free_around=around, wide_attempts=0)
            _, configs, _ = hand_job(HandJob(role, scene, collision, p, grasps, placed, robot.q_rest, np.random.default_rng(0)))
            assert len(configs.q) >= 2
            for q in configs.q:
                assert not collision.in_collision(q, placed, (arm,))
                # the free arm is never moved by IK: within 5 sigma of its centre, joint by joint
                assert np.all(np.abs(q[free_arm] - center[free_arm]) <= 5 * p.free_arm_sigma + 1e-9), (role, around)


def test_forced_arms_are_checked_before_the_reach_search(tmp_path, default_scene):
    from planner.core.errors import RegraspError

    session = Session.create(tmp_path / "s", default_scene, 0)
    with pytest.raises(RegraspError, match=r"arms of the robot \(right, left; the same one twice for a direct transfer\); "
                                           r"got 'middle' and 'left'"):
        run_pipeline(session, "arms", {"arms": {"picking_arm": "middle", "placing_arm": "left"}})
    run_pipeline(session, "arms", {"arms": {"picking_arm": "left", "placing_arm": "right"}})  # forcing stays possible
    arms = session.result("arms")
    assert (arms.picking_arm, arms.placing_arm, arms.choice) == ("left", "right", "forced by the step's parameters")
    run_pipeline(session.branch(tmp_path / "one", before="arms"), "arms", {"arms": {"picking_arm": "right", "placing_arm": "right"}})
    arms = Session.open(tmp_path / "one").result("arms")
    assert (arms.picking_arm, arms.placing_arm, arms.handover) == ("right", "right", False)
