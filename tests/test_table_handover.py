"""The table handover (issue 36): a 5 cm cube or a 4.5 cm x 9 cm can on the default desk leaves no pair of grasps that
keeps the two Allegro hands apart, so the right hand sets it down where the left takes it.

The placements are checked with the oracle's own geometry (python-fcl on the obstacles' shapes) and the mesh's
vertices; the motion end to end: the object held by one hand, then at rest on the desk, then held by the other, every
sample re-checked by the independent oracle (tests/oracle.py).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from generated_objects import TASK_TEXT_ROBOT
from oracle import Oracle, grasp_offset, motion_collisions
from test_motion_workers import sampled_runs, transit_runs

from planner.core.results import load_result, save_result
from planner.core.runner import run_pipeline, run_step
from planner.core.session import Session
from planner.core.steps import StepFailed
from planner.model.shapes import box, cylinder, obj_text, on_desk
from planner.model.task import load_task
from planner.motion.result import PHASES, TABLE_PHASES, Motion
from planner.pipeline import step_named
from planner.regrasp.placements import PlacementParams, stable_placements
from workbench.layers.arms import ARM_COLORS
from workbench.layers.motion import route_segments, table_one
from workbench.layers.phases import PHASE_COLORS
from workbench.layers.placements import BOTH_COLOR, NONE_COLOR, reach_colors

DESK_TOP = 0.72  # m: the default desk's top surface (assets/tasks/default.toml)
CUBE_GRASPS = {"positions": 40, "orientations": 60}  # 4,860 frames: a cube's hundreds of grasps, 6 s a hand instead of 36
SHARED_ROADMAP = {"roadmap": {"task_nodes": 0}}  # the desk's roadmap without the task's sites, built once for every task
CUBE_PARAMS = {**SHARED_ROADMAP, "pick_grasps": CUBE_GRASPS, "place_grasps": CUBE_GRASPS}
CAN_GRASPS = {"positions": 20, "orientations": 60}  # 2,880 frames: enough grasps clear the desk without a denser search
SMALL_OBJECT_PARAMS = {"cube": CUBE_PARAMS, "can": {**SHARED_ROADMAP, "pick_grasps": CAN_GRASPS, "place_grasps": CAN_GRASPS}}
EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


SMALL_OBJECTS = {"cube": lambda: box((0.05, 0.05, 0.05)), "can": lambda: cylinder(0.0225, 0.09)}  # 5 cm; 4.5 x 9 cm


def small_object_task(folder: Path, name: str = "cube") -> Path:
    """The default task with a small object (a 5 cm cube, or a 4.5 cm x 9 cm can) instead of the statuette."""
    mesh = folder / f"{name}.obj"
    mesh.write_text(obj_text(on_desk(SMALL_OBJECTS[name]())))
    task = folder / f"{name}.toml"
    task.write_text(TASK_TEXT_ROBOT.replace('mesh = "statuette"', f'mesh = "{mesh}"'))
    return task


@pytest.fixture(scope="module")
def cube_scene(tmp_path_factory):
    return load_task(small_object_task(tmp_path_factory.mktemp("cube")))


@pytest.mark.slow
def test_placements_rest_on_a_support_clear_of_every_other_obstacle(cube_scene):
    scene = cube_scene
    placements, seconds = stable_placements(scene, PlacementParams(0.2, 2, 0.05, 2, 0.02))
    assert [s["stage"] for s in placements.stages][0] == "resting poses" and len(seconds) == len(placements.stages)
    assert placements.stages[0]["count"] == 6  # a cube rests on any of its faces
    assert len(placements) and np.allclose(placements.probability, 1 / 6, atol=0.02)
    oracle = Oracle(scene)
    obstacles = {ob.name: ob for ob in scene.environment}
    vertices = np.asarray(scene.object_mesh.vertices)
    for T, support in zip(placements.pose, placements.support):
        world = vertices @ T[:3, :3].T + T[:3, 3]
        ob = obstacles[support]
        top = ob.pose[2, 3] + ob.size[2] / 2
        assert abs(world[:, 2].min() - top) < 1e-9, "the object does not rest on its support"
        local = (world - ob.pose[:3, 3]) @ ob.pose[:3, :3]
        assert np.all(np.abs(local[:, :2]) <= np.asarray(ob.size[:2]) / 2 + 1e-9), "the object overhangs its support"
        assert not oracle.object_obstacle_hits(T, {support}), "the object hits an obstacle"
    both = placements.reached.all(axis=1)
    assert both.any() and not np.any(np.diff(both.astype(int)) > 0), "placements both arms reach come first"


def test_the_placements_step_is_recorded_and_drawn(tmp_path, cube_scene):
    """The step's result goes through its session files unchanged; every placement rests on a support the task names,
    and the layer colours each by the arms that reach it."""
    session = Session.create(tmp_path / "session", cube_scene, 0)
    run_step(session, step_named("placements"), {"spacing": 0.3, "headings": 1, "seeds": 1})  # it needs nothing but the scene
    again = Session.open(tmp_path / "session").result("placements")
    first = session.result("placements")
    assert np.array_equal(again.pose, first.pose) and np.array_equal(again.reached, first.reached) and again.stages == first.stages
    assert len(again) and set(again.support) <= {ob.name for ob in cube_scene.environment}
    assert again.stats()["reached_by_both"] == int(again.reached.all(axis=1).sum())
    colors = reach_colors(np.array([[True, True], [True, False], [False, True], [False, False]]))
    assert [tuple(c) for c in colors] == [BOTH_COLOR, ARM_COLORS[0], ARM_COLORS[1], NONE_COLOR]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SMALL_OBJECTS))
def test_a_small_object_is_handed_over_through_the_table(tmp_path, name, monkeypatch):
    sampled = sampled_runs(monkeypatch)
    scene = load_task(small_object_task(tmp_path, name))
    session = Session.create(tmp_path / "session", scene, 0)
    run_pipeline(session, params=SMALL_OBJECT_PARAMS[name])
    m = session.result("motion")
    assert not m.failure and m.strategy == "table"
    # each of the five transit jobs (Grasp, Set down, Regrasp, Carry, Rest) smoothed the run its transit completes
    (pieces, made), = sampled
    transits = transit_runs(pieces)
    assert len(transits) == 5 and set(transits) <= set(made)
    rejected = {a["strategy"]: a["failure"] for a in m.alternatives}
    assert set(rejected) == {"handover", "regrasp"} and rejected["handover"].startswith("double grasps:")
    assert rejected["regrasp"].startswith("arms:")  # the two arms: no hand picks and places
    assert [t["kind"] for t in m.sequence] == ["pick", "set down", "take", "carry", "place"]
    assert m.sequence[1]["hand"] != m.sequence[2]["hand"] and m.sequence[1]["at"] >= 0
    assert session.result("double_grasps").failure  # recorded, and the pipeline went on to the motion
    first, second = moved_through_a_placement(session, m)
    assert m.holder[first[0]] != m.holder[second[0]]  # held by one hand, at rest, held by the other
    # forced to hand over in the air, the motion fails naming the stage that removed every double grasp
    branch = session.branch(tmp_path / "handover", "motion")
    with pytest.raises(StepFailed, match="handover strategy: double grasps: no compatible pair"):
        run_pipeline(branch, params={**SMALL_OBJECT_PARAMS[name], "motion": {"strategy": "handover"}})


def moved_through_a_placement(session, m) -> tuple[np.ndarray, np.ndarray]:
    """The samples of the two spans where a hand holds the object, checked: the object at rest before, between (on the
    desk, at the motion's intermediate placement) and after them; the phases in time Grasp, Set down, Regrasp, Carry,
    Place, Rest, each named; the object at its final placement at the end; every sample clear by the oracle."""
    scene = session.scene
    runs = held_spans(m)
    assert len(runs) == 5 and runs[0] == runs[2] == runs[4] == -1 and runs[1] >= 0 and runs[3] >= 0, runs
    held = np.flatnonzero(m.holder >= 0)
    gap = int(np.flatnonzero(np.diff(held) > 1)[0])
    first, second = held[: gap + 1], held[gap + 1:]
    between = np.arange(first[-1] + 1, second[0])
    assert len(between) > 1 and np.allclose(m.object_pose[between], m.object_pose[between[0]])
    rest = m.object_pose[between[0]]
    assert np.allclose(rest, np.asarray(m.intermediate), atol=1e-6)
    low = (np.asarray(scene.object_mesh.vertices) @ rest[:3, :3].T + rest[:3, 3])[:, 2].min()
    assert abs(low - DESK_TOP) < 1e-4, f"the object rests {low - DESK_TOP:+.4f} m off the desk"
    assert not np.allclose(rest, scene.object_initial) and not np.allclose(rest, scene.object_final)
    order = [m.phase_names[int(p)] for k, p in enumerate(m.phase) if k == 0 or p != m.phase[k - 1]]
    assert order == ["Grasp", "Set down", "Regrasp", "Carry", "Place", "Rest"], order
    assert [row["phase"] for row in m.phases] == list(m.phase_names)
    assert np.allclose(m.object_pose[-1], scene.object_final, atol=1e-4)
    bad = motion_collisions(session, m)
    assert not bad, f"{len(bad)} colliding configurations, first: {bad[:3]}"
    assert grasp_offset(session, m) < 2e-4, "a hand holds the object away from its listed grasp"
    return first, second


def held_spans(m) -> list[int]:
    """The holder of each span of samples where it stays the same (-1: the object at rest)."""
    return [int(h) for k, h in enumerate(m.holder) if k == 0 or h != m.holder[k - 1]]


def _motion(phases: list[int], names: tuple, **extra) -> Motion:
    """A small motion result with these phase integers (robot of 2 joints, 2 arms)."""
    n = len(phases)
    rows = [{"phase": name, "nodes_planning": 0, "nodes_validating": 0, "edges_invalidated": 0, "rrt_calls": 0, "searches": 0,
             "transit_checks": 0, "smoothing_checks": 0, "path_length": 0.0, "straight_distance": 0.0, "duration": 0.0}
            for name in names]
    return Motion("roadmap", -1, [""], rows, ["right", "left"], {}, [], "", np.arange(n) / 30.0, np.zeros((n, 2)),
                  np.array(phases, np.int8), np.tile(np.eye(4), (n, 1, 1)), np.full(n, -1, np.int8), np.full(n, -1, np.int8),
                  np.zeros((n, 2, 3)), np.zeros(5, np.int64), ("a", "b"), names, **extra)


def test_a_table_motion_names_its_phases_and_keeps_them_in_its_files(tmp_path):
    table = _motion([0, 4, 5, 1, 2, 3], TABLE_PHASES, strategy="table", intermediate=tuple(map(tuple, np.eye(4))),
                    alternatives=({"strategy": "handover", "failure": "double grasps: none"},))
    assert [table.phase_name(int(p)) for p in table.phase] == ["Grasp", "Set down", "Regrasp", "Carry", "Place", "Rest"]
    assert table.phase_name(9) == "phase 9"  # a session is untrusted: an integer it names no phase for
    text = table_one(table, None)
    assert "Set down" in text.splitlines()[0] and "Regrasp" in text.splitlines()[0]
    _, colors = route_segments(table)
    assert tuple(colors[0][0]) == PHASE_COLORS[4] and tuple(colors[2][0]) == PHASE_COLORS[5]  # two wrists a sample
    save_result(table, tmp_path, "table")
    again = load_result(Motion, tmp_path, "table")
    assert (again.phase_names, again.strategy, again.alternatives[0]["strategy"]) == (TABLE_PHASES, "table", "handover")
    handover = _motion([0, 1, 2, 3], PHASES)
    save_result(handover, tmp_path, "handover")
    written = json.loads((tmp_path / "handover.json").read_text())
    assert not {"phase_names", "strategy", "alternatives", "intermediate"} & set(written)  # as sessions before them
    assert load_result(Motion, tmp_path, "handover").phase_names == PHASES
