"""The `regrasp` command line, run as a user runs it: exit codes, tables, JSON, clear errors."""
from __future__ import annotations

import argparse
import dataclasses
import io
import json
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import sandbox

from planner.cli.arguments import Command, task_argument
from planner.cli.progress import Bars
from planner.core.paths import PROJECT_ROOT
from planner.pipeline import PIPELINE
from workbench.cli import command_line, main


def regrasp(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, timeout=600)


@pytest.mark.slow  # 4-6 s: kept out of the fast subset (CI runs it)
def test_check_default_task():
    run = regrasp("check", "default")
    assert run.returncode == 0, run.stdout + run.stderr
    out = run.stdout
    assert "total           49" in out
    assert "initial   collision-free" in out and "final     collision-free" in out
    assert "initial   right: yes" in out and "left: no" in out.split("initial", 3)[-1]
    assert "OK: a valid two-hand regrasping task" in out


@pytest.mark.slow
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


@pytest.mark.slow
def test_check_reports_a_task_that_needs_no_regrasp(tmp_path):
    from planner.core.paths import ASSETS

    text = (ASSETS / "tasks" / "default.toml").read_text()
    moved = text.replace("final = { xyz = [0.50, 0.85, 0.72]", "final = { xyz = [0.50, -0.70, 0.72]")
    assert moved != text, "the default task's final placement changed: update this test"
    text = moved
    task = tmp_path / "same_side.toml"
    task.write_text(text.replace('robot = "alex_allegro.toml"', f'robot = "{ASSETS / "robots" / "alex_allegro.toml"}"'))
    run = regrasp("check", str(task))
    assert run.returncode == 0, run.stdout + run.stderr  # a valid task: one arm carries the object, no handover
    assert "arms: the right arm picks and places (no handover is needed: the right arm reaches both placements" in run.stdout
    assert "handover = true" in run.stdout and "OK: a valid pick-and-place task for one arm (no handover)" in run.stdout


@pytest.mark.slow  # 4-6 s: kept out of the fast subset (CI runs it)
def test_bench_collision_json(tmp_path):
    out = tmp_path / "bench.json"
    run = regrasp("bench", "collision", "--samples", "300", "--json", str(out))
    assert run.returncode == 0, run.stderr
    figures = json.loads(out.read_text())
    for key in ("full_check_us_median", "full_check_us_p95", "arm_env_check_us_median", "fk_us_median", "pairs_kept", "dof"):
        assert key in figures
    assert figures["dof"] == 49 and figures["pairs_kept"] > 1000
    assert "median µs" in run.stdout


SMALL_BENCH = ("roadmap.nodes=4", "roadmap.task_nodes=0", "pick_grasps.orientations=16", "place_grasps.orientations=16",
               "motion.smooth_checks_per_s=80")  # a motion benchmark's inputs made in seconds


def _small_bench(tmp_path: Path, *args: str) -> tuple:
    """(the run, its JSON figures) of `regrasp bench ARGS` on one seed with SMALL_BENCH's settings, from an empty cache."""
    out = tmp_path / "bench.json"
    run = sandbox.regrasp("bench", *args, "--seeds", "1", *(a for s in SMALL_BENCH for a in ("--set", s)),
                          "--json", str(out), REGRASP_CACHE=str(tmp_path / "cache"))
    assert run.returncode == 0, run.stderr
    return run, json.loads(out.read_text())


