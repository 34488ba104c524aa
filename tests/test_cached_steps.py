"""A step whose result came from the user cache says so in its session record, and the step table, the step's details
and `regrasp plan`'s table mark its seconds as cached (they are a load's, not what the step costs)."""
from __future__ import annotations

from pathlib import Path

import pytest
from sandbox import copy_example

from planner.core.runner import run_step
from planner.core.session import Session
from planner.pipeline import step_named
from workbench.step_table import step_details, step_table

SMALL = {"positions": 20, "orientations": 20, "densify": 1}  # a grasp list computed in seconds


def _row(table: str, name: str) -> str:
    return next(line for line in table.splitlines() if line.startswith(f"| {name} |"))


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> list[Session]:
    """pick_grasps run twice from the example's arms with an empty cache: computed, then loaded from the cache."""
    root = tmp_path_factory.mktemp("cached")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("REGRASP_CACHE", str(root / "cache"))
        example = copy_example(root / "example")
        sessions = []
        for k in range(2):
            session = Session.open(example).branch(root / f"run{k}", "pick_grasps")
            run_step(session, step_named("pick_grasps"), SMALL)
            sessions.append(Session.open(session.folder))
    return sessions


def test_the_record_says_which_run_came_from_the_cache(runs: list[Session]) -> None:
    computed, loaded = (s.record_of("pick_grasps") for s in runs)
    assert "cached" not in computed and loaded["cached"] is True
    assert runs[0].result("pick_grasps").stats() == runs[1].result("pick_grasps").stats()


def test_the_step_table_and_details_mark_cached_seconds(runs: list[Session]) -> None:
    computed, loaded = runs
    assert "(cached)" not in _row(step_table(computed), "pick_grasps")
    assert "(cached)" in _row(step_table(loaded), "pick_grasps").split("|")[3]  # the seconds column
    assert "(cached)" not in _row(step_table(loaded), "arms")
    assert "loaded from the user cache" in step_details(loaded, "pick_grasps")
    assert "loaded from the user cache" not in step_details(computed, "pick_grasps")


def test_plan_marks_a_cached_step(runs: list[Session], capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch,
                                  tmp_path: Path) -> None:
    from workbench.cli import main

    monkeypatch.setenv("REGRASP_CACHE", str(runs[0].folder.parent / "cache"))
    out = tmp_path / "resumed"
    Session.open(runs[1].folder).branch(out, "place_grasps")
    assert main(["plan", "default", "--out", str(out), "--resume", "--until", "pick_grasps"]) == 0
    line = next(li for li in capsys.readouterr().out.splitlines() if li.startswith("pick_grasps"))
    assert "(from the cache)" in line and "(earlier run)" in line
