"""Task suites: deterministic generation of valid tasks, errors naming the field, the same per-task results on local
workers and on a local Ray cluster, and a killed suite resumed without redoing its finished tasks.

The suites run `--until place_grasps`: the arms step and both grasp lists of the statuette with session seed 0, which
the other end-to-end tests have already cached (the whole pipeline per task would take minutes here)."""
from __future__ import annotations

import io
import json
import logging
import os
import re
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from planner.check import check_task
from planner.core.errors import InputError
from planner.core.toml_text import toml_text
from planner.core.tomlread import load_toml
from planner.core.user_cache import computing
from planner.model.task import find_task, load_task
from planner.suite.generate import generate_tasks
from planner.suite.report import write_report
from planner.suite.spec import load_suite
from workbench.cli import main

UNTIL = "place_grasps"
PLAN_SEED = 3  # the session tests' seed, whose statuette grasp lists are in the shared test cache
# four statuettes near the default task's placements (the right arm picks, the left places), at other positions and headings
# start and goal regions near the default task's placements (the right arm picks, the left places)
REGIONS = """
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
SUITE = f"""
name = "four"
task = "default"
tasks = 4
seed = 1
plan_seed = {PLAN_SEED}
attempts = 20

[[objects]]
name = "statuette"
mesh = "statuette"

