"""Grasp configurations, exchange position and double grasps on the default task: every configuration re-checked
independently, the exchange node minimal over the free nodes, the ranking as documented, determinism, and the
stage-named failure of a task whose object only the placing arm can reach."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
import trimesh
from oracle import Oracle

from planner.core.paths import ASSETS
from planner.core.runner import run_pipeline
from planner.core.session import Session
from planner.handover.exchange_grid import PalmWaypoints, exchange_costs

SEED = 3  # as the session tests: the grasp lists come from the shared test cache
FEW_CONFIGS = {"grasp_configs": {"attempts": 2, "wide_attempts": 0}}  # a sixth of the IK starts
FEW_STARTS = tuple(a for k, v in FEW_CONFIGS["grasp_configs"].items() for a in ("--set", f"grasp_configs.{k}={v}"))
POSITION_TOL, ROTATION_TOL = 2e-3, 2e-2  # the step's IK tolerances
# m: how deep a holding hand may be in the object at these configurations: its grasp's (the grasp list's
# contact_clearance, 1 mm) plus how far the IK tolerances move a fingertip (the palm within POSITION_TOL, turned
# by up to ROTATION_TOL about its frame, the fingertips less than 0.2 m from it); the motion refines the palm onto its grasp
HELD_DEPTH = 1e-3 + POSITION_TOL + ROTATION_TOL * 0.2

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def planned(tmp_path_factory, default_scene):
    session = Session.create(tmp_path_factory.mktemp("dg") / "session", default_scene, seed=SEED)
    run_pipeline(session, until="double-grasps")
    return session


@pytest.fixture(scope="module")
def oracle(default_scene) -> Oracle:
    """The independent oracle (tests/oracle.py): full URDF meshes through python-fcl, no code shared with the checker;
    the holding hands as deep in the object as the IK tolerances let them (HELD_DEPTH)."""
    return Oracle(default_scene, depth=HELD_DEPTH)


def assert_holds(scene, q: np.ndarray, arm: str, grasps, rank: int, object_pose: np.ndarray) -> None:
    robot = scene.robot
    assert robot.within_limits(q), f"{arm} configuration outside the joint limits"
    palm = robot.frame_placement(q, robot.palm_frame(arm))
    target = object_pose @ grasps.hand_pose[rank]
    assert np.linalg.norm(palm[:3, 3] - target[:3, 3]) <= POSITION_TOL
    assert np.linalg.norm(pin.log3(palm[:3, :3].T @ target[:3, :3])) <= ROTATION_TOL
    np.testing.assert_array_equal(q[robot.hand_idx[arm]], grasps.finger_q[rank])


def test_grasp_and_place_configurations_are_valid(planned, oracle):
    scene = planned.scene
    configs = planned.result("grasp_configs")
    assert not configs.failure
    for role, grasps, pose, free in (("pick", planned.result("pick_grasps"), scene.object_initial, configs.pick_env_free),
                                     ("place", planned.result("place_grasps"), scene.object_final, configs.place_env_free)):
        hand = configs.hand(role)
        assert len(hand.rank) >= 1 and np.all(free[hand.rank]), f"{role}: a configuration for a grasp the filter removed"
        assert free.sum() < len(free), f"{role}: the environment filter removed nothing (the desk must cut grasps from below)"
        for rank, q in zip(hand.rank, hand.q):
            assert_holds(scene, q, hand.arm, grasps, int(rank), pose)
            assert oracle.collisions(q, pose, hand.arm, None, True) == []  # the object on its support, in the hand


def test_double_grasps_are_valid_and_ranked(planned, oracle):
    scene = planned.scene
    dg = planned.result("double_grasps")
    pick, place = planned.result("pick_grasps"), planned.result("place_grasps")
    a, b = dg.picking_arm, dg.placing_arm
    assert not dg.failure and len(dg) >= 4
    assert planned.record_of("double_grasps")["stats"]["double_grasps"] == len(dg)
    assert np.all(np.diff(dg.score) <= 1e-12), "double grasps are not best first"
    np.testing.assert_allclose(dg.score, dg.quality + dg.config)
    assert np.all((dg.quality > 0) & (dg.quality <= 1)) and np.all((dg.config > 0) & (dg.config <= 1))
    for n in range(len(dg)):
        r1, r2, T = int(dg.pick_rank[n]), int(dg.place_rank[n]), dg.object_exchange[n]
        assert_holds(scene, dg.q_grasp[n], a, pick, r1, scene.object_initial)
        assert_holds(scene, dg.q_place[n], b, place, r2, scene.object_final)
        assert_holds(scene, dg.q_exch[n], a, pick, r1, T)
        assert_holds(scene, dg.q_exch[n], b, place, r2, T)
        assert oracle.collisions(dg.q_grasp[n], scene.object_initial, a, None, True) == []
        assert oracle.collisions(dg.q_place[n], scene.object_final, b, None, True) == []
        assert oracle.collisions(dg.q_exch[n], T, a, b, False) == [], f"double grasp {n} at the exchange"  # the object too
        assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(T[:3, :3]), 1.0)


def test_exchange_node_is_the_cheapest_free_node(planned):
    scene = planned.scene
    x = planned.result("exchange")
    w = PalmWaypoints(*x.waypoints)
    d = lambda p, r: float(np.linalg.norm(p - r))
    brute = np.array([d(w.pick_initial, w.pick_grasp) + d(w.pick_grasp, e) + d(e, w.pick_final)
                      + d(w.place_initial, e) + d(e, w.place_place) + d(w.place_place, w.place_final) for e in x.nodes])
    np.testing.assert_allclose(x.cost, brute, atol=1e-12)
    np.testing.assert_allclose(exchange_costs(x.nodes, w), brute, atol=1e-12)
    free = np.flatnonzero(x.free)
    assert x.best[0] == free[np.argmin(brute[free])]
    assert np.all(np.diff(brute[x.best]) >= 0) and np.all(x.free[x.best])
    radius = float(np.max(np.linalg.norm(scene.object_mesh.vertices - scene.object_mesh.center_mass, axis=1)))
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=radius).apply_translation(x.position)
    manager = trimesh.collision.CollisionManager()
    for ob in scene.environment:
        manager.add_object(ob.name, ob.to_trimesh())
    assert not manager.in_collision_single(sphere), "the best exchange node's object sphere hits an obstacle"


def test_same_seed_same_double_grasps(default_scene, tmp_path):
    """Two sessions of one seed and parameters (few IK starts: a sixth of the work) write the same files, byte for byte."""
    first, again = (Session.create(tmp_path / name, default_scene, seed=SEED) for name in ("first", "again"))
    for session in (first, again):
        run_pipeline(session, until="double_grasps", params=FEW_CONFIGS)
    assert len(first.result("double_grasps")), "no double grasp to compare"
    for name in ("grasp_configs", "exchange", "double_grasps"):
        for file in (f"{name}.npz", f"{name}.json"):
            assert (first.folder / file).read_bytes() == (again.folder / file).read_bytes(), file


def test_exchange_ik_runs_with_the_sessions_grasp_config_parameters(planned, tmp_path, monkeypatch):
    """`--set grasp_configs.<p>` reaches the double grasps' exchange IK (only its torso_sigma is the double grasps' own),
    whose torso is sampled around the task's start, or around the rest with `free_around = "rest"`."""
    import planner.handover.double_grasps as step

    seen = []

    class Spy(step.ConfigSampler):
        def __init__(self, robot, collision, scorer, p):
            super().__init__(robot, collision, scorer, p)
            seen.append((p, self.center))

    monkeypatch.setattr(step, "ConfigSampler", Spy)
    scene = planned.scene
    for k, (around, center) in enumerate((("task", scene.q_initial), ("rest", scene.robot.q_rest))):
        branch = planned.branch(tmp_path / f"branch{k}", "grasp_configs")
        few = {"grasp_configs": {**FEW_CONFIGS["grasp_configs"], "ik_iterations": 31, "free_around": around},
               "double_grasps": {"torso_sigma": 0.05}}
        run_pipeline(branch, "double_grasps", few)
        (p, sampled_around), = seen[k:]
        assert (p.ik_iterations, p.torso_sigma) == (31, 0.05)
        np.testing.assert_array_equal(sampled_around, center)
    assert not np.array_equal(scene.q_initial, scene.robot.q_rest)  # the default task starts with its elbows bent


