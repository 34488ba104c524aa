"""The `regrasp` command line: one entry point, one sub-command per capability (it may import both planner and workbench)."""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from planner import __version__
from planner.core.errors import InputError, RegraspError
from planner.core.paths import DEFAULT_TASK, PROJECT_ROOT

from .progress import Bars

if TYPE_CHECKING:
    import trimesh

    from planner.model.robot_spec import RobotSpec
    from planner.model.task import Scene

EXAMPLE_SESSION = PROJECT_ROOT / "sessions" / "default-example"
SCREENSHOT = PROJECT_ROOT / "assets" / "workbench.png"


def _cmd_workbench(args: argparse.Namespace) -> int:
    from .app import run

    run(args.task, args.host, args.port)
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from planner.check import check_task
    from planner.model.task import load_task

    print(f"loading {args.task} ...", file=sys.stderr)
    report = check_task(load_task(args.task))
    print(report.render())
    return 0 if report.ok else 1


def _cmd_bench(args: argparse.Namespace) -> int:
    from planner.bench import bench_collision
    from planner.model.task import load_task

    scene = load_task(args.task)
    print(f"benchmarking collision checks on {scene.name} ({args.samples} configurations) ...", file=sys.stderr)
    result = bench_collision(scene, samples=args.samples, seed=args.seed)
    print(result.render())
    if args.json:
        _write_json(Path(args.json), result.to_dict())
    return 0


def _bench_in_scratch(args: argparse.Namespace, bench: Callable[[Scene, Path, Callable[[str], None]], Any]) -> int:
    """Run a benchmark that writes sessions into a scratch folder (deleted after), print its table and maybe its JSON."""
    import tempfile

    from planner.model.task import load_task

    scene = load_task(args.task)
    with tempfile.TemporaryDirectory(prefix="regrasp-bench-") as tmp:
        result = bench(scene, Path(tmp), lambda m: print(m, file=sys.stderr))
    print(result.render())
    if args.json:
        _write_json(Path(args.json), result.to_dict())
    return 0


def _cmd_bench_double_grasps(args: argparse.Namespace) -> int:
    from planner.bench import bench_double_grasps

    return _bench_in_scratch(args, lambda scene, tmp, say: bench_double_grasps(scene, args.seed, args.repeat, tmp, say))


def _cmd_bench_motion(args: argparse.Namespace) -> int:
    from planner.bench import bench_motion

    return _bench_in_scratch(args, lambda scene, tmp, say: bench_motion(scene, args.seeds, tmp, say, args.repeat))


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


def _cmd_suite(args: argparse.Namespace) -> int:
    import os

    from planner.model.task import load_task
    from planner.suite.executors import LocalExecutor, RayExecutor
    from planner.suite.job import check_until
    from planner.suite.run import run_suite
    from planner.suite.spec import load_suite

    from .suite_report import write_report

    until = check_until(args.until)  # a bad --until or suite file fails here: no folder is made
    spec = load_suite(args.suite)
    local = args.workers or os.cpu_count() or 1
    executor = RayExecutor(args.ray) if args.ray is not None else LocalExecutor(local)
    say = lambda message: print(message, file=sys.stderr, flush=True)
    out = Path(args.out)
    run = run_suite(spec, out, executor, until, args.resume, args.force, local, say)
    report = write_report(run.data, spec, load_task(spec.base_task).environment, out)
    data = run.data
    print(f"suite {spec.name}: {data['succeeded']} of {data['tasks']} tasks succeeded (success_rate {data['success_rate']:.3f}) "
          f"through {data['until']} in {data['wall_seconds']:.0f} s")
    for key, count in data["by_stage"].items():
        print(f"  failed at {key}: {count}")
    print(f"wrote {out / 'suite.json'}, {out / 'suite.csv'} and {report}")
    return 0


