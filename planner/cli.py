"""The `regrasp` command line: one entry point, one sub-command per capability."""
from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import RegraspError
from .paths import DEFAULT_TASK

if TYPE_CHECKING:
    import trimesh

    from .robot_spec import RobotSpec


def _cmd_workbench(args: argparse.Namespace) -> int:
    from workbench.app import run

    run(args.task, args.host, args.port)
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from .check import check_task
    from .task import load_task

    print(f"loading {args.task} ...", file=sys.stderr)
    report = check_task(load_task(args.task))
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


def _cmd_bench_double_grasps(args: argparse.Namespace) -> int:
    import tempfile

    from .bench import bench_double_grasps
    from .task import load_task

    scene = load_task(args.task)
    with tempfile.TemporaryDirectory(prefix="regrasp-bench-") as tmp:
        result = bench_double_grasps(scene, args.seed, args.repeat, Path(tmp), lambda m: print(m, file=sys.stderr))
    print(result.render())
    if args.json:
        _write_json(Path(args.json), result.to_dict())
    return 0


def _cmd_bench_motion(args: argparse.Namespace) -> int:
    import tempfile

    from .bench import bench_motion
    from .task import load_task

    scene = load_task(args.task)
    with tempfile.TemporaryDirectory(prefix="regrasp-bench-") as tmp:
        result = bench_motion(scene, args.seeds, Path(tmp), lambda m: print(m, file=sys.stderr))
    print(result.render())
    if args.json:
        _write_json(Path(args.json), result.to_dict())
    return 0


def _cmd_plan(args: argparse.Namespace) -> int:
    import dataclasses

    from tqdm import tqdm

    from .check import require_valid
    from .pipeline import step_named
    from .runner import run_pipeline
    from .session import Session
    from .stages import stage_table
    from .steps import StepFailed, parse_assignment
    from .task import load_task

    params: dict[str, dict] = {}
    for text in args.set or []:
        step, name, value = parse_assignment(text)
        params.setdefault(step, {})[name] = value
    out = Path(args.out)
    warned: set[str] = set()

    def warn(message: str) -> None:
        if message not in warned:  # the task is validated before the session is made, and again before the steps
            warned.add(message)
            print(message, file=sys.stderr)

    if args.resume and Session.exists(out):
        session = Session.open(out)
        print(f"resuming {out}: finished {', '.join(session.finished()) or 'nothing yet'}", file=sys.stderr)
    else:
        scene = load_task(args.task)
        require_valid(scene, warn)  # no session folder for a task `check` rejects
        session = Session.create(out, scene, args.seed, force=args.force)

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

    failed = None
    try:
        ran = run_pipeline(session, args.until, params, progress, warn)
    except StepFailed as exc:
        ran, failed = [r["name"] for r in session.records], exc
    print(f"{'step':<16}{'seconds':>9}  key figures")
    for record in session.records:
        figures = ", ".join(f"{k}={v}" for k, v in record["stats"].items() if k != "failure")
        mark = "" if record["name"] in ran else "  (earlier run)"
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


def _cmd_replay(args: argparse.Namespace) -> int:
    from workbench.app import run

    run(None, args.host, args.port, session=Path(args.session))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from workbench.export import export_html

    export_html(Path(args.session), Path(args.html))
    print(f"wrote {args.html}")
    return 0


