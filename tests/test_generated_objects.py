"""End to end through double grasps (slow): the Baxter task, a millimetre mesh with its scale, and a both-arms-reach task
asking for a handover. The generated objects' success table is a measurement, not a test: `python tests/generated_objects.py`
prints it (24 plans, too long for the suite)."""
from __future__ import annotations

from pathlib import Path

import pytest
from generated_objects import (
    TASK_TEXT_ROBOT,
    plan_outcome,
    succeeded,
)

from planner.model.object_mesh import load_object_mesh
from planner.model.statuette import STATUETTE_PATH

pytestmark = pytest.mark.slow
SEED = 3  # the session tests' seed: grasp lists of the same hand and object come from the shared test cache
QUICK_CONFIGS = {"grasp_configs": {"wide_attempts": 0}}  # the near-rest IK starts only: these test the objects, not the IK


def test_baxter_task_plans_through_double_grasps(tmp_path):
    outcome = plan_outcome(Path("baxter"), tmp_path / "s", SEED, QUICK_CONFIGS)
    assert succeeded(outcome), outcome


def test_millimetre_mesh_with_its_scale_plans(tmp_path):
    load_object_mesh(STATUETTE_PATH).apply_scale(1000.0).export(tmp_path / "horse_mm.stl")
    task = tmp_path / "mm.toml"
    task.write_text(TASK_TEXT_ROBOT.replace('mesh = "statuette"', 'mesh = "horse_mm.stl"\nscale = 0.001'))
    outcome = plan_outcome(task, tmp_path / "s", SEED, QUICK_CONFIGS)
    assert succeeded(outcome), outcome


def test_both_arms_reach_and_the_task_asks_for_a_handover(tmp_path):
    task = tmp_path / "near.toml"  # the case: the statuette 7 cm nearer the robot, where both arms reach it
    text = TASK_TEXT_ROBOT.replace("initial = { xyz = [0.45, -0.85, 0.72]", "initial = { xyz = [0.45, -0.78, 0.72]")
    task.write_text(text.replace('name = "default"', 'name = "near"\nhandover = true'))
    outcome = plan_outcome(task, tmp_path / "s", SEED, QUICK_CONFIGS)
    assert succeeded(outcome), outcome