@pytest.mark.slow  # about 20 s from an empty cache: grasp lists, two 4-node roadmaps, three motions
def test_bench_motion_on_two_roadmaps_from_an_empty_cache(tmp_path):
    run, figures = _small_bench(tmp_path, "motion", "--roadmaps", "2")
    assert figures["roadmaps"] == 2 and [r["roadmap"] for r in figures["per_roadmap"]] == [0, 1]
    assert [(r["seed"], r["roadmap"]) for r in figures["runs"]["roadmap"]] == [(0, 0), (0, 1)]
    assert [(r["seed"], r["roadmap"]) for r in figures["runs"]["rrt"]] == [(0, None)]
    assert figures["ours_success"] == 1.0 and figures["rrt_success"] == 1.0
    assert all(r["pair_tests"] > 0 and r["duration"] > 0 for r in figures["per_roadmap"])
    for r in figures["runs"]["roadmap"] + figures["runs"]["rrt"]:  # --set reached the motion step (24,000 by default)
        assert sum(p["smoothing_checks"] for p in r["phases"]) < 3000
        for p in r["phases"]:  # the RRTConnect's, the shortcuts' and the arm moved away's pair tests are parts of the transits'
            parts = p["transit_pair_tests_rrt"] + p["transit_pair_tests_shortcut"] + p["transit_pair_tests_away"]
            assert 0 <= parts <= p["transit_pair_tests"], p
    assert figures["rrt_pair_tests_by_part"]["RRTConnect"] > 0 and figures["pair_test_ratio_bound"] > 0
    assert "where the transits' pair tests go" in run.stdout
    assert "ours per roadmap" in run.stdout and "the roadmap of session seed 1" in run.stderr


@pytest.mark.slow  # about 15 s from an empty cache: grasp lists, a 4-node roadmap, two motions
def test_bench_smoothing_from_an_empty_cache(tmp_path):
    run, figures = _small_bench(tmp_path, "smoothing", "--repeat", "1")
    (row,) = figures["runs"]
    assert row["seed"] == 0 and row["success"] and figures["success"] == 1.0
    # --set reached the smoothed run: its checks stay within 80 a second it could save (1,000 by default), and those
    # seconds within the motion timed rest to rest at every vertex
    assert 0 < row["smoothing_checks"] <= 80 * row["unsmoothed_duration"]
    assert row["duration"] < row["unsmoothed_duration"]  # timed rest to rest at every vertex, the motion is longer
    assert row["seconds"] > 0 and row["unsmoothed_seconds"] > 0
    assert figures["planning_growth_median"] == row["seconds"] / row["unsmoothed_seconds"] - 1.0
    # per pass, what its kept shortcuts saved sums to the smoothing's saving (each run's duration rounded up to whole
    # samples, with and without: within a period per run and setting, at most 8 runs at 30 Hz)
    assert list(figures["passes"]) == ["vertices", "corners", "random"] and sum(row["smoothing_kept"]) > 0
    assert abs(sum(row["smoothing_saved"]) - (row["unsmoothed_duration"] - row["duration"])) < 8 / 30
    assert "the smoothing adds" in run.stdout and "at most 20% asked" in run.stdout


@pytest.mark.slow
def test_bench_motion_refuses_to_set_what_it_compares():
    run = regrasp("bench", "motion", "--seeds", "1", "--set", "motion.planner=rrt")
    assert run.returncode == 2 and run.stderr.strip().splitlines() == [
        "error: --set: bench motion sets motion.planner itself (it compares the planners on the handover)"]


# ---------------------------------------------------------------------------------------------
# A command line that teaches itself (issue 14, item 6).


def _commands() -> dict[str, Command]:
    """Every (sub-)command by its full name, e.g. 'plan', 'bench collision' ('' is the top level), with its options."""
    return command_line().commands


def parser() -> argparse.ArgumentParser:
    return command_line().root


def test_every_option_is_known_by_its_command():
    """The options each command's usage lists are the ones it was given through `Command.add` (what the tests below see)."""
    for name, command in _commands().items():
        listed = set(re.findall(r"(?<![\w-])(--?[a-z][a-z-]*)", command.parser.format_usage())) - {"-h", "--version"}
        assert listed == {option for action in command.arguments for option in action.option_strings}, name


def test_regrasp_alone_prints_help():
    run = regrasp()
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("usage: regrasp") and "error" not in run.stderr
    for command in ("workbench", "check", "plan", "params", "replay", "export", "screenshot", "roadmap", "grasps", "bench"):
        assert command in run.stdout