def _cmd_roadmap(args: argparse.Namespace) -> int:
    import time

    from tqdm import tqdm

    from .roadmap import RoadmapParams, roadmap_for
    from .roadmap.result import render_stats
    from .roadmap.step import session_roadmap_seed
    from .task import load_task

    scene = load_task(args.task)
    params = RoadmapParams(nodes=args.nodes, tree=args.tree)
    bar = tqdm(total=100, desc="roadmap", unit="%", file=sys.stderr, bar_format="{desc} {bar} {n:.0f}% {postfix}")

    def progress(fraction: float, message: str = "") -> None:
        bar.n = round(100 * min(max(fraction, 0.0), 1.0))
        bar.set_postfix_str(message, refresh=False)
        bar.refresh()

    start = time.perf_counter()
    roadmap, seconds = roadmap_for(scene, params, session_roadmap_seed(args.seed), not args.no_cache, progress)
    cached = not seconds
    bar.close()
    stats = roadmap.stats()
    print(render_stats(stats, seconds))
    loaded = time.perf_counter() - start
    print(f"loaded from the cache in {loaded:.2f} s" if cached else f"built in {loaded:.2f} s (cached for next time)")
    if args.json:
        _write_json(Path(args.json), {**stats, "cached": cached, "wall_seconds": round(loaded, 3),
                                      "stage_seconds": {k: round(v, 3) for k, v in seconds.items()}})
    return 0


def _cmd_grasps(args: argparse.Namespace) -> int:
    import dataclasses
    import math
    import time

    from tqdm import tqdm

    from .grasps import GraspParams, grasp_list, session_grasp_seed

    robot_spec, mesh, what = _grasp_inputs(args)
    params = GraspParams()
    if args.frames is not None:
        params = dataclasses.replace(params, orientations=max(1, math.ceil(args.frames / params.positions)))
    bar = tqdm(total=100, desc=f"{args.hand} grasps", unit="%", file=sys.stderr, bar_format="{desc} {bar} {n:.0f}% {postfix}")

    def progress(fraction: float, message: str = "") -> None:
        bar.n = round(100 * min(max(fraction, 0.0), 1.0))
        bar.set_postfix_str(message, refresh=False)
        bar.refresh()

    start = time.perf_counter()
    result, cached = grasp_list(robot_spec, args.hand, mesh, params, session_grasp_seed(args.seed), progress, use_cache=not args.no_cache)
    seconds = time.perf_counter() - start
    bar.close()
    s = result.stats()
    rows = [("frames tried", s["frames"], ""), ("contacts found", s["contacts_found"], "grasps with >= 3 contacts"),
            ("force-closed", s["force_closed"], ""), ("kept", s["kept"], "ranked, near-duplicates removed"),
            ("time", f"{seconds:.1f} s", "from the cache" if cached else "")]
    print(f"grasp list of the {args.hand} hand on {what}")
    print("\n".join(f"  {name:<15} {value!s:>8}  {note}".rstrip() for name, value, note in rows))
    if args.json:
        _write_json(Path(args.json), result.to_json(round(seconds, 3)))
    if result.failure:
        print(f"error: {result.failure}", file=sys.stderr)
        return 1
    return 0


def _grasp_inputs(args: argparse.Namespace) -> tuple[RobotSpec, trimesh.Trimesh, str]:
    """The robot spec, the object mesh and a label, from --task or from --robot and --object."""
    from .check import require_valid
    from .object_mesh import load_object_mesh
    from .robot_spec import load_robot_spec
    from .task import BUILTIN_OBJECTS, load_task

    if args.robot or args.object:
        if not (args.robot and args.object) or args.task:
            raise RegraspError("give either --task, or both --robot and --object")
        mesh_path = BUILTIN_OBJECTS.get(args.object, Path(args.object))
        return load_robot_spec(args.robot), load_object_mesh(mesh_path), f"{mesh_path.name} ({args.robot})"
    scene = load_task(args.task or DEFAULT_TASK)
    require_valid(scene, lambda message: print(message, file=sys.stderr))
    return scene.robot.spec, scene.object_mesh, f"{scene.object_name} (task {scene.name})"


