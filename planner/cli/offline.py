"""`regrasp roadmap` and `regrasp grasps`: the offline computations (the roadmap, one hand's grasp list), built or loaded
from the cache, and their summaries."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from planner.cli.arguments import CommandLine, add_json, add_task, positive_int, seed_argument, write_json
from planner.cli.progress import Bars
from planner.core.errors import RegraspError
from planner.core.paths import DEFAULT_TASK

if TYPE_CHECKING:
    import trimesh

    from planner.model.robot_spec import RobotSpec


def _cmd_roadmap(args: argparse.Namespace) -> int:
    import time

    from planner.model.task import load_task
    from planner.roadmap import roadmap_for
    from planner.roadmap.result import render_stats
    from planner.roadmap.step import session_roadmap_seed

    given = {"nodes": args.nodes, "task_nodes": args.task_nodes}
    params = _option_params("--nodes", "roadmap", {"tree": args.tree, **{k: v for k, v in given.items() if v is not None}})
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
        write_json(Path(args.json), {**stats, "cached": cached, "wall_seconds": round(loaded, 3),
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
        write_json(Path(args.json), result.to_json(round(seconds, 3)))
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


def add_roadmap(line: CommandLine) -> None:
    """`regrasp roadmap`."""
    rm = line.command("roadmap", "build (or load from the cache) the offline roadmap and print its statistics", _cmd_roadmap)
    add_task(rm)
    rm.add("--nodes", type=int, help="Vis-PRM nodes per elementary roadmap (roadmap.nodes: `regrasp params` gives its range "
           "and default)")
    rm.add("--seed", type=seed_argument, default=0, help="session seed (the same roadmap as a session with this seed)")
    rm.add("--task-nodes", type=int, help="nodes added per elementary roadmap around the task's sites (roadmap.task_nodes; "
           "0: Vis-PRM alone)")
    rm.add("--tree", action="store_true", help="the tree variant: SG edges only between different components")
    rm.add("--no-cache", action="store_true", help="rebuild even when a cached roadmap exists")
    add_json(rm, "the statistics")


def add_grasps(line: CommandLine) -> None:
    """`regrasp grasps`."""
    g = line.command("grasps", "compute (or load from the cache) one hand's single-grasp list and print its summary", _cmd_grasps)
    add_task(g, default=None, note="; default: default, unless --robot and --object are given")
    g.add("--robot", metavar="SPEC", help="robot spec (with --object, instead of TASK)")
    g.add("--object", metavar="MESH", help="object mesh file, or 'statuette' (with --robot)")
    g.add("--hand", required=True, help="the arm whose hand grasps, e.g. right or left")
    g.add("--frames", type=positive_int, help="about this many grasp frames (positions x orientations; default: the step's)")
    g.add("--seed", type=seed_argument, default=0, help="session seed: the list `plan --seed` computes (and caches) for the hand")
    g.add("--no-cache", action="store_true", help="recompute even when a cached list exists")
    add_json(g, "the list")
