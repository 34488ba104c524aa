"""The intermediate placements of the example session: the task's own orientations are among them, and they are
ordered as the table handover wants them (both arms reaching first, then the least travel and turning), each figure
recomputed here from the poses alone."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.core.session import Session
from planner.regrasp.placements import PlacementParams

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


@pytest.fixture(scope="module")
def example():
    s = Session.open(EXAMPLE)
    return s.scene, s.result("placements")


def angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1.0) / 2.0, -1.0, 1.0)))


def test_the_task_orientations_are_among_the_placements(example):
    scene, placements = example
    oi, of = scene.object_initial[:3, :3], scene.object_final[:3, :3]
    total = angle(oi, of)
    assert total > 0.1, "the example's object turns between its placements"
    turns = np.array([[angle(T[:3, :3], oi), angle(T[:3, :3], of)] for T in placements.pose])
    assert np.any(turns[:, 0] < 1e-6) and np.any(turns[:, 1] < 1e-6), "the initial or the final orientation is missing"
    assert np.any(np.abs(turns - total / 2).max(axis=1) < 1e-6), "the orientation halfway between them is missing"


def test_placements_come_by_reach_then_by_travel_and_turning(example):
    scene, placements = example
    turn = PlacementParams().turn
    com = np.asarray(scene.object_mesh.center_mass, float)

    def centre(T):
        return T[:3, :3] @ com + T[:3, 3]

    ends = (scene.object_initial, scene.object_final)
    both = placements.reached.all(axis=1)
    assert both.any() and not np.any(np.diff(both.astype(int)) > 0), "placements both arms reach come first"
    way = np.array([sum(np.linalg.norm(centre(T) - centre(E)) + turn * angle(T[:3, :3], E[:3, :3]) for E in ends)
                    for T in placements.pose[both]])
    assert np.all(np.diff(way) > -0.01 - 1e-9), "a placement comes before one the object reaches with less travel and turning"
    assert way[0] <= way.min() + 0.01
