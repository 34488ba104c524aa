"""Sessions: exact round trips, replay without planning, resume after a kill, and every bad-session message."""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from planner.core.errors import InputError, RegraspError
from planner.core.runner import KILL_AFTER, run_pipeline
from planner.core.session import MANIFEST, Session
from planner.pipeline import PIPELINE


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b)) and np.asarray(a).dtype == np.asarray(b).dtype
    return json.loads(json.dumps(a)) == json.loads(json.dumps(b))


EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"
# the near-rest IK starts only: the grasp configurations in a third of the time (35 pick configurations instead of 36 on
# the default task), as these tests are about sessions, not about what the steps find
QUICK_CONFIGS = {"grasp_configs": {"wide_attempts": 0}}


@pytest.fixture
def example(tmp_path) -> Path:
    """A copy of the committed example session (a finished plan of every step), to open, damage or refuse to overwrite."""
    import shutil

    return Path(shutil.copytree(EXAMPLE, tmp_path / "example"))


@pytest.fixture(scope="module")
def planned(tmp_path_factory, default_scene):
    """The whole pipeline run once on the default task, with its in-memory results."""
    folder = tmp_path_factory.mktemp("planned") / "session"
    session = Session.create(folder, default_scene, seed=3)
    run_pipeline(session, params=QUICK_CONFIGS)
    return folder, {name: session.result(name) for name in session.finished()}


@pytest.mark.slow
def test_round_trip_every_step_exactly(planned):
    folder, results = planned
    assert [s.name for s in PIPELINE] == list(results)
    reopened = Session.open(folder)
    for name, result in results.items():
        loaded = reopened.result(name)
        for f in dataclasses.fields(result):
            assert _same(getattr(result, f.name), getattr(loaded, f.name)), f"{name}.{f.name} changed in the round trip"
    manifest = json.loads((folder / MANIFEST).read_text())
    assert {"format_version", "task", "versions", "steps"} <= set(manifest)
    keys = {"name", "params", "seed", "seconds", "stats", "files"}
    assert [set(r) - {"stage_seconds", "cached"} for r in manifest["steps"]] == [keys] * len(PIPELINE)


def test_replay_calls_no_planner_step(example):
    """Opening a session in the workbench draws every layer from saved results: no step may run."""
    import socket

    from workbench.app import Workbench

    folder = example
    originals = [s.run for s in PIPELINE]

    def forbidden(ctx):
        raise AssertionError("a planner step ran during replay")

    for step in PIPELINE:
        object.__setattr__(step, "run", forbidden)  # Step is frozen: patch for this test only
    try:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        wb = Workbench(None, "127.0.0.1", port, session=folder)
        try:
            assert wb.session is not None and wb.session.finished() == [s.name for s in PIPELINE]
        finally:
            wb.close()
    finally:
        for step, original in zip(PIPELINE, originals):
            object.__setattr__(step, "run", original)


