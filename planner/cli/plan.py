"""`regrasp check`, `regrasp plan` and `regrasp params`: validate a task, run the pipeline into a session folder, list
every step's parameters."""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

from planner.cli.arguments import CommandLine, add_task, seed_argument
from planner.cli.progress import Bars


def _cmd_check(args: argparse.Namespace) -> int:
    from planner.check import check_task
    from planner.model.task import load_task

    print(f"loading {args.task} ...", file=sys.stderr)
    report = check_task(load_task(args.task))
    print(report.render())
    return 0 if report.ok else 1


def step_params(assignments: list[str]) -> dict[str, dict[str, Any]]:
    """The `--set STEP.PARAM=VALUE` assignments by step, each step's set checked whole (names, types) before anything runs."""
    from planner.core.steps import parse_assignment
    from planner.pipeline import step_named

    params: dict[str, dict[str, Any]] = {}
    for text in assignments:
        step, name, value = parse_assignment(text)
        params.setdefault(step_named(step).name, {})[name] = value
    for step, values in params.items():
        step_named(step).make_params(values)
    return params


def _cmd_plan(args: argparse.Namespace) -> int:
    from planner.check import require_valid
    from planner.core.runner import run_pipeline
    from planner.core.session import Session
    from planner.core.stages import stage_table
    from planner.core.steps import StepFailed
    from planner.model.task import load_task
    from planner.pipeline import step_named, steps_until

    params = step_params(args.set or [])  # a bad --set or --until fails here: no session folder is made
    steps_until(args.until)
    out = Path(args.out)
    warned: set[str] = set()
    with Bars() as bars:
        def warn(message: str) -> None:
            if message not in warned:  # the task is validated before the session is made, and again before the steps
                warned.add(message)
                bars.say(message)

        if args.resume and Session.exists(out):
            session = Session.open(out)
            bars.say(f"resuming {out}: finished {', '.join(session.finished()) or 'nothing yet'}")
        else:
            scene = load_task(args.task)
            require_valid(scene, warn)  # no session folder for a task `check` rejects
            session = Session.create(out, scene, args.seed, force=args.force)
        failed = None
        try:
            ran = run_pipeline(session, args.until, params, lambda step: bars.start(step.name), warn)
        except StepFailed as exc:
            ran, failed = [r["name"] for r in session.records], exc
    print(f"{'step':<16}{'seconds':>9}  key figures")
    for record in session.records:
        figures = ", ".join(f"{k}={v}" for k, v in record["stats"].items() if k != "failure")
        mark = ("  (from the cache)" if record.get("cached") else "") + ("" if record["name"] in ran else "  (earlier run)")
        print(f"{record['name']:<16}{record['seconds']:>9.2f}  {figures}{mark}")
    staged = [(r["name"], session.result(r["name"]).stages, r.get("stage_seconds", [])) for r in session.records
              if "stages" in {f.name for f in dataclasses.fields(step_named(r["name"]).result)}]
    if staged:
        print()
        print(stage_table(staged))
    print(f"session written to {out}")
    if failed is not None:
        print(f"error: {failed}", file=sys.stderr)
        return 1
    return 0


def params_text() -> str:
    """Every pipeline step's parameters with their types, defaults, ranges and units (or choices), each with its one-line
    hint below it, as `regrasp params` prints them."""
    from planner.core.bounds import field_choices, field_hint
    from planner.core.steps import param_bounds
    from planner.pipeline import PIPELINE

    lines = []
    for step in PIPELINE:
        defaults, bounds = step.params(), param_bounds(step.params)
        lines.append(f"{step.name}: {step.summary}")
        for f in dataclasses.fields(step.params):
            default, bound, choices = f"default {getattr(defaults, f.name)!r}", bounds.get(f.name), field_choices(f)
            allowed = bound.describe() if bound else f"one of {', '.join(choices)}" if choices else ""
            lines.append(f"  {step.name}.{f.name:<22} {f.type:<6} {default:<16} {allowed}".rstrip())
            if field_hint(f):
                lines.append(f"      {field_hint(f)}")
        lines.append("")
    lines.append("Set one with `regrasp plan TASK --out DIR --set STEP.PARAM=VALUE` (the value is read as JSON, else as a string).")
    return "\n".join(lines)


def _cmd_params(args: argparse.Namespace) -> int:
    print(params_text())
    return 0


def _pipeline_epilog() -> str:
    """The steps of `regrasp plan`, for its help."""
    from planner.pipeline import PIPELINE

    steps = "\n".join(f"  {s.name:<14} {s.summary}" for s in PIPELINE)
    return f"steps, in order (STEP in --until and --set; `regrasp params` lists every parameter):\n{steps}"


def add_check(line: CommandLine) -> None:
    """`regrasp check`."""
    add_task(line.command("check", "validate a task and print a summary; exit 1 if it is not a valid regrasping task", _cmd_check))


def add_plan(line: CommandLine) -> None:
    """`regrasp plan`."""
    pl = line.command("plan", "run the pipeline headless into a session folder", _cmd_plan, epilog=_pipeline_epilog)
    add_task(pl)
    pl.add("--out", required=True, metavar="DIR", help="session folder to write")
    pl.add("--seed", type=seed_argument, default=0, help="session seed (each step's generator is derived from it)")
    pl.add("--until", metavar="STEP", help="last step to run, e.g. double-grasps (default: every step)")
    pl.add("--resume", action="store_true", help="continue the session in --out where it stopped")
    pl.add("--force", action="store_true", help="replace an existing session in --out")
    pl.add("--set", action="append", metavar="STEP.PARAM=VALUE",
           help="a step parameter, checked against its range before any step runs (repeatable; `regrasp params` lists "
                "them with their ranges and units)")


def add_params(line: CommandLine) -> None:
    """`regrasp params`."""
    line.command("params", "list every step's parameters with their types, defaults, ranges, units and what they do", _cmd_params)
