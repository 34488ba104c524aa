"""`regrasp bench collision`, `bench double-grasps`, `bench motion`, `bench smoothing` and `bench grasps`: the benchmarks of
planner/cli/bench.py, bench_motion.py, bench_smoothing.py and bench_grasps.py with their options, printed as tables (and
written as JSON with --json)."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from planner.cli.arguments import CommandLine, add_json, add_task, positive_int, seed_argument, write_json

if TYPE_CHECKING:
    from planner.model.task import Scene


def _cmd_bench(args: argparse.Namespace) -> int:
    from planner.cli.bench import bench_collision
    from planner.model.task import load_task

    scene = load_task(args.task)
    print(f"benchmarking collision checks on {scene.name} ({args.samples} configurations) ...", file=sys.stderr)
    result = bench_collision(scene, samples=args.samples, seed=args.seed)
    print(result.render())
    if args.json:
        write_json(Path(args.json), result.to_dict())
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
        write_json(Path(args.json), result.to_dict())
    return 0


def _cmd_bench_double_grasps(args: argparse.Namespace) -> int:
    from planner.cli.bench import bench_double_grasps
    from planner.cli.plan import step_params

    params = step_params(args.set or [])  # a bad --set fails here, before any step runs
    return _bench_in_scratch(args, lambda scene, tmp, say: bench_double_grasps(scene, args.seed, args.repeat, tmp, say, params))


def _cmd_bench_motion(args: argparse.Namespace) -> int:
    from planner.cli.bench_motion import bench_motion
    from planner.cli.plan import step_params

    params = step_params(args.set or [])  # a bad --set fails here, before any step runs
    return _bench_in_scratch(args, lambda scene, tmp, say: bench_motion(scene, args.seeds, tmp, say, args.repeat, args.roadmaps,
                                                                        params))


def _cmd_bench_smoothing(args: argparse.Namespace) -> int:
    from planner.cli.bench_smoothing import bench_smoothing
    from planner.cli.plan import step_params

    params = step_params(args.set or [])  # a bad --set fails here, before any step runs
    return _bench_in_scratch(args, lambda scene, tmp, say: bench_smoothing(scene, args.seeds, tmp, say, args.repeat, params))


def _cmd_bench_grasps(args: argparse.Namespace) -> int:
    from planner.cli.bench_grasps import BASELINE, bench_grasps
    from planner.grasping.grasp_list import hand_spec_of, session_grasp_seed
    from planner.model.task import find_task, load_task

    scene = load_task(args.task)
    hands = [args.hand] if args.hand else list(scene.robot.spec.arm_names)
    for hand in hands:
        hand_spec_of(scene.robot.spec, hand)
    result = bench_grasps(scene, find_task(args.task).resolve(), hands, session_grasp_seed(args.seed), args.workers,
                          None if args.no_baseline else (args.baseline or BASELINE), args.repeat,
                          lambda m: print(m, file=sys.stderr))
    print(result.render())
    if args.json:
        write_json(Path(args.json), result.to_dict())
    return 0


def add_bench(line: CommandLine) -> None:
    """`regrasp bench` and its five benchmarks."""
    line.group("bench", "benchmarks, printed as tables", dest="what", metavar="WHAT")
    bc = line.command("collision", "collision checking and forward kinematics timings", _cmd_bench, within="bench")
    add_task(bc)
    bc.add("--samples", type=positive_int, default=2000, help="random configurations timed")
    bc.add("--seed", type=seed_argument, default=0, help="seed of the configurations")
    add_json(bc, "the figures")
    bd = line.command("double-grasps", "grasp configurations, exchange position and double grasps, timed over runs",
                      _cmd_bench_double_grasps, within="bench")
    add_task(bd)
    bd.add("--seed", type=seed_argument, default=0, help="session seed")
    bd.add("--repeat", type=positive_int, default=5, help="runs timed")
    bd.add("--set", action="append", metavar="STEP.PARAM=VALUE",
           help="a step parameter for every run (repeatable; `regrasp params` lists them)")
    add_json(bd, "the figures")
    bm = line.command("motion", "Table I: the motion over seeds with the Super Graph and with RRTConnect alone", _cmd_bench_motion,
                      within="bench")
    add_task(bm)
    bm.add("--seeds", type=positive_int, default=10, help="online seeds 0..N-1 (grasp lists and roadmap: seed 0, cached; see --roadmaps)")
    bm.add("--repeat", type=positive_int, default=1, metavar="K",
           help="plan each seed K times and keep its fastest run (the motion is the same each time; on a busy "
                "machine the fastest is the steadiest figure)")
    bm.add("--roadmaps", type=positive_int, default=1, metavar="K",
           help="plan ours on the roadmaps of session seeds 0..K-1 (each built once, then cached): one roadmap's seed moves "
                "ours' figures as much as a change may")
    bm.add("--set", action="append", metavar="STEP.PARAM=VALUE",
           help="a step parameter for every run (repeatable; `regrasp params` lists them; not motion.planner or motion.strategy)")
    add_json(bm, "the figures")
    bs = line.command("smoothing", "the motion step with its smoothing and without it, per seed: the planning time it adds, "
                      "the motion time it saves", _cmd_bench_smoothing, within="bench")
    add_task(bs)
    bs.add("--seeds", type=positive_int, default=5, help="online seeds 0..N-1 (grasp lists and roadmap: seed 0, cached)")
    bs.add("--repeat", type=positive_int, default=3, metavar="K",
           help="plan each seed K times with and K times without smoothing, alternately, and keep each one's fastest run")
    bs.add("--set", action="append", metavar="STEP.PARAM=VALUE",
           help="a step parameter for every run (repeatable; `regrasp params` lists them); the runs without smoothing set "
                "motion.smooth_checks_per_s and motion.smooth_attempts_per_s to 0")
    add_json(bs, "the figures")
    bg = line.command("grasps", "each hand's grasp list: frames left per stage, grasps, seconds, grasps per second, and the "
                      "ratio to an earlier commit's builder run side by side", _cmd_bench_grasps, within="bench")
    add_task(bg)
    bg.add("--hand", help="only this arm's hand (default: every hand)")
    bg.add("--seed", type=seed_argument, default=0, help="session seed: the lists `plan --seed` computes")
    bg.add("--workers", type=positive_int, default=2, help="processes per list, in both builders")
    bg.add("--baseline", metavar="COMMIT", help="the earlier builder's commit (default: the last with the frame-by-frame search)")
    bg.add("--no-baseline", action="store_true", help="time this code's builder only")
    bg.add("--repeat", type=positive_int, default=1, metavar="K", help="run each builder K times in turn and keep its fastest run")
    add_json(bg, "the figures")
