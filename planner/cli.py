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


def _cmd_plan(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .runner import run_pipeline
    from .session import Session
    from .steps import parse_assignment
    from .task import load_task

    params: dict[str, dict] = {}
    for text in args.set or []:
        step, name, value = parse_assignment(text)
        params.setdefault(step, {})[name] = value
    out = Path(args.out)
    if args.resume and Session.exists(out):
        session = Session.open(out)
        print(f"resuming {out}: finished {', '.join(session.finished()) or 'nothing yet'}", file=sys.stderr)
    else:
        session = Session.create(out, load_task(args.task), args.seed, force=args.force)

    def progress(step):
        bar = tqdm(total=100, desc=f"{step.name:<14}", unit="%", leave=True, file=sys.stderr,
                   bar_format="{desc} {bar} {n:.0f}% {postfix}")

        def report(fraction: float, message: str = "") -> None:
            bar.n = round(100 * min(max(fraction, 0.0), 1.0))
            bar.set_postfix_str(message, refresh=False)
            bar.refresh()
            if fraction >= 1.0:
                bar.close()
        return report

    ran = run_pipeline(session, args.until, params, progress)
    print(f"{'step':<16}{'seconds':>9}  key figures")
    for record in session.records:
        figures = ", ".join(f"{k}={v}" for k, v in record["stats"].items())
        mark = "" if record["name"] in ran else "  (earlier run)"
        print(f"{record['name']:<16}{record['seconds']:>9.2f}  {figures}{mark}")
    print(f"session written to {out}")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from workbench.app import run

    run(None, args.host, args.port, session=Path(args.session))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from workbench.export import export_html

    export_html(Path(args.session), Path(args.html))
    print(f"wrote {args.html}")
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
    pl = sub.add_parser("plan", help="run the pipeline headless into a session folder")
    pl.add_argument("task", help="task file, or a name in assets/tasks")
    pl.add_argument("--out", required=True, help="session folder to write")
    pl.add_argument("--seed", type=int, default=0)
    pl.add_argument("--until", help="last step to run (default: all)")
    pl.add_argument("--resume", action="store_true", help="continue the session in --out where it stopped")
    pl.add_argument("--force", action="store_true", help="replace an existing session in --out")
    pl.add_argument("--set", action="append", metavar="STEP.PARAM=VALUE", help="a step parameter (repeatable)")
    pl.set_defaults(func=_cmd_plan)
    r = sub.add_parser("replay", help="open the workbench on a saved session")
    r.add_argument("session", help="session folder")
    r.add_argument("--host", default="127.0.0.1")
    r.add_argument("--port", type=int, default=8080)
    r.set_defaults(func=_cmd_replay)
    e = sub.add_parser("export", help="export a saved session as one self-contained HTML file")
    e.add_argument("session", help="session folder")
    e.add_argument("--html", required=True, help="HTML file to write")
    e.set_defaults(func=_cmd_export)
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