def positive_int(text: str) -> int:
    """argparse type of a count: an integer of at least 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got '{text}'")
    return value


def seed_argument(text: str) -> int:
    """argparse type of --seed: a whole number in the range a session file accepts (checked before any folder is made)."""
    from planner.core.bounds import seed_problem

    try:
        value = int(text)
    except ValueError:
        value = text
    problem = seed_problem(value)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return value


def suite_argument(text: str) -> Path:
    """argparse type of SUITE: a suite file, or a name in assets/suites/."""
    from planner.suite.spec import find_suite

    try:
        return find_suite(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def params_text() -> str:
    """Every pipeline step's parameters with their types, defaults, ranges and units, as `regrasp params` prints them."""
    from planner.core.steps import param_bounds
    from planner.pipeline import PIPELINE

    lines = []
    for step in PIPELINE:
        defaults, bounds = step.params(), param_bounds(step.params)
        lines.append(f"{step.name}: {step.summary}")
        for f in dataclasses.fields(step.params):
            default, bound = f"default {getattr(defaults, f.name)!r}", bounds.get(f.name)
            lines.append(f"  {step.name}.{f.name:<22} {f.type:<6} {default:<16} {bound.describe() if bound else ''}".rstrip())
        lines.append("")
    lines.append("Set one with `regrasp plan TASK --out DIR --set STEP.PARAM=VALUE` (the value is read as JSON, else as a string).")
    return "\n".join(lines)


def _cmd_params(args: argparse.Namespace) -> int:
    print(params_text())
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from .app import run

    run(None, args.host, args.port, session=Path(args.session))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from .export import export_html

    export_html(Path(args.session), Path(args.html))
    print(f"wrote {args.html}")
    return 0


def _cmd_screenshot(args: argparse.Namespace) -> int:
    from .screenshot import screenshot

    size = screenshot(Path(args.session), Path(args.out))
    print(f"wrote {args.out} ({size // 1024} kB)")
    return 0


def _cmd_roadmap(args: argparse.Namespace) -> int:
    import time

    from planner.model.task import load_task
    from planner.roadmap import roadmap_for
    from planner.roadmap.result import render_stats
    from planner.roadmap.step import session_roadmap_seed

    params = _option_params("--nodes", "roadmap", {"nodes": args.nodes, "tree": args.tree})
    scene = load_task(args.task)
    start = time.perf_counter()
    with Bars() as bars:
        roadmap, seconds = roadmap_for(scene, params, session_roadmap_seed(args.seed), not args.no_cache, bars.start("roadmap"))
    cached = not seconds
    stats = roadmap.stats()
    print(render_stats(stats, seconds))
    loaded = time.perf_counter() - start
    print(f"loaded from the cache in {loaded:.2f} s" if cached else f"built in {loaded:.2f} s (cached for next time)")
    if args.json:
        _write_json(Path(args.json), {**stats, "cached": cached, "wall_seconds": round(loaded, 3),
                                      "stage_seconds": {k: round(v, 3) for k, v in seconds.items()}})
    return 0


def _cmd_grasps(args: argparse.Namespace) -> int:
    import math
    import time

    from planner.grasping.grasp_list import GraspParams, grasp_list, session_grasp_seed

    frames = {} if args.frames is None else {"orientations": math.ceil(args.frames / GraspParams().positions)}
    params = _option_params("--frames", "pick_grasps", frames)
    robot_spec, mesh, what = _grasp_inputs(args)
    start = time.perf_counter()
    with Bars() as bars:
        progress = bars.start(f"{args.hand} grasps")
        result, cached = grasp_list(robot_spec, args.hand, mesh, params, session_grasp_seed(args.seed), progress,
                                    use_cache=not args.no_cache)
    seconds = time.perf_counter() - start
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


def _option_params(option: str, step: str, values: dict[str, Any]) -> Any:
    """A step's parameters set by a command's option, checked against their ranges before anything loads or runs."""
    from planner.pipeline import step_named

    try:
        return step_named(step).make_params(values)
    except RegraspError as exc:
        raise RegraspError(f"{option}: {exc}") from exc


def _grasp_inputs(args: argparse.Namespace) -> tuple[RobotSpec, trimesh.Trimesh, str]:
    """The robot spec, the object mesh and a label, from TASK or from --robot and --object."""
    from planner.check import require_valid
    from planner.model.object_mesh import load_object_mesh
    from planner.model.robot_spec import load_robot_spec
    from planner.model.task import BUILTIN_OBJECTS, load_task

    if args.robot or args.object:
        if not (args.robot and args.object) or args.task:
            raise RegraspError("give either TASK, or both --robot and --object")
        mesh_path = BUILTIN_OBJECTS.get(args.object, Path(args.object))
        return load_robot_spec(args.robot), load_object_mesh(mesh_path), f"{mesh_path.name} ({args.robot})"
    scene = load_task(args.task or DEFAULT_TASK)
    require_valid(scene, lambda message: print(message, file=sys.stderr))
    return scene.robot.spec, scene.object_mesh, f"{scene.object_name} (task {scene.name})"