def test_version():
    from planner import __version__

    run = regrasp("--version")
    assert run.returncode == 0 and run.stdout.strip() == f"regrasp {__version__}"


def test_task_is_the_same_positional_in_every_command():
    commands = _commands()
    takes_task = {name for name, c in commands.items() if any(a.dest == "task" for a in c.arguments)}
    assert takes_task == {"workbench", "check", "plan", "roadmap", "grasps", "bench collision", "bench double-grasps", "bench motion",
                          "bench smoothing", "bench grasps"}
    for name in takes_task:
        (task,) = [a for a in commands[name].arguments if a.dest == "task"]
        assert task.option_strings == [] and task.type is task_argument and task.nargs == "?", name
    assert not any(re.search(r"--task\b(?!-)", c.parser.format_help()) for c in commands.values())  # no --task option
    args = parser().parse_args(["roadmap", "baxter"])
    assert args.task == PROJECT_ROOT / "assets" / "tasks" / "baxter.toml"
    assert parser().parse_args(["bench", "collision"]).task.name == "default.toml"


@pytest.mark.slow
def test_wrong_task_name_suggests_and_lists(tmp_path):
    for args in (("check", "defualt"), ("plan", "defualt", "--out", str(tmp_path / "s")), ("roadmap", "baxtr")):
        run = regrasp(*args)
        assert run.returncode == 2 and "Traceback" not in run.stderr, args
        assert "did you mean '" in run.stderr and "tasks: baxter, default" in run.stderr, run.stderr
    assert "did you mean 'baxter'" in run.stderr
    assert not (tmp_path / "s").exists()
    task = tmp_path / "mine.toml"
    task.write_text((PROJECT_ROOT / "assets" / "tasks" / "default.toml").read_text())
    assert parser().parse_args(["check", str(task)]).task == task  # a file is taken as a file


def test_every_option_has_help_and_shows_its_default():
    for name, command in _commands().items():
        text = command.parser.format_help()
        for action in command.arguments:
            assert action.help, f"regrasp {name}: {action.dest} has no help"
            if action.default not in (None, False):
                # argparse wraps long words (a default path) at the terminal's width: compared without whitespace
                shown = f"(default:{action.default})".replace(" ", "")
                assert shown in "".join(text.split()), f"regrasp {name}: {action.dest} hides its default"


def test_plan_help_lists_the_steps():
    text = _commands()["plan"].parser.format_help()
    for step in PIPELINE:
        assert f"  {step.name} " in text


