"""The same-hand regrasp (issue 36): one arm picks and places a 5 cm cube on the right of the default desk, setting it
down on the way and taking it again in another grasp.

The motion end to end: the object held by the right hand, at rest on the desk, held by the right hand again with the
palm elsewhere on the object; every sample re-checked by the independent oracle (tests/oracle.py).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_table_handover import CUBE_PARAMS, moved_through_a_placement, small_object_task

from planner.core.runner import run_pipeline
from planner.core.session import Session
from planner.model.task import load_task

RIGHT_ONLY = ("{ xyz = [0.45, -0.80, 0.72], rpy = [0.0, 0.0, 0.3] }", "{ xyz = [0.55, -0.50, 0.72], rpy = [0.0, 0.0, 1.1] }")


def right_side_task(folder: Path) -> Path:
    """The cube task with both placements on the right, where the right arm reaches both: it picks and places."""
    task = small_object_task(folder)
    text = task.read_text()
    text = text.replace("initial = { xyz = [0.45, -0.85, 0.72], rpy = [0.0, 0.0, 1.2] }", f"initial = {RIGHT_ONLY[0]}")
    text = text.replace("final = { xyz = [0.50, 0.85, 0.72], rpy = [0.0, 0.0, 2.7] }", f"final = {RIGHT_ONLY[1]}")
    assert RIGHT_ONLY[1] in text
    task.write_text(text)
    return task


@pytest.mark.slow
def test_one_arm_sets_the_cube_down_and_takes_it_again_in_another_grasp(tmp_path):
    scene = load_task(right_side_task(tmp_path))
    session = Session.create(tmp_path / "session", scene, 0)
    run_pipeline(session, params={**CUBE_PARAMS, "motion": {"strategy": "regrasp"}})
    arms = session.result("arms")
    assert arms.picking_arm == arms.placing_arm == "right" and not arms.handover
    m = session.result("motion")
    assert not m.failure and m.strategy == "regrasp" and not m.alternatives  # forced: nothing else was allowed
    assert [t["kind"] for t in m.sequence] == ["pick", "set down", "take", "carry", "place"]
    first, second = moved_through_a_placement(session, m)
    assert m.holder[first[0]] == m.holder[second[0]] == m.arms.index("right")  # the right hand, at rest, the right hand
    # another grasp: the palm sits elsewhere on the object in the second span
    robot = scene.robot
    palm = robot.palm_frame("right")
    grips = [np.linalg.inv(m.object_pose[k]) @ robot.frame_placement(m.q[k], palm) for k in (first[-1], second[-1])]
    assert not np.allclose(grips[0], grips[1], atol=1e-3)
