"""The `regrasp` command line: one entry point, one sub-command per capability."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .errors import RegraspError
from .paths import DEFAULT_TASK


def _cmd_workbench(args: argparse.Namespace) -> int:
    from workbench.app import run

    run(args.task, args.host, args.port)
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from .check import check_task
    from .task import load_task

    print(f"loading {args.task} ...", file=sys.stderr)
    report = check_task(load_task(args.task), np.random.default_rng(args.seed))
    print(report.render())
    return 0 if report.ok else 1


def _cmd_bench(args: argparse.Namespace) -> int:
    from .bench import bench_collision
    from .task import load_task

    scene = load_task(args.task)
    print(f"benchmarking collision checks on {scene.name} ({args.samples} configurations) ...", file=sys.stderr)
    result = bench_collision(scene, samples=args.samples, seed=args.seed)
    print(result.render())
    if args.json:
        _write_json(Path(args.json), result.to_dict())
    return 0


def _write_json(path: Path, data: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2))
    tmp.replace(path)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="regrasp", description="Pick-and-place with two-hand regrasping: planner and workbench.")
    sub = p.add_subparsers(dest="command", required=True)
    w = sub.add_parser("workbench", help="start the web workbench (viser)")
    w.add_argument("--task", default=str(DEFAULT_TASK), help="task file (default: the paper's task)")
    w.add_argument("--host", default="127.0.0.1")
    w.add_argument("--port", type=int, default=8080)
    w.set_defaults(func=_cmd_workbench)
    c = sub.add_parser("check", help="validate a task file and print a summary")
    c.add_argument("task", help="task file, or a name in assets/tasks")
    c.add_argument("--seed", type=int, default=0)
    c.set_defaults(func=_cmd_check)
    b = sub.add_parser("bench", help="benchmarks, printed as tables")
    bsub = b.add_subparsers(dest="what", required=True)
    bc = bsub.add_parser("collision", help="collision checking and forward kinematics timings")
    bc.add_argument("--task", default=str(DEFAULT_TASK))
    bc.add_argument("--samples", type=int, default=2000)
    bc.add_argument("--seed", type=int, default=0)
    bc.add_argument("--json", help="also write the figures to this JSON file")
    bc.set_defaults(func=_cmd_bench)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except RegraspError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
