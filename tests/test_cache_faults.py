"""Caches are disposable: an entry that cannot be read is deleted, recomputed (to the same result) and the user told so
in one line; nothing outside the cache is touched."""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sandbox import forbid, regrasp, snapshot

from planner.model.task import Scene


@dataclass(frozen=True)
class Entry:
    """One kind of cache entry: how to compute-or-load it, which files hold it, and what of it must come back equal."""

    kind: str  # the cache folder
    what: str  # how the warning names it
    get: Callable[[Scene], Any]
    same: Callable[[Any], Any]
    builder: str  # the function that computes an entry ('module.name'): forbidden where the cache must serve


def _grasps(scene: Scene) -> Any:
    from planner.grasping.grasp_list import GraspParams, grasp_list

    return grasp_list(scene.robot.spec, "right", scene.object_mesh, GraspParams(positions=3, orientations=3), 0, workers=1)[0]


def _roadmap(scene: Scene) -> Any:
    from planner.roadmap import RoadmapParams, roadmap_for

    return roadmap_for(scene, RoadmapParams(nodes=3, task_nodes=0), 1)[0]


def _pairs(scene: Scene) -> Any:
    from planner.collision.checker import simplified_robot_geometry
    from planner.collision.pairs import CollisionParams, robot_pair_set

    return robot_pair_set(scene.robot, simplified_robot_geometry(scene.robot), CollisionParams(prune_samples=20))


def _workspaces(scene: Scene) -> Any:
    from planner.grasping.finger_workspace import WorkspaceParams, hand_workspaces
    from planner.model.hand_model import load_hand_model

    return hand_workspaces(load_hand_model(scene.robot.spec.arm("right").hand), WorkspaceParams(samples_per_joint=5))


def _object(scene: Scene) -> Any:
    from planner.grasping.object_model import object_model

    return object_model(scene.object_mesh, 0.006)


ENTRIES = {
    "grasps": Entry("grasps", "grasp list of the right hand", _grasps,
                    lambda g: g.to_json(0.0), "planner.grasping.grasp_list.compute_grasp_list"),
    "roadmaps": Entry("roadmaps", "roadmap", _roadmap, lambda r: (r.node_q.tolist(), r.edges.tolist()),
                      "planner.roadmap.step.build_roadmap"),
    "collision_pairs": Entry("collision_pairs", "self-collision pair set", _pairs, lambda p: p,
                             "planner.collision.pairs.compute_pair_set"),
    "workspaces": Entry("workspaces", "workspaces", _workspaces, lambda ws: [w.centres.tolist() for w in ws],
                        "planner.grasping.finger_workspace.finger_workspace"),
    "objects": Entry("objects", "objects", _object, lambda o: o.points.tolist(), "planner.grasping.object_model.build_object_model"),
}


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _wrong_fields(path: Path) -> None:
    path.write_text('{"kept": 3}' if path.suffix == ".json" else "")


CASES = [("grasps", ".npz", _truncate), ("grasps", ".json", _truncate), ("grasps", ".json", _wrong_fields),
         ("roadmaps", ".npz", _truncate), ("roadmaps", ".json", _truncate), ("roadmaps", ".json", _wrong_fields),
         ("collision_pairs", ".json", _truncate), ("collision_pairs", ".json", _wrong_fields),
         ("workspaces", ".npz", _truncate), ("workspaces", ".npz", _wrong_fields), ("objects", ".npz", _truncate)]


@pytest.mark.parametrize(("kind", "suffix", "damage"), CASES,
                         ids=[f"{k}-{s.lstrip('.')}-{d.__name__.strip('_')}" for k, s, d in CASES])
def test_unreadable_entry_is_deleted_recomputed_and_told(default_scene: Scene, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         caplog: pytest.LogCaptureFixture, kind: str, suffix: str,
                                                         damage: Callable[[Path], None]) -> None:
    entry = ENTRIES[kind]
    cache = tmp_path / "cache"
    monkeypatch.setenv("REGRASP_CACHE", str(cache))
    first = entry.same(entry.get(default_scene))
    files = sorted((cache / kind).rglob(f"*{suffix}"))
    assert len(files) == 1, files
    damage(files[0])
    outside = snapshot(tmp_path, skip=(cache,))
    caplog.clear()  # the first build's lines are caught too when an earlier test left the logger at INFO
    with caplog.at_level(logging.WARNING, logger="regrasp.cache"):
        again = entry.same(entry.get(default_scene))
    warnings = [r.getMessage() for r in caplog.records if r.name == "regrasp.cache"]
    assert len(warnings) == 1, warnings
    assert f"the cached {entry.what} in {files[0].parent}" in warnings[0] and "deleted it, recomputing" in warnings[0]
    assert "\n" not in warnings[0]
    assert again == first, "the recomputed entry differs from the first"
    caplog.clear()
    forbid(monkeypatch, entry.builder)
    with caplog.at_level(logging.WARNING, logger="regrasp.cache"):
        assert entry.same(entry.get(default_scene)) == first
    assert not caplog.records, "the recomputed entry was not written back readable"
    assert snapshot(tmp_path, skip=(cache,)) == outside


@pytest.mark.slow
def test_cli_tells_a_corrupt_grasp_cache_in_one_line(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    args = ("grasps", "--hand", "right", "--frames", "2", "--json", str(tmp_path / "g.json"))
    first = regrasp(*args, REGRASP_CACHE=str(cache))
    assert first.returncode == 0, first.stderr
    [npz] = (cache / "grasps").rglob("grasps.npz")
    npz.write_bytes(b"PK\x03\x04 truncated")
    run = regrasp(*args, REGRASP_CACHE=str(cache))
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    told = [line for line in run.stderr.splitlines() if "cached" in line]
    assert len(told) == 1 and told[0].startswith("warning: the cached grasp list of the right hand") and str(npz.parent) in told[0]
    with np.load(npz) as rewritten:
        assert rewritten.files, "the recomputed list was not written back"
