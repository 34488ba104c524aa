"""Task suites: deterministic generation of valid tasks, errors naming the field, the same per-task results on local
workers and on a local Ray cluster, and a killed suite resumed without redoing its finished tasks.

The suites run `--until place_grasps`: the arms step and both grasp lists of the statuette with session seed 0, which
the other end-to-end tests have already cached (the whole pipeline per task would take minutes here)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from planner.check import check_task
from planner.errors import InputError
from planner.suite.generate import generate_tasks
from planner.suite.spec import load_suite
from planner.task import load_task
from workbench.cli import main

UNTIL = "place_grasps"
# four statuettes near the default task's placements (the right arm picks, the left places), at other positions and headings
SUITE = """
name = "four"
task = "default"
tasks = 4
seed = 1
plan_seed = 0
attempts = 20

[[objects]]
name = "statuette"
mesh = "statuette"

[[initial_regions]]
name = "right"
x = [0.43, 0.50]
y = [-0.87, -0.80]
z = 0.72
yaw = [0.8, 1.6]

[[final_regions]]
name = "behind_lamp"
x = [0.48, 0.56]
y = [0.80, 0.87]
z = 0.72
yaw = [2.3, 3.1]
"""


def regrasp(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, timeout=600,
                          env={**os.environ, **(env or {})})


def results(folder: Path) -> list[dict]:
    """suite.json's per-task results (the part that must not depend on the executor or on a resume)."""
    return json.loads((folder / "suite.json").read_text())["results"]


@pytest.fixture(scope="module")
def suite_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("suite") / "four.toml"
    path.write_text(SUITE)
    return path


@pytest.fixture(scope="module")
def local_run(suite_file, tmp_path_factory) -> Path:
    """The four-task suite run on two local workers (the command line, in its own process)."""
    out = tmp_path_factory.mktemp("local") / "out"
    run = regrasp("suite", str(suite_file), "--out", str(out), "--workers", "2", "--until", UNTIL)
    assert run.returncode == 0, run.stderr
    assert "4 of 4 tasks succeeded" in run.stdout and "done 4, failed 0, running 0" in run.stderr
    return out


def test_default_suite_has_fifty_tasks_and_six_objects():
    spec = load_suite("default")
    assert spec.tasks >= 50 and len(spec.objects) >= 6 and spec.base_task.name == "default.toml"
    assert "statuette" in [o.builtin for o in spec.objects] and sum(not o.builtin for o in spec.objects) >= 5


def test_generation_is_deterministic_and_every_task_passes_check(suite_file, tmp_path):
    spec = load_suite(suite_file)
    one, two = generate_tasks(spec, tmp_path / "a", workers=2), generate_tasks(spec, tmp_path / "b", workers=1)
    assert one == two and [t.id for t in one] == ["0001-statuette", "0002-statuette", "0003-statuette", "0004-statuette"]
    assert len({t.initial for t in one}) == 4  # four different tasks
    for name in sorted(p.name for p in (tmp_path / "a").iterdir()):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    for task in one:
        x, y, _, yaw = task.initial
        assert 0.43 <= x <= 0.50 and -0.87 <= y <= -0.80 and 0.8 <= yaw <= 1.6
        report = check_task(load_task(tmp_path / "a" / task.files[0]))
        assert report.ok and report.handover, report.render()


def test_a_region_that_yields_no_valid_task_is_named(tmp_path):
    path = tmp_path / "vase.toml"  # the final region is inside the vase: every placement there penetrates it
    path.write_text(SUITE.replace('name = "behind_lamp"\nx = [0.48, 0.56]\ny = [0.80, 0.87]',
                                  'name = "in_vase"\nx = [0.54, 0.56]\ny = [0.04, 0.06]').replace("attempts = 20", "attempts = 3"))
    with pytest.raises(InputError) as err:
        generate_tasks(load_suite(path), tmp_path / "tasks")
    assert err.value.field == "final_regions[0]" and "'in_vase'" in str(err.value) and "penetrates vase" in str(err.value)