@pytest.mark.slow
def test_existing_session_survives_without_force(example, default_scene):
    folder = example
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    with pytest.raises(RegraspError, match="already holds a session"):
        Session.create(folder, default_scene, seed=3)
    run = subprocess.run([sys.executable, "-m", "workbench.cli", "plan", "default", "--out", str(folder)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "--force" in run.stderr and "Traceback" not in run.stderr
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def _plan(out: Path, *extra: str, seed: int = 3, kill_after: str = "") -> subprocess.CompletedProcess:
    """`regrasp plan default` into `out` (seed 3, as `planned`: the grasp lists and roadmap come from this test session's
    cache); with `kill_after`, the process kills itself once that step is saved (runner.py)."""
    env = {**os.environ, KILL_AFTER: kill_after} if kill_after else None
    quick = ("--set", "grasp_configs.wide_attempts=0")  # as QUICK_CONFIGS
    command = ["plan", "default", "--out", str(out), "--seed", str(seed), *quick, *extra]
    return subprocess.run([sys.executable, "-m", "workbench.cli", *command], capture_output=True, text=True, env=env, timeout=900)


def _step_files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*")) if p.name not in (MANIFEST,)}


@pytest.mark.slow
def test_killed_plan_resumes_to_the_same_result(planned, tmp_path):
    """`plan default --seed 3` killed once grasp_configs is saved, then resumed: the same step files and records as the
    run in one go (`planned`, which a whole `regrasp plan` run matches byte for byte: see the warm-cache test)."""
    whole, _ = planned
    cut = tmp_path / "cut"
    assert _plan(cut, kill_after="grasp_configs").returncode == -signal.SIGKILL
    names = [s.name for s in PIPELINE]
    assert Session.open(cut).finished() == names[: names.index("grasp_configs") + 1]  # what was finished is readable
    resumed = _plan(cut, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert _step_files(cut) == _step_files(whole)
    # the records but their seconds and whether a result came from the cache (the other run may have filled it)
    strip = lambda m: [{k: v for k, v in r.items() if k not in ("seconds", "stage_seconds", "cached")} for r in m["steps"]]
    assert strip(json.loads((cut / MANIFEST).read_text())) == strip(json.loads((whole / MANIFEST).read_text()))


@pytest.mark.slow
def test_the_same_run_from_a_warm_cache_writes_identical_step_files(planned, tmp_path):
    """`plan default --seed 3` again, into another folder: the grasp lists and the roadmap now come from the user cache
    (the first run, on this test session's fresh cache, computed them), yet every step file is byte-identical; each
    session records its own run's seconds, and no statistic holds a time."""
    folder, _ = planned
    again = tmp_path / "again"
    run = _plan(again, seed=3)
    assert run.returncode == 0, run.stderr
    assert _step_files(again) == _step_files(folder)
    first, second = (json.loads((f / MANIFEST).read_text())["steps"] for f in (folder, again))
    assert [r["stats"] for r in second] == [r["stats"] for r in first]
    assert not [k for r in second for k in _keys(r["stats"]) if "second" in k], "a statistic holds a time"
    assert all(r["seconds"] > 0 for r in first + second)
    roadmap = next(r for r in second if r["name"] == "roadmap")
    assert "stage_seconds" not in roadmap, "the second run's roadmap came from the cache: no build stage ran"


def _keys(value) -> list[str]:
    """Every key in a JSON value, nested ones included."""
    if isinstance(value, dict):
        return [k for key, v in value.items() for k in (key, *_keys(v))]
    return [k for v in value for k in _keys(v)] if isinstance(value, list) else []


def _open_error(folder: Path) -> str:
    with pytest.raises(InputError) as info:
        Session.open(folder)
    return str(info.value)


def test_missing_npz(example):
    (example / "arms.npz").unlink()
    msg = _open_error(example)
    assert str(example / "arms.npz") in msg and "missing" in msg


def test_truncated_npz(example):
    data = (example / "arms.npz").read_bytes()
    (example / "arms.npz").write_bytes(data[: len(data) // 2])
    msg = _open_error(example)
    assert str(example / "arms.npz") in msg and "truncated or corrupt" in msg


def test_manifest_not_json(example):
    (example / MANIFEST).write_text("{ not json")
    msg = _open_error(example)
    assert str(example / MANIFEST) in msg and "not valid JSON" in msg


def test_newer_format_version(example):
    manifest = json.loads((example / MANIFEST).read_text())
    manifest["format_version"] = 99
    (example / MANIFEST).write_text(json.dumps(manifest))
    msg = _open_error(example)
    assert "format_version" in msg and "newer regrasp" in msg


def _rewrite_arms_array(folder: Path, name: str, value: np.ndarray) -> None:
    with np.load(folder / "arms.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays[name] = value
    np.savez(folder / "arms.npz", **arrays)


def test_array_of_wrong_shape(example):
    _rewrite_arms_array(example, "q_pick", np.zeros(7))
    msg = _open_error(example)
    assert str(example / "arms.npz") in msg and "q_pick" in msg and "shape" in msg


def test_array_of_wrong_dtype(example):
    _rewrite_arms_array(example, "q_place", np.zeros(49, dtype=np.float32))
    msg = _open_error(example)
    assert "q_place" in msg and "dtype float64" in msg


def test_embedded_task_with_unknown_field(example):
    manifest = json.loads((example / MANIFEST).read_text())
    manifest["task"]["colour"] = "red"
    (example / MANIFEST).write_text(json.dumps(manifest))
    msg = _open_error(example)
    assert str(example / MANIFEST) in msg and "task.colour" in msg and "unknown field" in msg


def test_unknown_step_in_manifest(example):
    manifest = json.loads((example / MANIFEST).read_text())
    manifest["steps"][0]["name"] = "teleport"
    (example / MANIFEST).write_text(json.dumps(manifest))
    msg = _open_error(example)
    assert "steps[0].name" in msg and "teleport" in msg


def test_a_session_saved_before_the_placements_step_opens(example):
    """Sessions written before the motion needed the placements step (it had none) open with their motion; a step
    that needs one listed before it is still refused."""
    manifest = json.loads((example / MANIFEST).read_text())
    record = next(r for r in manifest["steps"] if r["name"] == "placements")
    manifest["steps"].remove(record)
    for name in record["files"]:
        (example / name).unlink()
    (example / MANIFEST).write_text(json.dumps(manifest))
    session = Session.open(example)
    assert "placements" not in session.finished() and session.result("motion").duration > 0
    manifest["steps"] = [r for r in manifest["steps"] if r["name"] != "roadmap"]
    (example / MANIFEST).write_text(json.dumps(manifest))
    assert "needs 'roadmap'" in _open_error(example)


def test_a_session_saved_with_a_retired_parameter_opens_and_runs_again(example, tmp_path):
    """A session whose motion was planned with the smoothing's whole-motion budgets (`smooth_attempts`, `smooth_checks`,
    retired in stop 58 for per-run ones) opens with its motion; running the step again takes today's parameters. A
    parameter no version had is still refused."""
    from planner.core.forked import cpu_budget

    manifest = json.loads((example / MANIFEST).read_text())
    record = next(r for r in manifest["steps"] if r["name"] == "motion")
    for name in ("smooth_attempts_per_s", "smooth_checks_per_s"):
        record["params"].pop(name)
    record["params"].update(smooth_attempts=1000, smooth_checks=24000)
    (example / MANIFEST).write_text(json.dumps(manifest))
    session = Session.open(example)
    assert session.result("motion").duration > 0 and session.record_of("motion")["params"]["smooth_checks"] == 24000
    again = session.branch(tmp_path / "again", "motion")
    with cpu_budget(1):
        run_pipeline(again, params={"motion": {"smooth_attempts_per_s": 0.0, "smooth_checks_per_s": 0.0}})
    assert again.result("motion").duration > 0 and "smooth_checks" not in again.record_of("motion")["params"]
    record["params"]["smooth_everything"] = 1
    (example / MANIFEST).write_text(json.dumps(manifest))
    msg = _open_error(example)
    assert f"steps[{manifest['steps'].index(record)}].params" in msg and "smooth_everything" in msg


def test_branch_keeps_the_original(example, tmp_path):
    folder = example
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    session = Session.open(folder)
    new = session.branch(tmp_path / "branch", before=PIPELINE[0].name)
    assert new.finished() == []
    run_pipeline(new, "arms", params={"arms": {"seeds": 40}})
    assert new.record_of("arms")["params"]["seeds"] == 40
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def test_session_records_the_task_by_name_or_relative_path(tmp_path, default_scene):
    """session.json never holds an absolute path of the machine that wrote it; old sessions that do still load."""
    from planner.model.task import load_task

    named = Session.create(tmp_path / "named", default_scene, seed=0)
    assert json.loads((named.folder / MANIFEST).read_text())["task_source"] == "default"
    own = tmp_path / "tasks" / "mine.toml"
    own.parent.mkdir()
    own.write_text(default_scene.source.read_text())
    relative = Session.create(tmp_path / "runs" / "one", load_task(own), seed=0)
    recorded = json.loads((relative.folder / MANIFEST).read_text())["task_source"]
    assert recorded == "../../tasks/mine.toml" and str(tmp_path) not in (relative.folder / MANIFEST).read_text()
    for old in ("/somewhere/else/assets/tasks/default.toml", "../../../../etc/passwd"):  # a note for people: never opened
        manifest = json.loads((named.folder / MANIFEST).read_text())
        (named.folder / MANIFEST).write_text(json.dumps({**manifest, "task_source": old}))
        assert Session.open(named.folder).scene.source == named.folder / MANIFEST
