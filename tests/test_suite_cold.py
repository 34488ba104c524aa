"""A suite with an empty cache ends (issue 40): its tasks compute their grasp lists on the CPUs the executor gives them,
never more planner processes than --workers plus the suite's own, on local workers and on Ray; a task past its
time limit is recorded as failed at stage "timeout" and the suite goes on."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_suite import REGIONS

SMALL = f"""
name = "small"
task = "default"
tasks = 2
seed = 1
plan_seed = 0
attempts = 20
{{extra}}

[params.pick_grasps]
positions = 12
orientations = 24
densify = 1
min_clear = 1

[params.place_grasps]
positions = 12
orientations = 24
densify = 1
min_clear = 1

[[objects]]
name = "box"
shape = "box"
size = [0.06, 0.05, 0.12]

{REGIONS}"""


def _descendants(pid: int) -> set[int]:
    """Every live process below `pid` (read from /proc, sharing nothing with the fork helper)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if stat.rsplit(")", 1)[1].split()[0] == "Z":
                continue
            children.setdefault(int(stat.rsplit(")", 1)[1].split()[1]), []).append(int(entry.name))
    found, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.add(child)
            todo.append(child)
    return found


def _run(tmp_path: Path, where: list[str], extra: str = "") -> tuple[subprocess.CompletedProcess, int]:
    """Run the small suite with an empty cache; (the finished command, the most processes it had below it at once)."""
    suite = tmp_path / "small.toml"
    suite.write_text(SMALL.format(extra=extra))
    cache = tmp_path / "cache"
    cache.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "workbench.cli", "suite", str(suite), "--out", str(tmp_path / "out"),
                             "--until", "place_grasps", *where], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "REGRASP_CACHE": str(cache)})
    most, start = 0, time.monotonic()
    while proc.poll() is None and time.monotonic() - start < 300:
        most = max(most, len(_descendants(proc.pid)))
        time.sleep(0.05)
    if proc.poll() is None:
        proc.kill()
    out, err = proc.communicate()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err), most


def _results(tmp_path: Path) -> list[dict]:
    return json.loads((tmp_path / "out" / "suite.json").read_text())["results"]


@pytest.mark.slow
def test_a_cold_suite_on_two_local_workers_ends_within_its_workers(tmp_path):
    done, most = _run(tmp_path, ["--workers", "2"])
    assert done.returncode == 0, done.stderr[-2000:]
    assert [r["success"] for r in _results(tmp_path)] == [True, True]
    assert 1 <= most <= 2, f"{most} processes below the suite, with --workers 2"


@pytest.mark.slow
def test_a_cold_suite_on_ray_ends(tmp_path):
    pytest.importorskip("ray")
    done, _ = _run(tmp_path, ["--ray"])
    assert done.returncode == 0, done.stderr[-2000:]
    assert [r["success"] for r in _results(tmp_path)] == [True, True]


@pytest.mark.slow
def test_a_task_past_its_time_limit_fails_at_stage_timeout_and_the_suite_goes_on(tmp_path):
    done, _ = _run(tmp_path, ["--workers", "1"], extra="task_timeout = 0.5")
    assert done.returncode == 0, done.stderr[-2000:]
    results = _results(tmp_path)
    assert len(results) == 2
    for r in results:
        assert not r["success"] and r["failed_stage"] == "timeout", r
        assert "task_timeout of 0.5 s" in r["message"]