def test_a_command_that_reads_no_task_loads_neither_the_pipeline_nor_the_workbench():
    """`regrasp --version` and the top-level help need only the parser (`plan --help` lists the steps when printed:
    test_plan_help_lists_the_steps): in a fresh interpreter, neither imports viser, trimesh nor the pipeline."""
    probe = ("import sys\nfrom workbench.cli import main\nfor args in (['--version'], ['--help']):\n    try:\n"
             "        main(args)\n    except SystemExit:\n        pass\n"
             "print(sorted(m for m in ('viser', 'trimesh', 'planner.pipeline') if m in sys.modules))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert run.stdout.splitlines()[-1] == "[]", run.stdout[-300:]


def test_params_lists_every_parameter_with_type_and_default():
    run = regrasp("params")
    assert run.returncode == 0, run.stderr
    for step in PIPELINE:
        defaults = step.params()
        for f in dataclasses.fields(step.params):
            line = next(li for li in run.stdout.splitlines() if li.split()[:1] == [f"{step.name}.{f.name}"])
            assert f" {f.type} " in line and f" default {getattr(defaults, f.name)!r}" in line, line


@pytest.mark.parametrize("assignment, message", [
    ("nostep.seeds=3", "no step 'nostep'"),
    ("arms.nope=3", "step 'arms' has no parameter nope"),
    ("motion.rrt_motions=fast", "parameter rrt_motions expects int, got 'fast'"),
    ("exchange.keep=2.5", "parameter keep expects int"),
    ("roadmap.radius=NaN", "parameter radius expects a finite number"),
    ("motion.planner=fast", "parameter planner expects one of roadmap, rrt, got 'fast'"),
    ("motion.contact_coarse=0", "parameter contact_coarse expects a value from 1 to 100 (factor), got 0"),
    ("arms", "--set expects step.param=value"),
])
def test_every_set_is_checked_before_any_step(tmp_path, capsys, assignment, message):
    out = tmp_path / "session"
    assert main(["plan", "default", "--out", str(out), "--set", "arms.seeds=4", "--set", assignment]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists(), "a session folder was made for a --set that cannot run"


def test_a_port_in_use_is_an_error_naming_it(capsys):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["workbench", "--port", str(port)]) == 2
    out, err = capsys.readouterr()
    assert f"port {port} on 127.0.0.1 is in use" in err and "--port" in err
    assert err.count("\n") == 1 and out == "", (out, err)  # the error alone: no banner of a server on another port


@pytest.mark.slow
def test_a_port_in_use_prints_only_the_error_line(tmp_path):
    """As a user runs it: one line on stderr, nothing on stdout (viser's banner for the next free port never shows)."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = regrasp("workbench", "--port", str(port))
    assert run.returncode == 2 and run.stdout == "", run.stdout
    assert run.stderr.splitlines() == [f"error: port {port} on 127.0.0.1 is in use (another workbench?): stop it, or choose another "
                                       "with --port"], run.stderr


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_bars_end_their_line_before_a_message():
    stream = _Terminal()
    with Bars(stream) as bars:
        bars.start("arms")(0.3, "left arm")
        bars.say("a warning")
        bars.start("pick_grasps")(0.5, "frames")
    text = stream.getvalue()
    before, after = text.split("a warning\n")
    assert before.endswith("\r") and "arms" in before and "left arm" in before
    assert "pick_grasps" in after and text.endswith("\n"), "the last bar did not end its line"


def test_bars_print_plain_lines_off_a_terminal():
    stream = io.StringIO()
    with Bars(stream) as bars:
        report = bars.start("roadmap")
        for i in range(101):
            report(i / 100, f"node {i}")
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue() and len(lines) == 11
    assert lines[0] == "roadmap:   0% node 0" and lines[-1] == "roadmap: 100% node 100"


@pytest.mark.slow
def test_plan_progress_in_a_log_is_plain_lines(tmp_path):
    run = regrasp("plan", "default", "--out", str(tmp_path / "s"), "--until", "arms")
    assert run.returncode == 0, run.stderr
    assert "\r" not in run.stderr
    assert any(re.fullmatch(r"arms: 100% .*", line) for line in run.stderr.splitlines()), run.stderr


def test_planner_never_imports_workbench():
    """The backend stands alone: the command line that joins both halves lives in workbench/."""
    offenders = [f"{path}:{n}" for path in sorted((PROJECT_ROOT / "planner").rglob("*.py"))
                 for n, line in enumerate(path.read_text().splitlines(), 1)
                 if re.match(r"\s*(import workbench|from workbench)\b", line)]
    assert offenders == []


def test_readme_starts_with_the_workbench_and_shows_its_picture():
    text = (PROJECT_ROOT / "README.md").read_text()
    first_command = text.index("```bash")
    assert "regrasp workbench" in text[first_command:text.index("```", first_command + 7)]
    assert text.index("regrasp workbench") < text.index("http://127.0.0.1:8080") < text.index("pytest")
    images = re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", text)
    assert images == ["assets/workbench.png"], images
    image = PROJECT_ROOT / images[0]
    assert image.is_file() and image.stat().st_size < 300_000
    assert image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "regrasp screenshot" in text, "the README must say how its picture is made"