def test_bad_suite_fields_are_named_before_any_folder_is_made(tmp_path):
    cases = [("tasks = 4", "tasks = 0", "'tasks': expected an integer from 1"),
             ('shape = "box"', 'shape = "box"', ""),
             ('mesh = "statuette"', 'shape = "cube"', "'objects[0].shape': expected one of box, cylinder"),
             ("yaw = [0.8, 1.6]", "yaw = [1.6, 0.8]", "'initial_regions[0].yaw': expected [low, high] with low <= high")]
    for old, new, expected in cases:
        if not expected:
            continue
        path = tmp_path / "bad.toml"
        path.write_text(SUITE.replace(old, new))
        run = regrasp("suite", str(path), "--out", str(tmp_path / "out"))
        assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
        assert f"{path}, field {expected}" in run.stderr, run.stderr
        assert not (tmp_path / "out").exists()


def test_an_existing_suite_is_kept_without_resume_or_force(local_run, suite_file):
    before = (local_run / "suite.json").read_bytes()
    run = regrasp("suite", str(suite_file), "--out", str(local_run), "--until", UNTIL)
    assert run.returncode == 2 and "already holds a suite; use --resume" in run.stderr
    assert (local_run / "suite.json").read_bytes() == before


def test_suite_records_every_task(local_run):
    data = json.loads((local_run / "suite.json").read_text())
    assert data["tasks"] == data["succeeded"] == 4 and data["success_rate"] == 1.0 and data["by_stage"] == {}
    assert set(data["seconds"]) == {"arms", "pick_grasps", "place_grasps", "total"}
    assert all(s["median"] <= s["p95"] for s in data["seconds"].values())
    for r in data["results"]:
        assert r["steps"] == ["arms", "pick_grasps", "place_grasps"] and r["success"]
        session = json.loads((local_run / r["session"] / "session.json").read_text())
        assert session["task_source"] == f"../../tasks/{r['id']}.toml" and session["seed"] == 0
        assert (local_run / "tasks" / f"{r['id']}.toml").is_file()
    rows = (local_run / "suite.csv").read_text().splitlines()
    assert len(rows) == 5 and rows[0].startswith("id,object,initial_region,final_region") and ",True," in rows[1]


@pytest.mark.slow
def test_ray_gives_the_same_results_as_local_workers(local_run, suite_file, tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, object_store_memory=100 * 1024 * 1024, include_dashboard=False, log_to_driver=False)
    try:
        assert main(["suite", str(suite_file), "--out", str(tmp_path / "ray"), "--ray", "--until", UNTIL]) == 0
    finally:
        ray.shutdown()
    assert results(tmp_path / "ray") == results(local_run)
    for r in results(local_run):
        assert (tmp_path / "ray" / "results" / f"{r['id']}.json").is_file()


@pytest.mark.slow
def test_a_killed_suite_resumes_without_redoing_finished_tasks(local_run, suite_file, tmp_path):
    out = tmp_path / "out"
    killed = regrasp("suite", str(suite_file), "--out", str(out), "--workers", "1", "--until", UNTIL,
                     env={"REGRASP_SUITE_KILL_AFTER": "2"})
    assert killed.returncode == -9, killed.stderr
    done = sorted((out / "results").iterdir())
    assert [p.name for p in done] == ["0001-statuette.json", "0002-statuette.json"] and not (out / "suite.json").exists()
    stamps = {p.name: p.stat().st_mtime_ns for p in done}
    resumed = regrasp("suite", str(suite_file), "--out", str(out), "--workers", "2", "--until", UNTIL, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert "2 of 4 tasks finished, 2 to run" in resumed.stderr and "0001-statuette" not in resumed.stderr
    assert {p.name: p.stat().st_mtime_ns for p in done} == stamps
    assert results(out) == results(local_run)