def _write_json(path: Path, data: dict) -> None:
    from .results import atomic_write_text

    atomic_write_text(path, json.dumps(data, indent=2))


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
    c.add_argument("--seed", type=int, default=0, help="unused: reachability is tried from fixed starts, as the arms step does")
    c.set_defaults(func=_cmd_check)
    pl = sub.add_parser("plan", help="run the pipeline headless into a session folder")
    pl.add_argument("task", help="task file, or a name in assets/tasks")
    pl.add_argument("--out", required=True, help="session folder to write")
    pl.add_argument("--seed", type=int, default=0)
    pl.add_argument("--until", help="last step to run, e.g. double-grasps (default: all)")
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
    rm = sub.add_parser("roadmap", help="build (or load from the cache) the offline roadmap and print its statistics")
    rm.add_argument("--task", default=str(DEFAULT_TASK))
    rm.add_argument("--nodes", type=int, default=50, help="nodes per elementary roadmap")
    rm.add_argument("--seed", type=int, default=0, help="session seed (the same roadmap as a session with this seed)")
    rm.add_argument("--tree", action="store_true", help="the tree variant: SG edges only between different components")
    rm.add_argument("--no-cache", action="store_true", help="rebuild even when a cached roadmap exists")
    rm.add_argument("--json", help="also write the statistics to this JSON file")
    rm.set_defaults(func=_cmd_roadmap)
    g = sub.add_parser("grasps", help="compute (or load from the cache) one hand's single-grasp list and print its summary")
    g.add_argument("--task", help="task file (default: the paper's task)")
    g.add_argument("--robot", help="robot spec (with --object, instead of --task)")
    g.add_argument("--object", help="object mesh file, or 'statuette' (with --robot)")
    g.add_argument("--hand", required=True, help="the arm whose hand grasps, e.g. right or left")
    g.add_argument("--frames", type=int, help="about this many grasp frames (positions x orientations)")
    g.add_argument("--seed", type=int, default=0, help="session seed: the list `plan --seed` computes (and caches) for the hand")
    g.add_argument("--no-cache", action="store_true", help="recompute even when a cached list exists")
    g.add_argument("--json", help="also write the list to this JSON file")
    g.set_defaults(func=_cmd_grasps)
    b = sub.add_parser("bench", help="benchmarks, printed as tables")
    bsub = b.add_subparsers(dest="what", required=True)
    bc = bsub.add_parser("collision", help="collision checking and forward kinematics timings")
    bc.add_argument("--task", default=str(DEFAULT_TASK))
    bc.add_argument("--samples", type=int, default=2000)
    bc.add_argument("--seed", type=int, default=0)
    bc.add_argument("--json", help="also write the figures to this JSON file")
    bc.set_defaults(func=_cmd_bench)
    bd = bsub.add_parser("double-grasps", help="grasp configurations, exchange position and double grasps, timed over runs")
    bd.add_argument("--task", default=str(DEFAULT_TASK))
    bd.add_argument("--seed", type=int, default=0, help="session seed")
    bd.add_argument("--repeat", type=int, default=5)
    bd.add_argument("--json", help="also write the figures to this JSON file")
    bd.set_defaults(func=_cmd_bench_double_grasps)
    bm = bsub.add_parser("motion", help="Table I: the motion over seeds with the Super Graph and with RRTConnect alone")
    bm.add_argument("--task", default=str(DEFAULT_TASK))
    bm.add_argument("--seeds", type=int, default=10, help="online seeds 0..N-1 (the grasp lists and roadmap: seed 0, cached)")
    bm.add_argument("--json", help="also write the figures to this JSON file")
    bm.set_defaults(func=_cmd_bench_motion)
    return p


class _LineAboveBars(logging.Handler):
    """Prints regrasp's log lines (e.g. a cache entry recomputed) on their own line above the progress bars."""

    def emit(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm

        tqdm.write(self.format(record), file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run one sub-command; every fault a user can meet ends in one line on stderr and an exit code, never a traceback."""
    from .forked import Terminated, sigterm_unwinds

    args = parser().parse_args(argv)
    log = logging.getLogger("regrasp")
    if not any(isinstance(h, _LineAboveBars) for h in log.handlers):
        log.addHandler(_LineAboveBars(logging.INFO))  # found first: Python's last-resort stderr handler stays unused
    try:
        with sigterm_unwinds():
            return args.func(args)
    except RegraspError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # an I/O fault no step turned into a RegraspError: still one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except Terminated:
        print("error: terminated (SIGTERM)", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
