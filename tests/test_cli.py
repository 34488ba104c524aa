"""The `regrasp` command line, run as a user runs it: exit codes, tables, JSON, clear errors."""
from __future__ import annotations

import json
import subprocess
import sys


def regrasp(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, timeout=600)


def test_check_default_task():
    run = regrasp("check", "default")
    assert run.returncode == 0, run.stdout + run.stderr
    out = run.stdout
    assert "total           49" in out
    assert "initial   collision-free" in out and "final     collision-free" in out
    assert "initial   right: yes" in out and "left: no" in out.split("initial", 3)[-1]
    assert "OK: a valid two-hand regrasping task" in out


def test_check_second_robot():
    run = regrasp("check", "baxter")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "total           46" in run.stdout and "torso            0" in run.stdout


def test_check_bad_task_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\nrobot = "alex_allegro.toml"\n[object]\nmesh = "statuette"\ninitial = { xyz = [0, 0] }\n')
    run = regrasp("check", str(bad))
    assert run.returncode == 2
    assert "Traceback" not in run.stderr
    assert str(bad) in run.stderr and "object.initial" in run.stderr and "expected 3 numbers" in run.stderr


def test_check_reports_a_task_that_needs_no_regrasp(tmp_path):
    from planner.paths import ASSETS

    text = (ASSETS / "tasks" / "default.toml").read_text()
    moved = text.replace("final = { xyz = [0.50, 0.85, 0.72]", "final = { xyz = [0.50, -0.70, 0.72]")
    assert moved != text, "the default task's final placement changed: update this test"
    text = moved
    task = tmp_path / "same_side.toml"
    task.write_text(text.replace('robot = "alex_allegro.toml"', f'robot = "{ASSETS / "robots" / "alex_allegro.toml"}"'))
    run = regrasp("check", str(task))
    assert run.returncode == 0, run.stdout + run.stderr  # a valid task: one arm carries the object, no handover
    assert "arms: no handover is needed: the right arm reaches both placements" in run.stdout
    assert "handover = true" in run.stdout and "OK: a valid pick-and-place task for one arm (no handover)" in run.stdout


def test_bench_collision_json(tmp_path):
    out = tmp_path / "bench.json"
    run = regrasp("bench", "collision", "--samples", "300", "--json", str(out))
    assert run.returncode == 0, run.stderr
    figures = json.loads(out.read_text())
    for key in ("full_check_us_median", "full_check_us_p95", "arm_env_check_us_median", "fk_us_median", "pairs_kept", "dof"):
        assert key in figures
    assert figures["dof"] == 49 and figures["pairs_kept"] > 1000
    assert "median µs" in run.stdout
