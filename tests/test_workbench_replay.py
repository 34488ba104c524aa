"""Replaying a session recomputes nothing: the example's every step drawn in the workbench from its saved results, each
layer focused, each pose it offers, grasp rank, double grasp, exchange share, roadmap node and motion sample shown,
while the planner's expensive functions only count their calls (headless: no browser)."""
from __future__ import annotations

import shutil
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_workbench_browser import EXAMPLE, _free_port

from planner.collision.checker import CollisionChecker
from planner.collision.segments import SegmentChecker
from planner.core.session import Session
from planner.pipeline import PIPELINE
from workbench.app import Workbench
from workbench.layers.double_grasps import PHASES as PAIR_PHASES

# what builds a checker or a model, or plans: none of it may run while a session is replayed
EXPENSIVE = ("planner.collision.checker.build_collision_model", "planner.grasping.object_model.object_model",
             "planner.grasping.object_model.build_object_model", "planner.grasping.finger_workspace.hand_workspaces",
             "planner.grasping.finger_workspace.finger_workspace", "planner.grasping.grasp_list.compute_grasp_list",
             "planner.roadmap.build.build_roadmap", "planner.roadmap.build.roadmap_collision_model",
             "planner.motion.step.plan_motion")
CONSTRUCTORS = (CollisionChecker, SegmentChecker)


def _count_everywhere(monkeypatch: pytest.MonkeyPatch, target: str, calls: list[str]) -> None:
    """Replace the function at `target` ('module.name') by one that records its call and then runs it, in its module and
    in every loaded planner or workbench module that imported it by name."""
    module, name = target.rsplit(".", 1)
    original: Callable[..., Any] = getattr(sys.modules[module], name)

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(target)
        return original(*args, **kwargs)

    for mod in list(sys.modules.values()):
        if getattr(mod, "__name__", "").startswith(("planner", "workbench")):
            for attr, value in list(vars(mod).items()):
                if value is original:
                    monkeypatch.setattr(mod, attr, counted)


def _count_constructions(monkeypatch: pytest.MonkeyPatch, cls: type, calls: list[str]) -> None:
    original = cls.__init__

    def counted(self: Any, *args: Any, **kwargs: Any) -> None:
        calls.append(cls.__name__)
        original(self, *args, **kwargs)

    monkeypatch.setattr(cls, "__init__", counted)


def _show_everything(wb: Workbench) -> int:
    """Focus every layer and show what it offers (poses, ranks, pairs, nodes, samples); how many things were shown."""
    assert wb.session_layers is not None
    shown = 0
    for name, layer in wb.session_layers.layers.items():
        wb.focus_step(name)
        for label, pose in layer.poses.items():
            wb.pose_robot(pose.q, pose.object_pose, label)
            shown += 1
        result = getattr(layer, "result", None)
        if name in ("pick_grasps", "place_grasps"):
            for rank in range(len(result)):
                layer.show(rank)
                shown += 1
        elif name == "double_grasps":
            for index in range(len(result)):
                layer.select(index)
                for phase in PAIR_PHASES:
                    layer.show_phase(phase)
                    shown += 1
        elif name == "exchange":
            for percent in (1.0, 50.0, 100.0):
                layer.show_cheapest(percent)
                shown += 1
        elif name == "roadmap":
            for node in np.linspace(0, len(layer.roadmap.node_q) - 1, 5).astype(int):
                layer.pick(int(node))
                shown += 1
        elif name == "motion":
            for i in np.linspace(0, len(result.t) - 1, 20).astype(int):
                layer.playback.show(int(i))
                shown += 1
    return shown


@pytest.mark.slow
def test_replaying_the_example_recomputes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "example"
    shutil.copytree(EXAMPLE, folder)
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=tmp_path)
    try:
        assert wb.collision_ready.wait(120), "the workbench's own collision model (its live collision display) never came"
        assert wb.task_editor.live.idle.wait(120), "the task's live check (the Task tab's verdict) never ended"
        calls: list[str] = []
        for target in EXPENSIVE:
            _count_everywhere(monkeypatch, target, calls)
        for cls in CONSTRUCTORS:
            _count_constructions(monkeypatch, cls, calls)
        wb._draw_session(Session.open(folder))  # the replay: every finished step's layer from the saved results
        assert wb.session_layers is not None and not wb.session_layers.errors, wb.session_layers.errors
        drawn = set(wb.session_layers.layers)
        assert drawn == {s.name for s in PIPELINE} & drawn and len(drawn) >= 7, drawn
        assert _show_everything(wb) > 50
        assert calls == [], f"replaying recomputed: {sorted(set(calls))}"
    finally:
        wb.close()