{REGIONS}"""


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


def test_a_failed_motion_names_the_phase_and_part_its_first_sequence_failed_at():
    """The suite groups failures by stage: a motion's is where its first sequence failed, not the sequence's name."""
    from types import SimpleNamespace

    from planner.suite.job import _failed_stage

    said = "table through placement 3 on desk_top, grasps 97 and 34 (32.0 s estimated): Grasp phase, approach: collides (a)"
    motion = SimpleNamespace(stages=[{"stage": "regrasp graph", "count": 2}], tried=[said, "double grasp 1: Carry phase"])
    assert _failed_stage(SimpleNamespace(result=lambda step: motion), "motion") == "Grasp phase, approach"
    motion.stages[0]["count"] = 0  # no sequence: the stage that kept none
    assert _failed_stage(SimpleNamespace(result=lambda step: motion), "motion") == "regrasp graph"
    bare = SimpleNamespace(stages=[], tried=["no transit"])
    assert _failed_stage(SimpleNamespace(result=lambda step: bare), "motion") == "no transit"


def test_task_files_are_written_as_they_were_read():
    for name in ("default", "baxter"):
        data = load_toml(find_task(name))
        assert tomllib.loads(toml_text(data)) == data


@pytest.mark.slow
def test_generation_is_deterministic_and_every_task_passes_check(local_run, suite_file, tmp_path):
    tasks = generate_tasks(load_suite(suite_file), tmp_path, workers=1)  # the suite drew them on two workers
    assert [t.id for t in tasks] == ["0001-statuette", "0002-statuette", "0003-statuette", "0004-statuette"]
    assert len({t.initial for t in tasks}) == 4  # four different tasks
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in (local_run / "tasks").iterdir())
    for path in tmp_path.iterdir():
        assert path.read_bytes() == (local_run / "tasks" / path.name).read_bytes(), path.name
    for task in tasks:
        x, y, _, yaw = task.initial
        assert 0.43 <= x <= 0.50 and -0.87 <= y <= -0.80 and 0.8 <= yaw <= 1.6
        report = check_task(load_task(local_run / "tasks" / task.files[0]))
        assert report.ok and report.handover, report.render()


@pytest.mark.slow
def test_a_region_that_yields_no_valid_task_is_named(tmp_path):
    path = tmp_path / "vase.toml"  # the final region is inside the vase: every placement there penetrates it
    path.write_text(SUITE.replace('name = "behind_lamp"\nx = [0.48, 0.56]\ny = [0.80, 0.87]',
                                  'name = "in_vase"\nx = [0.54, 0.56]\ny = [0.04, 0.06]').replace("attempts = 20", "attempts = 3"))
    with pytest.raises(InputError) as err:
        generate_tasks(load_suite(path), tmp_path / "tasks")
    assert err.value.field == "final_regions[0]" and "'in_vase'" in str(err.value) and "penetrates vase" in str(err.value)


def test_bad_suite_fields_are_named_before_any_folder_is_made(tmp_path, capsys):
    cases = [("tasks = 4", "tasks = 0", "'tasks': expected an integer from 1"),
             ('mesh = "statuette"', 'shape = "cube"', "'objects[0].shape': expected one of box, cylinder"),
             ('mesh = "statuette"', 'shape = "box"\nsize = [0.5, 0.1, 0.1]', "'objects[0].shape': the box is 0.5 m long"),
             ("yaw = [0.8, 1.6]", "yaw = [1.6, 0.8]", "'initial_regions[0].yaw': expected [low, high] with low <= high"),
             ('name = "right"', 'name = "right/../x"', "'initial_regions[0].name': expected letters, digits")]
    for old, new, expected in cases:
        path = tmp_path / "bad.toml"
        path.write_text(SUITE.replace(old, new))
        assert main(["suite", str(path), "--out", str(tmp_path / "out")]) == 2
        assert f"{path}, field {expected}" in capsys.readouterr().err
        assert not (tmp_path / "out").exists()
    assert main(["suite", str(path), "--out", str(tmp_path / "out"), "--until", "motions"]) == 2
    assert "no step 'motions'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["suite", str(path), "--out", str(tmp_path / "out"), "--workers", "0"])
    assert "--workers: expected a whole number of at least 1" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_an_existing_suite_is_kept_without_resume_or_force(local_run, suite_file, capsys):
    before = (local_run / "suite.json").read_bytes()
    level = logging.getLogger("regrasp.cache").level
    assert main(["suite", str(suite_file), "--out", str(local_run), "--until", UNTIL]) == 2
    assert "already holds a suite; use --resume to continue it, or --force to replace it" in capsys.readouterr().err
    assert (local_run / "suite.json").read_bytes() == before
    assert logging.getLogger("regrasp.cache").level == level, "the suite left its log level behind for the caller"


def test_a_cache_entry_is_computed_by_one_process_at_a_time(tmp_path):
    entry, log = tmp_path / "entry", tmp_path / "log"

    def compute() -> None:
        with computing(entry):
            with log.open("a") as f:
                f.write(f"start {time.monotonic()}\n")
            time.sleep(0.3)
            with log.open("a") as f:
                f.write(f"end {time.monotonic()}\n")

    pids = []
    for _ in range(2):
        pid = os.fork()
        if pid == 0:
            compute()
            os._exit(0)
        pids.append(pid)
    assert all(os.waitpid(pid, 0)[1] == 0 for pid in pids)
    marks = [line.split()[0] for line in log.read_text().splitlines()]
    assert marks == ["start", "end", "start", "end"]  # never two starts in a row: the second waited for the first


@pytest.mark.slow
def test_suite_records_every_task(local_run):
    data = json.loads((local_run / "suite.json").read_text())
    assert data["tasks"] == data["succeeded"] == 4 and data["success_rate"] == 1.0 and data["by_stage"] == {}
    assert set(data["seconds"]) == {"arms", "pick_grasps", "place_grasps", "total"}
    assert all(s["median"] <= s["p95"] for s in data["seconds"].values())
    for r in data["results"]:
        assert r["steps"] == ["arms", "pick_grasps", "place_grasps"] and r["success"]
        session = json.loads((local_run / r["session"] / "session.json").read_text())
        assert session["task_source"] == f"../../tasks/{r['id']}.toml" and session["seed"] == PLAN_SEED
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
    killed = regrasp("suite", str(suite_file), "--out", str(out), "--workers", "2", "--until", UNTIL,
                     env={"REGRASP_SUITE_KILL_AFTER": "2"})
    assert killed.returncode == -9, killed.stderr
    done = sorted((out / "results").iterdir())
    assert len(done) == 2 and not (out / "suite.json").exists()
    stamps = {p.name: p.stat().st_mtime_ns for p in done}
    resumed = regrasp("suite", str(suite_file), "--out", str(out), "--workers", "2", "--until", UNTIL, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert "2 of 4 tasks finished, 2 to run" in resumed.stderr
    assert not any(p.stem in resumed.stderr for p in done)  # the finished tasks did not run again
    assert {p.name: p.stat().st_mtime_ns for p in done} == stamps
    assert results(out) == results(local_run)


def _pixels(element, rgb: tuple[int, int, int]) -> int:
    """How many pixels of an element's screenshot have (nearly) this colour."""
    image = np.asarray(Image.open(io.BytesIO(element.screenshot())).convert("RGB"), dtype=np.int16)
    return int((np.abs(image - np.array(rgb)).max(axis=2) < 30).sum())