def _plan(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench.cli", "plan", *args], capture_output=True, text=True, timeout=900)


def test_plan_until_double_grasps_prints_the_stage_table(tmp_path):
    out = tmp_path / "s"
    run = _plan("default", "--out", str(out), "--seed", str(SEED), "--until", "double-grasps", *FEW_STARTS)  # a sixth of the IK
    assert run.returncode == 0, run.stderr
    for stage in ("pick grasps clear of the environment", "place grasp configurations", "free nodes",
                  "compatible pairs", "exchange configurations"):
        assert stage in run.stdout
    steps = json.loads((out / "session.json").read_text())["steps"]
    assert [s["name"] for s in steps][-3:] == ["grasp_configs", "exchange", "double_grasps"]
    assert steps[-1]["stats"]["double_grasps"] >= 4 and all(s["seconds"] >= 0 for s in steps)


def test_object_only_the_placing_arm_reaches_fails_at_the_pick_stage(tmp_path):
    text = (ASSETS / "tasks" / "default.toml").read_text()
    moved = text.replace("initial = { xyz = [0.45, -0.85, 0.72], rpy = [0.0, 0.0, 1.2] }",
                         "initial = { xyz = [0.50, 0.85, 0.72], rpy = [0.0, 0.0, 2.7] }")  # where the final one is
    assert moved != text, "the default task's initial placement changed: update this test"
    task = tmp_path / "left_only.toml"
    task.write_text(moved.replace('robot = "alex_allegro.toml"', f'robot = "{ASSETS / "robots" / "alex_allegro.toml"}"'))
    out = tmp_path / "s"
    # forced arms; every pick grasp misses its IK, so a few starts each say so as well as the default's 24
    forced = ("--set", "arms.picking_arm=right", "--set", "arms.placing_arm=left", *FEW_STARTS)
    run = _plan(str(task), "--out", str(out), "--seed", str(SEED), "--until", "double-grasps", *forced)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "Traceback" not in run.stderr
    assert "step 'grasp_configs' failed: no collision-free pick grasp" in run.stderr
    assert "pick grasp configurations: 0" in run.stderr
    assert "pick grasp configurations" in run.stdout  # the stage table is printed too
    steps = json.loads((out / "session.json").read_text())["steps"]
    assert steps[-1]["name"] == "grasp_configs" and "no collision-free pick grasp" in steps[-1]["stats"]["failure"]
    resumed = _plan(str(task), "--out", str(out), "--resume", "--until", "double-grasps", *FEW_STARTS)
    assert resumed.returncode == 1 and "no collision-free pick grasp" in resumed.stderr


def test_bench_double_grasps_json(default_scene, tmp_path):
    """Two runs of the online steps with `--set` (few IK starts), each as a session planned with the same parameters."""
    out = tmp_path / "bench.json"
    run = subprocess.run([sys.executable, "-m", "workbench.cli", "bench", "double-grasps", "--seed", str(SEED), "--repeat", "2",
                          *FEW_STARTS, "--json", str(out)], capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    figures = json.loads(out.read_text())
    assert len(figures["runs"]) == 2 and set(figures["runs"][0]) == {"grasp_configs", "exchange", "double_grasps"}
    same = Session.create(tmp_path / "same", default_scene, seed=SEED)
    run_pipeline(same, until="double-grasps", params=FEW_CONFIGS)
    assert figures["double_grasps"][0] == figures["double_grasps"][1] == len(same.result("double_grasps"))
    found = {name: [(row["stage"], row["count"]) for row in rows] for name, rows, _ in figures["stages"]}
    assert found["grasp_configs"] == [(row["stage"], row["count"]) for row in same.result("grasp_configs").stages]  # --set reached it
    assert "total" in run.stdout and "exchange configurations" in run.stdout
    bad = subprocess.run([sys.executable, "-m", "workbench.cli", "bench", "double-grasps", "--set", "grasp_configs.nope=1"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode != 0 and "nope" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
