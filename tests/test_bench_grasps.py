"""`regrasp bench grasps`: the stages it reports add up to the outcomes, its JSON names what the issue asks for, a bad
baseline commit is one line, and (slow) the earlier builder run side by side finds as many grasps. Small searches keep
it quick; the figures themselves are in docs/benchmarks.md, never asserted on time."""
from __future__ import annotations

import functools
import json

import pytest

import planner.cli.bench_grasps as bench
from planner.cli.main import main
from planner.grasping.grasp_list import GraspParams
from planner.grasping.search import OUTCOMES

SMALL = functools.partial(GraspParams, positions=12, orientations=20)


def test_stages_count_the_frames_left_after_each_outcome():
    outcomes = {name: i + 1 for i, name in enumerate(OUTCOMES)}
    frames = sum(outcomes.values())
    left = bench.stages(frames, outcomes)
    assert list(left) == list(OUTCOMES[:-1])
    assert left[OUTCOMES[-2]] == outcomes["closed"]
    assert all(a - b == outcomes[name] for (_, a), (name, b) in zip(list(left.items()), list(left.items())[1:]))


def test_the_json_has_frames_stages_grasps_seconds_and_rate_per_hand(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(bench, "GraspParams", SMALL)
    out = tmp_path / "b.json"
    assert main(["bench", "grasps", "--hand", "right", "--no-baseline", "--workers", "1", "--json", str(out)]) == 0
    table = capsys.readouterr().out
    assert "right hand" in table and "grasps per second" in table and "ratio" not in table
    data = json.loads(out.read_text())
    (hand,) = data["hands"]
    assert hand["hand"] == "right" and hand["baseline"] is None and hand["ratio"] is None
    assert hand["frames"] > hand["stages"]["palm_inside"] >= hand["stages"]["not_closed"] >= hand["grasps"] > 0
    assert hand["grasps_per_second"] == pytest.approx(hand["grasps"] / hand["seconds"])
    assert 0 < hand["cpu_seconds"] and hand["cpu_ratio"] is None


def test_an_unknown_baseline_commit_is_one_line(monkeypatch, capsys):
    monkeypatch.setattr(bench, "GraspParams", SMALL)
    assert main(["bench", "grasps", "--hand", "left", "--baseline", "no-such-commit"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no-such-commit" in err


@pytest.mark.slow
def test_the_earlier_builder_finds_the_same_number_of_grasps(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(bench, "GraspParams", SMALL)
    out = tmp_path / "b.json"
    assert main(["bench", "grasps", "--workers", "1", "--json", str(out)]) == 0
    for hand in json.loads(out.read_text())["hands"]:
        assert hand["baseline"]["grasps"] == hand["grasps"] > 0 and hand["baseline"]["frames"] == hand["frames"]
        assert hand["ratio"] > 0 and hand["cpu_ratio"] > 0 and hand["baseline"]["cpu_seconds"] > 0