@pytest.mark.browser
def test_the_report_opens_in_chromium_and_shows_its_plots(local_run, suite_file, browser, tmp_path):
    data = json.loads((local_run / "suite.json").read_text())
    failed = data["results"][1] | {"success": False, "failed_step": "grasp_configs", "failed_stage": "pick grasps with a configuration",
                                   "message": "no collision-free pick grasp"}
    data |= {"results": [data["results"][0], failed, *data["results"][2:]], "by_stage": {"grasp_configs: pick grasps": 1},
             "by_strategy": {"handover": 2, "table": 1}}
    spec = load_suite(suite_file)
    write_report(data, spec, load_task(spec.base_task).environment, tmp_path)
    page = browser.new_page(viewport={"width": 1200, "height": 900})
    try:
        for folder, failures in ((local_run, 0), (tmp_path, 1)):
            page.goto((folder / "report.html").as_uri())
            plots = page.locator("figure.plot svg")
            assert plots.count() == 4 + 2 * failures  # no failure, no strategy (no motion): those plots say so instead
            strategies = page.locator("figure.strategies")
            assert (strategies.locator("text", has_text="table handover").count() == 1) == bool(failures), strategies.inner_html()
            for i in range(plots.count()):
                box = plots.nth(i).bounding_box()
                assert box and box["width"] > 100 and box["height"] > 20
            top = page.locator("figure.top-view svg")
            assert top.locator("circle.placement").count() == top.locator("rect.placement").count() == 4
            assert _pixels(top, (0x2A, 0x9D, 0x4A)) > 100  # the succeeded tasks' placements, drawn in green
            assert (_pixels(top, (0xD1, 0x49, 0x5B)) > 20) == bool(failures)
            assert _pixels(page.locator("figure.objects svg"), (0x2A, 0x9D, 0x4A)) > 100
            replay = page.locator("tr.failed code")
            assert replay.count() == failures
            if failures:
                assert replay.inner_text() == f"regrasp replay {tmp_path}/sessions/0002-statuette"
                assert page.locator("tr.failed a.replay").get_attribute("href") == "sessions/0002-statuette/"
                assert page.locator("#success-rate").inner_text() == "100.0%"  # the totals are the data's, as given
    finally:
        page.close()


@pytest.mark.slow
def test_a_cold_suite_in_a_log_says_each_task_and_each_cache_entry_it_builds(tmp_path):
    """Its stderr a file, with an empty cache: a line per cache entry as it is built and when it is stored, and one per
    finished task (a cold run used to say nothing between "generating" and the end)."""
    path = tmp_path / "one.toml"
    path.write_text(SUITE.replace("tasks = 4", "tasks = 1") + "\n[params.pick_grasps]\npositions = 20\norientations = 20\ndensify = 1\n")
    run = regrasp("suite", str(path), "--out", str(tmp_path / "out"), "--workers", "1", "--until", "pick_grasps",
                  env={"REGRASP_CACHE": str(tmp_path / "cache")})
    assert run.returncode == 0, run.stderr
    lines = run.stderr.splitlines()
    built = [li for li in lines if li.startswith("cache: built ")]
    assert any(li.startswith("cache: built the grasp list of the right hand (400 frames") for li in built), run.stderr
    assert any(li.startswith("cache: built the object model") for li in built), run.stderr
    assert all(re.search(r" in \d+\.\d s$", li) for li in built), built
    assert len([li for li in lines if li.startswith("cache: building ")]) == len(built)
    assert any(li.startswith("[1/1] 0001-statuette: ok (") for li in lines), run.stderr
