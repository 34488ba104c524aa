"""`regrasp suite`: every task of a suite through the pipeline (local workers or Ray), then its report."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from planner.cli.arguments import CommandLine, positive_int, suite_argument


def _cmd_suite(args: argparse.Namespace) -> int:
    import logging
    import os

    from planner.model.task import load_task
    from planner.suite.executors import LocalExecutor, RayExecutor
    from planner.suite.job import check_until
    from planner.suite.report import STRATEGY_NAMES, write_report
    from planner.suite.run import run_suite
    from planner.suite.spec import load_suite

    until = check_until(args.until)  # a bad --until or suite file fails here: no folder is made
    spec = load_suite(args.suite)
    local = args.workers or os.cpu_count() or 1
    executor = RayExecutor(args.ray) if args.ray is not None else LocalExecutor(local)
    say = lambda message: print(message, file=sys.stderr, flush=True)
    cache_log = logging.getLogger("regrasp.cache")
    level = cache_log.level
    cache_log.setLevel(logging.INFO)  # a line per cache entry built (local workers inherit it): a cold suite's first tasks
    # wait for the grasp lists and roadmaps, and its log shows which; the level is the caller's again after the run
    out = Path(args.out)
    try:
        run = run_suite(spec, out, executor, until, args.resume, args.force, local, say)
    finally:
        cache_log.setLevel(level)
    report = write_report(run.data, spec, load_task(spec.base_task).environment, out)
    data = run.data
    print(f"suite {spec.name}: {data['succeeded']} of {data['tasks']} tasks succeeded (success_rate {data['success_rate']:.3f}) "
          f"through {data['until']} in {data['wall_seconds']:.0f} s")
    for key, count in data.get("by_strategy", {}).items():
        print(f"  succeeded by {STRATEGY_NAMES.get(key, key)}: {count}")
    for key, count in data["by_stage"].items():
        print(f"  failed at {key}: {count}")
    print(f"wrote {out / 'suite.json'}, {out / 'suite.csv'} and {report}")
    return 0


def add_suite(line: CommandLine) -> None:
    """`regrasp suite`."""
    su = line.command("suite", "run every task of a suite through the pipeline (local workers or Ray) and report", _cmd_suite,
                      epilog="The folder gets suite.json, suite.csv, report.html (open it in a browser), tasks/ (the generated "
                             "task files), sessions/ (one session per task, for `regrasp replay`) and results/ (what --resume keeps).")
    su.add("suite", type=suite_argument, metavar="SUITE", help="a suite file, or the name of one in assets/suites/ (e.g. default)")
    su.add("--out", required=True, metavar="DIR", help="folder to write the suite's tasks, sessions and report into")
    where = su.parser.add_mutually_exclusive_group()
    su.add("--workers", within=where, type=positive_int, metavar="N", help="local worker processes (default: the number of CPUs)")
    su.add("--ray", within=where, nargs="?", const="", metavar="ADDRESS",
           help="run the tasks as Ray tasks: on the cluster at ADDRESS, or on a local Ray when none is given "
                "(needs pip install 'regrasp[cluster]')")
    su.add("--until", metavar="STEP", help="last step of every task, e.g. double-grasps (default: every step, through motion)")
    su.add("--resume", action="store_true", help="continue the suite in --out: finished tasks are kept, the others run")
    su.add("--force", action="store_true", help="replace an existing suite in --out")
