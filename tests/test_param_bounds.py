"""Every step parameter and every seed has one declared range (and a parameter its unit), checked before anything runs:
by `--set`, by the command options that set a parameter, by the workbench's inputs and by a session's recorded values."""
from __future__ import annotations

import dataclasses
import html
import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import viser
from sandbox import EXAMPLE, one_error_line
from test_workbench_browser import _free_port

from planner.cli.plan import params_text
from planner.core.bounds import SEED, field_hint
from planner.core.errors import InputError, RegraspError
from planner.core.paths import DEFAULT_TASK
from planner.core.session import MANIFEST, Session
from planner.core.steps import param_bounds
from planner.handover.exchange_grid import MAX_GRID_NODES, grid_nodes
from planner.model.task import load_task
from planner.pipeline import PIPELINE
from workbench.app import Workbench
from workbench.cli import main


def _forbid_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    """No step may run: a refused value must be refused before the pipeline (or the roadmap builder) starts."""
    def ran(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("the pipeline ran with a value it should have refused")

    monkeypatch.setattr("planner.core.runner.run_pipeline", ran)
    monkeypatch.setattr("planner.roadmap.roadmap_for", ran)


def test_every_numeric_parameter_declares_a_range_and_unit_holding_its_default() -> None:
    for step in PIPELINE:
        bounds, defaults = param_bounds(step.params), step.params()
        for f in dataclasses.fields(step.params):
            value = getattr(defaults, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                assert f.name not in bounds, f"{step.name}.{f.name}: a flag or a name has no range"
                continue
            bound = bounds.get(f.name)
            assert bound is not None, f"{step.name}.{f.name} declares no range"
            assert bound.unit.strip(), f"{step.name}.{f.name} declares no unit"
            assert bound.low < bound.high and bound.low <= value <= bound.high, (step.name, f.name, value, bound)
            assert type(bound.low) is type(value) or isinstance(value, float), f"{step.name}.{f.name}: an int's range is whole"
        step.make_params(dataclasses.asdict(defaults))  # the defaults pass every check, the steps' own constraints included


@pytest.mark.parametrize("assignment, message", [
    ("exchange.step=0.001", "parameter step expects a value from 0.01 to 0.5 m, got 0.001"),  # asked for 22 GiB
    ("exchange.step=-0.05", "parameter step expects a value from 0.01 to 0.5 m, got -0.05"),
    ("motion.rate=0", "parameter rate expects a value from 1 to 1000 Hz, got 0"),  # divided by zero
    ("motion.max_velocity=0", "parameter max_velocity expects a value from 0.01 to 20 rad/s, got 0"),
    ("motion.max_acceleration=-2", "parameter max_acceleration expects a value from 0.01 to 100 rad/s^2, got -2"),
    ("motion.straight_steps=-1", "parameter straight_steps expects a value from 1 to 100 waypoints, got -1"),
    ("roadmap.nodes=-5", "parameter nodes expects a value from 2 to 500 nodes, got -5"),
    ("roadmap.nodes=1000000000", "parameter nodes expects a value from 2 to 500 nodes, got 1000000000"),
    ("grasp_configs.workers=100000", "parameter workers expects a value from 1 to 64 processes, got 100000"),
    ("motion.rate=" + "9" * 400, "field 'motion.rate': an integer of 400 digits; expected at most 100 digits"),  # no OverflowError
    ("motion.contact_coarse=0", "parameter contact_coarse expects a value from 1 to 100 (factor), got 0"),
    ("roadmap.env_clearance=0.05", "parameter env_clearance must be below env_padding (0.03 m)"),
    ("motion.contact_env_clearance=0.01", "parameter contact_env_clearance must be below contact_env_padding (0.008 m)"),
])
def test_set_out_of_range_is_one_line_before_any_folder(tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch,
                                                        assignment: str, message: str) -> None:
    _forbid_runs(monkeypatch)
    out = tmp_path / "session"
    assert main(["plan", "default", "--out", str(out), "--set", assignment]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert assignment.split('.')[0] in line and message in line, line
    assert not out.exists(), "a session folder was made for a --set that cannot run"


@pytest.mark.parametrize("args, message", [
    (["roadmap", "--nodes", "1000000000"], "--nodes: step 'roadmap': parameter nodes expects a value from 2 to 500 nodes, got 1000000000"),
    (["roadmap", "--nodes", "1"], "--nodes: step 'roadmap': parameter nodes expects a value from 2 to 500 nodes, got 1"),
    (["grasps", "--hand", "right", "--frames", "100000000"], "--frames: step 'pick_grasps': parameter orientations expects a value "
                                                            "from 1 to 1000 orientations"),
])
def test_options_that_set_a_parameter_check_its_range(capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch,
                                                      args: list[str], message: str) -> None:
    _forbid_runs(monkeypatch)
    monkeypatch.setattr("planner.grasping.grasp_list.grasp_list", lambda *a, **k: pytest.fail("the grasp list was computed"))
    assert main(args) == 2
    assert message in one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("seed", ["18446744073709551616", "-1", "1e3", str(10**400)])
def test_seed_out_of_the_session_range_is_refused_before_any_folder(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                                     monkeypatch: pytest.MonkeyPatch, seed: str) -> None:
    _forbid_runs(monkeypatch)
    out = tmp_path / "session"
    with pytest.raises(SystemExit) as exit_:
        main(["plan", "default", "--out", str(out), "--seed", seed])
    assert exit_.value.code == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert len(errors) == 1 and "argument --seed: expected a seed" in errors[0] and "from 0 to 2**64 - 1" in errors[0], errors
    assert not out.exists(), "a session folder was made for a seed no session can hold"


def test_the_largest_seed_writes_a_session_that_reopens(tmp_path: Path) -> None:
    """The CLI's range and the session reader's are one: its top end is written and read back, one more is refused by both."""
    scene = load_task(DEFAULT_TASK)
    folder = tmp_path / "top"
    Session.create(folder, scene, SEED.high)
    assert Session.open(folder).seed == 2**64 - 1
    with pytest.raises(RegraspError, match=r"session seed: expected a seed from 0 to 2\*\*64 - 1, got -1"):
        Session.create(tmp_path / "negative", scene, -1)
    assert not (tmp_path / "negative").exists()
    manifest = json.loads((folder / MANIFEST).read_text())
    manifest["seed"] = 2**64
    (folder / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(InputError, match="field 'seed': expected a seed from 0 to 2"):
        Session.open(folder)


@pytest.mark.parametrize("step, name, value, message", [
    ("exchange", "step", 0.001, "parameter step expects a value from 0.01 to 0.5 m, got 0.001"),
    ("motion", "rate", 0, "parameter rate expects a value from 1 to 1000 Hz, got 0"),
    ("roadmap", "nodes", -3, "parameter nodes expects a value from 2 to 500 nodes, got -3"),
])
def test_a_session_recording_an_out_of_range_parameter_is_refused(tmp_path: Path, step: str, name: str, value: Any,
                                                                  message: str) -> None:
    folder = tmp_path / "session"
    shutil.copytree(EXAMPLE, folder)
    manifest = json.loads((folder / MANIFEST).read_text())
    index = next(i for i, r in enumerate(manifest["steps"]) if r["name"] == step)
    manifest["steps"][index]["params"][name] = value
    (folder / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(InputError) as error:
        Session.open(folder)
    text = str(error.value)
    assert "\n" not in text and str(folder / MANIFEST) in text and f"steps[{index}].params" in text and message in text, text


def test_a_grid_too_fine_for_the_box_is_refused_before_it_is_made() -> None:
    """The box both hands reach depends on the robot: a step within its range can still ask for too many nodes."""
    lower, upper = np.zeros(3), np.full(3, 1.75)
    assert len(grid_nodes(lower, upper, 0.05)) == 36**3
    with pytest.raises(RegraspError) as error:
        grid_nodes(lower, upper, 0.01)  # 176**3 = 5.5 million nodes
    text = str(error.value)
    assert f"{MAX_GRID_NODES:,}" in text and "exchange.step to 0.0" in text and "5,451,776 nodes" in text, text
    fits = float(text.rsplit("exchange.step to ", 1)[1].split(" m")[0])
    assert len(grid_nodes(lower, upper, fits)) <= MAX_GRID_NODES


def test_every_parameter_declares_a_one_line_hint() -> None:
    for step in PIPELINE:
        for f in dataclasses.fields(step.params):
            hint = field_hint(f)
            assert hint.strip() and "\n" not in hint and len(hint) <= 120, f"{step.name}.{f.name}: {hint!r}"


def test_a_name_with_choices_is_checked_against_them() -> None:
    motion = next(s for s in PIPELINE if s.name == "motion")
    assert motion.make_params({"planner": "rrt"}).planner == "rrt"
    with pytest.raises(RegraspError, match="parameter planner expects one of roadmap, rrt, got 'RRT'"):
        motion.make_params({"planner": "RRT"})


def test_params_lists_each_hint_below_its_parameter() -> None:
    lines = params_text().splitlines()
    at = next(i for i, li in enumerate(lines) if li.split()[:1] == ["exchange.reach_fraction"])
    assert lines[at + 1].strip() == "a node is reachable within this fraction of each arm's reach"
    planner = next(li for li in lines if li.split()[:1] == ["motion.planner"])
    assert planner.endswith("one of roadmap, rrt"), planner


def test_params_lists_each_range_and_unit() -> None:
    lines = params_text().splitlines()
    assert any(li.split()[:1] == ["exchange.step"] and "default 0.05 " in li and li.endswith("from 0.01 to 0.5 m") for li in lines), lines
    assert any(li.split()[:1] == ["motion.rate"] and li.endswith("from 1 to 1000 Hz") for li in lines)


@pytest.fixture(scope="module")
def workbench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workbench]:
    sessions = tmp_path_factory.mktemp("sessions")
    shutil.copytree(EXAMPLE, sessions / "example")
    wb = Workbench(None, "127.0.0.1", _free_port(), session=sessions / "example", sessions_dir=sessions)
    yield wb
    wb.close()


def test_workbench_inputs_take_their_limits_and_hints_from_the_declaration(workbench: Workbench) -> None:
    panel = workbench.session_panel
    panel.rerun_step.value = "exchange"
    assert panel._params is not None
    step = panel._params.handles["step"]
    assert (step.min, step.max) == (0.01, 0.5), (step.min, step.max)
    assert step.hint == "spacing of the exchange grid; from 0.01 to 0.5 m; default 0.05", step.hint
    panel.rerun_step.value = "motion"
    rate = panel._params.handles["rate"]
    assert (rate.min, rate.max) == (1.0, 1000.0) and "from 1 to 1000 Hz" in rate.hint
    planner = panel._params.handles["planner"]
    assert isinstance(planner, viser.GuiDropdownHandle) and tuple(planner.options) == ("roadmap", "rrt"), planner
    assert planner.value == "roadmap" and planner.hint.startswith("roadmap: Super Graph")
    planner.value = "rrt"
    assert panel._params.values()["planner"] == "rrt"
    panel.rerun_step.value = "roadmap"
    tree = panel._params.handles["tree"]
    assert isinstance(tree, viser.GuiCheckboxHandle) and tree.hint.startswith("the tree variant")


def test_workbench_refuses_an_out_of_range_value_before_a_rerun_folder(workbench: Workbench) -> None:
    """A client can send any number (the input's limits are the browser's); the re-run checks the range itself."""
    panel = workbench.session_panel
    assert panel.load(panel.sessions_dir / "example")
    before = sorted(p.name for p in panel.sessions_dir.iterdir())
    panel.rerun_step.value = "arms"
    assert panel._params is not None
    panel._params.handles["seeds"].value = -3
    assert panel.rerun("arms", panel._params.values()) is None
    assert "parameter seeds expects a value from 1 to 1000 IK starts, got -3" in html.unescape(panel.message.content), panel.message.content
    assert sorted(p.name for p in panel.sessions_dir.iterdir()) == before, "a re-run folder was made for a refused value"


def test_workbench_refuses_a_seed_out_of_range(workbench: Workbench) -> None:
    panel = workbench.session_panel
    workbench._load(DEFAULT_TASK, None)
    assert workbench.session is None
    panel.seed.value = -1
    job = panel.run_next()
    assert job is not None
    job.join(60)
    assert "Seed: expected a seed from 0 to 2**64 - 1, got -1" in html.unescape(panel.message.content), panel.message.content
    assert workbench.session is None, "a session was started with a seed no session can hold"


def test_transit_paddings_below_the_roadmaps_clearances_are_a_user_error() -> None:
    """Two steps' parameters meet here (the roadmap's recorded clearance, the motion's paddings): one line naming them."""
    from planner.collision.validity import transit_profile

    with pytest.raises(RegraspError, match=r"step 'motion': parameters transit_env_padding \(0.03 m\) and transit_self_padding "
                                           r"\(0.015 m\) must exceed the roadmap's clearances \(0.05 m, 0 m\)"):
        transit_profile({"env_clearance_m": 0.05, "self_clearance_m": 0.0}, 0.03, 0.015)