def _write_json(path: Path, data: dict) -> None:
    from planner.core.results import atomic_write_text

    atomic_write_text(path, json.dumps(data, indent=2))


def task_argument(text: str) -> Path:
    """argparse type of TASK: a task file, or a name in assets/tasks/ ("did you mean" and the names otherwise)."""
    from planner.model.task import find_task

    try:
        return find_task(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


class _Help(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps epilogs as written and shows every option's default (not the empty ones: None, False)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default in (None, False, argparse.SUPPRESS) or "%(default)" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


def _pipeline_epilog() -> str:
    """The steps of `regrasp plan`, for its help."""
    from planner.pipeline import PIPELINE

    steps = "\n".join(f"  {s.name:<14} {s.summary}" for s in PIPELINE)
    return f"steps, in order (STEP in --until and --set; `regrasp params` lists every parameter):\n{steps}"


def _add_task(p: argparse.ArgumentParser, default: str | None = "default", note: str = "") -> None:
    p.add_argument("task", nargs="?", default=default, type=task_argument, metavar="TASK",
                   help=f"a task file, or the name of one in assets/tasks/ (e.g. default, baxter){note}")


def _add_server(p: argparse.ArgumentParser) -> None:
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (0.0.0.0: every interface)")
    p.add_argument("--port", type=int, default=8080, help="port to serve on; an error if it is in use")


def _add_json(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--json", metavar="FILE", help=f"also write {what} to this JSON file")


def parser() -> argparse.ArgumentParser:
    """The whole command line: every sub-command, each option with its help and default."""
    p = argparse.ArgumentParser(prog="regrasp", formatter_class=_Help,
                                description="Pick-and-place with two-hand regrasping: planner and workbench.",
                                epilog="Start with `regrasp workbench` and open the address it prints.")
    p.add_argument("--version", action="version", version=f"regrasp {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    def command(name: str, text: str, func: Callable[[argparse.Namespace], int], parent: Any = sub, **kw: Any) -> argparse.ArgumentParser:
        """A sub-command: `text` is its one-line help and, capitalised, its description."""
        c = parent.add_parser(name, help=text, description=text[0].upper() + text[1:] + ".", formatter_class=_Help, **kw)
        c.set_defaults(func=func)
        return c

    w = command("workbench", "start the web workbench (viser) on a task", _cmd_workbench)
    _add_task(w)
    _add_server(w)
    c = command("check", "validate a task and print a summary; exit 1 if it is not a valid regrasping task", _cmd_check)
    _add_task(c)
    pl = command("plan", "run the pipeline headless into a session folder", _cmd_plan, epilog=_pipeline_epilog())
    _add_task(pl)
    pl.add_argument("--out", required=True, metavar="DIR", help="session folder to write")
    pl.add_argument("--seed", type=seed_argument, default=0, help="session seed (each step's generator is derived from it)")
    pl.add_argument("--until", metavar="STEP", help="last step to run, e.g. double-grasps (default: every step)")
    pl.add_argument("--resume", action="store_true", help="continue the session in --out where it stopped")
    pl.add_argument("--force", action="store_true", help="replace an existing session in --out")
    pl.add_argument("--set", action="append", metavar="STEP.PARAM=VALUE",
                    help="a step parameter, checked against its range before any step runs (repeatable; `regrasp params` lists "
                         "them with their ranges and units)")
    su = command("suite", "run every task of a suite through the pipeline (local workers or Ray) and report", _cmd_suite,
                 epilog="The folder gets suite.json, suite.csv, report.html (open it in a browser), tasks/ (the generated task "
                        "files), sessions/ (one session per task, for `regrasp replay`) and results/ (what --resume keeps).")
    su.add_argument("suite", type=suite_argument, metavar="SUITE", help="a suite file, or the name of one in assets/suites/ (e.g. default)")
    su.add_argument("--out", required=True, metavar="DIR", help="folder to write the suite's tasks, sessions and report into")
    where = su.add_mutually_exclusive_group()
    where.add_argument("--workers", type=positive_int, metavar="N", help="local worker processes (default: the number of CPUs)")
    where.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                       help="run the tasks as Ray tasks: on the cluster at ADDRESS, or on a local Ray when none is given "
                            "(needs pip install 'regrasp[cluster]')")
    su.add_argument("--until", metavar="STEP", help="last step of every task, e.g. double-grasps (default: every step, through motion)")
    su.add_argument("--resume", action="store_true", help="continue the suite in --out: finished tasks are kept, the others run")
    su.add_argument("--force", action="store_true", help="replace an existing suite in --out")
    command("params", "list every step's parameters with their types, defaults, ranges and units", _cmd_params)
    r = command("replay", "open the workbench on a saved session (nothing is recomputed)", _cmd_replay)
    r.add_argument("session", metavar="SESSION", help="session folder")
    _add_server(r)
    e = command("export", "export a saved session as one self-contained HTML file", _cmd_export)
    e.add_argument("session", metavar="SESSION", help="session folder")
    e.add_argument("--html", required=True, metavar="FILE", help="HTML file to write")
    s = command("screenshot", "picture the workbench replaying a session (the README's image), with headless chromium", _cmd_screenshot)
    s.add_argument("session", nargs="?", default=str(EXAMPLE_SESSION), metavar="SESSION", help="session folder")
    s.add_argument("--out", default=str(SCREENSHOT), metavar="PNG", help="image to write")
    rm = command("roadmap", "build (or load from the cache) the offline roadmap and print its statistics", _cmd_roadmap)
    _add_task(rm)
    rm.add_argument("--nodes", type=int, default=50, help="nodes per elementary roadmap (roadmap.nodes: `regrasp params` gives its range)")
    rm.add_argument("--seed", type=seed_argument, default=0, help="session seed (the same roadmap as a session with this seed)")
    rm.add_argument("--tree", action="store_true", help="the tree variant: SG edges only between different components")
    rm.add_argument("--no-cache", action="store_true", help="rebuild even when a cached roadmap exists")
    _add_json(rm, "the statistics")
    g = command("grasps", "compute (or load from the cache) one hand's single-grasp list and print its summary", _cmd_grasps)
    _add_task(g, default=None, note="; default: default, unless --robot and --object are given")
    g.add_argument("--robot", metavar="SPEC", help="robot spec (with --object, instead of TASK)")
    g.add_argument("--object", metavar="MESH", help="object mesh file, or 'statuette' (with --robot)")
    g.add_argument("--hand", required=True, help="the arm whose hand grasps, e.g. right or left")
    g.add_argument("--frames", type=positive_int, help="about this many grasp frames (positions x orientations; default: the step's)")
    g.add_argument("--seed", type=seed_argument, default=0, help="session seed: the list `plan --seed` computes (and caches) for the hand")
    g.add_argument("--no-cache", action="store_true", help="recompute even when a cached list exists")
    _add_json(g, "the list")
    b = sub.add_parser("bench", help="benchmarks, printed as tables", description="Benchmarks, printed as tables.", formatter_class=_Help)
    bsub = b.add_subparsers(dest="what", required=True, metavar="WHAT")
    bc = command("collision", "collision checking and forward kinematics timings", _cmd_bench, parent=bsub)
    _add_task(bc)
    bc.add_argument("--samples", type=positive_int, default=2000, help="random configurations timed")
    bc.add_argument("--seed", type=seed_argument, default=0, help="seed of the configurations")
    _add_json(bc, "the figures")
    bd = command("double-grasps", "grasp configurations, exchange position and double grasps, timed over runs", _cmd_bench_double_grasps,
                 parent=bsub)
    _add_task(bd)
    bd.add_argument("--seed", type=seed_argument, default=0, help="session seed")
    bd.add_argument("--repeat", type=positive_int, default=5, help="runs timed")
    _add_json(bd, "the figures")
    bm = command("motion", "Table I: the motion over seeds with the Super Graph and with RRTConnect alone", _cmd_bench_motion, parent=bsub)
    _add_task(bm)
    bm.add_argument("--seeds", type=positive_int, default=10, help="online seeds 0..N-1 (the grasp lists and roadmap: seed 0, cached)")
    bm.add_argument("--repeat", type=positive_int, default=1, metavar="K",
                    help="plan each seed K times and keep its fastest run (the motion is the same each time; on a busy "
                         "machine the fastest is the steadiest figure)")
    _add_json(bm, "the figures")
    return p


class _LineAboveBars(logging.Handler):
    """Prints regrasp's log lines (e.g. a cache entry recomputed) on their own line above the progress bars."""

    def emit(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm

        tqdm.write(self.format(record), file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run one sub-command; every fault a user can meet ends in one line on stderr and an exit code, never a traceback."""
    from planner.core.forked import Terminated, sigterm_unwinds

    p = parser()
    args = p.parse_args(argv)
    if args.command is None:
        p.print_help()
        return 0
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
